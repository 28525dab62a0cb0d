"""Maximal coordinates (gainsched.model.maximal) agree with the reduced model where both apply."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gainsched.config import N_STATE, EffectSpec
from gainsched.errors import GainschedWarning
from gainsched.model.effects import EFFECTS, MotorLag
from gainsched.model.maximal import (
    LINKS,
    MaximalModel,
    maximal_from_reduced,
    reduced_from_maximal,
)
from gainsched.model.reduced import Model
from gainsched.rotations import matrix_from_quaternion
from gainsched.sim._plant import _Plant

from support import CIRCLE_TILT as TILT

K_STIFF = 1e6  # N/m
C_STIFF = 2 * np.sqrt(K_STIFF * 0.5)  # N s/m, critical for the 0.5 kg vehicle on the spring


def random_states(rng, n):
    """Random reduced states with xi in (-pi, pi) and |theta| < pi/2, shape (n, 10)."""
    z = np.empty((n, 10))
    z[:, 0] = rng.uniform(0.3, np.pi - 0.3, n)
    z[:, 1] = rng.uniform(-3.1, 3.1, n)
    z[:, 2:4] = rng.uniform(-8.0, 8.0, (n, 2))
    z[:, 4] = rng.uniform(-3.0, 3.0, n)
    z[:, 5] = rng.uniform(-1.4, 1.4, n)
    z[:, 6] = rng.uniform(-3.0, 3.0, n)
    z[:, 7:10] = rng.uniform(-5.0, 5.0, (n, 3))
    return z


def prestretched(model, x, u, alpha, k):
    """Move the COG outward by the static stretch f_t / k (the spring starts near equilibrium)."""
    f_t = MaximalModel(model, "rigid").tension(x, u, alpha)
    R = matrix_from_quaternion(x[6:10])
    p_t = x[:3] + R @ model.p_e
    out = x.copy()
    out[:3] += p_t / np.linalg.norm(p_t) * f_t / k
    return out


def lagged(model, tau=0.03):
    """The same vehicle with a first-order motor lag of ``tau`` s behind its effects."""
    return Model(model.config, effects=(*model.effects, MotorLag(tau=tau)))


def rigid_maximal_equals_reduced(md, z, u, alpha=0.3):
    """The rigid maximal model of ``md`` at the reduced state ``z`` has the reduced model's
    tension and omega' (to 1e-9 of their scale); returns ``(evaluation, x_dot)``."""
    mx = MaximalModel(md, "rigid")
    ev = md.evaluate(z, u, alpha)
    x_dot, f_t = mx.evaluate(mx.from_reduced(z), u, alpha)
    assert abs(f_t - ev.tension) <= 1e-9 * abs(ev.tension)
    np.testing.assert_allclose(x_dot[10:13], ev.z_dot[7:10], rtol=0,
                               atol=1e-9 * np.abs(ev.z_dot[7:10]).max())
    return ev, x_dot


def simulate_both(model, mx, z0, u_fn, alpha, t_end=1.0, method="DOP853", rtol=1e-11):
    """COG positions (m) of the reduced and the maximal run on a common time grid (z0 of
    the model's n_z: the effect states start where the reduced model's do)."""
    ts = np.linspace(0.0, t_end, 201)
    red = solve_ivp(lambda t, z: model.f(z, u_fn(t), alpha), (0, t_end), z0, method="DOP853",
                    rtol=1e-11, atol=1e-11, t_eval=ts)
    x0 = np.concatenate([maximal_from_reduced(model, z0), z0[N_STATE:]])
    if mx.link == "spring-damper":
        x0 = prestretched(model, x0, u_fn(0.0), alpha, mx.k)
    mxs = solve_ivp(lambda t, x: mx.f(x, u_fn(t), alpha), (0, t_end), x0, method=method,
                    rtol=rtol, atol=rtol, t_eval=ts)
    assert red.success and mxs.success
    return ts, model.cog_position(red.y.T), mxs.y.T, red.y.T


# --------------------------------------------------------------------------- conversions


