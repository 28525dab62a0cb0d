"""Closed-loop simulation: the scheduled LQR flying the nonlinear tethered vehicle.

The plant is a config of its own (the "truth"): other parameters, other
effects, another link model than the design config the tables came from.
Fixed-step RK4 at the control rate with the input held (zero-order hold),
motor saturation at the plant's thrust limits, and a clean stop when the
tether goes slack. Sensing: ideal state, or motion capture at a fixed rate
with noise and latency, fused with a model prediction in between pose updates
(the paper's scheme, Sec. V.A: pose updates, prediction in between).

Control law (paper Sec. IV): ``u = u_d - K(xi_d, xi_d', alpha) (x - x_d)``
with the 11-entry LQR state x (xi error wrapped to [-pi, pi)), the nominal
(x_d, u_d) of the reference path on the design model, and K from the tables.

This module is the flat public namespace of the simulator; each concept lives in a
private module of its own (pytransform3d's pattern), whose names are re-exported here:

- ``_scenario``: :class:`Scenario`, :class:`Sensing`, :class:`Maneuver`, their
  validation (:func:`load_scenario`) and the reference path (:func:`profile_path`);
- ``_plant``: the plant (reduced or maximal model, compiled or numpy) and its sensors;
- ``_estimator``: the path controller's state estimate (motion capture + prediction);
- ``_result``: :class:`SimResult` and the accelerometer of a flown path;
- ``_loop``: :func:`simulate`, the path controller's loop and the firmware's;
- ``_metrics``: :func:`metrics`;
- ``_schedulers``: the :class:`Scheduler` interface (the firmware's lookups as methods)
  and its implementations (:func:`table_scheduler`, ...);
- ``_logout``: :func:`log_from_result` and :func:`write_run`.
"""

from __future__ import annotations

from ._logout import log_from_result, write_run
from ._loop import LOOKUP_BITS, simulate, uncompensated_latency_text
from ._metrics import metrics
from ._result import SimResult, specific_force
from ._scenario import (
    INITIAL_ERROR_SIZES,
    MAX_LATENCY_S,
    MAX_MANEUVERS,
    SCENARIO_DIR,
    SENSING_RATE_HZ,
    Maneuver,
    Scenario,
    Sensing,
    Sine,
    check_flight_steps,
    load_scenario,
    profile_path,
    scenario_from_dict,
    scenario_text,
)
from ._schedulers import (
    RUNTIMES,
    CRuntimeScheduler,
    Scheduler,
    TableScheduler,
    c_runtime_scheduler,
    runtime_scheduler,
    table_scheduler,
)

__all__ = [
    "Scenario",
    "Sensing",
    "Maneuver",
    "Sine",
    "scenario_text",
    "SimResult",
    "SCENARIO_DIR",
    "load_scenario",
    "scenario_from_dict",
    "check_flight_steps",
    "profile_path",
    "simulate",
    "metrics",
    "Scheduler",
    "TableScheduler",
    "CRuntimeScheduler",
    "table_scheduler",
    "c_runtime_scheduler",
    "RUNTIMES",
    "runtime_scheduler",
    "log_from_result",
    "write_run",
    # limits and helpers of the modules above, importable from here as before the split
    "LOOKUP_BITS",
    "MAX_MANEUVERS",
    "SENSING_RATE_HZ",
    "MAX_LATENCY_S",
    "INITIAL_ERROR_SIZES",
    "specific_force",
    "uncompensated_latency_text",
]
