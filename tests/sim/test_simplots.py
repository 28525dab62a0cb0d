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
