"""The manoeuvre feed-forward a firmware computes from the generated files alone.

The table stores the nominal of constant-speed circles only (``u_d``, ``phi_d``).
An accelerating reference (a speed-up, a braking) needs more: the tangential
force of ``r xi''`` changes the roll, the collective and, through ``phi'`` and
``phi''``, the body rates and torques (paper eqs. 15-18). The firmware gets it as

    nominal(xi, xi', xi'', xi''', xi'''', alpha) =
        closed form of the drag-only model at the accelerating reference
      + [table nominal at (xi, xi', alpha) - closed form at the same constant speed]

The closed form (paper eqs. 15-18, eq. 17 corrected) covers the rigid body, the
tether, gravity and the drag effects exactly; the bracket is the tabulated
correction for every other effect of the config (the trim's nominal, any
effects). For a drag-only config the bracket is the table's interpolation error
only; on a constant-speed circle the sum is exactly today's lookup. What the
correction does not carry is how another effect changes *with* the acceleration
(a thrust scale scales the extra thrust a braking needs): the closed form's part
of it is right, the effect's share of the change is missing.

This module is the Python reference of that computation (``feedforward``); the
firmware's C form and its tests follow it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import N_STATE
from ..model.reduced import Model
from ..schedule.closedform import closed_form
from ..schedule.path import AzimuthPath
from .runtime import UNUSABLE, Interpolator

__all__ = ["FeedForward", "drag_only_model", "feedforward"]


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
        correction is left out (closed form only).
    """

    x_d: np.ndarray
    u_d: np.ndarray
    tension: np.ndarray
    status: np.ndarray


def drag_only_model(config) -> Model:
    """The part of ``config``'s model the closed form covers: the rigid body, the tether,
    gravity and the effects that are pure COG-velocity drags (no states, no thrust
    change)."""
    full = Model(config)
    drags = tuple(e for e in full.effects
                  if e.n_states == 0 and e.tangential_drag(1.0) is not None)
    return Model(config, effects=drags)


def feedforward(lookup: Interpolator, config, path: AzimuthPath, alpha: float) -> FeedForward:
    """The nominal a firmware flies along ``path`` (see the module docstring).

    Parameters
    ----------
    lookup : Interpolator
        The table's lookup (the Python reference of the C runtime).
    config : Config
        The config the table was built from (its vehicle, tether and drag).
    path : AzimuthPath
        The reference ``xi(t)`` with four derivatives (rad, rad/s, ... rad/s^4).
    alpha : float, rad
        Circle tilt.

    Example
    -------
    >>> from gainsched.schedule.path import maneuver_path           # doctest: +SKIP
    >>> path = maneuver_path(11.3, 1.0, 8.75, cfg.radius, t, 0.5)   # doctest: +SKIP
    >>> ff = feedforward(Interpolator(table), cfg, path, 0.0)       # doctest: +SKIP
    """
    model = drag_only_model(config)
    D = model.closed_form_drag()
    s, _, u_cf, tension = closed_form(model, path, alpha, D)
    # the correction is taken where the lookup is: at the clamped speed and tilt when the
    # reference leaves the grid (below the lowest speed the table holds, say)
    d = lookup.data
    xd = path.d[0]
    xd_grid = np.sign(xd) * np.clip(np.abs(xd), float(d.xi_dot[0]), float(d.xi_dot[-1]))
    a_grid = float(np.sign(alpha) * min(abs(alpha), float(d.tilt[-1])))
    zero = np.zeros_like(path.t)
    steady = AzimuthPath(path.t, path.xi, (xd_grid, zero, zero, zero))
    s0, _, u0, _ = closed_form(model, steady, a_grid, D)
    lk = lookup(path.xi, xd, np.full_like(path.t, alpha))
    usable = (lk.status & UNUSABLE) == 0
    # per motor, the table's thrust over the steady closed form's: a thrust scale or a
    # thrust change with airspeed multiplies the command, so a ratio carries them
    # through the manoeuvre exactly (an offset would not)
    ratio = np.where(usable[:, None], lk.u_d / u0, 1.0)
    dphi = np.where(usable, lk.phi_d - s0[:, 4], 0.0)
    x_d = np.array(s[:, :N_STATE], dtype=float)
    phi = x_d[:, 4] + dphi
    x_d[:, 4] = phi
    x_d[:, 8] = xd * np.sin(phi)
    x_d[:, 9] = xd * np.cos(phi)
    return FeedForward(x_d, u_cf * ratio, tension, lk.status.astype(int))
