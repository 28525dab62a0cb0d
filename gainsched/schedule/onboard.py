"""What a table carries for the firmware: the firmware record (docs/table-format.md,
"The firmware record").

The build computes, once, from the config and its model, everything the generated C
and its Python reference need beyond the gains and the nominal: the closed-form
constants of the feed-forward (``gs_vehicle``), the direction mirror's map of the LQR
state (S2, docs/symmetry.md) and the controller's design parameters (``gs_ctrl_params``
less the sensing fields). :func:`gainsched.schedule.tables.table_bytes` writes them into
the table's ``firmware/`` group, under its checksums, and
:func:`~gainsched.schedule.tables.load_table` reads them back: ``gainsched.firmware``
takes a table and nothing else, so the same table gives the same header whatever the
model code of the checkout that exports it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from ..actuators import MOTOR_ORDERS, slots_from_order
from ..constants import INTEGRATORS
from ..errors import InputError
from ..rotations import quaternion_from_matrix

__all__ = [
    "VEHICLE_FIELDS",
    "CONTROLLER_KEYS",
    "OUTPUT_KEYS",
    "G0",
    "ACCEL_MARGIN",
    "ACCEL_RANGE_MIN_G",
    "FirmwareRecord",
    "record_from_config",
    "vehicle_from_config",
    "state_map_from_config",
    "controller_from_config",
    "outputs_from_config",
    "largest_specific_force",
    "accel_range_for",
    "record_from_datasets",
]

#: the closed-form constants a table carries for the firmware's feed-forward (``gs_vehicle``
#: in gainsched_runtime.h, same order): name -> number of values
VEHICLE_FIELDS = {"mass": 1, "g": 1, "radius": 1, "min_tension": 1, "drag_mu1": 1,
                  "drag_mu2": 1, "J": 9, "alloc_inv": 16}

#: the controller's outputs ([firmware] motor_order, command, thr_mdl_fac, thrust_max_N)
OUTPUT_KEYS = ("motor_slot", "normalized", "thr_mdl_fac", "thrust_full")

#: the controller's design parameters a table carries (``firmware/controller``): the
#: fields of :class:`gainsched.firmware.controller.ControllerParams` that come from the
#: config (``int_limit`` the config's ``[control] int_limit``, null: sized from the gains)
CONTROLLER_KEYS = ("dt", "rho", "L_e", "thrust_min", "thrust_max", "thrust_idle", "int_limit",
                   "int_of", "accel_range", *OUTPUT_KEYS, "n_lag", "lag_keep", "gyro_scale",
                   "gyro_bias", "accel_scale", "accel_bias", "q_MB")

#: standard gravity, m/s^2: the unit of accelerometer ranges ("16 g")
G0 = 9.80665
#: the default accelerometer range over the largest specific force of the table's circles
ACCEL_MARGIN = 1.5
#: the least default accelerometer range, in g (a common MEMS range)
ACCEL_RANGE_MIN_G = 16


@dataclass(frozen=True)
class FirmwareRecord:
    """The firmware record of a table (``firmware/`` in the file).

    Attributes
    ----------
    vehicle : ndarray, shape (31,), float64
        The ``gs_vehicle`` values in :data:`VEHICLE_FIELDS` order: mass kg, g m/s^2,
        radius ``rho + L_e`` m, min_tension N, drag_mu1 N s/m, drag_mu2 N s^2/m^2 (the
        pure-drag effects summed), J (3 x 3) kg m^2, alloc_inv (4 x 4)
        ``(T_C N, tau_B N m) -> thrusts N``.
    state_map : ndarray, shape (n, n), float64
        ``P_x``: the S2 map of the LQR state (a signed involutive permutation).
    controller : dict
        The controller's design parameters, :data:`CONTROLLER_KEYS`: dt s, rho m, L_e m,
        thrust_min/max/idle N, int_limit (rad s, a number, one per integral state, or
        None), int_of (reduced-state indices), accel_range m/s^2, motor_slot (4 ints),
        normalized (bool), thr_mdl_fac, thrust_full N, n_lag (0 or 4), lag_keep,
        gyro_scale and gyro_bias rad/s (3 each) and q_MB (4: the marker frame's
        rotation, a quaternion), ``[sensors]``; a table without them was built before
        they were carried: 1, 0 and the identity.
    """

    vehicle: np.ndarray
    state_map: np.ndarray
    controller: dict

    def controller_json(self) -> str:
        """``controller`` as sorted-key JSON (the ``firmware/controller`` dataset)."""
        return json.dumps(self.controller, sort_keys=True)


def vehicle_from_config(config) -> np.ndarray:
    """The ``gs_vehicle`` values of a config, float64 shape (31,) (:data:`VEHICLE_FIELDS`):
    the drag-only part of its model (:meth:`gainsched.model.reduced.Model.drag_part`)."""
    from ..model.reduced import Model

    model = Model(config).drag_part()
    mu1, mu2 = model.drag_coefficients()
    values = {"mass": model.m, "g": model.g, "radius": model.r,
              "min_tension": config.feasibility.min_tension, "drag_mu1": mu1,
              "drag_mu2": mu2, "J": model.J, "alloc_inv": model.alloc_inv}
    return np.concatenate([np.ravel(values[k]) for k in VEHICLE_FIELDS]).astype(np.float64)


def state_map_from_config(config) -> np.ndarray:
    """``P_x`` of a config's LQR state (its integrals and its effects' states), (n, n)."""
    from ..model.effects import effects_from_specs
    from ..model.symmetry import state_mirror

    return np.asarray(state_mirror(effects_from_specs(config.effects),
                                   config.control.integrators), dtype=np.float64)


def largest_specific_force(config) -> float:
    """The largest specific force (m/s^2) an accelerometer at the COG senses on the
    nominal circles of the config's grid (the table's): ``f = a - g`` with the
    centripetal ``a = v^2 / r`` at the fastest speed, largest where the tilted circle's
    gravity adds to it, ``|f| = sqrt(a^2 + g^2 + 2 a g sin(alpha))`` at the largest tilt.

    Examples
    --------
    >>> round(largest_specific_force(gs.load_config("configs/paper.toml")), 1)  # 15 m/s, 40 deg
    147.1
    """
    v = float(np.max(np.abs(config.grid.speeds)))
    a = v * v / config.radius
    g = float(config.g)
    s = math.sin(float(np.max(np.abs(config.grid.tilts))))
    return math.sqrt(a * a + g * g + 2.0 * a * g * s)


def accel_range_for(config) -> float:
    """The default accelerometer range (m/s^2) of a config's controller: the largest
    specific force of its table's circles (:func:`largest_specific_force`) times
    :data:`ACCEL_MARGIN`, rounded up to whole g, at least :data:`ACCEL_RANGE_MIN_G` g.

    Examples
    --------
    >>> round(accel_range_for(gs.load_config("configs/paper.toml")) / G0)  # 147 m/s^2 x 1.5
    23
    """
    n = math.ceil(ACCEL_MARGIN * largest_specific_force(config) / G0 - 1e-9)
    return G0 * max(ACCEL_RANGE_MIN_G, n)


def outputs_from_config(config) -> dict:
    """The controller's outputs of a config's ``[firmware]`` (:data:`OUTPUT_KEYS`): the
    motor slots of ``motor_order``, ``command == "normalized"``, ``thr_mdl_fac`` and the
    thrust at full command (``thrust_max_N``, default ``vehicle.thrust_max``), N."""
    fw = config.firmware
    return {"motor_slot": [int(i) for i in slots_from_order(MOTOR_ORDERS[fw.motor_order])],
            "normalized": fw.command == "normalized", "thr_mdl_fac": float(fw.thr_mdl_fac),
            "thrust_full": float(config.vehicle.thrust_max if fw.thrust_full is None
                                 else fw.thrust_full)}


def controller_from_config(config) -> dict:
    """The controller's design parameters of a config (:data:`CONTROLLER_KEYS`): the
    loop, the vehicle and the motors, the outputs, the accelerometer range sized from
    the grid (:func:`accel_range_for`), ``[control] int_limit`` (None: sized from the
    table's gains by the firmware) and the motor lag's ``n_lag`` and ``lag_keep =
    exp(-dt / tau)`` (its 4 thrusts end the LQR state,
    :func:`~gainsched.schedule.linearize.lqr_system`), and the gyro's calibration
    (``[sensors]``), which the controller undoes as the log reader does."""
    v, t, c = config.vehicle, config.tether, config.control
    limit = c.int_limit
    if limit is not None:
        limit = float(limit) if np.ndim(limit) == 0 else [float(x) for x in limit]
    lag = [dict(e.params) for e in config.effects if e.name == "motor_lag"]
    out = {"dt": float(c.dt), "rho": float(t.length), "L_e": float(t.attachment_offset),
           "thrust_min": float(v.thrust_min), "thrust_max": float(v.thrust_max),
           "thrust_idle": float(v.thrust_min), "int_limit": limit,
           "int_of": [int(INTEGRATORS[n]) for n in c.integrators],
           "accel_range": float(accel_range_for(config)), **outputs_from_config(config),
           "n_lag": 4 if lag else 0,
           "lag_keep": math.exp(-c.dt / lag[0]["tau"]) if lag else 0.0,
           "gyro_scale": list(config.sensors.gyro_scale),
           "gyro_bias": list(config.sensors.gyro_bias),
           "accel_scale": list(config.sensors.accel_scale),
           "accel_bias": list(config.sensors.accel_bias),
           "q_MB": [float(x) for x in quaternion_from_matrix(config.sensors.R_MB)]}
    return {k: out[k] for k in CONTROLLER_KEYS}


def record_from_config(config) -> FirmwareRecord:
    """The firmware record of a config (computed at the build, stored in its table).

    Computed on the pinned numerics, where the circles are (the build's job runner,
    :func:`~gainsched.schedule.jobs.run_jobs`: in a pinned worker when this process is
    not pinned, a notebook or a test), since the record's bits are part of the table's
    bytes and the model's constants pass through kernels that differ between CPUs (the
    allocation matrix's inverse, vectorised sines).
    """
    from ..model.effects import registered_effects
    from .jobs import run_jobs

    effects = registered_effects({s.name for s in config.effects})
    (record,) = run_jobs([(config, effects)], 1, None, _record)
    return record


def _record(config, effects=()) -> FirmwareRecord:
    """:func:`record_from_config` in this process (``effects``: the registered effect
    classes the config names, which a worker does not know otherwise)."""
    from ..model.effects import registered_effects_context
    from ..native.reproducible import ensure_blas_single_thread

    ensure_blas_single_thread()
    with registered_effects_context(effects):
        return FirmwareRecord(vehicle_from_config(config), state_map_from_config(config),
                              controller_from_config(config))


def _signed_involution(P) -> bool:
    """Whether ``P`` (n, n) is a signed permutation and its own inverse."""
    n = P.shape[0]
    entries = np.sort(np.abs(P), axis=0)
    return bool(np.all(np.isin(P, (-1.0, 0.0, 1.0))) and np.all(entries[-1] == 1)
                and np.all(entries[:-1] == 0) and np.array_equal(P @ P, np.eye(n)))


def record_from_datasets(path, vehicle, state_map, controller, n: int) -> FirmwareRecord:
    """The firmware record read from a table file, checked: ``vehicle`` (31,) finite,
    ``state_map`` (n, n) a signed involution, ``controller`` a JSON object with exactly
    :data:`CONTROLLER_KEYS`. Raises InputError naming ``path`` and the dataset."""
    vehicle = np.asarray(vehicle, dtype=np.float64)
    size = sum(VEHICLE_FIELDS.values())
    if vehicle.shape != (size,) or not np.all(np.isfinite(vehicle)):
        raise InputError(path, "firmware/vehicle", f"must be {size} finite values, got shape "
                         f"{vehicle.shape}")
    P = np.asarray(state_map, dtype=np.float64)
    if P.shape != (n, n) or not _signed_involution(P):
        raise InputError(path, "firmware/state_map", f"must be a signed involutive permutation "
                         f"({n}, {n}) (the gains' states), got shape {P.shape}")
    try:
        ctl = json.loads(controller)
    except (TypeError, ValueError):
        raise InputError(path, "firmware/controller", "not a JSON record") from None
    if isinstance(ctl, dict):  # a table built before the gyro's calibration was carried
        ctl = {**_SENSORS_UNCALIBRATED, **ctl}
    if not isinstance(ctl, dict) or sorted(ctl) != sorted(CONTROLLER_KEYS):
        raise InputError(path, "firmware/controller", "must be a JSON object with the keys "
                         f"{', '.join(CONTROLLER_KEYS)}")
    for key, need in _SENSOR_CHECKS.items():
        v = ctl[key]
        n = len(_SENSORS_UNCALIBRATED[key])
        if (not isinstance(v, list) or len(v) != n
                or not all(isinstance(x, int | float) and not isinstance(x, bool)
                           and math.isfinite(x) for x in v) or not need[0](v)):
            raise InputError(path, "firmware/controller", f"{key} must be {n} finite "
                             f"numbers{need[1]}, got {v!r}")
    return FirmwareRecord(vehicle, P, {k: ctl[k] for k in CONTROLLER_KEYS})


#: the sensors' calibration of a table whose record has none (built before it was carried)
_SENSORS_UNCALIBRATED = {"gyro_scale": [1.0, 1.0, 1.0], "gyro_bias": [0.0, 0.0, 0.0],
                      "accel_scale": [1.0, 1.0, 1.0], "accel_bias": [0.0, 0.0, 0.0],
                      "q_MB": [1.0, 0.0, 0.0, 0.0]}
#: the sensors' keys of a record: (their check beyond finite, what it asks)
_SENSOR_CHECKS = {"gyro_scale": (lambda v: all(x > 0 for x in v), " > 0"),
                  "gyro_bias": (lambda v: True, ""),
                  "accel_scale": (lambda v: all(x > 0 for x in v), " > 0"),
                  "accel_bias": (lambda v: True, ""),
                  "q_MB": (lambda v: abs(sum(x * x for x in v) - 1.0) <= 1e-4,
                           " of unit norm")}
