"""Maximal-coordinate formulation: a free rigid body plus a link force model.

The second formulation of the plant (docs/architecture.md). The vehicle is a
free 6-DOF rigid body in the circle frame C (inertial, only rotated); the tether
is a force model acting at the attachment point ``p_t = p_q + R_CB p_e``
(``p_e = (-L_e, 0, 0)``) and anchored at the origin. This is the simulator for
what the reduced model of :mod:`gainsched.model.reduced` cannot express (slack,
stretch); where both apply they must agree.

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
- ``"spring-damper"``, ``"sls"``, ``"lumped-mass"``: the tension-only elastic
  links of :mod:`gainsched.model.links` (sec. 3.1 of the book chapter cited there).
  The link force ``F_t`` replaces ``-f_t n`` above (for the chain it acts along the
  last segment, not along ``n``) and the link's own states come last.

Stateful effects (a motor lag, a battery, the flight time) carry their states as in the
reduced model, after the rigid-body ones, with the same derivatives
(:meth:`gainsched.model.reduced.Model.effect_state_rates`): ``x = (p_q, v_q, q_CB, omega_B,
s_effects, s_link)``, shape (..., 13 + n_extra + n_link).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._vec import broadcast, cross, dot, mtv, mv
from ..constants import N_STATE
from ..rotations import (
    matrix_entries_from_quaternion,
    matrix_from_quaternion,
    quaternion_from_matrix,
    skew,
)
from .effects import Kinematics
from .geometry import (
    attachment_from_cog,
    cog_from_attachment,
    pose_angles_from_pose,
    tether_direction,
    wrap_angle,
)
from .links import ELASTIC_LINKS, LinkOutput, SpringDamper, link_from_tether

__all__ = ["MaximalModel", "maximal_from_reduced", "reduced_from_maximal", "N_MAXIMAL"]

N_MAXIMAL = 13  # p (3), v (3), q (4), omega (3); elastic links append their states
LINKS = ("rigid", *ELASTIC_LINKS)
RK4_REACH = 0.25  # |lambda dt| per RK4 substep: see MaximalModel.substeps


class MaximalModel:
    """Free rigid body plus a tether link model, sharing parameters and effects with ``model``.

    Parameters
    ----------
    model : gainsched.model.reduced.Model
        Mass, inertia, geometry, allocation, gravity and effects come from it.
    link : {"rigid", "spring-damper", "sls", "lumped-mass"} or link object, optional
        Default: the config's ``tether.link`` with its parameters. A name takes the
        other link parameters from the config; an object from :mod:`gainsched.model.links`
        is used as it is.
    stiffness : float, N/m, optional
        Overrides ``tether.stiffness`` (spring-damper k, SLS parallel k_p, chain k).
    damping : float, N s/m, optional
        Overrides ``tether.damping`` (spring-damper c, SLS parallel c, chain c).
    baumgarte : (float, float), 1/s
        Rigid link constraint stabilisation rates (a, b): ``c'' + 2 a c' + b^2 c = 0``.

    Attributes
    ----------
    link : str
        The link model's name.
    link_model : links.SpringDamper, links.StandardLinearSolid, links.LumpedMassChain or None
        None for the rigid link.
    n_x : int
        State size: 13, the effects' states (``model.n_extra``), the link's states.
    i_link : int
        Where the link's states start in x (``13 + model.n_extra``).
    """

    def __init__(self, model, link=None, stiffness=None, damping=None, baumgarte=(10.0, 10.0)):
        tether = model.config.tether
        self.model = model
        self.k = float(tether.stiffness if stiffness is None else stiffness)
        self.c = float(tether.damping if damping is None else damping)
        if link is None or isinstance(link, str):
            name = tether.link if link is None else link
            if name not in LINKS:
                raise ValueError(f"link must be one of {LINKS}, got {name!r}")
            if name == "spring-damper":  # no config fields beyond k, c
                self.link_model = SpringDamper(model.rho, self.k, self.c)
            else:
                self.link_model = link_from_tether(
                    dataclasses.replace(tether, link=name, stiffness=self.k, damping=self.c)
                )
        else:
            self.link_model = link
        self.link = "rigid" if self.link_model is None else self.link_model.kind
        self.n_link = 0 if self.link_model is None else int(self.link_model.n_states)
        self.i_link = N_MAXIMAL + model.n_extra
        self.n_x = self.i_link + self.n_link
        self.baumgarte = tuple(float(b) for b in baumgarte)
        self.J_inv = np.linalg.inv(model.J)
        self._S = skew(model.p_e)  # [p_e x]

    # ------------------------------------------------------------------ dynamics
    def evaluate(self, x, u, alpha, gamma=0.0):
        """State derivative and tension.

        Parameters
        ----------
        x : ndarray, shape (..., n_x)
            ``(p_q [m], v_q [m/s], q_CB, omega_B [rad/s], effect states, link states)``,
            p and v in C.
        u : ndarray, shape (..., 4), N
            Commanded motor thrusts.
        alpha : float or ndarray, rad
            Tilt of the circle plane (enters through gravity, and the wind's direction).
        gamma : float or ndarray, rad
            Heading of the circle plane (enters through the wind's direction only).

        Returns
        -------
        x_dot : ndarray, shape (..., n_x)
        tension : ndarray, shape (...), N
            ``f_t``; the force on the vehicle is ``-f_t p_t / |p_t|`` at the attachment point
            (chain: ``f_t`` along the last segment). Elastic links: >= 0, see :meth:`slack`.
        """
        return self._evaluate(x, u, alpha, gamma)[:2]

    def _evaluate(self, x, u, alpha, gamma=0.0):
        md = self.model
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        m, p_e = md.m, md.p_e
        p, v, q, w = x[..., 0:3], x[..., 3:6], x[..., 6:10], x[..., 10:13]
        qn = q / np.sqrt(dot(q, q))[..., None]
        R = matrix_from_quaternion(qn)
        kin = Kinematics(R, v, w, p, alpha, gamma, md.wind_I)
        # thrust after the stateful effects and the thrust modifiers; all but the tether
        x_e = x[..., N_MAXIMAL:self.i_link]
        T = md.thrust_from_effect_states(x_e, u, kin)
        F0, tau0 = md.body_wrench(T, kin, alpha)
        shape = F0.shape

        # attachment point: position, velocity, direction
        w_pe = w @ self._S  # omega x p_e
        p_t = attachment_from_cog(p, R, p_e)
        v_t = v + mv(R, w_pe)
        link = None
        if self.link_model is not None:
            link = self.link_model.evaluate(p_t, v_t, x[..., self.i_link:], md.g_C(alpha))
            F_B = mtv(R, link.force)
            a_q = (F0 + link.force) / m
            w_dot = (tau0 + F_B @ self._S.T) @ self.J_inv.T  # p_e x F_B
            f_t = link.tension
        else:
            a_q, w_dot, f_t = self._rigid(F0, tau0, R, w, w_pe, p_t, v_t)
        # quaternion kinematics q' = q (x) (0, omega) / 2
        qw, qv = q[..., :1], q[..., 1:]
        q_dot = 0.5 * np.concatenate([-dot(qv, w)[..., None], qw * w + cross(qv, w)], -1)
        parts = [broadcast(v, shape), a_q, broadcast(q_dot, shape[:-1] + (4,)), w_dot]
        parts += [broadcast(r, shape[:-1] + r.shape[-1:])
                  for r in md.effect_state_rates(x_e, u, kin)]
        if link is not None:
            sd = link.state_dot
            parts.append(broadcast(sd, shape[:-1] + sd.shape[-1:]))
        return np.concatenate(parts, -1), f_t, link

    def _rigid(self, F0, tau0, R, w, w_pe, p_t, v_t):
        """COG acceleration, omega' and multiplier f_t of the Baumgarte-stabilised constraint."""
        md, m = self.model, self.model.m
        dist = np.sqrt(dot(p_t, p_t))
        n = p_t / dist[..., None]
        lever = md.tether_lever(mtv(R, n))
        # c'' = c0 - kf f with the tension-free part c0 and kf = |p_t| (1/m + l^T J^-1 l)
        a_q0 = F0 / m
        wd0 = tau0 @ self.J_inv.T
        a_t0 = a_q0 + mv(R, wd0 @ self._S + cross(w, w_pe))
        c0 = dot(v_t, v_t) + dot(p_t, a_t0)
        kf = dist * (1.0 / m + dot(lever, lever @ self.J_inv.T))
        a, b = self.baumgarte
        c = 0.5 * (dist * dist - md.rho**2)
        c_dot = dot(p_t, v_t)
        f_t = (c0 + 2 * a * c_dot + b * b * c) / kf
        a_q = (F0 - f_t[..., None] * n) / m
        w_dot = (tau0 - f_t[..., None] * lever) @ self.J_inv.T
        return a_q, w_dot, f_t

    def f(self, x, u, alpha, gamma=0.0):
        """State derivative, shape (..., n_x). See :meth:`evaluate`."""
        return self.evaluate(x, u, alpha, gamma)[0]

    def tension(self, x, u, alpha, gamma=0.0):
        """Tether tension f_t, shape (...), N (0 when an elastic link is slack)."""
        return self.evaluate(x, u, alpha, gamma)[1]

    def slack(self, x, u, alpha, gamma=0.0):
        """Whether the tether is slack, shape (...), bool.

        Rigid link: the multiplier came out negative (the constraint would push).
        Elastic links: some part of the link carries no tension (force law <= 0;
        for the chain, any segment).
        """
        _, f_t, link = self._evaluate(x, u, alpha, gamma)
        return f_t < 0 if link is None else link.slack

    def link_output(self, x, alpha) -> LinkOutput:
        """The elastic link's force, tension, slack flag and state rate at x (not for rigid)."""
        if self.link_model is None:
            raise ValueError("the rigid link has no link output (its force needs the input)")
        x = np.asarray(x, dtype=float)
        p_t, v_t = self._attachment(x)
        return self.link_model.evaluate(p_t, v_t, x[..., self.i_link:], self.model.g_C(alpha))

    def _attachment(self, x):
        """Attachment point position (m) and velocity (m/s) in C, shapes (..., 3)."""
        p, v, q, w = x[..., 0:3], x[..., 3:6], x[..., 6:10], x[..., 10:13]
        R = matrix_from_quaternion(q / np.sqrt(dot(q, q))[..., None])
        return attachment_from_cog(p, R, self.model.p_e), v + mv(R, w @ self._S)

    def energy(self, x, alpha):
        """Mechanical energy of the vehicle (kinetic + gravitational potential), J.

        Excludes the link (see :meth:`link_energy`)."""
        md = self.model
        p, v, w = x[..., 0:3], x[..., 3:6], x[..., 10:13]
        kinetic = 0.5 * md.m * dot(v, v) + 0.5 * np.einsum("...i,ij,...j", w, md.J, w)
        return kinetic - md.m * dot(md.g_C(alpha), p)

    def link_energy(self, x, alpha):
        """Energy held by an elastic link (springs; chain nodes' kinetic and potential), J."""
        if self.link_model is None:
            return np.zeros(np.shape(x)[:-1])
        p_t, v_t = self._attachment(np.asarray(x, dtype=float))
        return self.link_model.energy(p_t, v_t, x[..., self.i_link:], self.model.g_C(alpha))

    def power_loss(self, x, alpha):
        """Power dissipated in an elastic link (dampers, and the tension-only clip), W >= 0.

        With no thrust and no effects, ``d/dt (energy + link_energy) = -power_loss``.
        """
        if self.link_model is None:
            return np.zeros(np.shape(x)[:-1])
        p_t, v_t = self._attachment(np.asarray(x, dtype=float))
        return self.link_model.power_loss(p_t, v_t, x[..., self.i_link:],
                                          self.model.g_C(alpha))

    # ------------------------------------------------------------------ simulation
    def from_reduced(self, z, tension=None, u=None, alpha=0.0, gamma=0.0):
        """Maximal state (..., n_x) from the reduced state z (..., 10 or n_z), link in
        equilibrium.

        The effect states are z's after its first 10 when z has them (``model.n_z``
        entries), else at rest at the thrusts ``u``
        (:meth:`~gainsched.model.reduced.Model.steady_effect_states`). The elastic link
        starts stretched to the static elongation of ``tension`` (N) along ``e(delta,
        xi)``, its own states relaxed at that tension (SLS: ``s_p = f / k_p``; chain: nodes
        evenly on the straight line, moving with it). Default ``tension``: the rigid-link
        tension of the reduced model at ``(z, u, alpha)`` (``u`` default: hover thrust ``m
        g / 4`` per motor), clipped at 0. The rigid link ignores ``tension``
        (:func:`maximal_from_reduced`).
        """
        md = self.model
        z = np.asarray(z, dtype=float)
        u = np.full(4, md.m * md.g / 4) if u is None else np.asarray(u, dtype=float)
        if z.shape[-1] >= md.n_z:
            z = z[..., :md.n_z]
        else:
            rest = md.steady_effect_states(u)
            z = np.concatenate([z[..., :N_STATE], np.broadcast_to(
                rest, z.shape[:-1] + rest.shape[-1:])], -1)
        x_e = z[..., N_STATE:]
        if self.link_model is None:
            return np.concatenate([maximal_from_reduced(md, z), x_e], -1)
        if tension is None:
            tension = np.maximum(md.evaluate(z, u, alpha, gamma).tension, 0.0)
        x = maximal_from_reduced(md, z, stretch=self.link_model.stretch(tension))
        p_t, v_t = self._attachment(x)
        return np.concatenate([x, x_e, self.link_model.initial(p_t, v_t, tension)], -1)

    def to_reduced(self, x, xi_ref=None):
        """Reduced state (..., 10) of x; see :func:`reduced_from_maximal`."""
        return reduced_from_maximal(self.model, x, xi_ref)

    def substeps(self, dt: float) -> int:
        """RK4 substeps per step of ``dt`` s that keep the link's fastest mode accurate
        (``|lambda| dt / n <= RK4_REACH``: RK4's relative error per substep ~ (lambda h)^5 /
        120 < 1e-5); 1 for the rigid link. At the stability bound (lambda h ~ 2) the stiff
        tether (k = 2e5 N/m) rang at 0.63 per step and its simulated acceleration was
        0.16 % off its own model: the simulated accelerometer showed it."""
        if self.link_model is None:
            return 1
        rate = self.link_model.max_rate(self.model.m)
        return max(1, int(np.ceil(dt * rate / RK4_REACH)))

    def step(self, x, u, alpha, dt, gamma=0.0):
        """Advance x by ``dt`` s with the input u held: RK4 with :meth:`substeps` substeps.

        Returns ``(x_next (..., n_x), signed tension at x (...) N)``, like the
        simulator's RK4: negative means slack. Rigid link: the multiplier. Elastic
        links: the tension, or when slack the link's ``margin`` (<= 0, the push it
        would need; :class:`gainsched.model.links.LinkOutput`).
        """
        x = np.asarray(x, dtype=float)
        n = self.substeps(dt)
        h = dt / n
        ten = None
        for _ in range(n):
            k1, t1, link = self._evaluate(x, u, alpha, gamma)
            if ten is None:
                ten = t1 if link is None else np.where(link.slack, link.margin, t1)
            k2 = self.f(x + 0.5 * h * k1, u, alpha, gamma)
            k3 = self.f(x + 0.5 * h * k2, u, alpha, gamma)
            k4 = self.f(x + h * k3, u, alpha, gamma)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x, ten


# ---------------------------------------------------------------------- conversions
def maximal_from_reduced(model, z, stretch=0.0):
    """Maximal state (..., 13) from the reduced state z (..., >= 10) (docs/conventions.md).

    ``R_CB = Rz(chi + xi) Ry(theta) Rx(phi)``, ``p_q = rho e(delta, xi) + L_e x_B``,
    COG velocity from :meth:`gainsched.model.reduced.Model.kinematics`; omega_B is copied.
    ``stretch`` (m, broadcastable to z.shape[:-1]): the attachment point at
    ``(rho + stretch) e`` instead, moving with the same angular rates (an elastic
    link's elongation; z is recovered exactly by :func:`reduced_from_maximal`).
    """
    z = np.asarray(z, dtype=float)
    R, d, v_q, w_x_pe = model.kinematics(z)
    p_t = model.rho * d.e
    if np.any(stretch):
        scale = (1.0 + np.asarray(stretch, dtype=float) / model.rho)[..., None]
        Rw = mv(R, w_x_pe)
        p_t = scale * p_t
        v_q = scale * (v_q + Rw) - Rw  # v_t scales with the radius; v_q = v_t - R (w x p_e)
    p_q = cog_from_attachment(p_t, R, model.p_e)
    return np.concatenate([p_q, v_q, quaternion_from_matrix(R), z[..., 7:10]], -1)


def reduced_from_maximal(model, x, xi_ref=None):
    """Reduced state (..., 10) from the maximal state x (..., >= 13; link states ignored).

    ``delta, xi`` are the spherical angles of the attachment point, ``delta', xi'``
    its angular rates (the radial rate, non-zero only for an elastic link, is
    dropped); ``phi, theta, psi`` the Z-Y-X Euler angles of ``R_CB`` and
    ``chi = psi - xi`` wrapped to [-pi, pi). ``xi`` is in (-pi, pi], or unwrapped
    to the branch nearest ``xi_ref`` (rad, broadcastable) when given.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1 and xi_ref is not None:
        return _reduced_one(model, x, float(xi_ref))
    p, v, q, w = x[..., 0:3], x[..., 3:6], x[..., 6:10], x[..., 10:13]
    R = matrix_from_quaternion(q / np.sqrt(dot(q, q))[..., None])
    dist, pose = pose_angles_from_pose(p, R, model.p_e, xi_ref)
    delta, xi = pose[..., 0], pose[..., 1]
    v_t = v + mv(R, cross(w, np.broadcast_to(model.p_e, w.shape)))
    d = tether_direction(delta, xi)
    delta_dot = dot(d.e_delta, v_t) / dist
    xi_dot = dot(d.e_xi, v_t) / (dist * np.sin(delta) ** 2)  # |e_xi| = sin(delta)
    z = np.concatenate([pose[..., :2], np.stack([delta_dot, xi_dot], -1), pose[..., 2:]], -1)
    return np.concatenate([z, w], -1)[..., :N_STATE]


def _reduced_one(model, x, xi_ref: float):
    """:func:`reduced_from_maximal` of one real state (the per-step plants, every control
    step of a flight on an elastic tether) in Python floats and :mod:`math`: numpy's
    per-call overhead on 3-vectors was most of the conversion (a flight's largest share).
    The batched formulas, each sum in index order; tests/model/test_maximal.py checks
    them against the batched conversion to a few ulp."""
    p0, p1, p2, v0, v1, v2, qw, qx, qy, qz, w0, w1, w2 = x[:13].tolist()
    qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = matrix_entries_from_quaternion(
        qw / qn, qx / qn, qy / qn, qz / qn)
    e0, e1, e2 = model.p_e.tolist()
    # the attachment point p_t = p_q + R p_e, and its velocity v_t = v + R (w x p_e)
    t0, t1, t2 = (p0 + (r00 * e0 + r01 * e1 + r02 * e2), p1 + (r10 * e0 + r11 * e1 + r12 * e2),
                  p2 + (r20 * e0 + r21 * e1 + r22 * e2))
    c0, c1, c2 = w1 * e2 - w2 * e1, w2 * e0 - w0 * e2, w0 * e1 - w1 * e0
    u0, u1, u2 = (v0 + (r00 * c0 + r01 * c1 + r02 * c2), v1 + (r10 * c0 + r11 * c1 + r12 * c2),
                  v2 + (r20 * c0 + r21 * c1 + r22 * c2))
    dist = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    delta, xi = math.atan2(math.hypot(t0, t1), t2), math.atan2(t1, t0)
    xi += 2 * math.pi * round((xi_ref - xi) / (2 * math.pi))
    phi, psi = math.atan2(r21, r22), math.atan2(r10, r00)
    theta = math.asin(min(max(-r20, -1.0), 1.0))
    sd, cd, sx, cx = math.sin(delta), math.cos(delta), math.sin(xi), math.cos(xi)
    delta_dot = (cd * cx * u0 + cd * sx * u1 - sd * u2) / dist
    xi_dot = (-sd * sx * u0 + sd * cx * u1) / (dist * sd**2)  # |e_xi| = sin(delta)
    return np.array([delta, xi, delta_dot, xi_dot, phi, theta, wrap_angle(psi - xi),
                     w0, w1, w2])[:N_STATE]
