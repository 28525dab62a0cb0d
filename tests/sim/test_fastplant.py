"""Compiled plant (gainsched/native/plant.c) against the numpy reference model (issue 5).

- z_dot, tension and actual thrusts of ``FastPlant`` equal ``Model.evaluate`` at
  random seeded states, inputs and tilts, for every combination of the supported
  effects (and both orders of the thrust modifiers): relative error <= 1e-12 of the
  largest entry (entries near zero inherit the rounding of the 6x6 solve, so a
  per-entry relative bound would test LAPACK's pivoting order, not the physics).
- One RK4 step equals ``sim._rk4`` on the numpy model.
- The maximal model with the spring-damper link (``FastMaximal``) equals
  ``MaximalModel``: derivative and tension at random states (taut and slack, every
  combination of the effects, their states random: issue 59), and a step with its RK4
  substeps (a stiff link).
- A closed-loop flight with the compiled plants equals the numpy-plant flight.
- A wind (issue 37): derivative, tension and thrusts of both plants, reduced and
  maximal, equal the numpy models at random tilts *and headings* gamma (the wind's
  direction in C), with every airspeed effect beside it; an RK4 step too; and a
  closed-loop flight at a heading in a wind equals the numpy-plant flight.
- The numpy model is used with ``GAINSCHED_NATIVE=0`` and for configs the kernel
  does not implement.
- The campaigns' truth outside the library (an azimuth thrust loss) is compiled too, on
  the rigid and the elastic tether.
- The state estimator predicts a design with effect states (a motor lag), on a rigid or
  an elastic tether, with its compiled reduced model.
- The simulator's single-query interpolator path gives the vectorised reference's
  numbers bit for bit, and a flight with block-wise (batched) gain lookups is bit
  for bit the flight with per-step lookups.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from gainsched import native
from gainsched.config import N_STATE, EffectSpec, config_from_text, remove_key, set_values
from gainsched.firmware.runtime import Interpolator
from gainsched.model.effects import EFFECTS, registered_effect
from gainsched.model.maximal import MaximalModel
from gainsched.model.reduced import Model
from gainsched.schedule.tables import load_table
from gainsched.sim._estimator import _Estimator
from gainsched.sim._plant import _Plant, _rk4
from gainsched.sim.campaign import AzimuthThrustLoss, plant_config
from gainsched.sim.fastplant import (
    SUPPORTED_EFFECTS,
    FastMaximal,
    FastPlant,
    fast_plant,
    fast_plant_supported,
    reduced_fast_plant,
)
from gainsched.sim.loop import Scenario, Sensing, simulate, table_scheduler

from support import PAPER_H5

pytestmark = [
    pytest.mark.needs_cc,
    # the compiled plant in use, not only a compiler: GAINSCHED_NATIVE=0 switches it off too
    pytest.mark.skipif(not native.available("plant"), reason="no C compiler"),
]

# one table per supported effect, with non-default parameters
EFFECT_PARAMS = {
    "drag": {"mu1": 0.172, "mu2": 0.0025},
    "rotor_drag": {"k_rd": 0.03},
    "thrust_scale": {"k_T": 0.93},
    "thrust_airspeed": {"c1": -0.012, "c2": 0.0004},
    "motor_lag": {"tau": 0.03},
    "thrust_momentum": {"disk_area": 0.006},
    "motor_efficiency": {"eta1": 1.04, "eta2": 0.97, "eta3": 0.92, "eta4": 1.01},
    "thrust_time": {"rate": 0.013},
    "wind": {"east": 2.4, "north": -1.8},
    "thrust_voltage": {"v_ref": 11.9, "exponent": 1.8, "capacity": 0.04, "resistance": 0.1,
                       "current": 1.3, "tau": 0.04},
}
#: every combination of the first six, the per-motor one after a lag, before and after
#: the airspeed modifiers, and the flight-time one (a second stateful effect) beside a lag
COMBOS = [
    c for r in range(7) for c in itertools.combinations(list(EFFECT_PARAMS)[:6], r)
] + [("thrust_airspeed", "thrust_scale", "drag"),  # modifiers in the other order
     ("motor_efficiency",), ("motor_lag", "motor_efficiency", "thrust_momentum"),
     ("thrust_airspeed", "motor_efficiency", "rotor_drag"), ("thrust_time",),
     ("thrust_time", "motor_lag", "drag"), ("motor_lag", "thrust_scale", "thrust_time"),
     ("thrust_voltage",), ("thrust_voltage", "motor_lag", "drag"),
     ("motor_lag", "thrust_time", "thrust_voltage", "motor_efficiency")]


def with_effects(paper_text: str, names) -> object:
    """The paper config with exactly the named effects (in this order)."""
    base = remove_key(paper_text, "effects", "drag")
    assert "mu1" not in base
    keys = {f"effects.{n}.{k}": v for n in names for k, v in EFFECT_PARAMS[n].items()}
    return config_from_text(set_values(base, keys), "fx.toml")


def random_states(model: Model, n: int, seed: int):
    """States (n, n_z) around the circle (fast, tilted, rotating), inputs (n, 4) N, tilts (n,)."""
    rng = np.random.default_rng(seed)
    z = np.zeros((n, model.n_z))
    z[:, 0] = np.pi / 2 + rng.normal(0, 0.2, n)
    z[:, 1] = rng.uniform(-np.pi, np.pi, n)
    z[:, 2] = rng.normal(0, 1.0, n)
    z[:, 3] = rng.uniform(-10, 10, n)
    z[:, 4:7] = rng.normal(0, 0.4, (n, 3))
    z[:, 7:10] = rng.normal(0, 3.0, (n, 3))
    z[:, N_STATE:] = rng.uniform(0.1, 3.5, (n, model.n_z - N_STATE))
    i = N_STATE
    for e in model.effects:  # a battery's states: open-circuit voltage and drop, V
        if e.kind == "thrust_voltage":
            z[:, i] = rng.uniform(10.5, 12.6, n)
            z[:, i + 1] = rng.uniform(0.0, 1.0, n)
        i += e.n_states
    return z, rng.uniform(0.1, 3.5, (n, 4)), rng.uniform(-0.8, 0.8, n)


@pytest.mark.parametrize("names", COMBOS, ids=lambda c: "+".join(c) or "none")
def test_derivative_and_tension_equal_numpy_model(paper_text, names):
    cfg = with_effects(paper_text, names)
    assert fast_plant_supported(cfg)
    model = Model(cfg)
    fp = fast_plant(cfg)
    assert isinstance(fp, FastPlant) and fp.n_z == model.n_z
    z, u, alpha = random_states(model, 64, seed=len(names) * 7 + 1)
    ref = model.evaluate(z, u, alpha)  # batched numpy
    for i in range(z.shape[0]):
        z_dot, ten, T = fp.evaluate(z[i], u[i], alpha[i])
        scale = np.abs(ref.z_dot[i]).max()
        assert np.abs(z_dot - ref.z_dot[i]).max() <= 1e-12 * scale
        assert abs(ten - ref.tension[i]) <= 1e-12 * max(abs(ref.tension[i]), 1.0)
        assert np.abs(T - ref.T[i]).max() <= 1e-12 * np.abs(ref.T[i]).max()
        z_dot2, ten2 = fp.f(z[i], u[i], alpha[i])
        np.testing.assert_array_equal(z_dot2, z_dot)
        assert ten2 == ten


#: the wind with each airspeed effect, all of them, and before / after the others
WIND_COMBOS = [("drag", "wind"), ("wind", "rotor_drag"), ("thrust_airspeed", "wind"),
               ("wind", "thrust_momentum", "drag"),
               ("motor_lag", "wind", "drag", "rotor_drag", "thrust_airspeed", "thrust_momentum"),
               ("wind",)]


@pytest.mark.parametrize("names", WIND_COMBOS, ids=lambda c: "+".join(c))
def test_wind_derivative_and_tension_equal_numpy_model(paper_text, names):
    """The compiled plant turns the wind into C with the heading it is given, as the
    numpy model does: 1e-12 of the largest entry at random tilts and headings."""
    cfg = with_effects(paper_text, names)
    assert fast_plant_supported(cfg)
    model, fp = Model(cfg), fast_plant(cfg)
    assert isinstance(fp, FastPlant) and model.wind_I is not None
    z, u, alpha = random_states(model, 48, seed=len(names) * 11 + 5)
    gamma = np.random.default_rng(len(names)).uniform(-np.pi, np.pi, alpha.size)
    ref = model.evaluate(z, u, alpha, gamma)  # batched numpy, a heading per state
    still = Model(cfg, effects=tuple(e for e in model.effects if e.kind != "wind"))
    moved = np.abs(ref.z_dot - still.evaluate(z, u, alpha, gamma).z_dot).max()
    assert moved > (1e-3 if any(n != "wind" for n in names) else -1)  # the wind acts...
    if names == ("wind",):  # ...through the airspeed effects only
        np.testing.assert_array_equal(ref.z_dot, still.evaluate(z, u, alpha).z_dot)
    for i in range(z.shape[0]):
        z_dot, ten, T = fp.evaluate(z[i], u[i], alpha[i], gamma[i])
        scale = np.abs(ref.z_dot[i]).max()
        assert np.abs(z_dot - ref.z_dot[i]).max() <= 1e-12 * scale
        assert abs(ten - ref.tension[i]) <= 1e-12 * max(abs(ref.tension[i]), 1.0)
        assert np.abs(T - ref.T[i]).max() <= 1e-12 * np.abs(ref.T[i]).max()
        z_dot2, ten2 = fp.f(z[i], u[i], alpha[i], gamma[i])
        np.testing.assert_array_equal(z_dot2, z_dot)
        x_ref, ten_ref = _rk4(lambda x, v, a, g=gamma[i]: (model.f(x, v, a, g),
                                                            model.evaluate(x, v, a, g).tension),
                              z[i], u[i], alpha[i], 1e-3)
        x_next, ten3 = fp.rk4_step(z[i], u[i], alpha[i], 1e-3, gamma[i])
        assert np.abs(x_next - x_ref).max() <= 1e-12 * np.abs(x_ref).max()
        assert ten3 == ten


@pytest.mark.parametrize("names", [("drag", "wind"), ("wind", "rotor_drag", "thrust_momentum")],
                         ids=lambda c: "+".join(c))
def test_wind_maximal_equals_numpy_model(paper_text, names):
    """The spring-damper plant in a wind, at random headings: derivative, tension and a
    step with substeps within 1e-12 of ``MaximalModel``."""
    cfg = spring_damper(paper_text, names, 2e5, 20.0)
    fm, mm = fast_plant(cfg), MaximalModel(Model(cfg))
    assert isinstance(fm, FastMaximal)
    x, u, alpha = maximal_states(mm, 24, seed=len(names) + 40)
    gamma = np.random.default_rng(3).uniform(-np.pi, np.pi, alpha.size)
    ref, ten_ref = mm.f(x, u, alpha, gamma), mm.tension(x, u, alpha, gamma)
    assert np.abs(ref - mm.f(x, u, alpha)).max() > 1e-3  # the heading matters
    for i in range(x.shape[0]):
        x_dot, ten = fm.f(x[i], u[i], alpha[i], gamma[i])
        assert np.abs(x_dot - ref[i]).max() <= 1e-12 * np.abs(ref[i]).max()
        assert abs(ten - ten_ref[i]) <= 1e-12 * max(ten_ref[i], 1.0)
        x_ref, t_ref = mm.step(x[i], u[i], alpha[i], 1e-3, gamma[i])
        x_next, t_next = fm.rk4_step(x[i], u[i], alpha[i], 1e-3, gamma[i])
        assert np.abs(x_next - x_ref).max() <= 1e-12 * np.abs(x_ref).max()
        assert abs(t_next - t_ref) <= 1e-12 * max(abs(t_ref), 1.0)


@pytest.mark.parametrize("names", [("drag",), tuple(EFFECT_PARAMS)], ids=["drag", "all"])
def test_rk4_step_equals_numpy(paper_text, names):
    cfg = with_effects(paper_text, names)
    model, fp = Model(cfg), fast_plant(cfg)

    def f(x, u, a):
        ev = model.evaluate(x, u, a)
        return ev.z_dot, ev.tension

    z, u, alpha = random_states(model, 8, seed=3)
    for i in range(z.shape[0]):
        x_ref, ten_ref = _rk4(f, z[i], u[i], alpha[i], 1e-3)
        x_next, ten = fp.rk4_step(z[i], u[i], alpha[i], 1e-3)
        assert np.abs(x_next - x_ref).max() <= 1e-12 * np.abs(x_ref).max()
        assert ten == fp.f(z[i], u[i], alpha[i])[1]
        assert abs(ten - ten_ref) <= 1e-12 * max(abs(ten_ref), 1.0)


@pytest.mark.slow
def test_closed_loop_in_a_wind_equals_numpy_plant(paper_config, paper_text, monkeypatch):
    """0.5 s tilted flight at heading 70 deg in a wind: the compiled and the numpy flights
    agree to 1e-9 m, and the wind (its direction in C set by the heading) moved the
    vehicle against the same flight in still air."""
    sched = table_scheduler(load_table(PAPER_H5))
    truth = with_effects(paper_text, ("drag", "wind"))
    scn = Scenario("wind", np.deg2rad(20), 9.0, 0.5, gamma=np.deg2rad(70))
    assert _Plant(truth).fast is not None
    fast = simulate(paper_config, sched, scn, truth)
    calm = simulate(paper_config, sched, dataclasses.replace(scn, gamma=0.0), truth)
    assert np.abs(fast.z - calm.z).max() > 1e-4
    monkeypatch.setenv("GAINSCHED_NATIVE", "0")
    assert _Plant(truth).fast is None
    slow = simulate(paper_config, sched, scn, truth)
    assert np.abs(fast.p_I - slow.p_I).max() <= 1e-9
    assert np.abs(fast.z - slow.z).max() <= 1e-9


def test_closed_loop_with_a_battery_equals_numpy_plant(paper_config, paper_text, monkeypatch):
    """Issue 37: 0.5 s level 9 m/s flight on a plant with a battery (thrust_voltage, its
    2 states integrated by plant.c): the compiled and the numpy flights agree to 1e-9 m,
    their battery voltages to 1e-9 V; the voltage sags under load (below the open-circuit
    voltage by the drop, falling with the charge drawn) and the log carries it."""
    from gainsched.sim.loop import log_from_result

    sched = table_scheduler(load_table(PAPER_H5))
    truth = with_effects(paper_text, ("drag", "thrust_voltage"))
    scn = Scenario("battery", 0.0, 9.0, 0.5)
    assert _Plant(truth).fast is not None
    fast = simulate(paper_config, sched, scn, truth)
    monkeypatch.setenv("GAINSCHED_NATIVE", "0")
    assert _Plant(truth).fast is None
    slow = simulate(paper_config, sched, scn, truth)
    assert np.abs(fast.p_I - slow.p_I).max() <= 1e-9
    assert np.abs(fast.z - slow.z).max() <= 1e-9
    assert np.abs(fast.vbat - slow.vbat).max() <= 1e-9
    eff = next(e for e in Model(truth).effects if e.kind == "thrust_voltage")
    drain, load = eff.coefficients()
    T_C = fast.u.sum(1)
    # the flight starts with a full battery, its drop settled at the command that gives
    # the nominal thrust at that voltage
    x0, u0 = eff.steady_states(fast.u_d[0], np.zeros(4))
    np.testing.assert_allclose(u0 * eff.factor(eff.voltage(x0)), fast.u_d[0], rtol=1e-12)
    assert x0[0] == eff.v_full and x0[1] == pytest.approx(load * u0.sum(), rel=1e-12)
    assert fast.vbat[0] == pytest.approx(eff.voltage(x0), rel=1e-12)
    # the open-circuit voltage fell by the charge drawn (held commands, Euler sum exact)
    fall = drain * np.sum(T_C[:-1]) * (fast.t[1] - fast.t[0])
    assert eff.v_full - fast.vbat[-1] == pytest.approx(fall + load * T_C[-1], abs=0.01)
    log = log_from_result(fast)
    assert "vbat" in log.optional and log.optional["vbat"].size == len(log)


@pytest.mark.slow
def test_closed_loop_equals_numpy_plant(paper_config, paper_text, monkeypatch):
    """1 s tilted flight, motion-capture sensing (the estimator's prediction model is
    compiled too), truth plant with more effects than the design model: the compiled
    and the numpy flights agree to 1e-9 m."""
    sched = table_scheduler(load_table(PAPER_H5))
    truth = with_effects(paper_text, ("drag", "rotor_drag", "thrust_scale"))
    sens = Sensing(False, 200.0, 0.0005, np.deg2rad(0.2), 0.01, 0.005, 7)
    scn = Scenario("cmp", np.deg2rad(20), 9.0, 1.0, sensing=sens, initial_error=(0.02, 0.05))
    assert _Plant(truth).fast is not None
    fast = simulate(paper_config, sched, scn, truth)
    monkeypatch.setenv("GAINSCHED_NATIVE", "0")
    assert _Plant(truth).fast is None
    slow = simulate(paper_config, sched, scn, truth)
    assert fast.t.size == slow.t.size == 1001 and fast.slack_time is None
    assert np.abs(fast.p_I - slow.p_I).max() <= 1e-9
    assert np.abs(fast.z - slow.z).max() <= 1e-9
    assert np.abs(fast.tension - slow.tension).max() <= 1e-9 * slow.tension.max()
    np.testing.assert_array_equal(fast.status, slow.status)
    np.testing.assert_array_equal(fast.saturated, slow.saturated)


def test_fallback_without_native(paper_config, monkeypatch):
    monkeypatch.setenv("GAINSCHED_NATIVE", "0")
    native._load.cache_clear()
    assert native.load("plant") is None
    assert fast_plant(paper_config) is None
    assert _Plant(paper_config).fast is None
    monkeypatch.delenv("GAINSCHED_NATIVE")
    assert _Plant(paper_config).fast is not None


def test_fallback_for_unsupported_configs(paper_config):
    def link(name, cfg=paper_config):
        return dataclasses.replace(cfg, tether=dataclasses.replace(cfg.tether, link=name))

    for name in ("sls", "lumped-mass"):  # elastic links plant.c lacks: numpy maximal model
        elastic = link(name)
        assert not fast_plant_supported(elastic) and fast_plant(elastic) is None
        assert _Plant(elastic).fast is None and _Plant(elastic).maximal is not None
    lagged = link("spring-damper", with_effects(paper_config.text, ("drag", "motor_lag")))
    assert fast_plant_supported(lagged)  # stateful effects in maximal coordinates (#59)
    assert isinstance(_Plant(lagged).fast, FastMaximal)
    other = dataclasses.replace(paper_config, effects=(EffectSpec("latency", ()),))
    assert not fast_plant_supported(other) and fast_plant(other) is None
    for kind in sorted(set(EFFECTS) - SUPPORTED_EFFECTS):  # real effects plant.c lacks
        cfg = dataclasses.replace(paper_config, effects=(EffectSpec(kind, ()),))
        assert not fast_plant_supported(cfg)
        assert _Plant(cfg).fast is None  # numpy model
    with pytest.raises(ValueError, match="not supported"):
        FastPlant(link("spring-damper"), native.load("plant"))
    with pytest.raises(ValueError, match="not supported"):
        FastMaximal(paper_config, native.load("plant"))


@pytest.mark.parametrize("link", ["rigid", "spring-damper", "sls"])
def test_the_estimator_predicts_a_design_with_effect_states_compiled(paper_text, link):
    """A design with a motor lag's states (and momentum theory), on a rigid or an elastic
    tether (one the compiled plant cannot fly too: the estimator's model is the reduced
    one): the state estimator predicts with its compiled reduced model
    (``reduced_fast_plant``), never the numpy one, whose numbers it has to 1e-12 of the
    largest entry; an effect the kernel lacks gives the numpy model."""
    names = ("drag", "thrust_momentum", "motor_lag")
    cfg = (with_effects(paper_text, names) if link == "rigid" else
           spring_damper(paper_text, names, 2e5, 40.0))
    if link == "sls":
        cfg = dataclasses.replace(cfg, tether=dataclasses.replace(cfg.tether, link="sls"))
    model = Model(cfg)
    fp = reduced_fast_plant(model)
    assert isinstance(fp, FastPlant) and fp.n_z == model.n_z == N_STATE + 4
    z, u, alpha = random_states(model, 16, seed=3)
    for i in range(z.shape[0]):
        ref = model.f(z[i], u[i], alpha[i])
        assert np.abs(fp.f(z[i], u[i], alpha[i])[0] - ref).max() <= 1e-12 * np.abs(ref).max()
    sens = Sensing(False, 200.0, 0.0005, np.deg2rad(0.2), 0.01, 0.005, 7)
    est = _Estimator(model, None, sens, 0.001, alpha[0], 0.0, z[0], np.random.default_rng(0))

    def numpy_model(*args):
        raise AssertionError("the estimator predicted with the numpy model")

    model.f = numpy_model
    est.predict(u[0])
    expect = z[0] + 0.001 * fp.f(z[0], u[0], alpha[0])[0]
    np.testing.assert_array_equal(est.z, expect)
    kind = sorted(set(EFFECTS) - SUPPORTED_EFFECTS)[0]
    other = dataclasses.replace(cfg, effects=(*cfg.effects, EffectSpec(kind, ())))
    assert reduced_fast_plant(Model(other)) is None


# ----------------------------------------------------------- maximal model, spring-damper
# every combination, stateful effects included (the wind's own maximal test is
# test_wind_maximal_equals_numpy_model)


def spring_damper(paper_text: str, names, stiffness: float, damping: float):
    """The paper config with the named effects and a spring-damper tether."""
    cfg = with_effects(paper_text, names)
    text = set_values(cfg.text, {"tether.link": "spring-damper", "tether.stiffness": stiffness,
                                 "tether.damping": damping})
    return config_from_text(text, "elastic.toml")


def maximal_states(mm: MaximalModel, n: int, seed: int):
    """Maximal states (n, n_x) from random reduced states and effect states, the link
    stretched to 0-40 N and the radius jittered by 1e-4; every third one 1 mm shorter
    than its rest length (slack); inputs (n, 4) N, tilts (n,)."""
    model = mm.model
    z, u, alpha = random_states(model, n, seed)
    rng = np.random.default_rng(seed + 100)
    tension = rng.uniform(0.0, 40.0, n)
    tension[::3] = 0.0
    x = mm.from_reduced(z, tension=tension)
    np.testing.assert_array_equal(x[:, 13:], z[:, N_STATE:])
    x[:, :3] *= 1 + 1e-4 * rng.standard_normal((n, 1))
    x[::3, :3] *= 1 - 1e-3 / model.rho
    return x, u, alpha


@pytest.mark.parametrize("hidden", ["azimuth_thrust_dip", "elastic_and_dip"])
def test_the_campaigns_truth_outside_the_library_is_compiled_as_numpy(paper_config, hidden):
    """The azimuth thrust loss (gainsched.sim._outside, a campaign's hidden truth) on the
    rigid and the elastic tether: the compiled plant's derivative and tension equal the
    numpy models' to 1e-12 of the largest entry at random states (every direction of
    travel), where the loss moves them by more than 1e-3."""
    with registered_effect(AzimuthThrustLoss):
        cfg = plant_config(paper_config, hidden)
        model = Model(cfg)
        without = Model(cfg, effects=tuple(e for e in model.effects
                                           if not isinstance(e, AzimuthThrustLoss)))
        fp = fast_plant(cfg)
        if cfg.tether.link == "rigid":
            assert isinstance(fp, FastPlant)
            x, u, alpha = random_states(model, 48, seed=9)
            ev = model.evaluate(x, u, alpha)
            ref, ten_ref = ev.z_dot, ev.tension
            moved = np.abs(ref - without.evaluate(x, u, alpha).z_dot).max()
        else:
            assert isinstance(fp, FastMaximal)
            mm = MaximalModel(model)
            x, u, alpha = maximal_states(mm, 48, seed=9)
            ref, ten_ref = mm.f(x, u, alpha), mm.tension(x, u, alpha)
            moved = np.abs(ref - MaximalModel(without).f(x, u, alpha)).max()
        assert moved > 1e-3
        for i in range(x.shape[0]):
            x_dot, ten = fp.f(x[i], u[i], alpha[i])
            assert np.abs(x_dot - ref[i]).max() <= 1e-12 * np.abs(ref[i]).max()
            assert abs(ten - ten_ref[i]) <= 1e-12 * max(abs(ten_ref[i]), 1.0)


@pytest.mark.parametrize("names", COMBOS, ids=lambda c: "+".join(c) or "none")
def test_maximal_derivative_and_tension_equal_numpy_model(paper_text, names):
    """x' within 1e-12 of its largest entry, tension within 1e-12 N; slack states
    (tension 0, no push) among them; the effect states' rates too."""
    cfg = spring_damper(paper_text, names, 3000.0, 5.0)
    fm = fast_plant(cfg)
    assert isinstance(fm, FastMaximal)
    mm = MaximalModel(Model(cfg))
    x, u, alpha = maximal_states(mm, 48, seed=len(names) * 5 + 2)
    ref, ten_ref = mm.f(x, u, alpha), mm.tension(x, u, alpha)
    assert np.any(ten_ref == 0) and np.any(ten_ref > 10)  # both sides of the clip
    for i in range(x.shape[0]):
        x_dot, ten = fm.f(x[i], u[i], alpha[i])
        assert np.abs(x_dot - ref[i]).max() <= 1e-12 * np.abs(ref[i]).max()
        assert abs(ten - ten_ref[i]) <= 1e-12 * max(ten_ref[i], 1.0)


