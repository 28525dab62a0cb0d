"""The gains and nominal on the schedule's axes: the fields a gain table
(:class:`~gainsched.schedule.tables.Table`, float64 as stored) and the runtime's data
(:class:`~gainsched.firmware.dense.RuntimeData`, float32 as the firmware holds them)
share, written once (docs/table-format.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GainSchedule"]


@dataclass(frozen=True)
class GainSchedule:
    """Axes, gains and nominal of a schedule; the shapes and units are those of
    :class:`~gainsched.schedule.tables.Table`, whose docstring describes every field:
    ``xi`` (n_xi,) rad, ``speed`` (n_v,) m/s, ``xi_dot`` (n_v,) rad/s, ``tilt`` (n_a,)
    rad, ``K_tilt0`` (n_v, 4, n) or (n_v, n_xi, 4, n) and ``K`` (n_a - 1, n_v, n_xi, 4,
    n) N per state unit, ``u_d`` (n_a, n_v, n_xi, 4) N, ``phi_d`` (n_a, n_v, n_xi) rad."""

    xi: np.ndarray
    speed: np.ndarray
    xi_dot: np.ndarray
    tilt: np.ndarray
    K_tilt0: np.ndarray
    K: np.ndarray
    u_d: np.ndarray
    phi_d: np.ndarray
