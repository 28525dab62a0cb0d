"""Synthetic flight campaigns with a hidden effect (test data for compare / diagnose).

A campaign flies a set of scenarios (several speeds and tilts, a speed-up, a
braking) in closed loop with the design config's gain table, on a *plant*
that differs from the design by one hidden effect, and returns the flight
logs a real campaign would leave (motion-capture noise on, commanded thrusts,
optionally the load cell). :data:`HIDDEN` lists the hidden effects the tests
and the example data set use; each says how the plant (or the logging) differs
from the design and the true parameter value diagnose should recover.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..analysis.logs import FlightLog, log_from_arrays, write_log
from ..config import Config, config_from_text, set_section, set_value
from ..model.effects import registered_effect
from ._outside import AzimuthThrustLoss
from .loop import Maneuver, Scenario, Sensing, log_from_result, simulate

__all__ = [
    "HiddenEffect",
    "HIDDEN",
    "REAL_TETHER",
    "outside_table",
    "AzimuthThrustLoss",
    "default_flights",
    "plant_config",
    "fly",
    "campaign",
    "write_campaign",
]


@dataclass(frozen=True)
class HiddenEffect:
    """How the truth differs from the design config.

    ``sections``: TOML edits, (section, key, value) or (section, None, items) for a whole
    table; ``latency``: pose delay in the logs, s; ``truth``: the parameter diagnose should
    recover, (candidate name, parameter, value); ``custom``: an effect class outside the
    registry that the plant uses.
    """

    name: str
    doc: str
    sections: tuple = ()
    latency: float = 0.0
    truth: tuple | None = None
    custom: type | None = None


HIDDEN: dict[str, HiddenEffect] = {
    h.name: h
    for h in (
        HiddenEffect("none", "no hidden effect (negative control)"),
        HiddenEffect("drag_quadratic", "quadratic drag mis-set: mu2 = 0.0075 instead of 0.0025",
                     (("effects.drag", "mu2", 0.0075),), truth=("drag_quadratic", "mu2", 0.0075)),
        HiddenEffect("drag_both", "both drag coefficients mis-set in opposite directions: "
                     "mu1 = 0.086 (-50 %), mu2 = 0.0045 (+80 %)",
                     (("effects.drag", "mu1", 0.086), ("effects.drag", "mu2", 0.0045)),
                     truth=("drag", "mu2", 0.0045)),
        HiddenEffect("thrust_airspeed", "thrust loss with airspeed, T *= 1 - 0.01 v",
                     (("effects.thrust_airspeed", None, (("c1", -0.01), ("c2", 0.0))),),
                     truth=("thrust_airspeed", "c1", -0.01)),
        HiddenEffect("thrust_momentum", "thrust change with airspeed by momentum theory "
                     "(eq. 29), disk area 0.006 m^2",
                     (("effects.thrust_momentum", None, (("disk_area", 0.006),)),),
                     truth=("thrust_momentum", "disk_area", 0.006)),
        HiddenEffect("rotor_drag", "rotor drag k_rd = 0.015 s/m",
                     (("effects.rotor_drag", None, (("k_rd", 0.015),)),),
                     truth=("rotor_drag", "k_rd", 0.015)),
        HiddenEffect("motor_lag", "first-order motor lag tau = 35 ms",
                     (("effects.motor_lag", None, (("tau", 0.035),)),),
                     truth=("motor_lag", "tau", 0.035)),
        HiddenEffect("latency", "motion-capture latency 15 ms", latency=0.015,
                     truth=("latency", "latency_s", 0.015)),
        HiddenEffect("tether_elasticity", "elastic tether, k = 3000 N/m, c = 5 N s/m",
                     (("tether", "link", "spring-damper"), ("tether", "stiffness", 3000.0),
                      ("tether", "damping", 5.0)),
                     truth=("tether_elasticity", "stiffness", 3000.0)),
        HiddenEffect("stiff_tether", "stiff elastic tether, k = 2e5 N/m, c = 20 N s/m (the "
                     "damping is not identified on these flights)",
                     (("tether", "link", "spring-damper"), ("tether", "stiffness", 2e5),
                      ("tether", "damping", 20.0)),
                     truth=("tether_elasticity", "stiffness", 2e5)),
        HiddenEffect("lag_on_stiff_tether", "a first-order motor lag tau = 35 ms on a stiff "
                     "elastic tether, k = 2e5 N/m, c = 20 N s/m: what a real vehicle has",
                     (("effects.motor_lag", None, (("tau", 0.035),)),
                      ("tether", "link", "spring-damper"), ("tether", "stiffness", 2e5),
                      ("tether", "damping", 20.0)),
                     truth=("motor_lag", "tau", 0.035)),
        HiddenEffect("thrust_scale", "thrust scale k_T = 0.92 (static test 8% optimistic)",
                     (("effects.thrust_scale", None, (("k_T", 0.92),)),),
                     truth=("thrust_scale", "k_T", 0.92)),
        HiddenEffect("motor_efficiency", "motor 3 gives 8 % less thrust (eta3 = 0.92: a worn "
                     "propeller)", (("effects.motor_efficiency", None, (("eta3", 0.92),)),),
                     truth=("motor_efficiency", "eta3", 0.92)),
        HiddenEffect("thrust_time", "thrust declining with flight time by 1.6% per second "
                     "(a sagging battery, sped up to show in flights of seconds)",
                     (("effects.thrust_time", None, (("rate", 0.016),)),),
                     truth=("thrust_time", "rate", 0.016)),
        HiddenEffect("battery", "thrust following a sagging battery, (vbat / 11.9 V)^2: a "
                     "3S pack of 40 mAh (a 1.3 Ah pack's sag sped up about 30x to show in "
                     "flights of seconds), 0.1 ohm, 1.2 A per N of thrust; the logs carry "
                     "vbat",
                     (("effects.thrust_voltage", None,
                       (("v_ref", 11.9), ("exponent", 2.0), ("v_full", 12.6),
                        ("v_empty", 10.5), ("capacity", 0.04), ("resistance", 0.1),
                        ("current", 1.2), ("tau", 0.05))),),
                     truth=("thrust_voltage", "exponent", 2.0)),
        HiddenEffect("wind", "steady wind of 3 m/s from 307 deg (north-west): east 2.4, "
                     "north -1.8 m/s; every flight's heading gamma_C = 0, so the level "
                     "circles see it in their plane and the tilted ones partly across it",
                     (("effects.wind", None, (("east", 2.4), ("north", -1.8))),),
                     truth=("wind", "east", 2.4)),
        HiddenEffect("mass", "mass 0.55 kg instead of 0.5 kg", (("vehicle", "mass", 0.55),),
                     truth=("mass", "mass", 0.55)),
        HiddenEffect("inertia_z", "yaw moment of inertia 30 % below the config's: Jzz = "
                     "0.00315 instead of 0.0045 kg m^2",
                     (("vehicle", "inertia", [2.5e-3, 2.5e-3, 3.15e-3]),),
                     truth=("inertia_z", "Jzz", 3.15e-3)),
        HiddenEffect("inertia_x", "roll moment of inertia 30 % above the config's: Jxx = "
                     "0.00325 instead of 0.0025 kg m^2",
                     (("vehicle", "inertia", [3.25e-3, 2.5e-3, 4.5e-3]),),
                     truth=("inertia_x", "Jxx", 3.25e-3)),
        HiddenEffect("cog_offset", "the centre of mass 3 mm to the right of the frame centre "
                     "and 2 mm below it (a battery slid sideways; the motion capture tracks "
                     "the frame)", (("effects.cog_offset", None, (("x", 0.0), ("y", 0.003),
                                                                  ("z", -0.002))),),
                     truth=("cog_offset", "y", 0.003)),
        HiddenEffect("kappa", "rotor reaction-torque coefficient 50 % above the config's: "
                     "kappa = 0.024 instead of 0.016 m",
                     (("vehicle", "kappa", 0.024),), truth=("kappa", "kappa", 0.024)),
        HiddenEffect("gyro", "an uncalibrated gyroscope: scale 1.03, 0.97, 1.02 and bias "
                     "0.010, -0.008, 0.012 rad/s on its x, y, z axes (a MEMS gyro's "
                     "tolerances before calibration)",
                     (("sensors", "gyro_scale", [1.03, 0.97, 1.02]),
                      ("sensors", "gyro_bias", [0.01, -0.008, 0.012])),
                     truth=("sensor_calibration", "gyro_scale_x", 1.03)),
        HiddenEffect("marker_rotation", "the motion capture's marker frame turned from the "
                     "body's by roll 1.0, pitch -1.5, yaw 2.0 deg (a rigid body defined by "
                     "hand on the markers)",
                     (("sensors", "marker_rotation_deg", [1.0, -1.5, 2.0]),),
                     truth=("sensor_calibration", "marker_yaw", 2.0)),
        HiddenEffect("gyro_and_markers", "both at once: the uncalibrated gyroscope of 'gyro' "
                     "and the turned marker frame of 'marker_rotation'",
                     (("sensors", "gyro_scale", [1.03, 0.97, 1.02]),
                      ("sensors", "gyro_bias", [0.01, -0.008, 0.012]),
                      ("sensors", "marker_rotation_deg", [1.0, -1.5, 2.0])),
                     truth=("sensor_calibration", "gyro_scale_x", 1.03)),
        HiddenEffect("accel", "an uncalibrated accelerometer: scale 0.98, 1.02, 1.01 and "
                     "bias 0.10, -0.15, 0.20 m/s^2 on its x, y, z axes",
                     (("sensors", "accel_scale", [0.98, 1.02, 1.01]),
                      ("sensors", "accel_bias", [0.1, -0.15, 0.2])),
                     truth=("sensor_calibration", "accel_scale_x", 0.98)),
        HiddenEffect("attachment_offset", "attachment offset L_e = 0.12 m instead of 0.10 m",
                     (("tether", "attachment_offset", 0.12),),
                     truth=("attachment_offset", "attachment_offset", 0.12)),
        HiddenEffect("example", "the example data set (docs/model-vs-measurement.md): "
                     "thrust change with airspeed by momentum theory (disk area 0.006 m^2) "
                     "and a 30 ms motor lag",
                     (("effects.thrust_momentum", None, (("disk_area", 0.006),)),
                      ("effects.motor_lag", None, (("tau", 0.03),))),
                     truth=("thrust_momentum", "disk_area", 0.006)),
        HiddenEffect("three_effects", "thrust loss with airspeed (c1 = -0.01), a 35 ms motor "
                     "lag and quadratic drag mu2 = 0.0045 instead of 0.0025, at once",
                     (("effects.thrust_airspeed", None, (("c1", -0.01), ("c2", 0.0))),
                      ("effects.motor_lag", None, (("tau", 0.035),)),
                      ("effects.drag", "mu2", 0.0045)),
                     truth=("motor_lag", "tau", 0.035)),
        HiddenEffect("four_effects", "thrust loss with airspeed (c1 = -0.01), a 35 ms motor "
                     "lag, quadratic drag mu2 = 0.0045 instead of 0.0025 and motor 3 giving "
                     "8 % less thrust (eta3 = 0.92), at once",
                     (("effects.thrust_airspeed", None, (("c1", -0.01), ("c2", 0.0))),
                      ("effects.motor_lag", None, (("tau", 0.035),)),
                      ("effects.drag", "mu2", 0.0045),
                      ("effects.motor_efficiency", None, (("eta3", 0.92),))),
                     truth=("motor_lag", "tau", 0.035)),
        HiddenEffect("three_small", "three effects of similar size: thrust loss with "
                     "airspeed c1 = -0.005, quadratic drag mu2 = 0.0055, rotor drag k_rd = "
                     "0.010 (the best single fit, quadratic drag, absorbs the others)",
                     (("effects.thrust_airspeed", None, (("c1", -0.005), ("c2", 0.0))),
                      ("effects.drag", "mu2", 0.0055),
                      ("effects.rotor_drag", None, (("k_rd", 0.010),))),
                     truth=("rotor_drag", "k_rd", 0.010)),
        HiddenEffect("azimuth_thrust_loss", "thrust loss of 15% localised at azimuth 90 deg "
                     "(outside the candidate library)",
                     (("effects.azimuth_thrust_loss", None,
                       (("depth", 0.15), ("xi0_deg", 90.0), ("width_deg", 25.0))),),
                     custom=AzimuthThrustLoss),
        HiddenEffect("azimuth_thrust_dip", "thrust dip of 5% at azimuth 115 deg, width 12 deg: "
                     "below the overall noise gate, visible averaged over revolutions",
                     (("effects.azimuth_thrust_loss", None,
                       (("depth", 0.05), ("xi0_deg", 115.0), ("width_deg", 12.0))),),
                     custom=AzimuthThrustLoss),
        HiddenEffect("elastic_and_dip", "two effects of similar size: a stiff elastic tether "
                     "(k = 9e4 N/m, c = 20 N s/m) and a thrust dip of 7% at azimuth 114 deg, "
                     "width 15 deg (the vehicle in its own wake; outside the library)",
                     (("tether", "link", "spring-damper"), ("tether", "stiffness", 9e4),
                      ("tether", "damping", 20.0),
                      ("effects.azimuth_thrust_loss", None,
                       (("depth", 0.07), ("xi0_deg", 114.0), ("width_deg", 15.0)))),
                     truth=("tether_elasticity", "stiffness", 9e4), custom=AzimuthThrustLoss),
    )
}


def default_flights(duration: float = 3.0, seed: int = 1) -> tuple[Scenario, ...]:
    """Speeds 3-15 m/s at tilt 0, 8 m/s at 20 deg, 7 m/s at 40 deg, a speed-up 3 -> 12 m/s
    and a braking 12 -> 3 m/s; motion-capture noise 0.5 mm / 0.2 deg at 200 Hz, gyro noise
    0.005 rad/s and accelerometer noise 0.1 m/s^2 (MEMS sensors on a vibrating frame)."""
    sens = Sensing(False, 200.0, 0.0005, math.radians(0.2), 0.005, 0.0, seed, 0.1)
    spec = [
        ("v3", 0, 3.0, ()), ("v9", 0, 9.0, ()), ("v15", 0, 15.0, ()),
        ("tilt20-v8", 20, 8.0, ()), ("tilt40-v7", 40, 7.0, ()),
        ("speedup", 0, 3.0, (Maneuver(0.6, 12.0, 6.25),)),
        ("braking", 0, 12.0, (Maneuver(0.6, 3.0, 8.0),)),
    ]
    return tuple(
        Scenario(nm, math.radians(tilt), v, duration, man,
                 sensing=dataclasses.replace(sens, seed=seed + i))
        for i, (nm, tilt, v, man) in enumerate(spec)
    )


def outside_table(scenarios, table) -> list[str]:
    """Names of the ``scenarios`` that fly outside ``table``'s speeds or tilts at some
    moment (their initial speed, a manoeuvre's target speed, their tilt): on a table's
    edge the runtime clamps the lookup, and the flight tests the clamped gains, not the
    table."""
    lo, hi = float(np.min(table.speed)), float(np.max(table.speed))
    tilt = float(np.max(np.abs(table.tilt)))
    return [s.name for s in scenarios
            if any(not lo - 1e-9 <= abs(v) <= hi + 1e-9
                   for v in (s.speed, *(m.speed for m in s.maneuvers)))
            or abs(s.tilt) > tilt + 1e-9]


#: the tether of a real vehicle, the base truth of a campaign with ``real_tether``: a
#: tension-only spring-damper of k = 2e5 N/m and c = 25 N s/m (M. Tognon and A. Franchi,
#: "Theory and Applications for Control of Aerial Robots in Physical Interaction Through
#: Tethers", Springer, 2021, sec. 3.1), which stretches about 0.3 mm at the highest
#: tensions of the flights, as every real tether does
REAL_TETHER = (("tether", "link", "spring-damper"), ("tether", "stiffness", 2e5),
               ("tether", "damping", 25.0))


def plant_config(design: Config, hidden: HiddenEffect | str, *,
                 real_tether: bool = False) -> Config:
    """The truth: the design config's text with the hidden effect's edits; with
    ``real_tether`` on :data:`REAL_TETHER` (unless the hidden effect is a tether link of
    its own)."""
    h = HIDDEN[hidden] if isinstance(hidden, str) else hidden
    text = design.text
    own_link = any(e[:2] == ("tether", "link") for e in h.sections)  # the tether is hidden
    base = REAL_TETHER if real_tether and not own_link else ()
    for section, key, value in (*base, *h.sections):
        if key is None:
            text = set_section(text, section, [(k, v, None) for k, v in value],
                               f"hidden: {h.name}")
        else:
            text = set_value(text, section, key, value, f"hidden: {h.name}")
    ctx = registered_effect(h.custom) if h.custom else contextlib.nullcontext()
    with ctx:
        return config_from_text(text, f"<plant {h.name}>")


def _delayed_result(res, latency: float):
    """The simulation result with the pose delayed by ``latency`` s (held at the start)."""
    dt = float(res.t[1] - res.t[0])
    s = int(round(latency / dt))
    if s == 0:
        return res
    idx = np.maximum(np.arange(res.t.size) - s, 0)
    return dataclasses.replace(res, p_I=res.p_I[idx], q_IB=res.q_IB[idx])


def _trim(log: FlightLog, t0: float, load_cell: bool, hidden: str) -> FlightLog:
    keep = log.t >= log.t[0] + t0
    opt = {k: v[keep] for k, v in log.optional.items() if load_cell or k != "tension"}
    meta = dict(log.meta)
    meta["notes"] = f"simulated by gainsched campaign (hidden: {hidden})"
    return log_from_arrays(log.t[keep], log.p_I[keep], log.q[keep], log.T_cmd[keep], meta,
                           source=log.source, **opt)


def fly(design: Config, scheduler, scenarios, plant: Config | None = None, *,
        latency: float = 0.0, load_cell: bool = True, trim_s: float = 0.25,
        hidden: str = "none", custom=None, progress=None) -> list[FlightLog]:
    """Fly ``scenarios`` on ``plant`` with ``scheduler`` and return the flight logs.

    The first ``trim_s`` s (start-up transient) are dropped; ``latency`` delays the
    logged pose; ``load_cell=False`` drops the tension column. Flights that go slack are
    kept up to the slack instant. ``progress(1)`` is called after each flight (a
    progress bar's increment).
    """
    ctx = registered_effect(custom) if custom else contextlib.nullcontext()
    logs = []
    with ctx:
        for scn in scenarios:
            res = simulate(design, scheduler, scn, plant)
            log = log_from_result(_delayed_result(res, latency))
            logs.append(_trim(log, trim_s, load_cell, hidden))
            if progress is not None:
                progress(1)
    return logs


def campaign(design: Config, scheduler, hidden: str = "none", *, scenarios=None,
             duration: float = 3.0, load_cell: bool = True,
             seed: int = 1, real_tether: bool = False, progress=None) -> list[FlightLog]:
    """Fly the default (or given) scenarios on the plant with the hidden effect ``hidden``
    (``progress(1)`` after each flight); ``real_tether``: on :data:`REAL_TETHER`, the
    elastic tether of a real vehicle, under the hidden effect (:func:`plant_config`)."""
    h = HIDDEN[hidden]
    scenarios = default_flights(duration, seed) if scenarios is None else scenarios
    plant = plant_config(design, h, real_tether=real_tether)
    return fly(design, scheduler, scenarios, plant, latency=h.latency, load_cell=load_cell,
               hidden=h.name, custom=h.custom, progress=progress)


def write_campaign(out_dir, logs, fmt: str = "csv") -> list[Path]:
    """Write each log as ``OUT/<flight_id>.<fmt>``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for log in logs:
        name = (log.meta.get("flight_id") or "flight").replace("sim-", "")
        p = out / f"{name}.{fmt}"
        write_log(p, log)
        paths.append(p)
    return paths
