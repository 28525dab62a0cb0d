"""Linearisation and discretisation (issue 3, paper Sec. IV).

- complex-step Jacobians against central differences at seeded random states,
  for the paper model and for a model with extra effects (motor-lag states,
  rotor drag, thrust scale);
- the batched matrix exponential against scipy.linalg.expm (random and real
  blocks) and the ZOH against scipy.signal.cont2discrete;
- a rough circle's system by the chain rule through the thrust modifiers against the
  whole model's complex steps at every step.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy.signal import cont2discrete

from gainsched.config import N_STATE
from gainsched.model.effects import Drag, MotorLag, RotorDrag, ThrustMomentum, ThrustScale
from gainsched.model.reduced import Model
from gainsched.schedule.linearize import (
    discretize,
    expm_batched,
    jacobians,
    lqr_state_names,
    lqr_system,
)
from gainsched.schedule.nominal import circle_nominal


def _extended(config):
    return Model(
        config,
        effects=(
            MotorLag(tau=0.03),
            Drag(mu1=0.172, mu2=0.0025),
            RotorDrag(k_rd=0.02),
            ThrustScale(k_T=0.9),
        ),
    )


@pytest.fixture(scope="module", params=["paper", "extended"])
def model(request, paper_config):
    return Model(paper_config) if request.param == "paper" else _extended(paper_config)


def random_states(rng, n_z, k):
    """Random states around the flight envelope (not on a nominal)."""
    z = np.empty((k, n_z))
    z[:, 0] = np.pi / 2 + rng.normal(0.0, 0.1, k)  # delta
    z[:, 1] = rng.uniform(0.0, 2 * np.pi, k)  # xi
    z[:, 2] = rng.normal(0.0, 0.5, k)  # delta'
    z[:, 3] = rng.uniform(1.0, 9.0, k) * rng.choice([-1.0, 1.0], k)  # xi'
    z[:, 4:7] = rng.normal(0.0, 0.3, (k, 3))  # phi, theta, chi
    z[:, 7:10] = rng.normal(0.0, 3.0, (k, 3))  # omega
    z[:, N_STATE:] = rng.uniform(0.5, 2.5, (k, n_z - N_STATE))  # effect states (thrusts)
    return z


def central_differences(model, z, u, alpha):
    """d f / d (z, u) by central differences, one direction at a time (shape (k, n_z, n_z+4))."""
    x = np.concatenate([z, u], -1)
    n_z = z.shape[-1]
    out = np.empty(z.shape[:-1] + (n_z, x.shape[-1]))
    for j in range(x.shape[-1]):
        h = 1e-6 * np.maximum(1.0, np.abs(x[:, j]))
        xp, xm = x.copy(), x.copy()
        xp[:, j] += h
        xm[:, j] -= h
        fp = model.f(xp[:, :n_z], xp[:, n_z:], alpha)
        fm = model.f(xm[:, :n_z], xm[:, n_z:], alpha)
        out[:, :, j] = (fp - fm) / (2 * h[:, None])
    return out


def test_jacobians_match_central_differences(model):
    rng = np.random.default_rng(20261122)
    k = 12
    z = random_states(rng, model.n_z, k)
    u = rng.uniform(0.3, 3.0, (k, 4))
    alpha = rng.uniform(-0.7, 0.7, k)
    A, B = jacobians(model, z, u, alpha)
    assert A.shape == (k, model.n_z, model.n_z) and B.shape == (k, model.n_z, 4)
    J = np.concatenate([A, B], -1)
    J_cd = central_differences(model, z, u, alpha)
    # relative error per output (row of the Jacobian), over all states and inputs
    err = np.abs(J - J_cd).max(-1) / np.abs(J).max(-1)
    assert err.max() <= 1e-6, f"worst row-relative error {err.max():.3g}"


def test_jacobians_batched_equal_pointwise(model):
    """A batch gives the same Jacobians as one state at a time (no cross-talk between points)."""
    rng = np.random.default_rng(7)
    z = random_states(rng, model.n_z, 3)
    u = rng.uniform(0.3, 3.0, (3, 4))
    alpha = np.array([0.0, 0.3, -0.5])
    A, B = jacobians(model, z, u, alpha)
    for i in range(3):
        Ai, Bi = jacobians(model, z[i], u[i], alpha[i])
        np.testing.assert_allclose(Ai, A[i], rtol=0, atol=1e-12 * np.abs(A[i]).max())
        np.testing.assert_allclose(Bi, B[i], rtol=0, atol=1e-12 * np.abs(B[i]).max())


def test_lqr_system_appends_delta_integrator(model):
    rng = np.random.default_rng(3)
    n_z = model.n_z
    A = rng.normal(size=(2, n_z, n_z))
    B = rng.normal(size=(2, n_z, 4))
    Ax, Bx = lqr_system(A, B)
    n = n_z + 1
    assert Ax.shape == (2, n, n) and Bx.shape == (2, n, 4)
    idx = [i if i < N_STATE else i + 1 for i in range(n_z)]  # z index -> LQR index
    np.testing.assert_array_equal(Ax[:, np.ix_(idx, idx)[0], np.ix_(idx, idx)[1]], A)
    np.testing.assert_array_equal(Bx[:, idx], B)
    expected_row = np.zeros(n)
    expected_row[0] = 1.0  # d/dt (integral of delta error) = delta error
    np.testing.assert_array_equal(Ax[:, N_STATE], np.broadcast_to(expected_row, (2, n)))
    np.testing.assert_array_equal(Ax[:, :, N_STATE], 0.0)
    np.testing.assert_array_equal(Bx[:, N_STATE], 0.0)
    names = lqr_state_names(model)
    assert len(names) == n and names[N_STATE] == "int_delta"


def _rel(E, E_ref):
    return np.linalg.norm(E - E_ref, axis=(-2, -1)) / np.linalg.norm(E_ref, axis=(-2, -1))


@pytest.mark.parametrize("scale", [1e-3, 0.3, 1.0, 4.0])
def test_expm_batched_matches_scipy_random(scale):
    rng = np.random.default_rng(int(scale * 1000) + 11)
    n = 15
    M = rng.normal(size=(6, n, n)) * scale / np.sqrt(n)  # ||M||_2 ~ 2 scale
    E = expm_batched(M)
    E_ref = scipy.linalg.expm(M)
    assert _rel(E, E_ref).max() <= 1e-13


def _real_blocks(config, speed, alpha, dt):
    """ZOH blocks [[A dt, B dt], [0, 0]] of the paper model along a tilted nominal circle."""
    model = Model(config)
    nom = circle_nominal(model, speed, alpha, 16)
    A, B = jacobians(model, nom.z, nom.u, alpha)
    Ax, Bx = lqr_system(A, B)
    n, m = Ax.shape[-1], Bx.shape[-1]
    M = np.zeros(Ax.shape[:-2] + (n + m, n + m))
    M[..., :n, :n] = Ax * dt
    M[..., :n, n:] = Bx * dt
    return M, Ax, Bx


@pytest.mark.parametrize("dt", [1e-3, 0.01, 0.05])
def test_expm_batched_matches_scipy_real_blocks(paper_config, dt):
    """Real linearised blocks at the control step and at 10x and 50x longer steps (1-norms
    2.4, 24, 120: exercises the scaling and squaring). Two correct algorithms differ by
    ~eps ||M|| on these non-normal blocks, so much longer steps would not hold 1e-13."""
    M, _, _ = _real_blocks(paper_config, 12.0, np.deg2rad(30), dt)
    assert _rel(expm_batched(M), scipy.linalg.expm(M)).max() <= 1e-13


def test_discretize_matches_cont2discrete(paper_config):
    dt = paper_config.control.dt
    _, Ax, Bx = _real_blocks(paper_config, 9.0, np.deg2rad(20), dt)
    A, B = Ax[5], Bx[5]
    Ad, Bd = discretize(A, B, dt)
    n = A.shape[0]
    Ad_ref, Bd_ref, *_ = cont2discrete((A, B, np.eye(n), np.zeros((n, 4))), dt, method="zoh")
    assert np.abs(Ad - Ad_ref).max() / np.abs(Ad_ref).max() <= 1e-13
    assert np.abs(Bd - Bd_ref).max() / np.abs(Bd_ref).max() <= 1e-13
    # batched call gives the same as the single block
    Ad_b, Bd_b = discretize(Ax, Bx, dt)
    np.testing.assert_allclose(Ad_b[5], Ad, rtol=0, atol=1e-14 * np.abs(Ad).max())
    np.testing.assert_allclose(Bd_b[5], Bd, rtol=0, atol=1e-14 * np.abs(Bd).max())


@pytest.mark.parametrize("integrators", [(), ("int_delta",), ("int_xi",),
                                         ("int_delta", "int_xi")])
def test_lqr_system_integrals_by_simulation(model, integrators):
    """A second formulation: integrate the augmented continuous system and compare each
    integral state with the quadrature of the reduced state it integrates."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(5)
    n_z = model.n_z
    A = rng.normal(scale=0.3, size=(n_z, n_z))
    B = rng.normal(size=(n_z, 4))
    Ax, Bx = lqr_system(A, B, integrators)
    n_i = len(integrators)
    assert Ax.shape == (n_z + n_i,) * 2
    x0 = np.concatenate([rng.normal(size=N_STATE), np.zeros(n_i), rng.normal(size=n_z - N_STATE)])
    u = rng.normal(size=4)
    t = np.linspace(0, 1, 201)
    sol = solve_ivp(lambda _, x: Ax @ x + Bx @ u, (0, 1), x0, t_eval=t, rtol=1e-11, atol=1e-12)
    z = np.delete(sol.y, np.s_[N_STATE:N_STATE + n_i], axis=0)  # the model's own states
    ref = solve_ivp(lambda _, x: A @ x + B @ u, (0, 1), np.delete(x0, np.s_[N_STATE:N_STATE + n_i]),
                    t_eval=t, rtol=1e-11, atol=1e-12).y
    np.testing.assert_allclose(z, ref, atol=1e-8)
    from scipy.integrate import trapezoid

    for j, name in enumerate(integrators):
        src = {"int_delta": 0, "int_xi": 1}[name]
        assert sol.y[N_STATE + j, -1] == pytest.approx(trapezoid(ref[src], t), abs=1e-4)
    names = lqr_state_names(model, integrators)
    assert names[N_STATE:N_STATE + n_i] == integrators and len(names) == n_z + n_i


