"""Plots of a simulated flight (:mod:`gainsched.sim.plots`): the tracking errors they
draw against a second formulation, and the files."""

from __future__ import annotations

import math

import numpy as np

from gainsched.config import load_config
from gainsched.model.geometry import pose_from_reduced
from gainsched.model.reduced import Model
from gainsched.schedule.tables import load_table
from gainsched.sim.loop import Maneuver, Scenario, simulate, table_scheduler
from gainsched.sim.plots import plot_result, tracking_errors

from support import PAPER_H5, PAPER_TOML


def test_tracking_errors_and_the_flight_plots(tmp_path):
    """A tilted, rotated circle with a speed-up: the out-of-plane error (the COG's
    distance from the circle plane, from the inertial position and the plane's normal)
    equals the reduced state's COG height in C (pose_from_reduced; 1e-9 m); the
    along-track error is r (xi - xi_ref) and the speed error r (xi' - xi'_ref); both
    PNGs are written."""
    cfg = load_config(PAPER_TOML)
    sched = table_scheduler(load_table(PAPER_H5))
    scn = Scenario("t", math.radians(30.0), 8.0, 1.5, (Maneuver(0.4, 10.0, 6.0),),
                   gamma=0.4)
    res = simulate(cfg, sched, scn)
    err = tracking_errors(res)
    model = Model(cfg)
    p_C, _ = pose_from_reduced(res.z, model.rho, model.p_e)
    np.testing.assert_allclose(err["out_of_plane_m"], p_C[:, 2], rtol=0, atol=1e-9)
    assert np.max(np.abs(err["out_of_plane_m"])) > 0  # the flight does leave the plane
    np.testing.assert_allclose(err["along_track_m"], res.r * (res.z[:, 1] - res.z_d[:, 1]),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(err["speed_mps"], res.r * (res.z[:, 3] - res.z_d[:, 3]))
    assert np.all((err["azimuth_deg"] >= 0) & (err["azimuth_deg"] < 360))
    paths = plot_result(res, tmp_path)
    assert [p.name for p in paths] == ["speed_roll.png", "path3d.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_intervals_off_the_table_are_the_ones_metrics_counts(tmp_path):
    """Issue 39: the paper's braking (11.3 -> 1 m/s; the table starts at 1.3 m/s): the
    shaded intervals of clamped speed and of the nominal's tension under the margin add up
    to the metrics' clamped_speed_s and below_tension_margin_s (to one sample), each lies
    at the end of the flight, and a circle inside the table has none."""
    from gainsched.sim.loop import load_scenario, metrics
    from gainsched.sim.plots import left_table_intervals

    cfg = load_config(PAPER_TOML)
    sched = table_scheduler(load_table(PAPER_H5))
    res = simulate(cfg, sched, load_scenario("braking"))
    m, spans = metrics(res), left_table_intervals(res)
    dt = float(res.t[1] - res.t[0])
    for cause, key in (("clamped speed", "clamped_speed_s"),
                       ("tension below margin", "below_tension_margin_s")):
        total = sum(t1 - t0 for t0, t1 in spans[cause])
        assert m[key] > 0 and abs(total - m[key]) <= dt + 1e-9, (cause, total, m[key])
        assert spans[cause][-1][1] >= res.t[-1] - 0.5, spans[cause]
    assert plot_result(res, tmp_path)[0].stat().st_size > 0
    calm = simulate(cfg, sched, Scenario("c", 0.0, 8.0, 0.5, ()))
    assert not any(left_table_intervals(calm).values())