def test_round_trip_reduced_maximal_reduced(model):
    rng = np.random.default_rng(11)
    z = random_states(rng, 200)
    x = maximal_from_reduced(model, z)
    assert x.shape == (200, 13)
    np.testing.assert_allclose(np.linalg.norm(x[:, 6:10], axis=1), 1.0, rtol=0, atol=1e-15)
    back = reduced_from_maximal(model, x)
    np.testing.assert_allclose(back, z, rtol=0, atol=1e-12)
    # one state at a time (unbatched) and the xi branch
    np.testing.assert_allclose(reduced_from_maximal(model, x[0]), z[0], rtol=0, atol=1e-12)
    far = reduced_from_maximal(model, x[:5], xi_ref=z[:5, 1] + 20 * np.pi)
    np.testing.assert_allclose(far[:, 1] - z[:5, 1], 20 * np.pi, rtol=0, atol=1e-12)


def test_one_state_with_its_branch_takes_the_scalar_path_to_the_batched_values(model):
    """One state and its xi branch (what the per-step plants convert at every control
    step) take scalar math: the batched conversion's values to a few ulp (the scalar
    atan2 of the pose angles against numpy's, through the rates' division by sin(delta)^2),
    on elastic links' stretched states and off the rigid constraint, and on the branch
    asked for."""
    rng = np.random.default_rng(12)
    z = random_states(rng, 300)
    x = maximal_from_reduced(model, z, stretch=rng.uniform(-0.01, 0.05, 300))
    x = x + 1e-3 * rng.standard_normal(x.shape)
    ref = z[:, 1] + 2 * np.pi * rng.integers(-3, 4, 300)
    batched = reduced_from_maximal(model, x, xi_ref=ref)
    one = np.array([reduced_from_maximal(model, xk, xi_ref=rk)
                    for xk, rk in zip(x, ref, strict=True)])
    np.testing.assert_allclose(one, batched, rtol=4e-15, atol=2e-14)
    assert np.all(np.abs(one[:, 1] - ref) <= np.pi)


def test_maximal_state_geometry(model):
    """The attachment point of the converted state is at rho e(delta, xi); v is the COG velocity."""
    rng = np.random.default_rng(12)
    z = random_states(rng, 20)
    x = maximal_from_reduced(model, z)
    R = matrix_from_quaternion(x[:, 6:10])
    p_t = x[:, :3] + R @ model.p_e
    e = np.stack([np.sin(z[:, 0]) * np.cos(z[:, 1]), np.sin(z[:, 0]) * np.sin(z[:, 1]),
                  np.cos(z[:, 0])], -1)
    np.testing.assert_allclose(p_t, model.rho * e, rtol=0, atol=1e-14)
    np.testing.assert_allclose(x[:, :3], model.cog_position(z), rtol=0, atol=1e-14)
    h = 1e-6
    zd = model.f(z, np.ones(4), 0.3)
    v_fd = (model.cog_position(z + h * zd) - model.cog_position(z - h * zd)) / (2 * h)
    np.testing.assert_allclose(x[:, 3:6], v_fd, rtol=0, atol=1e-7)


# --------------------------------------------------------------------------- instantaneous


@pytest.mark.parametrize("lag", [False, True], ids=["drag", "drag+motor_lag"])
def test_rigid_link_matches_reduced_accelerations(model, lag):
    """At random taut states: same tension, same COG acceleration, same omega'; with a
    motor lag (issue 59) its states (random thrusts, not the commands) after the rigid
    body's, with the reduced model's rates.

    The COG acceleration of the reduced model is the central difference (h = 1e-6) of the
    COG velocity along z' (error ~1e-9 relative); tolerance 1e-7 of the scale.
    """
    rng = np.random.default_rng(13)
    z = random_states(rng, 50)
    u = rng.uniform(0.2, 3.0, (50, 4))
    alpha = 0.4
    if lag:
        model = lagged(model)
        z = np.concatenate([z, rng.uniform(0.2, 3.0, (50, 4))], -1)
    mx = MaximalModel(model, "rigid")
    ev = model.evaluate(z, u, alpha)
    x = mx.from_reduced(z)
    assert x.shape == (50, 13 + model.n_extra) and mx.n_x == x.shape[-1]
    x_dot, f_t = mx.evaluate(x, u, alpha)
    np.testing.assert_array_equal(x_dot[:, 13:], ev.z_dot[:, N_STATE:])
    if lag:  # the lag's thrusts, not the commands, push: the commands' tension differs
        assert np.abs(Model(model.config).evaluate(z[:, :N_STATE], u, alpha).tension
                      - ev.tension).max() > 0.1
    np.testing.assert_allclose(f_t, ev.tension, rtol=0, atol=1e-9 * np.abs(ev.tension).max())
    h = 1e-6
    a_fd = (maximal_from_reduced(model, z[:, :N_STATE] + h * ev.z_dot[:, :N_STATE])[:, 3:6]
            - maximal_from_reduced(model, z[:, :N_STATE] - h * ev.z_dot[:, :N_STATE])[:, 3:6]
            ) / (2 * h)
    np.testing.assert_allclose(x_dot[:, 3:6], a_fd, rtol=0, atol=1e-7 * np.abs(a_fd).max())
    np.testing.assert_allclose(x_dot[:, 10:13], ev.z_dot[:, 7:10], rtol=0, atol=1e-9)
    np.testing.assert_allclose(x_dot[:, 0:3], x[:, 3:6], rtol=0, atol=0)
    # a single state evaluates like the batch
    one = mx.evaluate(x[3], u[3], alpha)
    np.testing.assert_allclose(one[0], x_dot[3], rtol=1e-13, atol=1e-12)


