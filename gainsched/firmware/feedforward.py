"""The manoeuvre feed-forward a firmware computes from the generated files alone.

The table stores the nominal of constant-speed circles only (``u_d``, ``phi_d``).
An accelerating reference (a speed-up, a braking) needs more: the tangential
force of ``r xi''`` changes the roll, the collective and, through ``phi'`` and
``phi''``, the body rates and torques (paper eqs. 15-18). The firmware gets it as

    u_d   = u_cf(ref) * [u_d,table(xi, xi', alpha) / u_cf(steady)]    (per motor)
    phi_d = phi_cf(ref) + [phi_d,table(xi, xi', alpha) - phi_cf(steady)]

``cf`` is the closed form of the drag-only model (paper eqs. 15-18, eq. 17
corrected) at the accelerating reference ``ref`` and at the constant-speed circle
``steady`` the lookup used (speed and tilt clamped into the table). It covers the
rigid body, the tether, gravity and the drag effects exactly; the brackets are the
tabulated correction for every other effect of the config (the trim's nominal, any
effects). For a drag-only config they carry the table's interpolation error only;
on a constant-speed circle inside the table the result is exactly the lookup's.
The thrust correction is a ratio, so an effect that scales the thrust (a thrust
scale, a loss with airspeed) scales the extra thrust of a manoeuvre too. What it
does not carry is a force effect's change *with* the acceleration (rotor drag
grows with the collective a braking needs).

This module is the Python reference of that computation (``feedforward``), in double
precision on the table's own float32 constants (``RuntimeData.vehicle``, the
``gs_vehicle`` of the header); ``gs_lookup_nominal`` in
``gainsched/firmware/c/gainsched_runtime.c`` is its C form, with the same clamps and
guards, and tests/firmware/test_feedforward_c.py holds the two together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import N_STATE
from ..errors import InputError
from ..schedule.closedform import closed_form
from ..schedule.path import AzimuthPath
from .runtime import LOW_TENSION, UNUSABLE, Interpolator, VehicleConstants

__all__ = ["FF_RATIO_FULL", "FF_RATIO_NONE", "FeedForward", "feedforward"]

#: a motor's closed-form thrust is corrected by the table's ratio where the steady closed
#: form's thrust is at least FF_RATIO_FULL (N), by the table's difference where it is at
#: most FF_RATIO_NONE, linearly blended between (``GS_FF_RATIO_FULL``, ``GS_FF_RATIO_NONE``):
#: a ratio near zero steady thrust is ill-conditioned
FF_RATIO_FULL = 0.5
FF_RATIO_NONE = 0.2


@dataclass(frozen=True)
class FeedForward:
    """The firmware's nominal along a reference, per sample.

    Attributes
    ----------
    x_d : ndarray, shape (N, 10)
        Nominal reduced state: ``delta = pi/2``, the reference ``xi, xi'``, ``phi_d``,
        ``theta = chi = 0``, ``omega_d = (phi_d', xi' sin phi_d, xi' cos phi_d)``.
    u_d : ndarray, shape (N, 4), N
        Nominal motor thrust commands.
    tension : ndarray, shape (N,), N
        Nominal tether tension of the closed form (paper eq. 18 with the acceleration
        terms; the drag-only model's, the firmware's estimate).
    status : ndarray, shape (N,), int
        The lookup's status bits (:mod:`gainsched.firmware.runtime`); where unusable the
        correction is left out (closed form only). Plus ``LOW_TENSION`` where the
        nominal tension is below the config's ``min_tension``.
    K : ndarray, shape (N, 4, n), optional
        The lookup's gains at the reference when the source returns them with the
        nominal (the C runtime's ``gs_lookup_nominal``), else None.
    """

    x_d: np.ndarray
    u_d: np.ndarray
    tension: np.ndarray
    status: np.ndarray
    K: np.ndarray | None = None


def feedforward(lookup: Interpolator, path: AzimuthPath, alpha: float) -> FeedForward:
    """The nominal a firmware flies along ``path`` (see the module docstring).

    Parameters
    ----------
    lookup : Interpolator
        The table's lookup (the Python reference of the C runtime); its data carry the
        closed form's vehicle constants.
    path : AzimuthPath
        The reference ``xi(t)`` with four derivatives (rad, rad/s, ... rad/s^4).
    alpha : float, rad
        Circle tilt.

    Example
    -------
    >>> from gainsched.schedule.path import maneuver_path           # doctest: +SKIP
    >>> path = maneuver_path(11.3, 1.0, 8.75, cfg.radius, t, 0.5)   # doctest: +SKIP
    >>> ff = feedforward(Interpolator(table), path, 0.0)            # doctest: +SKIP
    """
    d = lookup.data
    if d.vehicle is None:
        raise InputError(d.name, "vehicle", "the table carries no closed-form constants "
                         "(its config cannot be loaded here): no manoeuvre feed-forward")
    vehicle = VehicleConstants.from_array(d.vehicle)
    D = vehicle.closed_form_drag()
    s, _, u_cf, tension = closed_form(vehicle, path, alpha, D)
    # the correction is taken where the lookup is: at the clamped speed and tilt when the
    # reference leaves the grid (below the lowest speed the table holds, say); the
    # runtime's sign conventions: xi' = 0 is a positive rate, alpha = 0 a positive tilt
    xd = path.d[0]
    lo, hi, top = float(d.xi_dot[0]), float(d.xi_dot[-1]), float(d.tilt[-1])
    xd_grid = np.where(xd < 0, -1.0, 1.0) * np.clip(np.abs(xd), lo, hi)
    a_grid = (-1.0 if alpha < 0 else 1.0) * min(abs(alpha), top)
    zero = np.zeros_like(path.t)
    steady = AzimuthPath(path.t, path.xi, (xd_grid, zero, zero, zero))
    s0, _, u0, _ = closed_form(vehicle, steady, a_grid, D)
    lk = lookup(path.xi, xd, np.full_like(path.t, alpha))
    usable = (lk.status & UNUSABLE) == 0
    # per motor, the table's thrust over the steady closed form's: a thrust scale or a
    # thrust change with airspeed multiplies the command, so a ratio carries them
    # through the manoeuvre exactly (an offset would not)
    # (a ratio is ill-conditioned where the steady thrust nears zero: there the table's
    # difference, and a linear blend between)
    s_ratio = np.clip((u0 - FF_RATIO_NONE) / (FF_RATIO_FULL - FF_RATIO_NONE), 0.0, 1.0)
    by_ratio = u_cf * lk.u_d / np.where(u0 > FF_RATIO_NONE, u0, 1.0)
    corrected = s_ratio * by_ratio + (1 - s_ratio) * (u_cf + lk.u_d - u0)
    u_d = np.where(usable[:, None], corrected, u_cf)
    dphi = np.where(usable, lk.phi_d - s0[:, 4], 0.0)
    x_d = np.array(s[:, :N_STATE], dtype=float)
    phi = x_d[:, 4] + dphi
    # the correction's rate, xi' d/dxi (phi_table - phi_steady): the table's slope in its
    # xi cell, the steady closed form's rate over its own xi'
    slope = lookup.roll_slope(path.xi, xd, np.full_like(path.t, alpha))
    x_d[:, 7] += np.where(usable, xd * (slope - s0[:, 7] / xd_grid), 0.0)
    # the table's attitude offsets (theta, chi and their azimuth slopes) and the body
    # rates of the ZYX Euler kinematics with them (closedform.state_from_attitude)
    off = lookup.attitude(path.xi, xd, np.full_like(path.t, alpha))
    theta, chi = off[:, 0], off[:, 2]
    dpsi, dtheta = xd * (1 + off[:, 3]), xd * off[:, 1]
    x_d[:, 4], x_d[:, 5], x_d[:, 6] = phi, theta, chi
    x_d[:, 7] = x_d[:, 7] - dpsi * np.sin(theta)
    x_d[:, 8] = dtheta * np.cos(phi) + dpsi * np.cos(theta) * np.sin(phi)
    x_d[:, 9] = dpsi * np.cos(theta) * np.cos(phi) - dtheta * np.sin(phi)
    status = lk.status.astype(int) | np.where(tension < vehicle.min_tension, LOW_TENSION, 0)
    return FeedForward(x_d, u_d, tension, status)