@pytest.mark.parametrize("names", [(), COMBOS[63], COMBOS[-1]],
                         ids=["none", "first six", "stateful+efficiency"])
def test_maximal_step_with_substeps_equals_numpy(paper_text, names):
    """A stiff link (k = 2e5 N/m: 3 RK4 substeps per 1 ms) and a soft one (1 substep): the
    compiled step equals ``MaximalModel.step``, the signed tension (negative when
    slack) included."""
    for k, c, subs in ((2e5, 20.0, 3), (3000.0, 5.0, 1)):
        cfg = spring_damper(paper_text, names, k, c)
        fm, mm = fast_plant(cfg), MaximalModel(Model(cfg))
        assert mm.substeps(1e-3) == subs
        x, u, alpha = maximal_states(mm, 12, seed=9)
        signs = set()
        for i in range(x.shape[0]):
            x_ref, ten_ref = mm.step(x[i], u[i], alpha[i], 1e-3)
            x_next, ten = fm.rk4_step(x[i], u[i], alpha[i], 1e-3)
            assert np.abs(x_next - x_ref).max() <= 1e-12 * np.abs(x_ref).max()
            assert abs(ten - ten_ref) <= 1e-12 * max(abs(ten_ref), 1.0)
            signs.add(bool(ten_ref > 0))
        assert signs == {True, False}


