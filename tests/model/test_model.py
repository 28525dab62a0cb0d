"""Reduced model (gainsched.model.reduced): allocation, 6x6 solve, energy, complex steps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gainsched.model.effects import Drag
from gainsched.model.reduced import allocation_matrix, motor_positions
from gainsched.rotations import matrix_from_euler_zyx


def random_states(rng, n):
    """Random reduced states near the operating envelope, shape (n, 10)."""
    z = np.empty((n, 10))
    z[:, 0] = np.pi / 2 + rng.uniform(-0.4, 0.4, n)  # delta
    z[:, 1] = rng.uniform(-np.pi, np.pi, n)  # xi
    z[:, 2] = rng.uniform(-1.0, 1.0, n)  # delta'
    z[:, 3] = rng.choice([-1, 1], n) * rng.uniform(2.0, 8.0, n)  # xi'
    z[:, 4:7] = rng.uniform(-0.4, 0.4, (n, 3))  # phi, theta, chi
    z[:, 7:10] = rng.uniform(-2.0, 2.0, (n, 3))  # body rates
    return z


# --------------------------------------------------------------------------- (1) allocation


def test_motor_positions_x_layout():
    L = motor_positions(0.17)
    a = 0.17 / np.sqrt(2)  # 0.12021 m
    expected = np.array([[a, a, 0], [-a, a, 0], [-a, -a, 0], [a, -a, 0]])
    np.testing.assert_allclose(L, expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.abs(L[:, :2]), 0.1202, rtol=0, atol=1e-4)


def test_allocation_matrix_matches_cross_products(model, paper_config):
    l, kappa = paper_config.vehicle.arm_length, paper_config.vehicle.kappa
    A = allocation_matrix(l, kappa)
    np.testing.assert_array_equal(A, model.alloc)
    L = motor_positions(l)
    spin = [1.0, -1.0, 1.0, -1.0]  # reaction torque sign per motor (paper eq. 8)
    rng = np.random.default_rng(1)
    for i in range(4):
        T_i = rng.uniform(0.1, 3.5)
        u = np.zeros(4)
        u[i] = T_i
        torque = np.cross(L[i], [0.0, 0.0, T_i]) + [0.0, 0.0, kappa * spin[i] * T_i]
        np.testing.assert_allclose(A @ u, np.concatenate([[T_i], torque]), rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(model.alloc_inv @ A, np.eye(4), rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- (2) 6x6 solve


def _second_derivative_along_flow(model, z0, u, alpha, h=1e-3):
    """p_q'' at t = 0 by a 5-point stencil of p_q(z(t)) with z(t) integrated with model.f.

    Error ~1e-7 m/s^2: truncation O(h^4) (measured: halving h changes the result by
    ~1e-7 at h = 1e-3) plus integration error (rtol = atol = 1e-13) over h^2.
    """
    ts = np.array([-2, -1, 1, 2]) * h
    p = {0: model.cog_position(z0)}
    for sign in (-1, 1):
        t_eval = ts[ts * sign > 0] if sign > 0 else ts[ts < 0][::-1]
        sol = solve_ivp(lambda t, z: model.f(z, u, alpha), (0, sign * 2 * h), z0,
                        method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t_eval)
        for t, z in zip(sol.t, sol.y.T, strict=True):
            p[round(t / h)] = model.cog_position(z)
    return (-p[2] + 16 * p[1] - 30 * p[0] + 16 * p[-1] - p[-2]) / (12 * h * h)


def test_translational_and_rotational_balance(model, paper_config):
    """Newton-Euler residuals with p_q'' differentiated numerically along the model's own flow.

    A second formulation: forces summed directly in C (thrust, gravity, tether along -e,
    drag recomputed from mu1, mu2); torques with np.cross. Tolerance 1e-6 of the force scale.
    """
    rng = np.random.default_rng(2)
    m, J, L_e = model.m, model.J, model.L_e
    mu1, mu2 = (paper_config.effects[0].param_dict()[k] for k in ("mu1", "mu2"))
    L = motor_positions(paper_config.vehicle.arm_length)
    kappa = paper_config.vehicle.kappa
    for z0, u, alpha in zip(random_states(rng, 5), rng.uniform(0.5, 2.5, (5, 4)),
                            rng.uniform(0.0, 0.7, 5), strict=True):
        ev = model.evaluate(z0, u, alpha)
        acc = _second_derivative_along_flow(model, z0, u, alpha)

        R = matrix_from_euler_zyx(z0[4], z0[5], z0[6] + z0[1])
        d, xi = z0[0], z0[1]
        e = np.array([np.sin(d) * np.cos(xi), np.sin(d) * np.sin(xi), np.cos(d)])
        w = z0[7:10]
        # COG velocity by central differences of p_q along the flow
        h = 1e-6
        v = (model.cog_position(z0 + h * ev.z_dot) - model.cog_position(z0 - h * ev.z_dot)) / (
            2 * h
        )
        speed = np.linalg.norm(v)
        gravity = -m * model.g * np.array([0.0, np.sin(alpha), np.cos(alpha)])
        forces = (R @ [0, 0, u.sum()] + gravity - ev.tension * e
                  - (mu1 + mu2 * speed) * v)
        scale = np.abs(m * acc).max()
        assert scale > 1.0
        np.testing.assert_allclose(m * acc, forces, rtol=0, atol=1e-6 * scale)

        # rotational: J w' + w x J w = sum L_i x T_i + tau_M + p_e x R^T F_t
        w_dot = ev.z_dot[7:10]
        p_e = np.array([-L_e, 0.0, 0.0])
        torque = sum(np.cross(L[i], [0, 0, u[i]]) for i in range(4))
        torque = torque + [0, 0, kappa * (u[0] - u[1] + u[2] - u[3])]
        torque = torque + np.cross(p_e, R.T @ (-ev.tension * e))
        lhs = J @ w_dot + np.cross(w, J @ w)
        np.testing.assert_allclose(lhs, torque, rtol=0, atol=1e-12 * max(1.0, scale))


# --------------------------------------------------------------------------- (3) energy


@pytest.mark.slow
def test_energy_conserved_without_thrust_and_drag(model_nodrag):
    """Zero thrust, no drag, alpha = 0.3 rad: relative energy drift <= 1e-6 over 2 s.

    xi' = 8 rad/s keeps the tether taut (m r xi'^2 = 51 N >> m g = 4.9 N); asserted.
    """
    md = model_nodrag
    alpha = 0.3
    phi = 0.2  # body rates near the co-rotating ones (0, xi' sin phi, xi' cos phi), eq. 15
    z0 = np.array([np.pi / 2, 0.3, 0.1, 8.0, phi, 0.0, 0.0, 0.3, 8 * np.sin(phi), 8 * np.cos(phi)])
    u = np.zeros(4)
    sol = solve_ivp(lambda t, z: md.f(z, u, alpha), (0.0, 2.0), z0, method="DOP853",
                    rtol=1e-12, atol=1e-12, dense_output=True)
    assert sol.success
    zs = sol.sol(np.linspace(0.0, 2.0, 401)).T
    E = md.energy(zs, alpha)
    assert np.abs(E - E[0]).max() / abs(E[0]) <= 1e-6
    assert md.evaluate(zs, np.zeros((len(zs), 4)), alpha).tension.min() > 0
    # and the test can fail: drag dissipates energy
    drag = type(md)(md.config, effects=(Drag(mu1=0.172, mu2=0.0025),))
    sol = solve_ivp(lambda t, z: drag.f(z, u, alpha), (0.0, 1.0), z0, method="DOP853",
                    rtol=1e-8, atol=1e-8)
    assert drag.energy(sol.y[:, -1], alpha) < 0.9 * E[0]


# --------------------------------------------------------------------------- (4) complex step


def test_complex_step_matches_central_differences(model):
    """Im f(z + i h e_j) / h equals the central difference to 1e-6 (relative to the column)."""
    rng = np.random.default_rng(4)
    for z, u in zip(random_states(rng, 3), rng.uniform(0.5, 2.5, (3, 4)), strict=True):
        alpha = 0.35
        for j in range(10):
            ej = np.zeros(10)
            ej[j] = 1.0
            cs = model.f(z + 1j * 1e-30 * ej, u, alpha).imag / 1e-30
            h = 1e-6
            cd = (model.f(z + h * ej, u, alpha) - model.f(z - h * ej, u, alpha)) / (2 * h)
            scale = max(1.0, np.abs(cs).max())
            np.testing.assert_allclose(cs, cd, rtol=0, atol=1e-6 * scale)
        for j in range(4):  # and with respect to the inputs
            ej = np.zeros(4)
            ej[j] = 1.0
            cs = model.f(z, u + 1j * 1e-30 * ej, alpha).imag / 1e-30
            h = 1e-6
            cd = (model.f(z, u + h * ej, alpha) - model.f(z, u - h * ej, alpha)) / (2 * h)
            np.testing.assert_allclose(cs, cd, rtol=0, atol=1e-6 * max(1.0, np.abs(cs).max()))


def test_batched_evaluation_equals_loop(model):
    rng = np.random.default_rng(5)
    Z, U = random_states(rng, 6), rng.uniform(0.5, 2.5, (6, 4))
    ev = model.evaluate(Z, U, 0.2)
    for k in range(6):
        one = model.evaluate(Z[k], U[k], 0.2)
        np.testing.assert_allclose(ev.z_dot[k], one.z_dot, rtol=1e-13, atol=1e-13)
        assert ev.tension[k] == pytest.approx(one.tension, rel=1e-13)


def test_the_eliminated_tether_system_is_the_dense_solve(model):
    """Issue 39: the equations of motion solved by eliminating the body rates and Cramer's
    rule (`Model._tether_solve`) equal the dense 6 x 6 solve of the same system (paper
    eqs. 3-8 with p_t = rho e), real and under a complex step, to 1e-12 relative."""
    from gainsched._vec import cross, mtv
    from gainsched.model.geometry import tether_direction
    from gainsched.rotations import matrix_from_euler_zyx, skew

    rng = np.random.default_rng(7)
    z = random_states(rng, 40) + 1j * 1e-20 * rng.normal(size=(40, 10))
    R = matrix_from_euler_zyx(z[:, 4], z[:, 5], z[:, 6] + z[:, 1])
    d = tether_direction(z[:, 0], z[:, 1])
    e_B = mtv(R, d.e)
    rhs_F, rhs_tau = rng.normal(size=(2, 40, 3)) * 10
    m, mr = model.m, model.m * model.rho
    A = np.zeros((40, 6, 6), dtype=complex)
    A[:, :3, 0], A[:, :3, 1] = mr * d.e_delta, mr * d.e_xi
    A[:, :3, 2:5] = m * R @ skew(model.p_e)
    A[:, :3, 5] = d.e
    A[:, 3:, 2:5] = model.J
    A[:, 3:, 5] = cross(model.p_e, e_B)
    dense = np.linalg.solve(A, np.concatenate([rhs_F, rhs_tau], -1)[..., None])[..., 0]
    got = model._tether_solve(R, d, e_B, rhs_F, rhs_tau)
    for part in (np.real, np.imag):
        want = part(dense)
        np.testing.assert_allclose(part(got), want, rtol=0, atol=1e-12 * np.abs(want).max())
    assert np.abs(np.imag(dense)).max() > 0  # the complex step does reach the solution
