"""Reduced-coordinate dynamics of the tethered quadcopter (paper Sec. II).

Frames, angles and motor numbering: docs/conventions.md.

State ``s = (delta, xi, delta', xi', phi, theta, chi, wx, wy, wz)`` (rad, rad/s)
followed by the states of stateful effects (e.g. motor lag); input ``u = (T1..T4)``
commanded motor thrusts (N). With ``p_q = p_t - R p_e`` and

    m p_q''  = R (0,0,T_C) + m g_C - f_t e + F_eff                  (paper eq. 3)
    J omega' = sum L_i x T_i + tau_M + p_e x (R^T (-f_t e))
               - omega x J omega + tau_eff                           (paper eq. 6, 8)
    p_q''    = p_t'' - R (omega' x p_e + omega x (omega x p_e))      (eq. 9, corrected)

the unknowns ``(delta'', xi'', omega', f_t)`` enter linearly: six equations, one
6x6 solve per state. Everything is batched over leading dimensions and is
complex-step safe, so :mod:`gainsched.schedule.linearize` can take exact Jacobians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .._vec import broadcast, cross, dot, mtv, mv
from ..constants import N_STATE
from ..rotations import (
    euler_zyx_rates_from_body_rates,
    matrix_from_euler_zyx,
    matrix_from_euler_zyx_scalar,
    up_C_from_tilt,
)
from .effects import (
    Effect,
    Kinematics,
    air_velocity,
    cog_offset,
    effects_from_specs,
    polynomial_drag,
)
from .geometry import cog_from_attachment, pose_from_reduced, tether_direction

if TYPE_CHECKING:  # the config imports the effects of this package
    from ..config import Config

__all__ = ["Model", "Evaluation", "allocation_matrix", "motor_positions"]


def motor_positions(arm_length: float) -> np.ndarray:
    """Rotor hub positions L_i in B for the X layout, shape (4, 3), m.

    Motor i sits at angle 45 deg + (i-1) 90 deg: 1 (+,+), 2 (-,+), 3 (-,-), 4 (+,-).
    """
    b = np.deg2rad(45.0 + 90.0 * np.arange(4))
    return arm_length * np.stack([np.cos(b), np.sin(b), np.zeros(4)], axis=-1)


def allocation_matrix(arm_length: float, kappa: float, cog_offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Map from motor thrusts (N) to (T_C, tau_x, tau_y, tau_z) (N, N m), shape (4, 4).

    ``tau = sum (L_i - d) x (0, 0, T_i) + (0, 0, kappa (T1 - T2 + T3 - T4))`` (paper eqs.
    6, 8) about the COG at ``d`` = ``cog_offset`` (3,), m, in B from the frame centre
    (:class:`~gainsched.model.effects.CogOffset`).
    """
    L = motor_positions(arm_length) - np.asarray(cog_offset, dtype=float)
    return np.stack([np.ones(4), L[:, 1], -L[:, 0], kappa * np.array([1.0, -1.0, 1.0, -1.0])])


@dataclass(frozen=True)
class Evaluation:
    """Result of one model evaluation (batched).

    Attributes
    ----------
    z_dot : ndarray, shape (..., n_z)
        Time derivative of the full state.
    tension : ndarray, shape (...), N
        Tether tension f_t (negative means the model needs a pushing tether: slack).
    T : ndarray, shape (..., 4), N
        Actual motor thrusts after the effects.
    """

    z_dot: np.ndarray
    tension: np.ndarray
    T: np.ndarray