@pytest.mark.parametrize("lag", [False, True], ids=["momentum", "momentum_and_lag"])
def test_a_rough_circles_system_through_the_thrust_modifiers_is_the_whole_models(
        paper_config, lag):
    """Issue 39: a circle whose commands are rough (momentum theory's floored inflow, 9 m/s
    and 40 deg) is linearised at every step by the chain rule through the thrust modifiers,
    the model at given thrusts interpolated from a few azimuths: its discrete system equals
    the whole model's complex steps at every step (``discrete_at``) to 1e-9 relative, with
    momentum theory alone and with a motor lag whose states are the modifiers' input."""
    from gainsched.schedule.discrete import discrete_at, discrete_system
    from gainsched.schedule.grid import steps_per_period
    from gainsched.schedule.nominal import circle_is_rough

    effects = (Drag(mu1=0.172, mu2=0.0025), ThrustMomentum(disk_area=0.005986))
    m = Model(paper_config, effects=((MotorLag(tau=0.02979),) if lag else ()) + effects)
    v, a = 9.0, np.deg2rad(40.0)
    N = steps_per_period(v, m.r, paper_config.control.dt)
    dt = 2 * np.pi * m.r / v / N
    assert circle_is_rough(m, v, a)
    Ad, Bd, M, err = discrete_system(m, v, [a], N, dt)
    Ad0, Bd0 = discrete_at(m, v, [a], N, dt)
    assert M == N and 0.0 < err < 1e-10  # the smooth part interpolated
    I = np.eye(Ad.shape[-1])
    assert np.abs(Ad - Ad0).max() < 1e-9 * np.abs(Ad0 - I).max()
    assert np.abs(Bd - Bd0).max() < 1e-9 * np.abs(Bd0).max()
