"""Nominal trajectories on great circles (paper Sec. III).

An :class:`~gainsched.schedule.path.AzimuthPath` is the azimuth profile xi(t) with four
derivatives. From it,
:func:`nominal_from_path` builds the nominal state and input ``(s_d, u_d)``:

- closed form (:mod:`gainsched.schedule.closedform`) when every effect is a pure COG
  velocity drag;
- otherwise :mod:`gainsched.schedule.trim` solves the same model numerically.

The nominal keeps ``delta = pi/2``, ``theta = chi = 0``, ``psi = xi``; the roll
phi carries the tangential force balance and the tether carries the radial one.
With ``[feasibility] attitude_offsets = "free"`` a constant-speed circle whose
motors that nominal drives out of range gets pitch and yaw offsets instead
(:mod:`gainsched.schedule.offsets`, :func:`circle_offsets`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import REASONS, Reason
from .closedform import closed_form
from .offsets import CHECK_SAMPLES, AttitudeOffsets, solve_offsets
from .path import AzimuthPath, circle_path, period
from .trim import is_rough, solutions, trim_path

__all__ = [
    "Nominal",
    "nominal_from_path",
    "circle_nominal",
    "circle_offsets",
    "circle_is_rough",
    "feasibility_reasons",
    "REASONS",
    "min_taut_speed",
]



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


def feasibility_reasons(config, u, tension) -> np.ndarray:
    """Reason bits per sample: tension margin and per-motor thrust limits (with margin)."""
    f, v = config.feasibility, config.vehicle
    bits = np.zeros(np.shape(tension), dtype=np.uint8)
    bits |= np.where(tension < f.min_tension, Reason.SLACK, 0).astype(np.uint8)
    low, high = v.thrust_min + f.thrust_margin, v.thrust_max - f.thrust_margin
    bits |= np.where(np.any(u < low, -1), Reason.THRUST_LOW, 0).astype(np.uint8)
    bits |= np.where(np.any(u > high, -1), Reason.THRUST_HIGH, 0).astype(np.uint8)
    return bits


def nominal_from_path(model, path: AzimuthPath, alpha: float, *,
                      periodic: bool | None = None,
                      offsets: AttitudeOffsets | None = None) -> Nominal:
    """Nominal (state, input, tension, feasibility) along ``path`` at tilt ``alpha`` (rad).

    Uses the closed form when the model's effects allow it and there are no attitude
    ``offsets``, otherwise the numerical trim of :mod:`gainsched.schedule.trim`
    (``periodic`` selects the Fourier collocation for whole constant-speed circles;
    default: inferred).
    """
    D = model.closed_form_drag()
    if offsets is not None:
        z, zdot, u, tension = trim_path(model, path, alpha, periodic=periodic, offsets=offsets)
    elif D is not None:
        z, zdot, u, tension = closed_form(model, path, alpha, D)
    else:
        z, zdot, u, tension = trim_path(model, path, alpha, periodic=periodic)
    reasons = feasibility_reasons(model.config, u, tension)
    return Nominal(path.t, z, zdot, u, tension, float(alpha), reasons)


def circle_nominal(model, speed: float, alpha: float, n: int, xi0: float = 0.0) -> Nominal:
    """Nominal over one period of a constant-speed circle, sampled at ``n`` equal steps.

    Sample k is at ``t = k T / n`` and ``xi = xi0 + sign(speed) 2 pi k / n``.
    """
    T = period(speed, model.r)
    t = np.arange(n) * (T / n)
    return nominal_from_path(model, circle_path(speed, model.r, t, xi0), alpha, periodic=True,
                             offsets=circle_offsets(model, speed, alpha))



def circle_is_rough(model, speed: float, alpha: float) -> bool:
    """Whether the circle's nominal (:func:`circle_nominal`) is not smooth at the trim's
    resolution (:func:`gainsched.schedule.trim.is_rough`, checked once per circle: its
    thrusts solved sample by sample, or its commands sharper than the interpolant of the
    node commands). False for the closed form.

    Parameters
    ----------
    model : Model
    speed : float
        Tangential COG speed, m/s.
    alpha : float
        Circle tilt, rad.
    """
    offsets = circle_offsets(model, speed, alpha)
    if offsets is None and model.closed_form_drag() is not None:
        return False
    return is_rough(model, circle_path(speed, model.r, np.zeros(1)), alpha, offsets)


def circle_offsets(model, speed: float, alpha: float) -> AttitudeOffsets | None:
    """The attitude offsets of a constant-speed circle's nominal, or None for none.

    None unless the config asks for free offsets (``[feasibility] attitude_offsets =
    "free"``) and the zero-offset nominal, checked at ``CHECK_SAMPLES`` azimuths, needs a
    motor outside ``[thrust_min + margin, thrust_max - margin]`` with the tether taut
    (offsets do not change the tension much, so a slack circle stays slack); then the
    least-mean-square offsets of :func:`gainsched.schedule.offsets.solve_offsets`, or None
    when none within ``max_attitude_offset`` exist. Cached per model and circle.
    """
    f = model.config.feasibility
    if f.attitude_offsets != "free":
        return None
    cache = solutions(model).offsets  # a circle's nominal is asked for at several counts
    key = (float(speed), float(alpha))
    if key not in cache:
        T = period(speed, model.r)
        t = np.arange(CHECK_SAMPLES) * (T / CHECK_SAMPLES)
        zero = nominal_from_path(model, circle_path(speed, model.r, t), alpha, periodic=True)
        bits = int(np.bitwise_or.reduce(zero.reasons))
        thrust = bits & (Reason.THRUST_LOW | Reason.THRUST_HIGH)
        cache[key] = (solve_offsets(model, speed, alpha, bound=f.max_attitude_offset)
                      if thrust and not bits & Reason.SLACK else None)
    return cache[key]


def min_taut_speed(config, alpha: float) -> float:
    """Lowest constant speed (m/s) keeping tension >= min_tension at every azimuth (eq. 19)."""
    r, m = config.radius, config.vehicle.mass
    return float(np.sqrt(r * (config.feasibility.min_tension / m + config.g * np.sin(abs(alpha)))))
