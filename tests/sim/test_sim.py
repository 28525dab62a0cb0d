"""Closed loop on the nonlinear plant (issue 5, first slice).

Each test flies the paper table through the Python reference interpolator.
"""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.analysis.logs import read_log
from gainsched.config import config_from_text, set_values
from gainsched.sim.loop import (
    Maneuver,
    Scenario,
    Sensing,
    load_scenario,
    log_from_result,
    metrics,
    profile_path,
    simulate,
    table_scheduler,
)
from gainsched.sim.paper import SCENARIO_DIR

SCENARIOS = SCENARIO_DIR  # the shipped scenarios (package data)


@pytest.fixture(scope="module")
def sched(paper_table):
    return table_scheduler(paper_table)


def test_profile_path_composes_manoeuvres():
    scn = load_scenario(SCENARIOS / "staircase.toml")
    t = np.linspace(0, scn.duration, 44001)
    p = profile_path(scn, 1.6, t)
    v = p.d[0] * 1.6
    # each plateau reached; speed is the integral of the acceleration (trapezoid, 1e-6 m/s)
    assert v[0] == pytest.approx(3.0) and v[-1] == pytest.approx(3.0)
    assert np.max(v) == pytest.approx(15.0, abs=1e-9)
    dv = 1.6 * np.cumsum(0.5 * (p.d[1][1:] + p.d[1][:-1]) * np.diff(t))
    assert np.abs(v[0] + np.concatenate([[0], dv]) - v).max() < 1e-6
    xi_int = p.xi[0] + np.concatenate(
        [[0], np.cumsum(0.5 * (p.d[0][1:] + p.d[0][:-1]) * np.diff(t))]
    )
    assert np.abs(xi_int - p.xi).max() < 1e-6


@pytest.mark.parametrize(("speed", "tilt_deg"), [(4.0, 0.0), (9.0, 20.0), (8.0, 40.0)])
def test_design_plant_tracks_from_an_initial_error(paper_config, sched, speed, tilt_deg):
    """Plant = design model, ideal sensing: an initial error decays, no slack or saturation.
    Sample of the grid (speed, tilt) named in the parameters; 2 s each."""
    scn = Scenario("t", np.deg2rad(tilt_deg), speed, 2.0, initial_error=(0.02, 0.05))
    res = simulate(paper_config, sched, scn)
    err0 = np.abs(res.z[0] - res.z_d[0])
    err = np.abs(res.z - res.z_d)
    assert res.slack_time is None
    assert not res.saturated.any()
    assert err[-200:, 0].max() < 0.5 * err0[0]  # out-of-plane angle error halves
    assert err[:, 0].max() < 0.05  # bounded: < 0.05 rad (8 cm) all along


def test_braking_paper_figure(paper_config, sched):
    """Braking 11.3 -> 1.0 m/s with peak deceleration 17.5 m/s^2 completes in < 1.5 s
    without slack or saturation (paper Fig. 4)."""
    scn = Scenario("braking", 0.0, 11.3, 2.2, (Maneuver(0.2, 1.0, 8.75),))
    res = simulate(paper_config, sched, scn)
    m = metrics(res)
    v = res.z[:, 3] * res.r
    t_done = res.t[np.argmax(v < 1.0 + 0.05)] - 0.2
    assert t_done < 1.5
    assert m["slack_events"] == 0 and m["saturation_fraction"] == 0.0
    assert np.abs(v[-1] - 1.0) < 0.05


def test_higher_drag_plant_makes_speed_lag(paper_config, sched):
    """A plant with 50% more drag than the design model: the vehicle flies slower than
    the reference (mean speed error negative), more than with the design plant."""
    text = set_values(paper_config.text, {"effects.drag.mu1": 0.258, "effects.drag.mu2": 0.00375})
    plant = config_from_text(text, "drag150.toml")
    scn = Scenario("h", 0.0, 12.0, 2.0)
    e_design = metrics(simulate(paper_config, sched, scn))["mean_speed_error_mps"]
    e_drag = metrics(simulate(paper_config, sched, scn, plant))["mean_speed_error_mps"]
    assert e_drag < e_design - 0.01
    assert e_drag < 0


def test_simulated_log_round_trips(paper_config, sched, tmp_path):
    scn = Scenario("rt", np.deg2rad(20), 8.0, 0.5,
                   sensing=Sensing(True, 200.0, 0.0005, np.deg2rad(0.2), 0.0, 0.0, 3))
    res = simulate(paper_config, sched, scn)
    log = log_from_result(res)
    for ext in ("csv", "h5"):
        from gainsched.analysis.logs import write_log

        path = tmp_path / f"log.{ext}"
        write_log(path, log)
        (back,) = read_log(path, min_samples=10)
        np.testing.assert_array_equal(back.t, log.t)
        np.testing.assert_array_equal(back.p_I, log.p_I)
        np.testing.assert_array_equal(back.q, log.q)
        np.testing.assert_array_equal(back.T_cmd, log.T_cmd)
        assert back.alpha_c == pytest.approx(np.deg2rad(20))
    # the log's pose is the simulated pose plus the configured noise (0.5 mm)
    dev = log.p_I - res.p_I[:: int(round(1 / (200 * paper_config.control.dt)))]
    assert 0.0002 < dev.std() < 0.001


def test_bad_scenario_names_key(tmp_path):
    from gainsched.errors import InputError

    p = tmp_path / "bad.toml"
    p.write_text("speed = 5.0\nduration = 1.0\nwind = 3\n")
    with pytest.raises(InputError, match="bad.toml: wind: unknown key"):
        load_scenario(p)
    p.write_text("speed = 5.0\nduration = -1.0\n")
    with pytest.raises(InputError, match="duration"):
        load_scenario(p)
    braking = load_scenario(SCENARIOS / "braking.toml")  # the good file loads
    assert (braking.name, braking.speed, braking.duration) == ("braking", 11.3, 3.0)
