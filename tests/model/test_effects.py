"""Effects as the one place physics is added (issue 13): hooks and the registry.

- the exact held-command states of the motor lag against a fine integration of its
  own ``state_derivative`` (an independent second formulation);
- a user-defined effect becomes nameable in configs through ``registered_effect``,
  and only inside the block;
- the simulator says once, in one line, when the compiled plant cannot run a config.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.config import config_from_text
from gainsched.errors import InputError
from gainsched.model.effects import (
    Drag,
    Effect,
    MotorLag,
    Param,
    registered_effect,
)
from gainsched.model.momentum import _bracketed, induced_velocity
from gainsched.model.reduced import Model

from support import PAPER_H5, PAPER_TOML, REPO, paper_config_text


def test_motor_lag_held_commands_equal_fine_integration():
    tau, dt = 0.03, 0.005  # s
    lag = MotorLag(tau=tau)
    rng = np.random.default_rng(3)
    t = np.arange(60) * dt
    T_cmd = 1.2 + 0.3 * rng.standard_normal((60, 4))  # N, held over each interval
    exact = lag.states_from_held_commands(t, T_cmd)
    x = T_cmd[0].copy()  # steady state at the first command
    sub, ref = 50, [T_cmd[0].copy()]
    h = dt / sub
    for k in range(1, t.size):  # the command of sample k acts over (t_{k-1}, t_k]
        f = lambda y, u=T_cmd[k]: lag.state_derivative(y, u, None)  # noqa: E731
        for _ in range(sub):  # classical RK4, error ~ (h / tau)^5 ~ 1e-12
            k1 = f(x)
            k2 = f(x + h / 2 * k1)
            k3 = f(x + h / 2 * k2)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + f(x + h * k3))
        ref.append(x.copy())
    np.testing.assert_allclose(exact, np.array(ref), rtol=0, atol=1e-10)  # N


def test_stateless_effects_have_no_held_command_form():
    assert Drag(mu1=0.1, mu2=0.0).states_from_held_commands(np.arange(3.0), np.ones((3, 4))) \
        is None


def _largest_root(vh, vz, vxy):
    """Largest positive real root of v^2 ((v + vz)^2 + vxy^2) = vh^4, by numpy's companion
    matrix (an independent solver)."""
    r = np.roots([1.0, 2 * vz, vz * vz + vxy * vxy, 0.0, -vh ** 4])
    r = r[np.abs(r.imag) < 1e-7 * vh].real
    return float(r[r > 0].max())


def test_momentum_induced_velocity_is_the_largest_root_everywhere():
    """The induced velocity of paper eq. 29 over hover, climb, descent, vortex ring and
    fast forward flight: the largest root (rel. 1e-9), with its complex-step derivatives
    in each input equal to central differences (rel. 1e-6)."""
    vh = np.array([2.0, 5.0, 11.0])  # m/s
    ratio = np.linspace(-3.0, 3.0, 25)  # vz / vh
    vxy = np.array([0.0, 1.0, 4.0, 15.0])  # m/s
    VH, R, VXY = np.meshgrid(vh, ratio, vxy, indexing="ij")
    VZ = R * VH
    v = induced_velocity(VH, VZ, VXY ** 2)
    ref = np.vectorize(_largest_root)(VH, VZ, VXY)
    np.testing.assert_allclose(v, ref, rtol=1e-9)
    h = 1e-6
    for k in range(3):  # d/d vh, d/d vz, d/d vxy^2 (the complex step: implicit function)
        inside = VXY > 0 if k == 2 else VXY >= 0  # vxy^2 - h < 0 has no meaning
        args = [VH[inside] + 0j, VZ[inside] + 0j, VXY[inside] ** 2 + 0j]
        step = [a + (1e-30j if j == k else 0) for j, a in enumerate(args)]
        cs = induced_velocity(*step).imag / 1e-30
        up, down = (induced_velocity(*[np.real(a) + (s if j == k else 0)
                                        for j, a in enumerate(args)]) for s in (h, -h))
        cd = (up - down) / (2 * h)
        np.testing.assert_allclose(cs, cd, rtol=1e-6, atol=1e-6, err_msg=f"input {k}")



@pytest.mark.parametrize("native", ["1", "0"], ids=["compiled", "numpy"])
def test_momentum_plain_newton_equals_the_safeguarded_iteration(native, monkeypatch):
    """Issue 39: the plain Newton steps from Glauert's estimate that most samples take (the
    numpy fallback), and the compiled plant's safeguarded Newton per sample (issue 57: the
    model's default, the simulator's plant's own), give the root of the numpy safeguarded
    Newton-bisection (the induced velocity's only iteration before) to 1e-13 relative,
    over a build's range of thrust and airspeed (hover induced velocity 1-8 m/s, axial
    airspeed -1.5..3 vh, in-plane 0-16 m/s)."""
    monkeypatch.setenv("GAINSCHED_NATIVE", native)
    rng = np.random.default_rng(39)
    n = 20000
    vh = rng.uniform(1.0, 8.0, n)
    vz, vxy2 = rng.uniform(-1.5, 3.0, n) * vh, rng.uniform(0.0, 16.0, n) ** 2
    one_root = (vz >= 0) | (8 * vxy2 >= vz * vz)
    assert one_root.mean() > 0.8
    hi = vh + 0.5 * (np.sqrt(vz * vz + 1e-12) - vz)
    start = np.where(one_root, vh * vh / np.sqrt(vxy2 + (vh + vz) ** 2 + 1e-12), hi)
    ref = _bracketed(start, np.zeros(n), hi.copy(), vh * vh, vz, vxy2, vh, 1e-12, 80)
    np.testing.assert_allclose(induced_velocity(vh, vz, vxy2), ref, rtol=1e-13)

class _Wake(Effect):
    """A test effect: a relative thrust loss (position- or velocity-free, for the registry)."""

    kind = "test_wake"
    params = (Param("depth", "-", 0.0, 0.0, 0.5, "relative thrust loss"),)

    def modify_thrust(self, T, kin, x):
        return T * (1 - self.depth)


def _with_wake(depth: float) -> str:
    return paper_config_text(**{"effects.test_wake.depth": depth})


def test_registered_effect_is_nameable_only_inside_the_block():
    text = _with_wake(0.1)
    with pytest.raises(InputError, match="unknown effect"):
        config_from_text(text, "wake.toml")
    with registered_effect(_Wake):
        cfg = config_from_text(text, "wake.toml")
        model = Model(cfg)
        assert any(isinstance(e, _Wake) and e.depth == 0.1 for e in model.effects)
        with pytest.raises(InputError, match=r"effects.test_wake.depth"):
            config_from_text(_with_wake(0.9), "wake.toml")  # bounds from the class's Param
    with pytest.raises(InputError, match="unknown effect"):
        config_from_text(text, "wake.toml")


def test_registered_effect_refuses_a_clash():
    class OtherDrag(Effect):
        kind = "drag"

    with pytest.raises(ValueError, match="exists already"), registered_effect(OtherDrag):
        pass


@pytest.mark.slow
def test_simulator_says_once_when_the_compiled_plant_cannot_run_it(tmp_path):
    """thrust_azimuth (the empirical series) has no compiled form: one warning line, and
    the flight still flies."""
    text = paper_config_text(**{"effects.thrust_azimuth.a1": -0.02})
    plant = tmp_path / "plant.toml"
    plant.write_text(text)
    scenario = tmp_path / "short.toml"  # the numpy plant is slow: a 0.5 s flight
    scenario.write_text((REPO / "gainsched/sim/scenarios/horizontal.toml").read_text()
                        .replace("duration = 5.0", "duration = 0.5"))
    args = ["simulate", str(PAPER_TOML), "--tables", str(PAPER_H5), "--scenario",
            str(scenario), "--plant", str(plant), "-o", str(tmp_path / "out")]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("gainsched: warning:")]
    assert len(lines) == 1 and "thrust_azimuth" in lines[0] and "numpy model" in lines[0]
    assert "Warning:" not in res.stderr  # no Python-style warning text


def test_thrust_voltage_law_and_battery_model():
    """Issue 37, ThrustVoltage: at a fixed command the thrust goes as (vbat / v_ref)^2
    (rotor speed ~ voltage, thrust ~ speed^2): 10 % more voltage gives 21 % more thrust,
    v_ref none; a dead battery none at all. The battery model (an independent second
    formulation: the open-circuit voltage from the charge drawn, coulomb counting, and
    the drop settling to R I) integrated by RK4 under a held command; in a log the
    states are (vbat, 0), so the terminal voltage is the logged one."""
    from gainsched.model.effects import ThrustVoltage

    eff = ThrustVoltage(v_ref=11.1, exponent=2.0, v_full=12.6, v_empty=10.5, capacity=0.5,
                        resistance=0.08, current=1.5, tau=0.05)
    T = np.array([1.0, 2.0, 3.0, 4.0])
    x = eff.states_from_log(np.array([11.1, 12.21, 0.0]))
    np.testing.assert_array_equal(x[:, 1], 0.0)
    np.testing.assert_allclose(eff.modify_thrust(T, None, x), [T, 1.21 * T, 0 * T],
                               rtol=1e-14)
    assert eff.refusal().startswith("changes with the battery's charge and load")
    assert eff.time_varying and eff.log_channel == "vbat" and eff.n_states == 2
    np.testing.assert_array_equal(eff.mirror(), np.eye(2))
    # the battery under a held command of 5 N for 20 s
    u = np.full(4, 1.25)
    I = 1.5 * 5.0  # A  # noqa: E741
    x = np.array([12.6, 0.0])  # just connected, at rest
    h, n = 1e-3, 20000
    for k in range(n):
        if k == 100:  # 0.1 s: the drop rises as R I (1 - exp(-t / tau))
            assert x[1] == pytest.approx(0.08 * I * (1 - np.exp(-0.1 / 0.05)), rel=1e-9)
        f = lambda y: eff.state_derivative(y, u, None)  # noqa: E731
        k1 = f(x)
        k2 = f(x + h / 2 * k1)
        k3 = f(x + h / 2 * k2)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + f(x + h * k3))
    drawn = I * h * n / 3600.0  # A h
    ocv = 12.6 - (12.6 - 10.5) * drawn / 0.5
    assert eff.voltage(x) == pytest.approx(ocv - 0.08 * I, abs=1e-9)
    # complex-step safe: d/dv (v / v_ref)^2 = 2 v / v_ref^2
    v = 11.7
    d = eff.factor(np.array(v + 1e-30j)).imag / 1e-30
    assert d == pytest.approx(2 * v / 11.1**2, rel=1e-12)
