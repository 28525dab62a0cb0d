"""Physical plausibility of a config: refused at validation, in milliseconds, what no
build could fly.

Types and ranges of single keys are :mod:`gainsched.config`'s; this module checks
what the keys mean together, naming the key and the figures:

- **gravity** ``environment.g`` in ``G_RANGE`` = [0.1, 100] m/s^2: the Moon has 1.62,
  Mars 3.71, the Earth 9.81, Jupiter's cloud tops 24.8; 100 leaves room for a
  centrifuge test, and beyond either end the value is a unit slip (mm/s^2, or
  ``g = 9810``);
- **lengths** ``tether.length`` at most ``MAX_TETHER_LENGTH`` (1 km: a quadcopter
  lifts no longer tether, and the build's control steps per period grow with the
  radius), and ``vehicle.arm_length`` shorter than the tether (the rotors would reach
  past the anchor); ``tether.attachment_offset < tether.length`` is the config's;
- **hover**: the four motors carry the weight, ``4 thrust_max > m g``, and at most
  ``MAX_THRUST_TO_WEIGHT`` (1000) times it (racing quadcopters reach 15, the lightest
  vehicle a config may have, 0.01 kg, on 3.5 N motors 143; more is a unit slip);
- **a flyable circle** (:func:`check_circles`): some circle of the grid has a taut
  tether (tension >= ``feasibility.min_tension``) and a collective thrust inside
  ``4 [thrust_min + margin, thrust_max - margin]`` at every azimuth, by the
  closed-form nominal (paper eqs. 17-18, :func:`balance`, shared with
  :func:`gainsched.schedule.closedform.closed_form`) with the config's velocity drag.
  The estimate is optimistic (the gyroscopic torques that split the collective between
  the motors, and effects other than drag, are left out), so a config it refuses has
  no feasible circle at all, where a build would have run to a 0 % feasible table.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError

if TYPE_CHECKING:  # the config module calls this one: no import at run time
    from ._reader import Config

__all__ = ["G_RANGE", "MAX_TETHER_LENGTH", "MAX_THRUST_TO_WEIGHT", "balance", "check_lengths",
           "check_hover", "check_circles"]

#: m/s^2: the gravity a config may set (see the module docstring)
G_RANGE = (0.1, 100.0)
#: m: the longest tether
MAX_TETHER_LENGTH = 1000.0
#: 4 thrust_max / (m g) at most this
MAX_THRUST_TO_WEIGHT = 1000.0
#: azimuths per circle and most speeds / tilts of an automatic axis the circle check tries
CHECK_AZIMUTHS = 16
CHECK_AXIS_POINTS = 64


def balance(m, g, r, sa, ca, xi, xd, xdd, Dv):
    """The nominal's force balance on the great circle (paper eqs. 17-18).

    Mass ``m`` kg, gravity ``g`` m/s^2, radius ``r`` m, sine and cosine of the tilt
    ``sa, ca``; azimuth ``xi`` rad, its rate ``xd`` rad/s and acceleration ``xdd``
    rad/s^2; the tangential drag ``Dv`` N. Returns ``N`` (tangential specific force,
    m/s^2), ``Dn`` (normal, m/s^2), ``H = Dn^2 + N^2`` (the collective thrust is
    ``m sqrt(H)``) and the tether tension (N, eq. 18).
    """
    N = r * xdd + g * sa * np.cos(xi) + Dv / m
    Dn = g * ca
    H = Dn**2 + N**2
    tension = m * r * xd**2 - m * g * sa * np.sin(xi)  # eq. 18
    return N, Dn, H, tension


def check_lengths(source, arm_length: float, length: float) -> None:
    """``tether.length <= MAX_TETHER_LENGTH`` and ``vehicle.arm_length < tether.length``."""
    if length > MAX_TETHER_LENGTH:
        raise InputError(source, "tether.length", f"must be <= {MAX_TETHER_LENGTH:g} m, got "
                         f"{length:g} (the build's steps per period grow with the radius)")
    if arm_length >= length:
        raise InputError(source, "vehicle.arm_length",
                         f"{arm_length:g} m is not shorter than tether.length = {length:g} m: "
                         "the rotors would reach past the anchor")


def check_hover(source, mass: float, thrust_max: float, g: float) -> None:
    """The motors carry the weight, and not absurdly more: ``1 < 4 thrust_max / (m g) <=
    MAX_THRUST_TO_WEIGHT``."""
    weight, full = mass * g, 4 * thrust_max
    if not full > weight:
        raise InputError(source, "vehicle.mass",
                         f"weight m g = {mass:g} kg x {g:g} m/s^2 = {weight:.4g} N is more "
                         f"than the motors carry, 4 x vehicle.thrust_max = 4 x {thrust_max:g} "
                         f"N = {full:.4g} N: the vehicle cannot hover")
    if full > MAX_THRUST_TO_WEIGHT * weight:
        raise InputError(source, "vehicle.thrust_max",
                         f"4 x {thrust_max:g} N is {full / weight:.3g} times the weight m g = "
                         f"{weight:.4g} N; at most {MAX_THRUST_TO_WEIGHT:g} (a unit slip?)")


def _axis(values, rng) -> np.ndarray:
    if rng is None:
        return np.asarray(values, dtype=float)
    return np.linspace(rng.lo, rng.hi, min(rng.max_count, CHECK_AXIS_POINTS))


def check_circles(config: Config, source) -> None:
    """Some circle of the grid is flyable by the closed-form estimate (module docstring).

    Raises InputError naming ``grid.speeds`` when no circle keeps the tether taut (with
    the lowest taut speed) and ``vehicle.thrust_max`` (or ``vehicle.thrust_min``) when
    every taut circle needs a collective thrust outside the motors' range.
    """
    from ..model.reduced import Model  # the drag of the config's effects

    model = Model(config)
    coeffs = model.drag_coefficients()
    if coeffs is None:  # other effects too: their velocity drags only
        coeffs = model.drag_part().drag_coefficients()
    mu1, mu2 = coeffs
    v, f = config.vehicle, config.feasibility
    m, g, r = v.mass, config.g, config.radius
    lo, hi = 4 * (v.thrust_min + f.thrust_margin), 4 * (v.thrust_max - f.thrust_margin)
    speeds = _axis(config.grid.speeds, config.grid.speeds_auto)
    tilts = _axis(config.grid.tilts, config.grid.tilts_auto)
    xi = 2 * np.pi * np.arange(CHECK_AZIMUTHS) / CHECK_AZIMUTHS
    xd = (speeds / r)[:, None] * np.ones_like(xi)
    drag = mu1 * speeds + mu2 * speeds**2
    best = None  # (the taut circle that needs the least out-of-range thrust)
    taut_any = False
    for a in tilts:
        _, _, H, tension = balance(m, g, r, np.sin(a), np.cos(a), xi, xd, 0.0,
                                   drag[:, None] * np.ones_like(xi))
        T_C = m * np.sqrt(H)
        taut = np.all(tension >= f.min_tension, axis=1)
        t_hi, t_lo = T_C.max(axis=1), T_C.min(axis=1)
        if np.any(taut & (t_hi <= hi) & (t_lo >= lo)):
            return
        taut_any |= bool(taut.any())
        for k in np.flatnonzero(taut):
            excess = max(t_hi[k] - hi, lo - t_lo[k])
            if best is None or excess < best[0]:
                best = (excess, speeds[k], a, t_hi[k], t_lo[k])
    if not taut_any:
        v_top, a0 = speeds[-1], tilts[0]
        need = np.sqrt(r * (f.min_tension / m + g * np.sin(a0)))
        raise InputError(
            source, "grid.speeds",
            f"no circle of the grid keeps the tether taut: the fastest, {v_top:g} m/s on the "
            f"{r:g} m circle, pulls m v^2 / r = {m * v_top**2 / r:.3g} N; tension >= "
            f"feasibility.min_tension = {f.min_tension:g} N needs >= {need:.3g} m/s at tilt "
            f"{np.rad2deg(a0):g} deg")
    _, sp, a, t_hi, t_lo = best
    where = f"at {sp:g} m/s, tilt {np.rad2deg(a):g} deg"
    if t_hi > hi:
        raise InputError(
            source, "vehicle.thrust_max",
            f"no circle of the grid is flyable: every taut one needs more collective thrust "
            f"than 4 x (thrust_max - thrust_margin) = {hi:.4g} N (the least, {where}, "
            f"{t_hi:.4g} N for m = {m:g} kg at g = {g:g} m/s^2)")
    raise InputError(
        source, "vehicle.thrust_min",
        f"no circle of the grid is flyable: every taut one needs less collective thrust than "
        f"4 x (thrust_min + thrust_margin) = {lo:.4g} N (the most, {where}, {t_lo:.4g} N)")
