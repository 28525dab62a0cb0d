"""Motor numbering and motor commands: the tool's motors T1..T4 in newtons, and what a
flight stack calls them.

The tool numbers the motors of its X layout 1..4 counter-clockwise from the front left
(docs/conventions.md, "Motors") and commands thrusts in N. PX4 numbers a quad-X 1 front
right, 2 rear left, 3 front left, 4 rear right, and commands each motor with a
normalised ``u`` in 0..1 that its thrust curve maps to a thrust (PX4 parameter
``THR_MDL_FAC``, the fraction of the curve that is quadratic)::

    T / T_full = (1 - f) u + f u^2,      0 <= f <= 1,  0 <= u <= 1

(``T_full``: the thrust at full command, N). Its inverse, written so that it holds for
every ``f`` in 0..1 without cancellation (``f = 0``: ``u = T / T_full``)::

    u = 2 y / ((1 - f) + sqrt((1 - f)^2 + 4 f y)),      y = T / T_full

The log readers (:mod:`gainsched.analysis.logs._foreign`) go one way, the generated controller
(``[firmware] motor_order``, ``command``; docs/runtime.md, "PX4") the other, both with
these functions.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "MOTOR_ORDERS",
    "PX4_MOTOR_ORDER",
    "thrust_from_command",
    "command_from_thrust",
    "slots_from_order",
]

#: PX4's quad-X motors for the tool's motors 1..4 (docs/conventions.md, "Motors"): tool
#: motor 1 (front left) is PX4's 3, 2 (rear left) its 2, 3 (rear right) its 4, 4 (front
#: right) its 1. The spin directions agree (tool 1 and 3, PX4 3 and 4: one way).
PX4_MOTOR_ORDER = (3, 2, 4, 1)

#: motor numberings by name: the flight stack's number (1-based) of the tool's motors 1..4
MOTOR_ORDERS = {"gainsched": (1, 2, 3, 4), "px4": PX4_MOTOR_ORDER}


def slots_from_order(order) -> tuple[int, ...]:
    """The 0-based output slot of each of the tool's motors 1..4, from a numbering.

    Parameters
    ----------
    order : sequence of 4 int
        The flight stack's motor number (1..4) of the tool's motors 1..4
        (:data:`MOTOR_ORDERS`).

    Returns
    -------
    tuple of 4 int
        ``order[i] - 1``.

    Examples
    --------
    >>> slots_from_order(PX4_MOTOR_ORDER)
    (2, 1, 3, 0)
    """
    return tuple(int(m) - 1 for m in order)


def thrust_from_command(u, thr_mdl_fac: float, thrust_full: float):
    """Thrust of a normalised motor command through PX4's thrust curve.

    Parameters
    ----------
    u : array_like, shape (...)
        Normalised commands, 0..1 (not clipped here).
    thr_mdl_fac : float
        ``THR_MDL_FAC``, 0..1: the quadratic part of the curve.
    thrust_full : float, N
        Thrust at ``u = 1``.

    Returns
    -------
    ndarray, shape (...), N

    Examples
    --------
    >>> float(gs.thrust_from_command(0.5, 0.3, 6.0))
    2.55
    """
    u = np.asarray(u, dtype=float)
    return thrust_full * ((1.0 - thr_mdl_fac) * u + thr_mdl_fac * u * u)


def command_from_thrust(thrust, thr_mdl_fac: float, thrust_full: float):
    """Normalised motor command of a thrust: the inverse of :func:`thrust_from_command`.

    Parameters
    ----------
    thrust : array_like, shape (...), N
        Thrusts; below 0 gives 0 and above ``thrust_full`` gives 1.
    thr_mdl_fac : float
        ``THR_MDL_FAC``, 0..1.
    thrust_full : float, N
        Thrust at full command (> 0).

    Returns
    -------
    ndarray, shape (...)
        Commands in 0..1 (NaN stays NaN).

    Examples
    --------
    >>> u = gs.command_from_thrust([0.0, 2.55, 6.0], 0.3, 6.0)
    >>> np.allclose(u, [0.0, 0.5, 1.0], rtol=0, atol=1e-15)
    True
    """
    y = np.clip(np.asarray(thrust, dtype=float) / thrust_full, 0.0, 1.0)
    a = 1.0 - thr_mdl_fac
    den = a + np.sqrt(a * a + 4.0 * thr_mdl_fac * y)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(y > 0.0, 2.0 * y / den, np.where(np.isnan(y), np.nan, 0.0))