def test_single_query_interpolator_is_bitwise_the_reference():
    """``Interpolator.query`` (the simulator's per-step lookup) against ``__call__`` on
    scalars: every symmetry branch, clamped, infeasible, grid planes and bad inputs."""
    it = Interpolator(load_table(PAPER_H5))
    d = it.data
    rng = np.random.default_rng(11)
    n = 2000
    vmax, amax = float(d.xi_dot[-1]), float(d.tilt[-1])
    q = np.stack(
        [
            rng.uniform(-20, 20, n),
            rng.choice([-1, 1], n) * rng.uniform(0, 1.2 * vmax, n),
            rng.choice([-1, 1], n) * rng.uniform(0, 1.2 * amax, n),
        ],
        1,
    )
    q[::50, 0] = np.nan
    q[1::97, 2] = 1.7  # beyond the tilt limit
    q[2::89, 1] = 0.0
    q[3::83, 0] = np.round(q[3::83, 0] / (2 * np.pi / d.xi.size)) * (2 * np.pi / d.xi.size)
    q[4::71, 1] = d.xi_dot[rng.integers(0, d.xi_dot.size, q[4::71].shape[0])]
    q[5::67, 2] = d.tilt[rng.integers(0, d.tilt.size, q[5::67].shape[0])]
    statuses = set()
    for x, v, a in q:
        ref = it(x, v, a)
        K, u_d, phi_d, status = it.query(x, v, a)
        statuses.add(status)
        assert status == int(ref.status)
        np.testing.assert_array_equal(K, ref.K)
        assert K.flags.c_contiguous  # so that K @ x rounds as with the reference's K
        np.testing.assert_array_equal(u_d, ref.u_d)
        assert phi_d == float(ref.phi_d)
    assert {0, 1, 2, 16} <= statuses and any(s & 4 for s in statuses)


def test_batched_gain_lookup_flies_the_same_as_per_step(paper_config):
    """``table_scheduler`` offers ``batch`` (gains of the reference path looked up in
    blocks); a flight with it is bit for bit the flight with per-step lookups, on
    every symmetry branch (negative tilt, reversed direction) and across blocks."""
    sched = table_scheduler(load_table(PAPER_H5))
    assert callable(sched.batch)

    def per_step(xi, xi_dot, alpha):  # no batch attribute
        return sched(xi, xi_dot, alpha)

    sens = Sensing(False, 200.0, 0.0005, np.deg2rad(0.2), 0.01, 0.005, 2)
    for scn in (
        Scenario("m", np.deg2rad(-30), -7.0, 1.2, sensing=sens, initial_error=(0.02, 0.05)),
        Scenario("p", np.deg2rad(10), 9.0, 1.2, initial_error=(0.02, 0.05)),
    ):
        a, b = simulate(paper_config, sched, scn), simulate(paper_config, per_step, scn)
        for key in ("z", "z_hat", "u", "tension", "p_I", "q_IB", "status", "saturated"):
            np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