def test_spring_damper_is_tension_only(model):
    """Slack (inside the sphere, or stretched but retracting fast enough): zero tension."""
    rng = np.random.default_rng(14)
    z = random_states(rng, 10)
    z[:, 2:4] = 0.0  # attachment point at rest relative to the anchor (rate term 0 below)
    z[:, 7:10] = 0.0
    x = maximal_from_reduced(model, z)
    mx = MaximalModel(model, "spring-damper", stiffness=1e4, damping=10.0)
    R = matrix_from_quaternion(x[:, 6:10])
    n = (x[:, :3] + R @ model.p_e) / model.rho
    u = np.full((10, 4), 1.0)
    for shift in (-1e-3, -0.2):  # inside the sphere: slack
        xs = x.copy()
        xs[:, :3] += shift * n
        assert np.all(mx.tension(xs, u, 0.3) == 0.0)
        acc = mx.f(xs, u, 0.3)[:, 3:6]  # free flight: thrust + gravity + drag (v = 0)
        free = (R[:, :, 2] * 4.0 + model.m * model.g_C(0.3)) / model.m
        np.testing.assert_allclose(acc, free, rtol=0, atol=1e-12)
    xs = x.copy()
    xs[:, :3] += 1e-3 * n  # stretched 1 mm, at rest: k * stretch
    np.testing.assert_allclose(mx.tension(xs, u, 0.3), 10.0, rtol=1e-9)
    xs[:, 3:6] -= 2.0 * n  # retracting at 2 m/s: 10 - 10 * 2 < 0 -> slack
    assert np.all(mx.tension(xs, u, 0.3) == 0.0)
    # the rigid link keeps its bilateral multiplier (can be negative when pushed)
    assert np.all(np.isfinite(MaximalModel(model, "rigid").tension(xs, u, 0.3)))


def test_an_unknown_link_is_refused(paper_config):
    with pytest.raises(ValueError, match="link"):
        MaximalModel(Model(paper_config), link="bungee")


def test_effect_states_sit_between_the_rigid_body_and_the_link(model):
    """x = (rigid body 13, effect states, link states): a lag on the chain link starts at
    rest at the commands and its nodes follow; the link reads its own states."""
    md = lagged(model)
    mx = MaximalModel(md, "lumped-mass")
    z = random_states(np.random.default_rng(3), 4)
    u = np.array([1.1, 1.2, 1.3, 1.4])
    x = mx.from_reduced(z, tension=20.0, u=u)
    assert mx.i_link == 17 and x.shape == (4, mx.n_x) and mx.n_link > 0
    np.testing.assert_array_equal(x[:, 13:17], np.broadcast_to(u, (4, 4)))
    x_dot = mx.f(x, u, 0.2)
    np.testing.assert_array_equal(x_dot[:, 13:17], 0.0)  # at rest at the commands
    assert np.all(np.isfinite(x_dot[:, 17:])) and mx.tension(x, u, 0.2).min() > 0


# --------------------------------------------------------------------------- trajectories