class Model:
    """The reduced model built from a :class:`~gainsched.config.Config`.

    Parameters
    ----------
    config : Config
    effects : sequence of Effect, optional
        Overrides the config's effects (used by fits and by the simulator's plant).

    Attributes
    ----------
    wind_I : ndarray, shape (3,), m/s, or None
        The velocity of the air in I the effects set (:func:`~gainsched.model.effects.
        air_velocity`, e.g. ``[effects.wind]``); None: still air. With a wind the circle's
        heading ``gamma`` matters: :meth:`evaluate` takes it.
    cog_offset : ndarray, shape (3,), m
        The COG in B from the frame centre (:class:`~gainsched.model.effects.CogOffset`;
        zeros without one).
    p_e : ndarray, shape (3,), m
        The attachment point in B from the COG, ``(-L_e, 0, 0) - cog_offset``.
    p_e_frame : ndarray, shape (3,), m
        The attachment point in B from the frame centre, ``(-L_e, 0, 0)``: what the
        motion capture's pose (the frame centre) is turned into reduced coordinates with.
    memo : dict
        What the layers above compute from this model and keep with it, for as long as
        it lives (the schedule's circle solutions:
        :class:`gainsched.schedule.trim.Solutions`); a new model starts with none.
    """

    def __init__(self, config: Config, effects: tuple[Effect, ...] | None = None):
        v, t = config.vehicle, config.tether
        self.config = config
        self.m = v.mass
        self.J = np.array(v.inertia, dtype=float)
        self.rho = t.length
        self.L_e = t.attachment_offset
        self.r = t.length + t.attachment_offset
        self.g = config.g
        self.effects = tuple(effects_from_specs(config.effects) if effects is None else effects)
        # every lever is measured from the COG, which sits at cog_offset from the frame
        # centre (the arms', the attachment's and the markers' origin; effects.CogOffset)
        self.cog_offset = cog_offset(self.effects)
        self.p_e_frame = np.array([-self.L_e, 0.0, 0.0])
        self.p_e = self.p_e_frame - self.cog_offset
        self.L = motor_positions(v.arm_length) - self.cog_offset
        self.alloc = allocation_matrix(v.arm_length, v.kappa, self.cog_offset)
        self.alloc_inv = np.linalg.inv(self.alloc)
        self.wind_I = air_velocity(self.effects)
        self.n_extra = sum(e.n_states for e in self.effects)
        self.n_z = N_STATE + self.n_extra
        self._J_inv = np.linalg.inv(self.J)
        self.memo: dict = {}

    # ------------------------------------------------------------------ helpers
    def g_C(self, alpha):
        """Gravity in the circle frame, ``-g (0, sin a, cos a)``, shape alpha.shape + (3,)."""
        return -self.g * up_C_from_tilt(alpha)

    def drag_coefficients(self):
        """``(mu1, mu2)`` summed over the effects when every effect is a pure COG-velocity
        drag (:meth:`Effect.drag_coefficients`), else None."""
        parts = [e.drag_coefficients() for e in self.effects]
        if any(c is None for c in parts):
            return None
        return sum(c[0] for c in parts), sum(c[1] for c in parts)

    def drag_part(self) -> Model:
        """The same vehicle with only the effects that are pure COG-velocity drags: the part
        of the model the closed form (and the firmware's compiled feed-forward) covers."""
        return Model(self.config, effects=tuple(
            e for e in self.effects if e.drag_coefficients() is not None))

    def closed_form_drag(self):
        """The tangential drag ``D(v) -> (D, D', D'')`` of the closed-form nominal if it
        applies (every effect a pure velocity drag), else None."""
        c = self.drag_coefficients()
        return None if c is None else polynomial_drag(*c)

    def kinematics(self, s):
        """Body rotation, tether direction and COG velocity of states ``s`` (..., >= 10).

        Returns
        -------
        R_CB : ndarray, shape (..., 3, 3)
            ``Rz(chi + xi) Ry(theta) Rx(phi)`` (paper eq. 2).
        direction : :class:`~gainsched.model.geometry.TetherDirection`
        v_q : ndarray, shape (..., 3), m/s
            COG velocity in C, ``rho e' - R_CB (omega x p_e)``.
        w_x_pe : ndarray, shape (..., 3), m/s
            ``omega x p_e`` in B.
        """
        xi, dd, dx = s[..., 1], s[..., 2], s[..., 3]
        phi, theta, chi, w = s[..., 4], s[..., 5], s[..., 6], s[..., 7:10]
        if s.ndim == 1 and s.dtype == np.float64:  # one real state (the per-step plants):
            # the same entries in scalar math, ~3 us against ~0.3 ms of numpy overhead
            R = matrix_from_euler_zyx_scalar(float(phi), float(theta), float(chi + xi))
        else:
            R = matrix_from_euler_zyx(phi, theta, chi + xi)
        d = tether_direction(s[..., 0], xi)
        w_x_pe = cross(w, self.p_e)
        v_q = self.rho * d.rate(dd, dx) - mv(R, w_x_pe)
        return R, d, v_q, w_x_pe

    def effect_kinematics(self, s, alpha, gamma=0.0):
        """The :class:`~gainsched.model.effects.Kinematics` effects see at states ``s``
        (..., >= 10) on a circle of tilt ``alpha`` and heading ``gamma`` (rad), in the
        model's wind (:attr:`wind_I`)."""
        R, d, v_q, _ = self.kinematics(s)
        return self._effect_kinematics(R, d, v_q, s[..., 7:10], alpha, gamma)

    def _effect_kinematics(self, R, d, v_q, w, alpha, gamma=0.0):
        return Kinematics(R, v_q, w, cog_from_attachment(self.rho * d.e, R, self.p_e), alpha,
                          gamma, self.wind_I)

    def thrust(self, z, u, kin):
        """Actual motor thrusts (N) after stateful effects and thrust modifiers, at states
        ``z`` (..., n_z) (the effect states follow the first 10)."""
        return self.thrust_from_effect_states(z[..., N_STATE:], u, kin)

    def thrust_from_effect_states(self, x_e, u, kin):
        """Actual motor thrusts (..., 4), N, of the commands ``u`` (..., 4), N, after the
        stateful effects at their states ``x_e`` (..., n_extra) and the thrust modifiers:
        what :meth:`thrust` computes, for any formulation that carries the effect states
        (the maximal model's follow its rigid-body states)."""
        T = u
        i = 0
        for eff in self.effects:
            T = eff.modify_thrust(T, kin, x_e[..., i : i + eff.n_states])
            i += eff.n_states
        return T

    def steady_effect_states(self, T):
        """The effect states (..., n_extra) at rest at the thrusts ``T`` (..., 4), N (a
        motor lag at T, a full battery, the flight time 0): where a simulation starts."""
        T = np.asarray(T, dtype=float)
        parts = [e.steady_states(T, np.zeros_like(T))[0] for e in self.effects if e.n_states]
        return np.concatenate(parts, -1) if parts else np.zeros(T.shape[:-1] + (0,))

    def effect_state_rates(self, x_e, u, kin):
        """Derivatives of the effect states ``x_e`` (..., n_extra) under the commands ``u``
        (..., 4), N, as a list of one array (..., n_states) per stateful effect, in model
        order (empty without one): the same in every formulation."""
        parts, i = [], 0
        for eff in self.effects:
            if eff.n_states:
                parts.append(eff.state_derivative(x_e[..., i : i + eff.n_states], u, kin))
                i += eff.n_states
        return parts

    @property
    def thrust_modifiers(self) -> tuple[Effect, ...]:
        """The effects without states that change the thrust, in the order :meth:`thrust`
        applies them (after the stateful ones): empty when the actual thrusts are the
        commands, or with a motor lag its states."""
        return tuple(e for e in self.effects if not e.n_states
                     and type(e).modify_thrust is not Effect.modify_thrust)

    def effect_wrench(self, T, kin):
        """Sum of the effects' forces at the COG (in C, N) and torques (in B, N m)."""
        shape = np.broadcast_shapes(T.shape[:-1], kin.v_C.shape[:-1]) + (3,)
        F = np.zeros(shape, dtype=np.result_type(T, kin.v_C))
        tau = np.zeros_like(F)
        for eff in self.effects:
            wr = eff.wrench(T, kin)
            if wr is not None:
                F = F + wr[0]
                tau = tau + wr[1]
        return F, tau

    def body_wrench(self, T, kin, alpha):
        """Everything acting on the vehicle except the tether: the one body wrench that
        the reduced model, the maximal model and the model-versus-measurement
        comparison use.

        ``F = R_CB (0, 0, T_C) + m g_C + F_eff`` (paper eq. 3 without ``-f_t e``) and
        ``tau = sum L_i x T_i + tau_M - omega x J omega + tau_eff`` (paper eqs. 6, 8
        without the tether torque).

        Parameters
        ----------
        T : ndarray, shape (..., 4), N
            Actual motor thrusts (after :meth:`thrust`).
        kin : Kinematics
            Where the vehicle is (:meth:`effect_kinematics`).
        alpha : float or ndarray, rad
            Tilt of the circle plane.

        Returns
        -------
        F_C : ndarray, shape (..., 3), N
            Force at the COG in C.
        tau_B : ndarray, shape (..., 3), N m
            Torque about the COG in B.
        """
        F, tau = self.effect_wrench(T, kin)
        w = kin.omega_B
        T_C = T.sum(-1)
        F_C = kin.R_CB[..., :, 2] * T_C[..., None] + self.m * self.g_C(alpha) + F
        tau_B = T @ self.alloc[1:].T - cross(w, w @ self.J.T) + tau
        return F_C, tau_B

    def tether_lever(self, n_B):
        """``p_e x n_B``, shape (..., 3), m: the tether's torque about the COG is
        ``-f_t p_e x n_B`` for a tension ``f_t`` (N) pulling the attachment point along
        ``-n`` (paper eq. 6); ``n_B`` (..., 3) is the unit vector from the anchor to the
        attachment point, in B."""
        return cross(self.p_e, n_B)

    # ------------------------------------------------------------------ dynamics
    def _tether_solve(self, R, d, e_B, rhs_F, rhs_tau):
        """Solve the six equations of motion (paper eqs. 3-8 with the constraint
        ``p_t = rho e``) for ``(delta'', xi'', omega' (3), f_t)``, shape (..., 6).

        The system is ``[m rho e_delta, m rho e_xi, m R [p_e x], e] x = rhs_F`` (in C)
        and ``[0, 0, J, p_e x e_B] x = rhs_tau`` (in B). The torque rows give ``omega' =
        J^-1 (rhs_tau - (p_e x e_B) f_t)``; put into the force rows they leave three
        equations in ``delta'', xi'', f_t`` with the columns ``a = m rho e_delta``, ``b
        = m rho e_xi`` and ``c = e - m R (p_e x J^-1 (p_e x e_B))``, solved by Cramer's
        rule. The columns are near orthogonal (``|e_xi| = sin delta``, 1 on the sphere's
        equator the model flies), so the rule is as accurate as a pivoted LU, and it is
        written out because a batched ``numpy.linalg.solve`` of the 6 x 6 systems cost
        a third of every build with a numerical trim (complex steps included: no
        ``abs``, no ``conj``).
        """
        m, mr = self.m, self.m * self.rho
        J_inv = self._J_inv

        def torque_term(v):  # m R (p_e x J^-1 v), in C
            return m * mv(R, cross(self.p_e, v @ J_inv.T))

        lever = self.tether_lever(e_B)
        a, b = mr * d.e_delta, mr * d.e_xi
        c = d.e - torque_term(lever)
        r = rhs_F - torque_term(rhs_tau)
        bc = cross(b, c)
        det = dot(a, bc)
        dd, dx, ft = dot(r, bc) / det, dot(a, cross(r, c)) / det, dot(a, cross(b, r)) / det
        w_dot = (rhs_tau - lever * ft[..., None]) @ J_inv.T
        return np.concatenate([dd[..., None], dx[..., None], w_dot, ft[..., None]], -1)

    def evaluate(self, z, u, alpha, gamma=0.0, thrust=None) -> Evaluation:
        """Full-state derivative and tether tension.

        Parameters
        ----------
        z : ndarray, shape (..., n_z)
            State (see module docstring), rad, rad/s, plus effect states.
        u : ndarray, shape (..., 4), N
            Commanded motor thrusts.
        alpha : float or ndarray broadcastable to z.shape[:-1], rad
            Tilt of the circle plane.
        gamma : float or ndarray broadcastable to z.shape[:-1], rad
            Heading of the circle plane (``R_IC = Rz(gamma) Rx(alpha)``); it matters only
            with a wind (:attr:`wind_I`).
        thrust : ndarray, shape (..., 4), N, optional
            The actual motor thrusts, in place of those :meth:`thrust` makes of ``u`` and
            the effect states (the trim's unknowns: :mod:`gainsched.schedule.trim`); ``u``
            then enters the effect states' derivatives alone.
        """
        z = np.asarray(z)
        u = np.asarray(u)
        m = self.m
        dd, dx = z[..., 2], z[..., 3]
        phi, theta, w = z[..., 4], z[..., 5], z[..., 7:10]
        R, d, v_q, w_x_pe = self.kinematics(z)
        e = d.e
        kin = self._effect_kinematics(R, d, v_q, w, alpha, gamma)
        T = self.thrust(z, u, kin) if thrust is None else thrust
        F0, rhs_tau = self.body_wrench(T, kin, alpha)

        # p_t'' = rho (e_delta delta'' + e_xi xi'' + c2), c2 the velocity-product terms
        c2 = d.velocity_products(dd, dx)
        w_w_pe = cross(w, w_x_pe)
        rhs_F = F0 - m * self.rho * c2 + m * mv(R, w_w_pe)

        sol = self._tether_solve(R, d, mtv(R, e), rhs_F, rhs_tau)

        euler_dot = euler_zyx_rates_from_body_rates(phi, theta, w)
        parts = [
            dd[..., None],
            dx[..., None],
            sol[..., 0:2],
            euler_dot[..., 0:2],
            (euler_dot[..., 2] - dx)[..., None],
            sol[..., 2:5],
        ]
        parts += self.effect_state_rates(z[..., N_STATE:], u, kin)
        shape = np.broadcast_shapes(*(p.shape[:-1] for p in parts))
        z_dot = np.concatenate([broadcast(p, shape + p.shape[-1:]) for p in parts], -1)
        return Evaluation(z_dot, sol[..., 5], T)

    def f(self, z, u, alpha, gamma=0.0):
        """State derivative only, shape (..., n_z). See :meth:`evaluate`."""
        return self.evaluate(z, u, alpha, gamma).z_dot

    # ------------------------------------------------------------------ outputs
    def cog_acceleration(self, z, z_dot):
        """COG acceleration in C, shape (..., 3), m/s^2, of states ``z`` moving at ``z_dot``
        (:meth:`f`): ``p_q'' = rho e'' - R_CB (omega' x p_e + omega x (omega x p_e))``
        (paper eq. 9, corrected; docs/conventions.md)."""
        R, d, _, w_x_pe = self.kinematics(z)
        w, w_dot = z[..., 7:10], z_dot[..., 7:10]
        p_tt = self.rho * d.acceleration(z[..., 2], z[..., 3], z_dot[..., 2], z_dot[..., 3])
        arm = cross(w_dot, self.p_e) + cross(w, w_x_pe)
        return p_tt - mv(R, arm)

    def cog_motion_one(self, z, z_dot):
        """COG position, velocity and acceleration in C and ``R_CB`` of one state ``z``
        (n_z,) moving at ``z_dot`` (real): the one-sample form of :meth:`kinematics` and
        :meth:`cog_acceleration` in scalar math, for per-step code (the simulator's
        sensors: ~10 us where the batched forms spend ~0.5 ms in numpy's per-call
        overhead). tests/firmware/test_controller.py checks it against them.

        Returns
        -------
        p_q, v_q, a_q : ndarray, shape (3,), m, m/s, m/s^2
        R_CB : ndarray, shape (3, 3)
        """
        p_q, v_q, a_q, r = self.cog_motion_floats(z, z_dot)
        return np.array(p_q), np.array(v_q), np.array(a_q), np.array(r)

    def cog_motion_floats(self, z, z_dot):
        """:meth:`cog_motion_one` as Python floats, for per-step code that goes on in
        scalar math (the simulator's sensors): ``p_q, v_q, a_q`` lists of 3 (m, m/s,
        m/s^2) and ``R_CB`` a list of its 3 rows, the same numbers."""
        delta, xi, dd, dx, phi, theta, chi, w0, w1, w2 = np.asarray(z[:10], dtype=float).tolist()
        _, _, ddd, dxx, _, _, _, wd0, wd1, wd2 = np.asarray(z_dot[:10], dtype=float).tolist()
        r = matrix_from_euler_zyx_scalar(phi, theta, chi + xi).tolist()
        sd, cd, sx, cx = math.sin(delta), math.cos(delta), math.sin(xi), math.cos(xi)
        e = (sd * cx, sd * sx, cd)
        e_d = (cd * cx, cd * sx, -sd)
        e_x = (-sd * sx, sd * cx, 0.0)
        e_dx = (-cd * sx, cd * cx, 0.0)
        e_xx = (-sd * cx, -sd * sx, 0.0)
        rho = self.rho
        pe0, pe1, pe2 = (float(v) for v in self.p_e)

        def cross3(a0, a1, a2, b0, b1, b2):
            return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)

        w_pe = cross3(w0, w1, w2, pe0, pe1, pe2)  # omega x p_e
        w_w_pe = cross3(w0, w1, w2, *w_pe)
        wd_pe = cross3(wd0, wd1, wd2, pe0, pe1, pe2)
        arm = (wd_pe[0] + w_w_pe[0], wd_pe[1] + w_w_pe[1], wd_pe[2] + w_w_pe[2])
        p_q, v_q, a_q = [], [], []
        for i in range(3):
            ri = r[i]
            p_q.append(rho * e[i] - (ri[0] * pe0 + ri[1] * pe1 + ri[2] * pe2))
            v_q.append(rho * (e_d[i] * dd + e_x[i] * dx)
                       - (ri[0] * w_pe[0] + ri[1] * w_pe[1] + ri[2] * w_pe[2]))
            a_q.append(rho * (e_d[i] * ddd + e_x[i] * dxx - e[i] * dd * dd
                              + 2 * e_dx[i] * dd * dx + e_xx[i] * dx * dx)
                       - (ri[0] * arm[0] + ri[1] * arm[1] + ri[2] * arm[2]))
        return p_q, v_q, a_q, r

    def specific_force(self, z, z_dot, alpha):
        """What an accelerometer at the COG senses, in B, shape (..., 3), m/s^2:
        ``R_CB^T (p_q'' - g_C)`` (:meth:`cog_acceleration`) on a circle of tilt ``alpha``."""
        R = self.kinematics(z)[0]
        f_C = self.cog_acceleration(z, z_dot) - self.g_C(alpha)
        return mtv(R, f_C)

    def cog_position(self, z, alpha=0.0, gamma=0.0, frame="C"):
        """COG position ``p_q = rho e - R_CB p_e`` in C (or I with ``frame="I"``), m."""
        p = pose_from_reduced(z, self.rho, self.p_e)[0]
        if frame == "I":
            from ..rotations import R_IC_from_tilt

            p = np.einsum("ij,...j->...i", R_IC_from_tilt(alpha, gamma), p)
        return p

    def energy(self, z, alpha):
        """Mechanical energy (kinetic + potential), J; conserved with zero thrust, no drag."""
        _, _, v_q, _ = self.kinematics(z)
        w = z[..., 7:10]
        p = self.cog_position(z)
        kinetic = 0.5 * self.m * np.sum(v_q * v_q, -1) + 0.5 * np.einsum(
            "...i,ij,...j", w, self.J, w
        )
        return kinetic - self.m * np.sum(self.g_C(alpha) * p, -1)
