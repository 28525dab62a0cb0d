"""Nominal trajectories on great circles (DESIGN.md section 3, paper Sec. III).

A :class:`Path` is the azimuth profile xi(t) with four derivatives. From it,
:func:`nominal_from_path` builds the nominal state and input ``(s_d, u_d)``:

- closed form (paper eqs. 15-18, with the eq. 17 typo corrected: the
  tangential-acceleration term is ``r xi''``) when every effect is a pure COG
  velocity drag;
- otherwise :mod:`gainsched.trim` solves the same model numerically.

The nominal keeps ``delta = pi/2``, ``theta = chi = 0``, ``psi = xi``; the roll
phi carries the tangential force balance and the tether carries the radial one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import N_STATE

__all__ = [
    "Path",
    "Nominal",
    "circle_path",
    "maneuver_path",
    "nominal_from_path",
    "circle_nominal",
    "feasibility_reasons",
    "REASONS",
    "min_taut_speed",
    "period",
]

#: feasibility reason bits (uint8), stored in tables
REASONS = {
    1: "tether slack",
    2: "thrust below minimum",
    4: "thrust above maximum",
    8: "trim failed",
    16: "circle infeasible elsewhere",
}


@dataclass(frozen=True)
class Path:
    """Azimuth profile: ``xi[k]`` (rad) and its derivatives ``dxi[j][k]`` (rad/s^j), j = 1..4.

    Attributes
    ----------
    t : ndarray, shape (N,), s
    xi : ndarray, shape (N,), rad
    d : tuple of 4 ndarrays, shape (N,)
        First to fourth time derivatives of xi.
    """

    t: np.ndarray
    xi: np.ndarray
    d: tuple


def period(speed: float, r: float) -> float:
    """Period of a circle of radius ``r`` (m) flown at tangential speed ``speed`` (m/s), s."""
    return 2 * np.pi * r / abs(speed)


def circle_path(speed: float, r: float, t, xi0: float = 0.0) -> Path:
    """Constant-speed circle: ``xi = xi0 + (speed / r) t``. ``speed`` may be negative."""
    t = np.asarray(t, dtype=float)
    w = speed / r
    z = np.zeros_like(t)
    return Path(t, xi0 + w * t, (np.full_like(t, w), z, z, z))


def maneuver_path(v0: float, v1: float, a: float, r: float, t, t_start: float = 0.0,
                  xi0: float = 0.0) -> Path:  # fmt: skip
    """Speed-up or stop (paper eq. 20, in tangential terms), from ``v0`` to ``v1`` (m/s).

    Tangential acceleration ``a_t = +-2 a sin^2(pi a tau / |v1 - v0|)`` for
    ``tau = t - t_start`` in ``[0, |v1 - v0| / a]``: it integrates to ``v1 - v0``
    with peak ``2 a`` (m/s^2). Constant speed before and after.
    """
    t = np.asarray(t, dtype=float)
    dv = v1 - v0
    sgn = np.sign(dv)
    dur = abs(dv) / a
    om = np.pi * a / abs(dv) if dv else 0.0
    tau = np.clip(t - t_start, 0.0, dur)
    inside = (t - t_start >= 0) & (t - t_start <= dur)
    after = np.maximum(t - t_start - dur, 0.0)
    before = np.minimum(t - t_start, 0.0)
    if dv:
        at = sgn * 2 * a * np.sin(om * tau) ** 2
        jt = sgn * 2 * a * om * np.sin(2 * om * tau)
        st = sgn * 4 * a * om**2 * np.cos(2 * om * tau)
        v = v0 + sgn * (a * tau - a * np.sin(2 * om * tau) / (2 * om))
        s = v0 * tau + sgn * (a * tau**2 / 2 + a * (np.cos(2 * om * tau) - 1) / (4 * om**2))
    else:
        at = jt = st = np.zeros_like(t)
        v, s = np.full_like(t, v0), v0 * tau
    s = s + v0 * before + v1 * after
    v = np.where(t - t_start < 0, v0, v)
    at, jt, st = (np.where(inside, x, 0.0) for x in (at, jt, st))
    return Path(t, xi0 + s / r, (v / r, at / r, jt / r, st / r))


@dataclass(frozen=True)
class Nominal:
    """A nominal trajectory.

    Attributes
    ----------
    t : ndarray, shape (N,), s
    z : ndarray, shape (N, n_z)
        Nominal full state (reduced state plus effect states).
    z_dot : ndarray, shape (N, n_z)
        Its time derivative (from the path, independent of the model's solve).
    u : ndarray, shape (N, 4), N
        Nominal commanded motor thrusts.
    tension : ndarray, shape (N,), N
    alpha : float, rad
    reasons : ndarray of uint8, shape (N,)
        Feasibility reason bits (0 = feasible), see :data:`REASONS`.
    """

    t: np.ndarray
    z: np.ndarray
    z_dot: np.ndarray
    u: np.ndarray
    tension: np.ndarray
    alpha: float
    reasons: np.ndarray

    @property
    def phi(self):
        """Nominal roll, rad."""
        return self.z[:, 4]

    @property
    def collective(self):
        """Nominal collective thrust (commanded), N."""
        return self.u.sum(-1)

    @property
    def feasible(self):
        return self.reasons == 0


def state_from_roll(path: Path, phi, dphi, ddphi):
    """Nominal reduced state and its derivative from the path and the roll profile (eqs. 15-16)."""
    n = path.t.shape[0]
    xd, xdd = path.d[0], path.d[1]
    sp, cp = np.sin(phi), np.cos(phi)
    s = np.zeros((n, N_STATE), dtype=np.result_type(phi, dphi, ddphi, float))
    s[:, 0] = np.pi / 2
    s[:, 1] = path.xi
    s[:, 3] = xd
    s[:, 4] = phi
    s[:, 7:10] = np.stack([dphi, xd * sp, xd * cp], -1)  # eq. 15
    sdot = np.zeros_like(s)
    sdot[:, 1] = xd
    sdot[:, 3] = xdd
    sdot[:, 4] = dphi
    sdot[:, 7:10] = np.stack(  # eq. 16
        [ddphi, xd * dphi * cp + xdd * sp, -xd * dphi * sp + xdd * cp], -1
    )
    return s, sdot


def _closed_form(model, path: Path, alpha: float, D):
    """Closed-form roll, input and tension for drag-only effects (paper eqs. 15-18)."""
    m, g, r = model.m, model.g, model.r
    xi, (xd, xdd, xddd, xdddd) = path.xi, path.d
    sa, ca = np.sin(alpha), np.cos(alpha)
    v, vd, vdd = r * xd, r * xdd, r * xddd
    Dv, D1, D2 = D(v)
    # tangential balance T_C sin(phi) = -m N, normal T_C cos(phi) = m Dn
    N = r * xdd + g * sa * np.cos(xi) + Dv / m
    N1 = r * xddd - g * sa * np.sin(xi) * xd + D1 * vd / m
    N2 = r * xdddd - g * sa * (np.cos(xi) * xd**2 + np.sin(xi) * xdd) + (D2 * vd**2 + D1 * vdd) / m
    Dn = g * ca
    H = Dn**2 + N**2
    phi = np.arctan2(-N, Dn)
    dphi = -Dn * N1 / H
    ddphi = -Dn * (N2 * H - 2 * N * N1**2) / H**2
    s, sdot = state_from_roll(path, phi, dphi, ddphi)
    w, wd = s[:, 7:10], sdot[:, 7:10]
    J = model.J
    tau = wd @ J.T + np.cross(w, w @ J.T)  # tether torque is zero on the nominal (x_B || e)
    T_C = m * np.sqrt(H)
    u = np.concatenate([T_C[:, None], tau], -1) @ model.alloc_inv.T
    tension = m * r * xd**2 - m * g * sa * np.sin(xi)  # eq. 18
    return s, sdot, u, tension


def feasibility_reasons(config, u, tension) -> np.ndarray:
    """Reason bits per sample: tension margin and per-motor thrust limits (with margin)."""
    f, v = config.feasibility, config.vehicle
    bits = np.zeros(np.shape(tension), dtype=np.uint8)
    bits |= np.where(tension < f.min_tension, 1, 0).astype(np.uint8)
    bits |= np.where(np.any(u < v.thrust_min + f.thrust_margin, -1), 2, 0).astype(np.uint8)
    bits |= np.where(np.any(u > v.thrust_max - f.thrust_margin, -1), 4, 0).astype(np.uint8)
    return bits


def nominal_from_path(model, path: Path, alpha: float, *, periodic: bool | None = None) -> Nominal:
    """Nominal (state, input, tension, feasibility) along ``path`` at tilt ``alpha`` (rad).

    Uses the closed form when the model's effects allow it, otherwise the
    numerical trim of :mod:`gainsched.trim` (``periodic`` selects the Fourier
    collocation for whole constant-speed circles; default: inferred).
    """
    D = model.closed_form_drag()
    if D is not None:
        s, sdot, u, tension = _closed_form(model, path, alpha, D)
        z, zdot = s, sdot
    else:
        from .trim import trim_path

        z, zdot, u, tension = trim_path(model, path, alpha, periodic=periodic)
    reasons = feasibility_reasons(model.config, u, tension)
    return Nominal(path.t, z, zdot, u, tension, float(alpha), reasons)


def circle_nominal(model, speed: float, alpha: float, n: int, xi0: float = 0.0) -> Nominal:
    """Nominal over one period of a constant-speed circle, sampled at ``n`` equal steps.

    Sample k is at ``t = k T / n`` and ``xi = xi0 + sign(speed) 2 pi k / n``.
    """
    T = period(speed, model.r)
    t = np.arange(n) * (T / n)
    return nominal_from_path(model, circle_path(speed, model.r, t, xi0), alpha, periodic=True)


def min_taut_speed(config, alpha: float) -> float:
    """Lowest constant speed (m/s) keeping tension >= min_tension at every azimuth (eq. 19)."""
    r, m = config.radius, config.vehicle.mass
    return float(np.sqrt(r * (config.feasibility.min_tension / m + config.g * np.sin(abs(alpha)))))
