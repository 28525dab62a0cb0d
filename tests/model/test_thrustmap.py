"""The thrust modifiers' inverse (gainsched.model.thrustmap): the input it finds makes the
asked thrusts through the model's own thrust chain, and its rate is the time derivative
of that input (a second formulation: central differences along a path)."""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.model.effects import EFFECTS, Effect
from gainsched.model.reduced import Model
from gainsched.model.thrustmap import input_from_thrust, thrust_from_input


def _states(t):
    """Reduced states (n, 10) and their rates along a smooth made-up motion at times t (n,) s:
    on the sphere's equator, azimuth rate 5 rad/s, roll, pitch and yaw swinging."""
    s = np.zeros((t.size, 10))
    s_dot = np.zeros_like(s)
    s[:, 0], s[:, 1], s[:, 3] = np.pi / 2, 5.0 * t, 5.0
    s_dot[:, 1] = 5.0
    for j, (amp, w) in zip((4, 5, 6), ((0.6, 3.0), (0.2, 5.0), (0.1, 7.0)), strict=True):
        s[:, j] = amp * np.sin(w * t)
        s_dot[:, j] = amp * w * np.cos(w * t)
    s[:, 7:10] = np.stack([np.cos(t), np.sin(2 * t), 5.0 + 0.1 * t], -1)
    s_dot[:, 7:10] = np.stack([-np.sin(t), 2 * np.cos(2 * t), 0.1 + 0 * t], -1)
    return s, s_dot


def _thrusts(t):
    """Actual thrusts (n, 4) N and their rates, between 0.3 and 3 N."""
    phase = np.arange(4)[None, :]
    T = 1.6 + 1.2 * np.sin(2 * t[:, None] + phase)
    return T, 2.4 * np.cos(2 * t[:, None] + phase)


def _model(paper_config, *effects):
    return Model(paper_config, effects=(EFFECTS["drag"](mu1=0.05, mu2=0.01),) + effects)


CHAINS = {
    "momentum": lambda: (EFFECTS["thrust_momentum"](disk_area=0.006),),
    "momentum_after_scale": lambda: (EFFECTS["thrust_scale"](k_T=0.9),
                                     EFFECTS["thrust_momentum"](disk_area=0.006)),
    "airspeed_polynomial": lambda: (EFFECTS["thrust_airspeed"](c1=-0.01, c2=0.0005),),
}


@pytest.mark.parametrize("chain", CHAINS)
def test_the_input_makes_the_thrusts(paper_config, chain):
    """Through the model's own thrust (Model.evaluate on the input) the input gives the
    asked thrusts to 1e-12 N, at every point of a path that crosses momentum theory's
    floored inflow (the largest thrust gain near 2)."""
    m = _model(paper_config, *CHAINS[chain]())
    t = np.linspace(0.0, 3.0, 400)
    s, _ = _states(t)
    T, _ = _thrusts(t)
    T0, rate, ok = input_from_thrust(m, s, T, 0.3)
    assert ok.all() and rate is None
    np.testing.assert_allclose(m.evaluate(s, T0, 0.3).T, T, rtol=0, atol=1e-12)
    assert np.abs(T0 - T).max() > 0.01  # N: the modifiers change the thrust


@pytest.mark.parametrize("chain", CHAINS)
def test_the_rate_is_the_inputs_time_derivative(paper_config, chain):
    """The rate by the implicit function theorem equals central differences (h = 1e-5 s) of
    the input found at the neighbouring times, to 1e-5 relative."""
    m = _model(paper_config, *CHAINS[chain]())
    t = np.linspace(0.0, 3.0, 97)
    s, s_dot = _states(t)
    T, T_dot = _thrusts(t)
    _, rate, ok = input_from_thrust(m, s, T, 0.3, (s_dot, T_dot))
    h = 1e-5
    ahead, behind = (input_from_thrust(m, *_states(t + d)[:1], _thrusts(t + d)[0], 0.3)[0]
                     for d in (h, -h))
    fd = (ahead - behind) / (2 * h)
    assert ok.all()
    np.testing.assert_allclose(rate, fd, rtol=0, atol=1e-5 * np.abs(fd).max())


class _Coupled(Effect):
    """A made-up modifier that couples the motors: each gains 20 % of the mean thrust."""

    kind = "coupled_for_test"

    def modify_thrust(self, T, kin, x):
        return T + 0.2 * T.mean(-1, keepdims=True)


def test_a_modifier_that_couples_the_motors_is_inverted_too(paper_config):
    """The Newton steps take each motor alone (exact for every library modifier); for a
    modifier that couples the motors they are a quasi-Newton's that still converges, and
    the rate takes the whole Jacobian: the input is exact (the mean-coupled map inverted
    in closed form) and so is its rate."""
    m = _model(paper_config, _Coupled())
    t = np.linspace(0.0, 3.0, 50)
    s, s_dot = _states(t)
    T, T_dot = _thrusts(t)
    T0, rate, ok = input_from_thrust(m, s, T, 0.3, (s_dot, T_dot))
    A = np.eye(4) + 0.05  # T = A T0
    assert ok.all()
    np.testing.assert_allclose(T0, np.linalg.solve(A, T.T).T, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rate, np.linalg.solve(A, T_dot.T).T, rtol=0, atol=1e-9)


def test_thrust_from_input_is_the_models_chain_after_a_lag(paper_config):
    """With a motor lag the model's thrust is the modifiers' map of the lag's states."""
    m = _model(paper_config, EFFECTS["motor_lag"](tau=0.03), *CHAINS["momentum"]())
    t = np.linspace(0.0, 1.0, 20)
    s, _ = _states(t)
    x, _ = _thrusts(t)
    z = np.concatenate([s, x], -1)
    kin = m.effect_kinematics(s, 0.3)
    np.testing.assert_array_equal(thrust_from_input(m, x, kin), m.evaluate(z, 0 * x, 0.3).T)
