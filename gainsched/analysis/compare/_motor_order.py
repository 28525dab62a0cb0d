"""The motor order: does another of the 24 orders of the four motor commands explain the
measured rotation far better than the log's (a map or writer with the motors swapped)?
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np

from ...errors import InputError
from ...model.reduced import Model
from ._predict import _gyro_operator, _savgol, predict

#: how many times lower the rotational residual RMS must be with the motor commands in
#: another order for :func:`check_motor_order` to refuse a log's order
MOTOR_ORDER_FACTOR = 10.0
#: the 24 orders of four motors, (24, 4), the identity first: order ``P`` reads the tool's
#: motor ``k + 1`` from the log's command column ``P[k]``
_MOTOR_ORDERS = np.array(list(itertools.permutations(range(4))))


def motor_order_fits(model: Model, measured) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """How well each of the 24 motor orders explains the measured rotation, per log file.

    For each segment one prediction (:func:`predict`) gives the rotational residual
    ``r`` (roll, pitch, yaw; core samples) of the log's own order and the actual
    thrusts ``T``; another order ``P`` changes the predicted body angular acceleration
    by ``J^-1 A (T[:, P] - T)`` (``A``: the torque rows of ``model.alloc``), put through
    the filter the measured one went through (:func:`_gyro_operator` with a gyro, the
    smoothing without). This is exact for the library's effects that act on each motor
    alike (the thrust modifiers but ``motor_efficiency``, motor lag), whose torques and
    the tether's tension see the motors only through their summed thrust; unequal
    motor efficiencies make it approximate (to their spread, a few per cent: far below
    the factor a wrong order shows).

    Parameters
    ----------
    model : Model
        The model of the comparison.
    measured : list of Measured
        The differentiated segments.

    Returns
    -------
    dict of str to (ndarray, ndarray)
        By log file (``Measured.source``): the orders, shape (24, 4) (0-based, the
        identity first; :data:`_MOTOR_ORDERS`), and the rotational residual RMS of each,
        shape (24,), rad/s^2, pooled over the file's segments and the three axes.
    """
    B = np.linalg.solve(model.J, model.alloc[1:])  # (3, 4): rad/s^2 per N of each motor
    E = np.eye(4)[:, _MOTOR_ORDERS].transpose(1, 0, 2)  # (24, 4, 4): T[:, P] = T @ E[P]
    D = np.einsum("pik,jk->pij", E - np.eye(4), B)  # (24, 4, 3): the change per N
    sse: dict[str, list] = {}
    for meas in measured:
        pred = predict(model, meas, inputs=False, edges=False)
        c = meas.core
        r = meas.omega_dot_measured(pred.latency)[c] - pred.omega_dot[c]  # (n, 3)
        G = (_gyro_operator(pred.T, meas, False) if meas.gyro_dot is not None
             else _savgol(pred.T, meas, 0, False))[c]  # (n, 4), N
        # |r - G D_P|^2 summed, from the Gram matrices (no (24, n, 3) array)
        GtG, Gtr = G.T @ G, G.T @ r
        acc = sse.setdefault(meas.source, [np.zeros(len(_MOTOR_ORDERS)), 0])
        acc[0] += (np.sum(r * r) - 2 * np.einsum("kj,pkj->p", Gtr, D)
                   + np.einsum("pkj,kl,plj->p", D, GtG, D))
        acc[1] += r.size
    return {src: (_MOTOR_ORDERS, np.sqrt(np.maximum(s, 0.0) / max(n, 1)))
            for src, (s, n) in sse.items()}


def _mapped_order(meta: dict) -> list[int] | None:
    """The channel map's ``motors.order`` a converted log records (``motors_order``,
    ``"[3, 2, 4, 1]"``), or None (no such key, or not four numbers)."""
    try:
        order = [int(i) for i in json.loads(meta["motors_order"])]
    except (KeyError, ValueError, TypeError):
        return None
    return order if len(order) == 4 else None


def check_motor_order(model: Model, measured, segs=None,
                      factor: float = MOTOR_ORDER_FACTOR) -> None:
    """Refuse a log whose motor commands are in the wrong order, before any statistic.

    A map (or a CSV writer) that puts the motors in the wrong order mirrors or swaps the
    commanded torques: the rotational residual is tens of times the right order's, and
    a fit would blame some physical effect. When another of the 24 orders explains the
    measured rotation ``factor`` times better (residual RMS, :func:`motor_order_fits`)
    than the log's, the log's order is wrong; a missing physical effect (motor lag,
    thrust loss, drag) leaves a residual that no order removes, so it never gets there.

    Parameters
    ----------
    model : Model
        The model of the comparison.
    measured : list of Measured
        The differentiated segments.
    segs : list of FlightLog, optional
        Their log segments (same order): a converted PX4 ULog or ROS 2 bag carries its
        map's ``motors_order`` in its metadata, and the error then gives the map's order
        that fits.
    factor : float, default :data:`MOTOR_ORDER_FACTOR`
        How many times lower the residual RMS must be.

    Raises
    ------
    InputError
        Naming the log file and ``motors.order`` (a converted log) or the thrust columns
        (the project's own format), with the order that fits and how much better.
    """
    meta = {m.source: s.meta for m, s in zip(measured, segs or [None] * len(measured),
                                               strict=True) if s is not None}
    for src, (orders, rms) in motor_order_fits(model, measured).items():
        best = int(np.argmin(rms))
        ratio = rms[0] / rms[best] if rms[best] > 0 else math.inf
        if best == 0 or not ratio > factor:
            continue
        P = orders[best]
        fits = (f"the commands fit the measured rotation {ratio:.0f}x better (residual RMS "
                f"{rms[best]:.3g} against {rms[0]:.3g} rad/s^2)")
        old = _mapped_order(meta.get(src, {}))
        if old is not None:
            raise InputError(src, "motors.order", f"{fits} with motors.order = "
                             f"{[old[k] for k in P]} than with the order "
                             f"{old} of the channel map {meta[src].get('channel_map', '')}: "
                             "check the map's motor order")
        cols = ", ".join(f"T{k + 1}" for k in P)
        raise InputError(src, "columns T1, T2, T3, T4", f"{fits} as the tool's motors 1..4 "
                         f"= columns {cols}: are the thrust columns in the tool's motor "
                         "order (docs/conventions.md, Motors)?")
