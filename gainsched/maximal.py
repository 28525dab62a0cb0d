"""Maximal-coordinate formulation: a free rigid body plus a link force model.

DESIGN.md section 2, last paragraph. The vehicle is a free 6-DOF rigid body in
the circle frame C (inertial, only rotated); the tether is a force model acting
at the attachment point ``p_t = p_q + R_CB p_e`` (``p_e = (-L_e, 0, 0)``) and
anchored at the origin. This is the simulator for what the reduced model of
:mod:`gainsched.model` cannot express (slack, stretch); where both apply they
must agree.

State ``x = (p_q, v_q, q_CB, omega_B)``, shape (..., 13): COG position (m) and
velocity (m/s) in C, the unit quaternion body->C (Hamilton, scalar first) and
the body rates (rad/s) in B. Input ``u = (T1..T4)`` commanded motor thrusts, N.

    m p_q''  = R (0, 0, T_C) + m g_C - f_t n + F_eff                 (paper eq. 3)
    J omega' = sum L_i x T_i + tau_M + p_e x (R^T (-f_t n))
               - omega x J omega + tau_eff                           (paper eqs. 6, 8)
    p_t''    = p_q'' + R (omega' x p_e + omega x (omega x p_e))      (paper eq. 9, corrected)

with ``n = p_t / |p_t|``. Link models for the tension ``f_t`` (N):

- ``"rigid"``: the holonomic constraint ``c = (|p_t|^2 - rho^2) / 2 = 0``; ``f_t``
  is the Lagrange multiplier solving ``c'' + 2 a c' + b^2 c = 0`` (Baumgarte
  stabilisation with rates ``(a, b)``, 1/s). Bilateral: may come out negative.
- ``"spring-damper"``: tension-only, ``f_t = max(0, k (|p_t| - rho) + c d|p_t|/dt)``.
"""

from __future__ import annotations

import numpy as np

from .config import N_STATE
from .effects import Kinematics
from .rotations import (
    euler_zyx_from_matrix,
    matrix_from_quaternion,
    quaternion_from_matrix,
    skew,
)

__all__ = ["MaximalModel", "maximal_from_reduced", "reduced_from_maximal", "N_MAXIMAL"]

N_MAXIMAL = 13  # p (3), v (3), q (4), omega (3)
LINKS = ("rigid", "spring-damper")


