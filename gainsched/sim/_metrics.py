"""The figures of a simulated flight (what ``gainsched simulate`` writes to
``metrics.json``)."""

from __future__ import annotations

import math

import numpy as np

from ..firmware.runtime import CLAMPED_SPEED
from ..rotations import (
    R_IC_from_tilt,
)
from ._result import SimResult

__all__ = [
    "metrics",
]


def metrics(res: SimResult) -> dict:
    """Tracking, load and saturation figures of a simulated flight, by name.

    What ``gainsched simulate`` writes to ``metrics.json``: the out-of-plane error (m),
    the along-track error (the azimuth error, rad, and its arc at the COG radius, m)
    with lap slips, the speed tracking error (m/s), the loads, the time spent at the
    edges of the table and the motors' limits.

    Parameters
    ----------
    res : SimResult
        A simulated flight (:func:`simulate`).

    Returns
    -------
    dict
        By name (the unit ends the name; errors are simulated minus nominal):

        - ``duration_s``: time flown, s (less than the scenario's after a slack stop);
        - ``rms_out_of_plane_m``, ``max_out_of_plane_m``: the COG's distance from the
          circle plane, m;
        - ``rms_along_track_m``, ``max_along_track_m``: the azimuth error times the COG
          radius ``r``, m;
        - ``mean_azimuth_error_rad``, ``final_azimuth_error_rad``,
          ``max_azimuth_error_rad`` (of its magnitude): xi - xi_d from continuous
          azimuths (a lap behind is -2 pi), rad;
        - ``lap_slips``: whole laps gained or lost, int;
        - ``rms_speed_error_mps``, ``mean_speed_error_mps``: tangential COG speed
          ``r xi_dot`` minus the nominal's, m/s; ``max_speed_mps``, m/s;
        - ``max_tension_N``: tether tension, N; ``max_g_load``: ``v^2 / (r g)``, the
          centripetal acceleration in g; ``max_tether_accel_g``: tension / (m g);
        - ``saturation_fraction``: share of motor commands clipped at a thrust limit,
          0..1;
        - ``held_gains_s``: time flown on held gains (an unusable lookup), s;
          ``clamped_speed_s``: time the lookup's speed was clamped to the table's range, s;
        - ``min_nominal_tension_N``: lowest tension of the nominal, N (nan if unknown);
          ``below_tension_margin_s``: time the nominal is below the config's
          ``min_tension``, s;
        - ``slack_events``: 1 if the tether went slack, else 0; ``slack_time_s``: when,
          s, or None;
        - ``max_roll_deg``: largest roll angle magnitude, deg.

    Examples
    --------
    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> table = gs.load_table("tables/paper.h5")
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> m = gs.metrics(gs.simulate(cfg, gs.table_scheduler(table), scn))
    >>> print(f"{100 * m['rms_along_track_m']:.1f} cm along track, "
    ...       f"{m['max_tension_N']:.1f} N, {m['max_g_load']:.1f} g, "
    ...       f"roll {m['max_roll_deg']:.0f} deg")
    3.1 cm along track, 20.0 N, 4.1 g, roll 17 deg
    >>> m["lap_slips"], m["saturation_fraction"], m["slack_events"]
    (0, 0.0, 0)
    """
    R_IC = R_IC_from_tilt(res.scenario.tilt, res.scenario.gamma)
    p_C = res.p_I @ R_IC  # rows: R_IC^T p
    out_of_plane = p_C[:, 2]
    v = res.z[:, 3] * res.r
    v_ref = res.z_d[:, 3] * res.r
    accel = res.tension / res.mass  # the tether carries the centripetal load
    xi_err = res.z[:, 1] - res.z_d[:, 1]  # both continuous: a lap behind is -2 pi
    dt = float(res.t[1] - res.t[0]) if res.t.size > 1 else 0.0
    return {
        "duration_s": float(res.t[-1]),
        "rms_out_of_plane_m": float(np.sqrt(np.mean(out_of_plane**2))),
        "max_out_of_plane_m": float(np.abs(out_of_plane).max()),
        "rms_along_track_m": float(res.r * np.sqrt(np.mean(xi_err**2))),
        "max_along_track_m": float(res.r * np.abs(xi_err).max()),
        "mean_azimuth_error_rad": float(np.mean(xi_err)),
        "final_azimuth_error_rad": float(xi_err[-1]),
        "max_azimuth_error_rad": float(np.abs(xi_err).max()),
        "lap_slips": int(np.abs(xi_err).max() // (2 * np.pi)),
        "rms_speed_error_mps": float(np.sqrt(np.mean((v - v_ref) ** 2))),
        "mean_speed_error_mps": float(np.mean(v - v_ref)),
        "max_speed_mps": float(np.abs(v).max()),
        "max_tension_N": float(res.tension.max()),
        "max_g_load": float(np.max(v**2 / res.r) / res.g),
        "max_tether_accel_g": float(accel.max() / res.g),
        "saturation_fraction": float(res.saturated.mean()),
        "held_gains_s": float(np.count_nonzero(res.held) * dt) if res.held is not None else 0.0,
        "clamped_speed_s": float(np.count_nonzero(res.status & CLAMPED_SPEED) * dt),
        "min_nominal_tension_N": (float(res.tension_d.min()) if res.tension_d is not None
                                  else math.nan),
        "below_tension_margin_s": (float(np.count_nonzero(res.tension_d < res.min_tension) * dt)
                                   if res.tension_d is not None else 0.0),
        "slack_events": 0 if res.slack_time is None else 1,
        "slack_time_s": res.slack_time,
        "max_roll_deg": float(np.rad2deg(np.abs(res.z[:, 4]).max())),
    }
