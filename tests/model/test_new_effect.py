"""A new position-dependent effect is one class (issue 13): the example of
docs/architecture.md, run from the doc itself, then configured, built into tables,
flown, compared and diagnosed with nothing else changed; and an effect that breaks
the table's symmetries is refused by the build."""

from __future__ import annotations

import dataclasses
import math
import re
import warnings

import numpy as np
import pytest

from gainsched.analysis.diagnose import candidate_library, diagnose
from gainsched.config import config_from_text, set_section, set_values
from gainsched.errors import InputError
from gainsched.model.effects import EFFECTS, Effect, Param, registered_effect
from gainsched.model.reduced import Model
from gainsched.model.symmetry import effect_symmetry_errors
from gainsched.schedule.grid import build_grid, check_effect_symmetries
from gainsched.schedule.tables import load_table, table_bytes, table_from_bytes
from gainsched.sim.campaign import AzimuthThrustLoss, HiddenEffect, fly, plant_config
from gainsched.sim.loop import Scenario, Sensing, table_scheduler

from support import PAPER_H5, PAPER_TOML, REPO

DOC = REPO / "docs/architecture.md"


def _doc_effect_class() -> type[Effect]:
    """Execute the first python block of the doc's "A new physical effect" section."""
    text = DOC.read_text()
    section = text[text.index("## A new physical effect"):]
    block = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    ns: dict = {}
    exec(compile(block, str(DOC), "exec"), ns)  # noqa: S102 - our own documentation
    return ns["GroundEffect"]


GroundEffect = _doc_effect_class()


def _config(rotor_radius, anchor_height=3.0, grid=None):
    text = PAPER_TOML.read_text()
    text = set_section(text, "effects.ground_effect",
                       [("rotor_radius", rotor_radius, None),
                        ("anchor_height", anchor_height, None)])
    if grid:
        text = set_values(text, grid)
    return config_from_text(text, "low_flight.toml")


def test_config_names_the_new_effect_only_when_registered():
    with pytest.raises(InputError, match="effects.ground_effect"):
        _config(0.12)
    with registered_effect(GroundEffect):
        cfg = _config(0.12)
        assert [s.name for s in cfg.effects] == ["drag", "ground_effect"]
        with pytest.raises(InputError, match=r"effects\.ground_effect\.rotor_radius.*\[0, 0\.3\]"):
            _config(0.5)


def test_thrust_gain_follows_the_height_closed_form():
    """Level flight through the anchor (tilt 0): the height is the COG's z. On a 30 deg
    circle the highest and lowest points of the circle see the closed-form gains."""
    with registered_effect(GroundEffect):
        model = Model(_config(0.12, anchor_height=1.5))
    u = np.full(4, 1.5)
    for alpha, xi, h in ((0.0, 0.7, 0.0), (math.radians(30), math.pi / 2, None),
                         (math.radians(30), -math.pi / 2, None)):
        z = np.zeros(10)
        z[0], z[1] = math.pi / 2, xi
        kin = model.effect_kinematics(z, alpha)
        if h is None:  # the attachment point at (0, +-rho, 0) in C, the COG L_e further out
            h = math.sin(alpha) * math.copysign(model.rho + model.L_e, xi)
        assert float(kin.height) == pytest.approx(h, abs=1e-12)
        k = 0.12 / (4 * (1.5 + h))
        T = model.thrust(z, u, kin)
        np.testing.assert_allclose(T, u / (1 - k * k), rtol=1e-14)


@pytest.mark.slow
def test_new_effect_keeps_the_symmetries_and_builds_tables():
    """Height-only: both symmetry maps hold exactly, so the table may be built; the
    trim, the linearisation and the LQR see the effect (gains move, a little)."""
    assert effect_symmetry_errors(GroundEffect(rotor_radius=0.12, anchor_height=2.0)) == {
        "S1": 0.0, "S2": 0.0}
    grid = {"grid.speeds": [4.0, 8.0], "grid.tilts_deg": [0.0, 30.0],
            "grid.azimuth_samples": 12}
    with registered_effect(GroundEffect):
        cfg = _config(0.12, anchor_height=2.0, grid=grid)
        # two jobs: worker processes build it, which know the class only because it
        # travels with the job (their registry has the built-in effects only)
        table = table_from_bytes(table_bytes(cfg, build_grid(cfg, n_jobs=2), Model(cfg)))
        cfg0 = _config(0.0, anchor_height=2.0, grid=grid)  # rotor_radius 0: effect off
        table0 = table_from_bytes(table_bytes(cfg0, build_grid(cfg0), Model(cfg0)))
    assert not table.reasons.any() and not table0.reasons.any()
    rel = np.abs(table.K_full() - table0.K_full()).max() / np.abs(table0.K_full()).max()
    assert 1e-6 < rel < 1e-2, rel
    # with the effect on, the level circle needs less commanded thrust (ground gain > 1)
    assert np.all(table.u_d[:, 0].sum(-1) < table0.u_d[:, 0].sum(-1))