def _mv(R, v):
    """Batched matrix-vector product ``R @ v``, shapes (..., 3, 3), (..., 3) -> (..., 3)."""
    return np.einsum("...ij,...j->...i", R, v)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _cross(a, b):
    """Cross product over the last axis (faster than ``np.cross`` for small batches)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], -1)


class MaximalModel:
    """Free rigid body plus a tether link model, sharing parameters and effects with ``model``.

    Parameters
    ----------
    model : gainsched.model.Model
        Mass, inertia, geometry, allocation, gravity and effects come from it.
    link : {"rigid", "spring-damper"}, optional
        Default: the config's ``tether.link``.
    stiffness : float, N/m, optional
        Spring-damper stiffness k (default: the config's ``tether.stiffness``).
    damping : float, N s/m, optional
        Spring-damper damping c (default: the config's ``tether.damping``).
    baumgarte : (float, float), 1/s
        Rigid link constraint stabilisation rates (a, b): ``c'' + 2 a c' + b^2 c = 0``.
    """

    def __init__(self, model, link=None, stiffness=None, damping=None, baumgarte=(10.0, 10.0)):
        if model.n_extra > 0:
            raise NotImplementedError(
                "stateful effects (e.g. motor_lag) are not supported in maximal coordinates"
            )
        tether = model.config.tether
        self.model = model
        self.link = tether.link if link is None else link
        if self.link not in LINKS:
            raise ValueError(f"link must be one of {LINKS}, got {self.link!r}")
        self.k = float(tether.stiffness if stiffness is None else stiffness)
        self.c = float(tether.damping if damping is None else damping)
        self.baumgarte = tuple(float(b) for b in baumgarte)
        self.J_inv = np.linalg.inv(model.J)
        self._S = skew(model.p_e)  # [p_e x]

    # ------------------------------------------------------------------ dynamics
    def evaluate(self, x, u, alpha):
        """State derivative and tension.

        Parameters
        ----------
        x : ndarray, shape (..., 13)
            ``(p_q [m], v_q [m/s], q_CB, omega_B [rad/s])``, p and v in C.
        u : ndarray, shape (..., 4), N
            Commanded motor thrusts.
        alpha : float or ndarray, rad
            Tilt of the circle plane (enters through gravity only).

        Returns
        -------
        x_dot : ndarray, shape (..., 13)
        tension : ndarray, shape (...), N
            ``f_t``; the force on the vehicle is ``-f_t p_t / |p_t|`` at the attachment point.
        """
        md = self.model
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        m, J, p_e = md.m, md.J, md.p_e
        p, v, q, w = x[..., 0:3], x[..., 3:6], x[..., 6:10], x[..., 10:13]
        qn = q / np.sqrt(_dot(q, q))[..., None]
        R = matrix_from_quaternion(qn)
        kin = Kinematics(R, v, w)

        # thrust after the (stateless) thrust modifiers, then the effect wrenches
        T = u
        no_state = np.zeros(x.shape[:-1] + (0,))
        for eff in md.effects:
            T = eff.modify_thrust(T, kin, no_state)
        F, tau = md.effect_wrench(T, kin)
        shape = F.shape
        T_C = np.sum(T, axis=-1)
        F0 = R[..., :, 2] * T_C[..., None] + m * md.g_C(alpha) + F  # without the tether
        tau0 = T @ md.alloc[1:].T + tau - _cross(w, w @ J.T)

        # attachment point: position, velocity, direction
        w_pe = w @ self._S  # omega x p_e
        p_t = p + _mv(R, p_e)
        v_t = v + _mv(R, w_pe)
        dist = np.sqrt(_dot(p_t, p_t))
        n = p_t / dist[..., None]
        n_B = np.einsum("...ji,...j->...i", R, n)
        lever = n_B @ self._S.T  # p_e x n_B: tether torque per newton of tension is -lever

        if self.link == "rigid":
            # c'' = c0 - kf f with the tension-free part c0 and kf = |p_t| (1/m + l^T J^-1 l)
            a_q0 = F0 / m
            wd0 = tau0 @ self.J_inv.T
            a_t0 = a_q0 + _mv(R, wd0 @ self._S + _cross(w, w_pe))
            c0 = _dot(v_t, v_t) + _dot(p_t, a_t0)
            kf = dist * (1.0 / m + _dot(lever, lever @ self.J_inv.T))
            a, b = self.baumgarte
            c = 0.5 * (dist * dist - md.rho**2)
            c_dot = _dot(p_t, v_t)
            f_t = (c0 + 2 * a * c_dot + b * b * c) / kf
        else:
            stretch = dist - md.rho
            rate = _dot(n, v_t)
            f_t = np.maximum(0.0, self.k * stretch + self.c * rate)

        a_q = (F0 - f_t[..., None] * n) / m
        w_dot = (tau0 - f_t[..., None] * lever) @ self.J_inv.T
        # quaternion kinematics q' = q (x) (0, omega) / 2
        qw, qv = q[..., :1], q[..., 1:]
        q_dot = 0.5 * np.concatenate([-_dot(qv, w)[..., None], qw * w + _cross(qv, w)], -1)
        x_dot = np.concatenate(
            [np.broadcast_to(v, shape), a_q, np.broadcast_to(q_dot, shape[:-1] + (4,)), w_dot], -1
        )
        return x_dot, f_t

    def f(self, x, u, alpha):
        """State derivative, shape (..., 13). See :meth:`evaluate`."""
        return self.evaluate(x, u, alpha)[0]

    def tension(self, x, u, alpha):
        """Tether tension f_t, shape (...), N (0 when the spring-damper link is slack)."""
        return self.evaluate(x, u, alpha)[1]

    def energy(self, x, alpha):
        """Mechanical energy (kinetic + gravitational potential, no spring energy), J."""
        md = self.model
        p, v, w = x[..., 0:3], x[..., 3:6], x[..., 10:13]
        kinetic = 0.5 * md.m * _dot(v, v) + 0.5 * np.einsum("...i,ij,...j", w, md.J, w)
        return kinetic - md.m * _dot(md.g_C(alpha), p)


# ---------------------------------------------------------------------- conversions
def maximal_from_reduced(model, z):
    """Maximal state (..., 13) from the reduced state z (..., >= 10) (DESIGN.md section 1).

    ``R_CB = Rz(chi + xi) Ry(theta) Rx(phi)``, ``p_q = rho e(delta, xi) + L_e x_B``,
    COG velocity from :meth:`gainsched.model.Model.kinematics`; omega_B is copied.
    """
    z = np.asarray(z, dtype=float)
    R, e, _, _, v_q, _ = model.kinematics(z)
    p_q = model.rho * e - _mv(R, model.p_e)
    return np.concatenate([p_q, v_q, quaternion_from_matrix(R), z[..., 7:10]], -1)


def reduced_from_maximal(model, x, xi_ref=None):
    """Reduced state (..., 10) from the maximal state x (..., 13).

    ``delta, xi`` are the spherical angles of the attachment point, ``delta', xi'``
    its angular rates (the radial rate, non-zero only for an elastic link, is
    dropped); ``phi, theta, psi`` the Z-Y-X Euler angles of ``R_CB`` and
    ``chi = psi - xi`` wrapped to [-pi, pi). ``xi`` is in (-pi, pi], or unwrapped
    to the branch nearest ``xi_ref`` (rad, broadcastable) when given.
    """
    x = np.asarray(x, dtype=float)
    p, v, q, w = x[..., 0:3], x[..., 3:6], x[..., 6:10], x[..., 10:13]
    R = matrix_from_quaternion(q / np.sqrt(_dot(q, q))[..., None])
    p_t = p + _mv(R, model.p_e)
    v_t = v + _mv(R, _cross(w, np.broadcast_to(model.p_e, w.shape)))
    rxy = np.hypot(p_t[..., 0], p_t[..., 1])
    dist = np.sqrt(_dot(p_t, p_t))
    delta = np.arctan2(rxy, p_t[..., 2])
    xi = np.arctan2(p_t[..., 1], p_t[..., 0])
    if xi_ref is not None:
        xi = xi + 2 * np.pi * np.round((np.asarray(xi_ref) - xi) / (2 * np.pi))
    sd, cd, sx, cx = np.sin(delta), np.cos(delta), np.sin(xi), np.cos(xi)
    e_d = np.stack([cd * cx, cd * sx, -sd], -1)  # de/ddelta
    e_x = np.stack([-sx, cx, np.zeros_like(sx)], -1)  # (de/dxi) / sin(delta)
    delta_dot = _dot(e_d, v_t) / dist
    xi_dot = _dot(e_x, v_t) / (dist * sd)
    phi, theta, psi = euler_zyx_from_matrix(R)
    chi = (psi - xi + np.pi) % (2 * np.pi) - np.pi
    z = np.stack([delta, xi, delta_dot, xi_dot, phi, theta, chi], -1)
    return np.concatenate([z, w], -1)[..., :N_STATE]