@pytest.mark.parametrize("perturbed", [False, True], ids=["nominal", "perturbed"])
def test_rigid_trajectory_agrees(model, circle, perturbed):
    """1 s open loop on the 8 m/s, 20 deg circle with u_d(t): COG difference <= 1 mm.

    (Measured ~1e-12 m; the constraint drift |p_t| - rho stays below 1e-9 m.)
    """
    nom, u_fn = circle
    z0 = nom.z[0].copy()
    if perturbed:
        rng = np.random.default_rng(21)
        z0 += np.concatenate(
            [rng.normal(0, 0.02, 4), rng.normal(0, 0.05, 3), rng.normal(0, 0.3, 3)]
        )
    mx = MaximalModel(model, "rigid")
    ts, p_red, xs, zs = simulate_both(model, mx, z0, u_fn, TILT)
    assert np.abs(p_red - xs[:, :3]).max() <= 1e-3
    assert np.abs(p_red - xs[:, :3]).max() <= 1e-8  # far tighter in practice
    R = matrix_from_quaternion(xs[:, 6:10])
    dist = np.linalg.norm(xs[:, :3] + R @ model.p_e, axis=1)
    assert np.abs(dist - model.rho).max() <= 1e-9
    assert model.evaluate(zs, u_fn(ts), TILT).tension.min() > 0
    # and the comparison can fail: the COG moved far over the second
    assert np.abs(p_red - p_red[0]).max() > 1.0
    back = reduced_from_maximal(model, xs, xi_ref=zs[:, 1])
    np.testing.assert_allclose(back, zs, rtol=0, atol=1e-7)


@pytest.mark.slow
@pytest.mark.parametrize("perturbed,lag", [(False, False), (True, False), (True, True)],
                         ids=["nominal", "perturbed", "perturbed+motor_lag"])
def test_stiff_spring_trajectory_agrees(model, circle, perturbed, lag):
    """k = 1e6 N/m, critical damping: COG difference <= 1 mm over 1 s; with a 30 ms motor
    lag in both models too (issue 59: its thrusts start at the commands and lag them).

    The spring's fast mode (|lambda| ~ 1.4e3 1/s) makes DOP853 stability-limited
    (~5e4 evaluations); Radau, an L-stable implicit method, is used instead.
    The difference is dominated by the stretch f_t / k ~ 2e-5 m (measured 7.5e-5 m).
    """
    nom, u_fn = circle
    z0 = nom.z[0].copy()
    if perturbed:
        rng = np.random.default_rng(22)
        z0 += np.concatenate(
            [rng.normal(0, 0.02, 4), rng.normal(0, 0.05, 3), rng.normal(0, 0.3, 3)]
        )
    if lag:
        model = lagged(model)
        z0 = np.concatenate([z0, u_fn(0.0)])
    mx = MaximalModel(model, "spring-damper", stiffness=K_STIFF, damping=C_STIFF)
    ts, p_red, xs, zs = simulate_both(model, mx, z0, u_fn, TILT, method="Radau", rtol=1e-9)
    assert np.abs(p_red - xs[:, :3]).max() <= 1e-3
    if lag:  # the lag's thrusts (N) follow the same commands in both: equal to the
        # solver's rtol (measured 7e-11 N; the COG difference with the lag 7.2e-5 m, as
        # without it)
        assert np.abs(xs[:, 13:13 + model.n_extra] - zs[:, N_STATE:]).max() <= 1e-6
    f_t = mx.tension(xs, u_fn(ts), TILT)
    assert f_t.min() > 5.0  # taut throughout: the comparison is meaningful
    R = matrix_from_quaternion(xs[:, 6:10])
    stretch = np.linalg.norm(xs[:, :3] + R @ model.p_e, axis=1) - model.rho
    np.testing.assert_allclose(stretch, f_t / K_STIFF, rtol=0.05, atol=2e-6)


def test_rigid_energy_conserved(model_nodrag):
    """Maximal rigid link, zero thrust, no drag: relative energy drift <= 1e-6 over 1 s."""
    md = model_nodrag
    mx = MaximalModel(md, "rigid")
    phi = 0.2
    z0 = np.array([np.pi / 2, 0.3, 0.1, 8.0, phi, 0.0, 0.0, 0.3, 8 * np.sin(phi), 8 * np.cos(phi)])
    x0 = maximal_from_reduced(md, z0)
    sol = solve_ivp(lambda t, x: mx.f(x, np.zeros(4), 0.3), (0.0, 1.0), x0, method="DOP853",
                    rtol=1e-12, atol=1e-12, dense_output=True)
    xs = sol.sol(np.linspace(0.0, 1.0, 101)).T
    E = mx.energy(xs, 0.3)
    assert np.abs(E - E[0]).max() / abs(E[0]) <= 1e-6
    np.testing.assert_allclose(E[0], md.energy(z0, 0.3), rtol=1e-14)


