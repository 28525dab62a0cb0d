"""The next flight of a diagnosis (issue 55): gainsched/sim/plan.py, ``gainsched plan``,
and the speed excitation of scenarios it flies.

- the multisine's azimuth and its four derivatives are what its tones say (against
  central differences and the speed itself); a scenario file round-trips;
- a thrust 7 % short of the model (``thrust_scale``) and momentum theory's loss with
  airspeed are look-alikes on fast circles: the plan ranks the slow circle first (where
  momentum theory's loss vanishes and the deficit does not), the fast circle last, and
  every interval it expects is the report's and the flight's combined;
- the command writes the flights as scenarios and references, and refuses a file that
  is no diagnose report in one line.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from gainsched.errors import InputError
from gainsched.sim.loop import (
    Scenario,
    Sine,
    load_scenario,
    profile_path,
    scenario_from_dict,
    scenario_text,
)

#: a diagnosis that cannot tell a thrust deficit from momentum theory (its twin)
LOOK_ALIKES = {
    "accepted": "thrust_scale", "ranking": ["thrust_scale", "thrust_momentum"],
    "twins": [{"candidate": "thrust_momentum", "abs_cos": 0.97, "separating_flight": ""}],
    "candidates": {
        "thrust_scale": {"params": {"k_T": {"estimate": 0.93, "ci95": 0.004, "unit": "-"}},
                         "heldout_rms_reduction": 0.8},
        "thrust_momentum": {"params": {"disk_area": {"estimate": 0.004, "ci95": 5e-4,
                                                     "unit": "m^2"}},
                            "heldout_rms_reduction": 0.75}}}


def test_the_excitation_is_the_speed_its_tones_say():
    """v(t) = v0 + sum A sin(2 pi f t + phi): the path's rate is it over r, and each
    derivative the central difference of the one before (to 1e-6 of its scale)."""
    tones = (Sine(0.8, 0.3, 0.4), Sine(0.5, 1.1, -1.0), Sine(0.2, 2.3, 2.0))
    scn = Scenario("x", 0.0, 6.0, 4.0, excitation=tones)
    r, h = 1.6, 1e-4
    t = np.linspace(0.5, 3.5, 31)
    path = profile_path(scn, r, t)
    v = 6.0 + sum(s.amplitude * np.sin(2 * np.pi * s.frequency * t + s.phase) for s in tones)
    np.testing.assert_allclose(path.d[0] * r, v, rtol=1e-12)
    lo, hi = profile_path(scn, r, t - h), profile_path(scn, r, t + h)
    series = [(lo.xi, hi.xi), *zip(lo.d, hi.d, strict=True)]
    for j in range(4):
        cd = (series[j][1] - series[j][0]) / (2 * h)
        scale = float(np.max(np.abs(path.d[j])))
        np.testing.assert_allclose(path.d[j], cd, rtol=0, atol=1e-6 * scale, err_msg=str(j))
    assert profile_path(scn, r, np.array([0.0])).xi[0] == 0.0


def test_a_scenario_with_an_excitation_round_trips_and_a_bad_tone_is_named():
    scn = dataclasses.replace(load_scenario("speedup"),
                              excitation=(Sine(1.0, 0.5, 0.3), Sine(0.5, 1.3)))
    back = scenario_from_dict(__import__("tomllib").loads(scenario_text(scn)), "x.toml")
    assert dataclasses.replace(back, source="") == dataclasses.replace(scn, source="")
    text = scenario_text(scn).replace("frequency_hz = 0.5", "frequency_hz = 50.0")
    with pytest.raises(InputError, match=r"^x.toml: excitation\[0\].frequency_hz: "):
        scenario_from_dict(__import__("tomllib").loads(text), "x.toml")


@pytest.fixture(scope="module")
def look_alike_plan(paper_config, paper_table):
    from gainsched.sim.plan import plan_flights

    return plan_flights(paper_config, LOOK_ALIKES, paper_table, duration=6.0)


def test_the_plan_separates_a_thrust_deficit_from_momentum_theory(look_alike_plan):
    """Flown on the plant with the deficit, the slow circle tells the two apart best
    (+60 points and more of held-out RMS), the fast level circle least; the 40 deg
    circle at 15 m/s is beyond the vehicle and says so; every expected interval is the
    report's and the flight's alone combined (1 / ci^2 adds) and no wider than now."""
    p = look_alike_plan
    assert p.focus == "thrust_scale" and p.look_alikes == ("thrust_momentum",)
    names = [f.name for f in p.flights]
    assert names[0] == "circle 1.3 m/s level", p.lines()
    assert names[-1] == "circle 15 m/s level", p.lines()
    seps = [f.separation["thrust_momentum"] for f in p.flights]
    assert seps == sorted(seps, reverse=True) and seps[0] > 0.6 and seps[-1] < 0.3
    for f in p.flights:
        now, alone, exp = f.ci["k_T"]
        assert now == 0.004 and exp <= now
        assert exp == pytest.approx((now**-2 + alone**-2) ** -0.5, rel=1e-12)
    assert ("circle 15 m/s 40 deg", "beyond the vehicle on the fitted model (tension "
            "margin or motor range)") in p.skipped


def test_cli_plan_writes_each_flight_as_a_scenario_and_a_reference(look_alike_plan,
                                                                    paper_config, tmp_path,
                                                                    monkeypatch):
    """``gainsched plan CONFIG REPORT -o DIR``: the table printed, plan.md and plan.json,
    and per flight NN.toml (loaded back: the flight planned) and NN-reference.csv (the
    azimuth rate of its profile at the control step)."""
    from click.testing import CliRunner

    import gainsched.sim.plan as plan_mod
    from gainsched.cli import cli
    from gainsched.model.reduced import Model

    monkeypatch.setattr(plan_mod, "plan_flights", lambda *a, **k: look_alike_plan)
    rep = tmp_path / "diagnose.json"
    rep.write_text(json.dumps(LOOK_ALIKES))
    r = CliRunner().invoke(cli, ["plan", "paper", str(tmp_path), "-o", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    assert r.output.splitlines()[0].startswith("plan for thrust_scale (k_T = 0.93 +- 0.004")
    out = tmp_path / "out"
    n = len(look_alike_plan.flights)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["plan.md", "plan.json"] + [f"{i:02d}.toml" for i in range(1, n + 1)]
        + [f"{i:02d}-reference.csv" for i in range(1, n + 1)])
    first = look_alike_plan.flights[0].scenario
    back = load_scenario(out / "01.toml")
    assert dataclasses.replace(back, source="") == dataclasses.replace(first, source="")
    ref = np.loadtxt(out / "01-reference.csv", delimiter=",", skiprows=2)
    path = profile_path(first, Model(paper_config).r, ref[:, 0])
    np.testing.assert_array_equal(ref[:, 2], path.d[0])
    assert ref[-1, 0] == pytest.approx(first.duration)
    data = json.loads((out / "plan.json").read_text())
    assert data["flights"][0]["file"] == "01.toml" and math.isfinite(
        data["flights"][0]["separation"]["thrust_momentum"])


def test_a_file_that_is_no_diagnose_report_is_one_line(tmp_path):
    from click.testing import CliRunner

    from gainsched.cli import cli

    bad = tmp_path / "x.json"
    bad.write_text('{"verdict": "none"}')
    r = CliRunner().invoke(cli, ["plan", "paper", str(bad)])
    assert r.exit_code == 2 and r.output.strip() == (
        f"gainsched: error: {bad}: candidates: not a diagnose report (no candidates): give "
        "the diagnose.json of diagnose --report"), r.output
