"""Diagnose on a plant it has never seen (issue 53): the hidden effects flown on the
elastic tether of a real vehicle (:data:`gainsched.sim.campaign.REAL_TETHER`, k = 2e5
N/m, which stretches about 0.3 mm at the highest tensions), the effects a real vehicle
has (its moments of inertia, the rotors' reaction torque), the library without the true
effect, and the acceptance rule that keeps a wrong story out (no residual axis worse).

A module of its own beside tests/analysis/test_diagnose.py: its campaigns (flown once
here, 2.5 s flights) run on another test worker.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gainsched.analysis.diagnose import apply_candidate, diagnose
from gainsched.config import config_from_text

from support import (
    REAL_TETHER_CASES,
    REAL_TETHER_OWN,
    REPO,
    assert_named_on_the_real_tether,
    excess_rms_fall,
    story,
)


def test_a_real_tether_is_the_base_truth_under_any_hidden_effect(paper_config):
    """plant_config(real_tether=True): the hidden effect's edits on the elastic tether of
    REAL_TETHER; a hidden effect that is a tether link of its own keeps its own."""
    from gainsched.sim.campaign import REAL_TETHER, plant_config

    assert dict(((s, k), v) for s, k, v in REAL_TETHER)[("tether", "stiffness")] == 2e5
    p = plant_config(paper_config, "rotor_drag", real_tether=True)
    assert (p.tether.link, p.tether.stiffness, p.tether.damping) == ("spring-damper", 2e5, 25.0)
    assert "rotor_drag" in {e.name for e in p.effects}
    assert plant_config(paper_config, "rotor_drag").tether.link == "rigid"
    own = plant_config(paper_config, "tether_elasticity", real_tether=True).tether
    assert (own.stiffness, own.damping) == (3000.0, 5.0)


@pytest.mark.slow
@pytest.mark.parametrize("hidden", REAL_TETHER_OWN)
def test_on_a_real_tether_the_physical_effect_is_named(paper_config, diagnosed, hidden):
    assert_named_on_the_real_tether(paper_config, diagnosed(hidden, real_tether=True), hidden)


@pytest.mark.slow
@pytest.mark.parametrize("hidden", ["rotor_drag", "motor_lag", "thrust_time", "kappa",
                                    "inertia_x", "cog_offset"])
def test_on_a_real_tether_without_the_true_effect_no_other_physics_is_named(
        paper_config, fly, hidden):
    """Issue 53: the true effect left out of the library (--exclude): no other physical
    effect is accepted (the tether's own stretch aside); the verdict is "no library effect
    explains it" with where, or an empirical term whose held-out residual above noise
    falls >= 80 %. (Measured: thrust_time_series for the battery sag; none for the
    others.)"""
    d = diagnose(paper_config, fly(hidden, real_tether=True), exclude=[hidden])
    a = d.accepted
    if a is None:
        assert d.verdict.startswith("no library effect explains it: "), d.verdict
        assert " residual " in d.verdict.split(".")[0]  # where it fails
        return
    physical = {p.name for p in getattr(a.candidate, "parts", (a.candidate,))
                if not getattr(p, "empirical", False)}
    assert physical <= {"tether_elasticity"} and physical != {p.name for p in getattr(
        a.candidate, "parts", (a.candidate,))}, d.verdict
    assert excess_rms_fall(a) >= 0.8, a.excess_explained


@pytest.mark.slow
def test_the_yaw_inertia_on_circles_is_named_with_its_twin(diagnosed):
    """A yaw inertia 30 % low: on steady circles only Jzz - Jyy shows (the gyroscopic roll
    torque), so inertia_y and inertia_z explain it alike: the verdict names both and the
    flight that would separate them, and each fit gets Jzz - Jyy right within 10 %."""
    d = diagnosed("inertia_z")
    assert d.accepted is not None and story(d.accepted) in ("inertia_y", "inertia_z")
    names = {story(d.accepted), *(t[0] for t in d.twins)}
    assert names == {"inertia_y", "inertia_z"} and "a yaw step" in d.verdict, d.verdict
    fits = {r.name: r for r in d.results}
    assert fits["inertia_z"].values["Jzz"] - 2.5e-3 == pytest.approx(0.65e-3, rel=0.1)
    assert 4.5e-3 - fits["inertia_y"].values["Jyy"] == pytest.approx(0.65e-3, rel=0.1)


@pytest.mark.slow
def test_on_a_real_tether_the_negative_control_names_at_most_the_stretch(diagnosed):
    """No hidden effect, the real tether: nothing but the tether's own elasticity is
    accepted, its stiffness within 15 % of the truth, the damping (not identified on
    these flights) not a reason to refuse it."""
    d = diagnosed("none", real_tether=True)
    assert d.accepted is not None and story(d.accepted) == "tether_elasticity", d.verdict
    assert d.accepted.values["stiffness"] == pytest.approx(2e5, rel=0.15)
    assert "Not identified, so --apply keeps the config's value: damping_time" in d.verdict



def test_a_fit_that_makes_an_axis_worse_fails(paper_config):
    """Issue 53: no fit is accepted that makes a residual axis worse held out (by more
    than 5 %, to above 1.25x its noise floor): the rule on a passing fit with one axis's
    held-out RMS raised, and below the noise band not counted."""
    logs = sorted((REPO / "examples" / "flights").glob("*.csv"))
    d = diagnose(paper_config, logs, candidates=["thrust_momentum"])
    r = d.results[0]
    assert r.passes and not r.worse_axes(), r.failed()
    before = r.axis_rms_before["pitch"]
    worse = dataclasses.replace(r, axis_rms_after={**r.axis_rms_after,
                                                   "pitch": max(1.3, 1.1 * before)})
    assert worse.worse_axes() == ["pitch"] and not worse.passes
    assert any(f.startswith("makes the pitch axis worse held out") for f in worse.failed())
    quiet = dataclasses.replace(r, axis_rms_after={**r.axis_rms_after, "pitch": 1.2})
    assert not quiet.worse_axes() and quiet.passes  # 1.2 < 1.25: noise either way


@pytest.mark.slow
def test_on_a_real_tether_the_twin_is_another_story_not_more_of_the_same(diagnosed):
    """A 2 cm attachment-offset error on the real tether is named as its twin, a tether
    length error (both move the radius), fitted beside the tether's stretch: the twin
    the report names is the attachment offset alone, with the flight that separates the
    two, not the joint fits that hold the accepted effect or more parts."""
    d = diagnosed("attachment_offset", real_tether=True)
    assert d.accepted is not None and "tether_length" in d.accepted.name.split(" + ")
    assert [t[0] for t in d.twins] == ["attachment_offset"], d.twins
    assert "restoring torque" in d.twins[0][2]


@pytest.mark.slow
def test_a_centre_of_mass_off_the_frame_centre_is_found_in_all_its_axes(paper_config, fly,
                                                                          diagnosed):
    """The COG at (0, 3, -2) mm (HIDDEN["cog_offset"]) on the real tether: both its lateral
    and its vertical offsets within 10 % (of 3 and 2 mm), the one along the tether (x,
    which circles barely show) within 0.5 mm of the truth 0, or not identified and kept;
    --apply writes [effects.cog_offset]. Without it in the library, the where-it-fails
    line points at it: a roll residual that grows with thrust is a torque in proportion
    to the thrust."""
    from gainsched.analysis.diagnose._results import unidentified

    a = diagnosed("cog_offset", real_tether=True).accepted
    assert a is not None and "cog_offset" in a.name.split(" + ")
    assert a.values["y"] == pytest.approx(0.003, rel=0.1)
    assert a.values["z"] == pytest.approx(-0.002, rel=0.1)
    assert "x" in unidentified(a) or abs(a.values["x"]) <= 5e-4, a.values
    new = config_from_text(apply_candidate(paper_config, a), "fitted.toml")
    spec = next(s.param_dict() for s in new.effects if s.name == "cog_offset")
    assert spec["y"] == pytest.approx(a.values["y"], rel=1e-12)
    # with the fitted config, the IMU's lever to the COG is the reader's, not a sensor error
    again = diagnose(new, fly("cog_offset", real_tether=True))
    assert again.calibration is not None and not again.calibration.accepted, again.verdict
    assert again.accepted is None, again.verdict
    d = diagnose(paper_config, fly("cog_offset", real_tether=True), exclude=["cog_offset"])
    assert "as a centre of mass off the frame centre gives ([effects.cog_offset])" in d.verdict


def test_the_imu_at_the_frame_centre_reads_the_cog_motion_through_its_lever(paper_config, fly):
    """With the COG offset known (the truth's [effects.cog_offset] in the config), the
    accelerometer at the frame centre is explained by the COG's motion plus the lever
    ``R_CB (omega' x r + omega x (omega x r))`` (Measured.cog_lever; about 0.1 m/s^2 at
    15 m/s for r = 3.6 mm): compare's acceleration axes at their noise floor (measured
    0.88-0.93; without the lever 1.12 and 1.31) and a true accelerometer's calibration
    within 0.5 % in scale and within its interval in bias, not accepted (measured <=
    0.2 %; without the lever the lateral scale reads 0.9 % low)."""
    from gainsched.analysis.compare import compare
    from gainsched.analysis.diagnose import sensor_calibration
    from gainsched.sim.campaign import plant_config

    known = plant_config(paper_config, "cog_offset")  # the COG; the rigid tether will do
    c = compare(known, fly("cog_offset", real_tether=True))
    assert all(c.stats[a].rms_over_noise < 1.05 for a in ("tangential", "normal", "radial")), \
        {a: s.rms_over_noise for a, s in c.stats.items()}
    cal = sensor_calibration(known, c.measured)
    assert not cal.accepted, cal.sentence()
    assert np.all(np.abs(cal.accel.scale - 1) <= 0.005), cal.accel.scale
    assert np.all(np.abs(cal.accel.bias) <= cal.accel.bias_ci), cal.accel.bias


def test_a_passing_fit_left_out_by_parsimony_is_said_so():
    """The verdict when no fit is accepted although the best one passes every threshold
    (forward selection kept it out: a larger fit must lower delta-BIC by
    nested_bic_gain): it says that, not "fails: " with nothing after it."""
    from types import SimpleNamespace

    from gainsched.analysis.diagnose._verdict import _verdict

    best = SimpleNamespace(name="a + b + c", rms_reduction=0.93, delta_bic=-5000.0,
                           passes=True, failed=lambda: [])
    base = SimpleNamespace(where={"sentence": "roll residual grows with thrust"}, structure=[],
                           stats={})
    v = _verdict(base, [best], None, [], False)
    assert "a + b + c, removes 93% of the held-out RMS and passes every threshold" in v, v
    assert "fails: ." not in v and "more parameters than these flights ask for" in v


#: flights as long as users fly them (issue 53): the default flights at 20 s each
LONG_FLIGHT_S = 20.0


@pytest.mark.slow
@pytest.mark.parametrize("hidden", ["none", "motor_lag", "cog_offset"])
def test_flights_as_long_as_users_fly_tell_the_same_story(paper_config, paper_table, hidden):
    """The default flights at 20 s each (eight times the suite's campaigns) on the real
    tether: the story does not change with the length of the flights. The negative
    control names at most the tether's stretch (its stiffness within 15 %); a motor lag
    and a centre of mass off the frame centre are named with the stretch beside them at
    most, their parameter within 10 %, the held-out residual above noise falling >= 80 %,
    no axis worse. (Before the IMU sat at the frame centre, 20 s flights took a COG
    offset's lever for an accelerometer bias.)"""
    from gainsched.sim.campaign import campaign
    from gainsched.sim.loop import table_scheduler

    logs = campaign(paper_config, table_scheduler(paper_table), hidden,
                    duration=LONG_FLIGHT_S, real_tether=True)
    d = diagnose(paper_config, logs)
    a = d.accepted
    assert d.calibration is None or not d.calibration.accepted, d.verdict
    if hidden == "none":
        assert a is None or story(a) == "tether_elasticity", d.verdict
        if a is not None:
            assert a.values["stiffness"] == pytest.approx(2e5, rel=0.15)
        return
    name, param, true, none = REAL_TETHER_CASES[hidden]
    assert a is not None and story(a) == name, d.verdict
    assert abs((a.values[param] - none) / (true - none) - 1) <= 0.10, (a.values, true)
    assert excess_rms_fall(a) >= 0.8 and not a.worse_axes(), a.excess_explained