def test_rigid_link_matches_reduced_accelerations_in_a_wind(paper_config):
    """Issue 37: both formulations in a wind (drag, rotor drag, momentum theory beside it)
    at random headings: the same tension, COG acceleration and omega' (the reduced model's
    acceleration through its exact Jacobian-free identity: maximal state rate at z')."""
    from gainsched.config import config_from_text, set_values
    from gainsched.model.reduced import Model

    text = set_values(paper_config.text, {"effects.wind.east": 3.0, "effects.wind.north": -2.0,
                                          "effects.rotor_drag.k_rd": 0.02,
                                          "effects.thrust_momentum.disk_area": 0.006})
    model = Model(config_from_text(text, "windy.toml"))
    assert model.wind_I is not None
    rng = np.random.default_rng(17)
    z = random_states(rng, 40)
    u = rng.uniform(0.2, 3.0, (40, 4))
    alpha, gamma = rng.uniform(-0.7, 0.7, 40), rng.uniform(-np.pi, np.pi, 40)
    mx = MaximalModel(model, "rigid")
    ev = model.evaluate(z, u, alpha, gamma)
    x = maximal_from_reduced(model, z)
    x_dot, f_t = mx.evaluate(x, u, alpha, gamma)
    np.testing.assert_allclose(f_t, ev.tension, rtol=0, atol=1e-9 * np.abs(ev.tension).max())
    h = 1e-6
    a_fd = (maximal_from_reduced(model, z[:, :N_STATE] + h * ev.z_dot[:, :N_STATE])[:, 3:6]
            - maximal_from_reduced(model, z[:, :N_STATE] - h * ev.z_dot[:, :N_STATE])[:, 3:6]
            ) / (2 * h)
    np.testing.assert_allclose(x_dot[:, 3:6], a_fd, rtol=0, atol=1e-7 * np.abs(a_fd).max())
    np.testing.assert_allclose(x_dot[:, 10:13], ev.z_dot[:, 7:10], rtol=0, atol=1e-9)
    calm = mx.evaluate(x, u, alpha, gamma + 1.0)[0]  # another heading, another wind in C
    assert np.abs(calm[:, 3:6] - x_dot[:, 3:6]).max() > 1e-2


def test_wind_model_is_complex_step_safe(paper_config):
    """The model in a wind takes complex-step Jacobians (as the linearisation does): they
    equal central differences."""
    from gainsched.config import config_from_text, set_values
    from gainsched.model.reduced import Model

    text = set_values(paper_config.text, {"effects.wind.east": 3.0, "effects.wind.north": 1.0})
    model = Model(config_from_text(text, "windy.toml"))
    rng = np.random.default_rng(3)
    z, u = random_states(rng, 1)[0], rng.uniform(0.5, 2.5, 4)
    for j in range(10):
        dz = np.zeros(10)
        dz[j] = 1.0
        cs = np.imag(model.f(z + 1e-30j * dz, u, 0.3, 0.8)) / 1e-30
        fd = (model.f(z + 1e-6 * dz, u, 0.3, 0.8) - model.f(z - 1e-6 * dz, u, 0.3, 0.8)) / 2e-6
        np.testing.assert_allclose(cs, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("kind", sorted(EFFECTS))
def test_every_library_effect_flies_on_every_link(paper_config, kind):
    """Issue 59: the simulator's plant takes every library effect (its default parameters,
    beside the paper's drag) on every tether link: the state holds the effect's states
    after the rigid body's and the link's after them, a 10 us step is finite, and the
    maximal model with the rigid link has the reduced model's tension, omega' and effect
    state rates at the same state (to 1e-9 of their scale)."""
    cfg = dataclasses.replace(paper_config, effects=(*paper_config.effects, EffectSpec(kind, ())))
    md = Model(cfg)
    z = np.array([np.pi / 2, 0.3, 0.05, 6.0, -0.6, 0.05, 0.02, 0.1, -0.2, 6.0])
    u = np.array([1.4, 1.5, 1.6, 1.5])
    zf = np.concatenate([z, md.steady_effect_states(u)])
    for link in LINKS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GainschedWarning)  # the numpy plant's note
            P = _Plant(dataclasses.replace(cfg, tether=dataclasses.replace(cfg.tether,
                                                                           link=link)))
        x = P.initial(z, u)
        n_link = 0 if P.maximal is None else P.maximal.n_link
        base = N_STATE if P.maximal is None else 13
        assert x.shape == (base + md.n_extra + n_link,), (link, x.shape)
        np.testing.assert_array_equal(x[base:base + md.n_extra], zf[N_STATE:])
        x_next, ten = P.step(x, u, 0.3, 1e-5)  # the chain's stiff nodes: ~1300 substeps/ms
        assert np.all(np.isfinite(x_next)) and ten > 0, link
    ev, x_dot = rigid_maximal_equals_reduced(md, zf, u)
    np.testing.assert_array_equal(x_dot[13:], ev.z_dot[N_STATE:])