@pytest.mark.slow
def test_new_effect_is_flown_compared_and_diagnosed():
    """Flights on a plant with the new effect (numpy plant, warned once); diagnose fits
    it in its own Param range with its own Refit and recovers the rotor radius."""
    with registered_effect(GroundEffect):
        design = _config(0.0, anchor_height=0.3)  # the anchor height measured, no effect yet
        hidden = HiddenEffect(
            "ground_effect", "ground effect 0.18 m rotors, anchor 0.3 m above the ground",
            (("effects.ground_effect", None, (("rotor_radius", 0.18),
                                               ("anchor_height", 0.3))),),
            custom=GroundEffect)
        plant = plant_config(design, hidden)
        sens = Sensing(False, 200.0, 0.0005, math.radians(0.2), 0.0, 0.0, 3)
        scns = [Scenario(f"v{v:g}", 0.0, v, 2.0, (), sensing=sens) for v in (4.0, 9.0)]
        sched = table_scheduler(load_table(PAPER_H5))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")  # Python's own: once per caller and text
            logs = fly(design, sched, scns, plant, custom=GroundEffect)
        assert sum("ground_effect" in str(w.message) for w in caught) == 1
        lib = candidate_library()
        assert lib["ground_effect"].params[0].upper == 0.2  # the Param's fit range
        dg = diagnose(design, logs, candidates=["ground_effect", "thrust_scale"])
    res = {r.name: r for r in dg.results}
    ge = res["ground_effect"]
    assert [p.name for p in ge.params] == ["rotor_radius"]
    assert ge.theta[0] == pytest.approx(0.18, rel=0.05)
    assert ge.rms_reduction > 0.03  # held out (2 short flights: the effect is 2% of thrust)
    # a second formulation: at constant height (level flights) the ground effect is a
    # thrust scale 1 / (1 - (R / 4h)^2), h = anchor height 0.3 m
    assert res["thrust_scale"].theta[0] == pytest.approx(1 / (1 - (0.18 / 1.2) ** 2), rel=5e-3)
    assert "ground_effect" not in candidate_library()  # the library follows the registry


def test_build_refuses_an_effect_that_breaks_the_symmetries():
    assert effect_symmetry_errors(AzimuthThrustLoss(depth=0.2))["S2"] > 0.01
    text = set_section(PAPER_TOML.read_text(), "effects.azimuth_thrust_loss",
                       [("depth", 0.1, None)])
    with registered_effect(AzimuthThrustLoss):
        cfg = config_from_text(text, "wake.toml")
        with pytest.raises(InputError, match=r"^wake.toml: effects.azimuth_thrust_loss: "
                                             r"breaks the tilt-sign symmetry S1"):
            build_grid(cfg)


def test_build_refuses_an_effect_of_flight_time():
    """thrust_time carries the flight time as its state: no periodic table can hold it,
    and the build says so in one line before any work."""
    text = set_section(PAPER_TOML.read_text(), "effects.thrust_time", [("rate", 0.001, None)])
    cfg = config_from_text(text, "sag.toml")
    with pytest.raises(InputError, match=r"^sag.toml: effects.thrust_time: changes with "
                                         r"flight time"):
        build_grid(cfg)


def test_build_refuses_a_thrust_of_the_battery_voltage():
    """Issue 37: thrust_voltage carries the battery's voltage as its states (the logged
    vbat, or a battery model in simulation), not the motion's: the build refuses it in
    one line before any work."""
    text = set_section(PAPER_TOML.read_text(), "effects.thrust_voltage",
                       [("exponent", 2.0, None)])
    cfg = config_from_text(text, "battery.toml")
    with pytest.raises(InputError, match=r"^battery.toml: effects.thrust_voltage: changes "
                                         r"with the battery's charge and load"):
        build_grid(cfg)


class _RollTorque(Effect):
    """A constant roll torque: keeps S1, breaks the direction mirror S2."""

    kind = "roll_torque"
    params = (Param("tau_x", "N m", 0.0, -1.0, 1.0),)

    def wrench(self, T, kin):
        tau = np.zeros(np.shape(kin.v_C))
        tau[..., 0] = self.tau_x
        return np.zeros_like(tau), tau


def test_symmetry_errors_tell_the_maps_apart():
    err = effect_symmetry_errors(_RollTorque(tau_x=0.01))
    assert err["S1"] == 0.0 and err["S2"] == pytest.approx(2.0)


@pytest.mark.parametrize("kind", sorted(EFFECTS))
def test_every_library_effect_keeps_both_symmetries(kind):
    """Mid-range parameters (a thrust modifier at 1 would hide a wrong map). An effect
    that declares it breaks them (``table_refusal``: an inertial direction) is the
    exception, and its declaration must be true."""
    cls = EFFECTS[kind]
    eff = cls(**{p.name: p.lower + 0.3 * (p.upper - p.lower) for p in cls.params})
    err = effect_symmetry_errors(eff)
    if "inertial direction" in cls.table_refusal and kind != "wind":  # the wind: no force
        assert err["S1"] > 1e-3 and err["S2"] > 1e-3, (eff, err)
    else:
        assert err["S1"] <= 1e-12 and err["S2"] <= 1e-12, (eff, err)


