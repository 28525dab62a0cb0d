"""Azimuth profiles of the circle flights: constant speed, speed-up and braking.

An :class:`AzimuthPath` is the azimuth xi(t) with its first four derivatives,
all a nominal needs (:mod:`gainsched.schedule.nominal`). The speed-up and braking
manoeuvre is eq. 20 of the paper "High-speed, Steady Flight with a Quadcopter
in a Confined Environment Using a Tether", in tangential terms.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["AzimuthPath", "period", "circle_path", "maneuver_path"]


@dataclass(frozen=True)
class AzimuthPath:
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


def circle_path(speed: float, r: float, t, xi0: float = 0.0) -> AzimuthPath:
    """Constant-speed circle: ``xi = xi0 + (speed / r) t``. ``speed`` may be negative."""
    t = np.asarray(t, dtype=float)
    w = speed / r
    z = np.zeros_like(t)
    return AzimuthPath(t, xi0 + w * t, (np.full_like(t, w), z, z, z))


def maneuver_path(v0: float, v1: float, a: float, r: float, t, t_start: float = 0.0,
                  xi0: float = 0.0) -> AzimuthPath:
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
    return AzimuthPath(t, xi0 + s / r, (v / r, at / r, jt / r, st / r))