def test_a_cog_offset_moves_every_lever_and_the_markers(paper_config):
    """Issue 53: the centre of mass d = (2, 3, -2) mm from the frame centre. Closed forms:
    the thrusts' torque about the COG is ``sum (L_i - d) x T_i e_z`` (np.cross of the hub
    positions) plus kappa's, i.e. the frame centre's minus ``d x T e_z``; the tether's lever
    is ``(p_e - d) x n_B``. A second formulation: the rigid maximal model (COG state) has
    the reduced model's tension and omega' to 1e-9. The compiled plant steps as the numpy
    one (1e-12 relative), and the pose the sensors see is the frame centre: the COG minus
    ``R_CB d``, whose attachment point (``p_e_frame`` from it) is the COG's (``p_e`` from
    it), on the sphere of radius rho on the rigid link."""
    from gainsched.model.reduced import motor_positions

    d = np.array([0.002, 0.003, -0.002])
    cfg = dataclasses.replace(paper_config, effects=(*paper_config.effects, EffectSpec(
        "cog_offset", tuple(zip("xyz", map(float, d), strict=True)))))
    md, md0 = Model(cfg), Model(paper_config)
    np.testing.assert_array_equal(md.cog_offset, d)
    np.testing.assert_allclose(md.p_e, md0.p_e - d, rtol=0, atol=1e-15)
    T = np.array([1.4, 1.5, 1.6, 1.5])
    hubs = motor_positions(paper_config.vehicle.arm_length) - d
    tau = np.cross(hubs, T[:, None] * np.array([0.0, 0.0, 1.0])).sum(0)
    tau[2] += paper_config.vehicle.kappa * (T[0] - T[1] + T[2] - T[3])
    np.testing.assert_allclose(T @ md.alloc[1:].T, tau, rtol=0, atol=1e-15)
    np.testing.assert_allclose(T @ md.alloc[1:].T - T @ md0.alloc[1:].T,
                               -np.cross(d, [0.0, 0.0, T.sum()]), rtol=0, atol=1e-15)
    n_B = np.array([0.6, -0.48, 0.64])
    np.testing.assert_allclose(md.tether_lever(n_B), np.cross(md0.p_e - d, n_B), atol=1e-15)

    z = np.array([np.pi / 2, 0.3, 0.05, 6.0, -0.6, 0.05, 0.02, 0.1, -0.2, 6.0])
    ev = rigid_maximal_equals_reduced(md, z, T)[0]
    assert np.abs(ev.z_dot[7:10] - md0.evaluate(z, T, 0.3).z_dot[7:10]).max() > 1.0  # rad/s^2

    for link in ("rigid", "spring-damper"):
        P = _Plant(dataclasses.replace(cfg, tether=dataclasses.replace(cfg.tether, link=link)))
        if P.fast is None:
            pytest.skip("no C compiler for the compiled plant")
        x = P.initial(z, T)
        fast = P.step(x, T, 0.3, 1e-3)[0]
        P.fast = None
        np.testing.assert_allclose(fast, P.step(x, T, 0.3, 1e-3)[0], rtol=1e-12, atol=1e-12)
        p_I, R_IB = P.pose(x, 0.3, 0.0)
        R_IC = R_IB @ np.linalg.inv(P.pose(x, 0.0, 0.0)[1])  # the tilt's turn
        cog_C = md.cog_position(z) if P.maximal is None else x[:3]
        R_CB = R_IC.T @ R_IB
        np.testing.assert_allclose(R_IC.T @ p_I, cog_C - R_CB @ d, rtol=0, atol=1e-12)
        attach = R_IC.T @ p_I + R_CB @ md.p_e_frame  # the one point of both frames
        np.testing.assert_allclose(attach, cog_C + R_CB @ md.p_e, rtol=0, atol=1e-12)
        if link == "rigid":
            assert abs(np.linalg.norm(attach) - md.rho) <= 1e-12
        np.testing.assert_allclose(P.sensors(x, T, 0.3, 0.0)[0], p_I, rtol=0, atol=1e-12)