@pytest.mark.parametrize("kind, values, what", [
    ("thrust_time_series", [("c1", -0.1, None)], "changes with flight time"),
    ("force_horizontal", [("e0", 0.4, None)], "comes from an inertial direction"),
])
def test_build_refuses_the_empirical_terms_a_table_cannot_hold(kind, values, what):
    """Issue 37: the empirical terms in flight time and from an inertial direction are for
    simulate and diagnose; the build refuses each in one line before any work."""
    cfg = config_from_text(set_section(PAPER_TOML.read_text(), f"effects.{kind}", values),
                           "fit.toml")
    with pytest.raises(InputError, match=rf"^fit.toml: effects.{kind}: {what}"):
        check_effect_symmetries(cfg)
    with pytest.raises(InputError, match=rf"^fit.toml: effects.{kind}: {what}"):
        build_grid(cfg)


def test_a_per_motor_term_is_built_for_both_flight_directions():
    """A per-motor term (thrust_motor) makes the vehicle's mirror image another vehicle:
    not refused, its table holds both flight directions, which the C runtime holds too
    (gs_table.reverse; tests/schedule/test_directions.py)."""
    from gainsched.schedule.grid import mirror_config

    cfg = config_from_text(set_section(PAPER_TOML.read_text(), "effects.thrust_motor",
                                       [("a3", -0.08, None)]), "fit.toml")
    check_effect_symmetries(cfg)  # no refusal
    assert mirror_config(cfg) is not None


def test_the_airspeed_series_of_orders_one_and_two_is_the_papers_drag():
    """A second formulation: force_airspeed with f1 = 10 m/s mu1 and f2 = (10 m/s)^2 mu2
    is the paper's drag (eq. 10), in still air and in a wind, to 1e-12; it keeps both
    symmetries, so a table can hold it (no refusal)."""
    from gainsched.model.effects import Drag, ForceAirspeed, Kinematics, Wind
    from gainsched.model.symmetry import table_refusal

    rng = np.random.default_rng(2)
    n = 200
    kin = Kinematics(np.broadcast_to(np.eye(3), (n, 3, 3)), rng.normal(0, 8, (n, 3)),
                     rng.normal(0, 1, (n, 3)), rng.normal(0, 2, (n, 3)),
                     rng.uniform(-0.8, 0.8, n), rng.uniform(-3, 3, n))
    windy = dataclasses.replace(kin, wind_I=Wind(east=2.0, north=-1.0).air_velocity())
    for k in (kin, windy):
        want = Drag(mu1=0.172, mu2=0.0025).wrench(None, k)[0]
        got = ForceAirspeed(f1=1.72, f2=0.25).wrench(None, k)[0]
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)
    assert table_refusal(ForceAirspeed(f0=0.1, f1=1.0, f2=0.3, f3=-0.05)) == ""


def test_the_time_series_of_order_one_is_the_linear_sag():
    """A second formulation: thrust_time_series with c1 alone is thrust_time with
    rate = -c1 / 60 s, at every flight time (the same state)."""
    from gainsched.model.effects import ThrustTime, ThrustTimeSeries

    T = np.array([[2.0, 3.0, 4.0, 5.0]])
    for t in (0.0, 1.5, 40.0, 600.0):
        x = np.array([[t]])
        a = ThrustTimeSeries(c1=-0.3).modify_thrust(T, None, x)
        b = ThrustTime(rate=0.3 / 60.0).modify_thrust(T, None, x)
        np.testing.assert_allclose(a, b, rtol=1e-15)


def test_a_thrust_curve_that_turns_back_is_implausible():
    """Issue 37: 1 - 0.060 v + 0.0034 v^2 (the fit to a weak motor) falls 26 % to
    8.8 m/s and rises again by 11.5 % (towards 3 m/s) and 13 % (towards 15 m/s): no
    rotor's curve; a monotone loss, or a turn outside the flown range, is plausible."""
    from gainsched.model.effects import ThrustPolynomial

    why = ThrustPolynomial(c1=-0.060, c2=0.0034).implausible((3.0, 15.0))
    assert why.startswith("thrust_airspeed falls to -26.5% at 8.8 m/s and turns back by "
                          "11.5% inside the flown 3.0-15.0 m/s"), why
    assert ThrustPolynomial(c1=-0.010, c2=0.0).implausible((3.0, 15.0)) == ""
    assert ThrustPolynomial(c1=-0.060, c2=0.0034).implausible((10.0, 15.0)) == ""
    assert ThrustPolynomial(c1=-0.002, c2=0.0001).implausible((3.0, 15.0)) == ""  # 0.9 %
