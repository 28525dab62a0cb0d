"""The numerical trim (gainsched.schedule.trim) against the closed form
(gainsched.schedule.closedform).

On a drag-only model both apply: the closed form (paper eqs. 15-18, eq. 17 typo
corrected) is the independent reference for the trim's Fourier collocation
(constant-speed circles) and its spline collocation (speed-up, braking).
"""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.schedule.closedform import closed_form
from gainsched.schedule.path import circle_path, maneuver_path, period
from gainsched.schedule.trim import trim_path

from support import IMPROVED, paper_model


@pytest.mark.parametrize("speed, tilt_deg", [(4.0, 0.0), (9.0, 20.0), (-12.0, 35.0)])
def test_trim_equals_closed_form_on_circles(model, speed, tilt_deg):
    alpha = np.deg2rad(tilt_deg)
    t = np.arange(64) * (period(speed, model.r) / 64)
    path = circle_path(speed, model.r, t)
    z, z_dot, u, tension = trim_path(model, path, alpha, periodic=True)
    s, s_dot, u_ref, tension_ref = closed_form(model, path, alpha, model.closed_form_drag())
    np.testing.assert_allclose(z, s, rtol=0, atol=1e-9)
    np.testing.assert_allclose(z_dot, s_dot, rtol=0, atol=1e-8)
    np.testing.assert_allclose(u, u_ref, rtol=0, atol=1e-8)  # N
    np.testing.assert_allclose(tension, tension_ref, rtol=1e-10, atol=1e-9)  # N


@pytest.mark.parametrize("v0, v1, a", [(2.0, 11.3, 6.25), (11.3, 1.0, 8.75)])
def test_trim_equals_closed_form_on_maneuvers(model, v0, v1, a):
    """Paper eq. 20 speed-up and braking (Sec. V): the spline collocation. The snap
    (fourth derivative of xi) of eq. 20 jumps by 4 a omega^2 where the manoeuvre starts
    and ends, which a quintic spline cannot follow: the thrusts there are off by up to
    0.04 N, within 0.1 s of the kinks; everywhere else the trim is the closed form to
    1e-7 N."""
    t = np.linspace(0.0, 2.5, 400)
    t0, dur = 0.3, abs(v1 - v0) / a
    path = maneuver_path(v0, v1, a, model.r, t, t_start=t0)
    z, _, u, tension = trim_path(model, path, 0.0, periodic=False)
    s, _, u_ref, tension_ref = closed_form(model, path, 0.0, model.closed_form_drag())
    far = (np.abs(t - t0) > 0.1) & (np.abs(t - t0 - dur) > 0.1)
    assert np.abs(z[far, 4] - s[far, 4]).max() < 1e-12  # roll, rad
    assert np.abs(u[far] - u_ref[far]).max() < 1e-7  # N
    assert np.abs(u - u_ref).max() < 0.05  # N, at the kinks
    np.testing.assert_allclose(tension, tension_ref, rtol=1e-8, atol=1e-8)


def test_trim_satisfies_the_model(model):
    """The trim's nominal is an equilibrium of the full model along the path (to 1e-9)."""
    speed, alpha = 8.0, np.deg2rad(25.0)
    t = np.arange(48) * (period(speed, model.r) / 48)
    path = circle_path(speed, model.r, t)
    z, z_dot, u, _ = trim_path(model, path, alpha, periodic=True)
    f = model.f(z, u, alpha)
    assert np.abs(f - z_dot).max() < 1e-8


def _collocation_jacobian(Jl, D1, D2):
    """The dense (5n, 5n) Jacobian of all node residuals in (phi nodes, T1 nodes, ...,
    T4 nodes) from the local partials ``Jl`` (n, 5, >= 7) and the differentiation
    operators: the system the trim's Newton solved directly before issue 39."""
    n = Jl.shape[0]
    J = np.zeros((5 * n, 5 * n))
    for i in range(5):
        rows = slice(i * n, (i + 1) * n)
        J[rows, :n] = np.diag(Jl[:, i, 0]) + Jl[:, i, 1, None] * D1 + Jl[:, i, 2, None] * D2
        for j in range(4):
            J[rows, n * (1 + j) : n * (2 + j)] = np.diag(Jl[:, i, 3 + j])
    return J


@pytest.mark.parametrize("k", [None, 3])
def test_the_eliminated_newton_step_is_the_dense_solve(k):
    """Issue 39: the Newton step with the thrusts eliminated node by node equals the dense
    (5n, 5n) solve of the collocation Jacobian (a second formulation, to 1e-9 relative),
    for one right-hand side and for several (the offsets' sensitivities)."""
    from gainsched.schedule.trim import fourier_operators, newton_step

    rng = np.random.default_rng(0)
    n = 32
    D1, D2 = fourier_operators(n, 0.7)
    Jl = rng.normal(size=(n, 5, 7))
    Jl[:, :, 0] += 5.0  # a well-posed system, as the trim's
    res = rng.normal(size=(n, 5) if k is None else (n, 5, k))
    d_phi, d_T = newton_step(Jl, D1, D2, res)
    dense = np.linalg.solve(_collocation_jacobian(Jl, D1, D2),
                            res.transpose(1, 0, *range(2, res.ndim)).reshape(5 * n, -1))
    scale = np.abs(dense).max()
    np.testing.assert_allclose(d_phi.reshape(n, -1), dense[:n], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(d_T.reshape(n, 4, -1).transpose(1, 0, 2).reshape(4 * n, -1),
                               dense[n:], rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("n_out", [7, 36, 128, 1024])
def test_equal_step_samples_of_the_interpolant_are_its_general_evaluation(n_out):
    """Issue 39: the interpolant at the equal steps of one period by one folded inverse FFT
    (`fourier_samples`, aliasing exactly where the steps are fewer than the nodes)
    equals its evaluation as a sum of complex exponentials at those times, value and two
    derivatives, to 1e-13 relative."""
    from gainsched.schedule.trim import _fourier_eval, fourier_samples

    rng = np.random.default_rng(2)
    T = 1.7
    values = rng.normal(size=(5, 128))
    ref = _fourier_eval(values, T, np.arange(n_out) * (T / n_out))
    for got, want in zip(fourier_samples(values, T, n_out), ref, strict=True):
        assert got.shape == want.shape == (n_out, 5)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(want).max())


@pytest.mark.parametrize("effect, values", [("rotor_drag", {"k_rd": 0.015}),
                                            ("motor_lag", {"tau": 0.035})])
def test_the_64_node_collocation_is_the_128_node_one(effect, values, monkeypatch):
    """Issue 39: the periodic collocation on 64 nodes (the trim since issue 39) gives the
    nominal of the 128 it had before, at 1024 samples of circles across the paper's
    speeds and tilts, to 1e-9 N in the commands and 1e-10 rad in the roll (measured
    4e-12 N)."""
    from gainsched.schedule import trim

    m = paper_model(**{f"effects.{effect}.{k}": v for k, v in values.items()})
    for v, a in ((3.0, 0.0), (9.0, 0.35), (15.0, 0.6)):
        T = period(v, m.r)
        path = circle_path(v, m.r, np.arange(1024) * (T / 1024))
        got = {}
        for nodes in (64, 128):
            monkeypatch.setattr(trim, "N_FOURIER", nodes)
            m.memo.clear()
            got[nodes] = trim_path(m, path, a, periodic=True)
        np.testing.assert_allclose(got[64][2], got[128][2], rtol=0, atol=1e-9)
        np.testing.assert_allclose(got[64][0][:, 4], got[128][0][:, 4], rtol=0, atol=1e-10)


def test_a_per_sample_thrust_trim_that_does_not_converge_is_an_error():
    """The per-sample Newton on the thrusts (the polish of a nominal the collocation's
    interpolant misses) raises TrimError when a sample has not converged in its steps,
    instead of returning the last iterate; with its default steps it converges to the
    model's equations. Started 50 mN off the nominal of momentum theory at 9 m/s, 40 deg,
    whose actual thrusts the interpolant meets (no polish since the trim solves for them)."""
    from gainsched.schedule import trim

    m = paper_model(**{"effects.thrust_momentum.disk_area": 0.006})
    v, a = 9.0, np.deg2rad(40.0)
    path = circle_path(v, m.r, np.arange(1024) * (period(v, m.r) / 1024))
    _, (phi, dphi, ddphi, T, *_), smooth = trim._periodic_guess(m, path, a)
    assert smooth  # the actual thrusts are smooth
    off = T + 0.05
    with pytest.raises(trim.TrimError, match="did not converge"):
        trim._solve_thrust(m, path, a, phi, dphi, ddphi, off, max_iter=0)
    got = trim._solve_thrust(m, path, a, phi, dphi, ddphi, off)
    res = trim._local(m, path, a, phi, dphi, ddphi, got)[0]
    assert np.abs(res[:, 1:]).max() < 1e-11 * max(1.0, np.abs(got).max())
    np.testing.assert_allclose(got, T, rtol=0, atol=1e-9)  # N: back to the nominal's


@pytest.mark.parametrize("effect, values", [("rotor_drag", {"k_rd": 0.015}),
                                            ("thrust_momentum", {"disk_area": 0.006}),
                                            ("motor_lag", {"tau": 0.035})])
def test_a_speeds_tilts_solved_together_equal_each_alone(effect, values):
    """Issue 39: a job's tilts solved in one batched Newton (solve_circles: one model
    evaluation per step for all of them) give each circle's nominal as its own Newton does,
    to 1e-12 N and rad at 1024 samples, the 40 deg circle of momentum theory (in the floored
    inflow) included; the batch fills the cache trim_path reads."""
    from gainsched.schedule import trim

    m = paper_model(**{f"effects.{effect}.{k}": v for k, v in values.items()})
    v, tilts = 9.0, np.deg2rad([0.0, 20.0, 34.0, 40.0])
    path = circle_path(v, m.r, np.arange(1024) * (period(v, m.r) / 1024))
    alone = []
    for a in tilts:
        m.memo.clear()
        alone.append(trim_path(m, path, a, periodic=True))
    m.memo.clear()
    kept = trim.solve_circles(m, path, tilts)
    assert kept is trim.solutions(m)
    assert all(trim._circle_key(path, a) in kept.nodes for a in tilts)
    for a, (z, _, u, tension) in zip(tilts, alone, strict=True):
        z_b, _, u_b, tension_b = trim_path(m, path, a, periodic=True)
        np.testing.assert_allclose(u_b, u, rtol=0, atol=1e-12)
        np.testing.assert_allclose(z_b, z, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tension_b, tension, rtol=0, atol=1e-11)


def test_a_lag_after_momentum_theory_has_its_states_rate():
    """Issue 39: with a motor lag and momentum theory (what improve fits on the example
    flights) the lag's states are the modifiers' inverse of the smooth actual thrusts,
    sharp where the inflow is floored (9 m/s, 40 deg); the rate the command ``x + tau x'``
    is made of integrates (trapezoid, 4096 samples) to their change over the circle to
    1e-4 N (measured 2.2e-5 N). The trim before solved the states sample by sample and
    kept the interpolant's rate: 0.024 N off."""
    from scipy.integrate import cumulative_trapezoid


    m = paper_model(**IMPROVED)
    v, a, n = 9.0, np.deg2rad(40.0), 4096
    Tp = period(v, m.r)
    z, z_dot, u, _ = trim_path(m, circle_path(v, m.r, np.arange(n) * (Tp / n)), a, periodic=True)
    change = cumulative_trapezoid(z_dot[:, 10:], dx=Tp / n, axis=0, initial=0.0)
    assert np.abs(change - (z[:, 10:] - z[0, 10:])).max() < 1e-4  # N
    tau = IMPROVED["effects.motor_lag.tau"]
    np.testing.assert_allclose(u, z[:, 10:] + tau * z_dot[:, 10:], rtol=0, atol=1e-12)


@pytest.mark.parametrize("keys", [{"effects.rotor_drag.k_rd": 0.015},
                                  {"effects.thrust_momentum.disk_area": 0.006}, IMPROVED],
                         ids=["rotor_drag", "thrust_momentum", "improved"])
@pytest.mark.parametrize("n", [96, 1000])
def test_a_circles_samples_are_the_models_equilibrium_and_tension(keys, n):
    """Issue 39: a whole circle's samples are the interpolant of its collocation, checked
    against the model once per circle (at 8 samples per node), not evaluated at every
    sampling: at sample counts that are not multiples of the nodes the model's derivative
    at the state and commands is the path's to 1e-8 (relative to xi'^2), and its tension
    the interpolated one to 1e-9 N, in and out of momentum theory's floored inflow."""
    m = paper_model(**keys)
    for v, a in ((9.0, np.deg2rad(40.0)), (15.0, np.deg2rad(20.0))):
        path = circle_path(v, m.r, np.arange(n) * (period(v, m.r) / n))
        z, z_dot, u, tension = trim_path(m, path, a, periodic=True)
        ev = m.evaluate(z, u, a)
        assert np.abs(ev.z_dot - z_dot).max() < 1e-8 * max(1.0, (v / m.r) ** 2)
        np.testing.assert_allclose(tension, ev.tension, rtol=0, atol=1e-9)  # N


def test_a_circle_the_interpolant_misses_is_solved_sample_by_sample(monkeypatch):
    """A circle whose interpolant misses the model by more than ``POLISH_TOL`` at the
    check (here every circle: the tolerance set to 0) has its thrusts solved at every
    sample and is rough; they are the smooth circle's to 1e-9 N, and its tension the
    model's at them."""
    from gainsched.schedule import trim

    m = paper_model(**{"effects.rotor_drag.k_rd": 0.015})
    v, a, n = 9.0, np.deg2rad(30.0), 700
    path = circle_path(v, m.r, np.arange(n) * (period(v, m.r) / n))
    smooth = trim_path(m, path, a, periodic=True)
    assert not trim.is_rough(m, path, a)
    m.memo.clear()
    monkeypatch.setattr(trim, "POLISH_TOL", 0.0)
    calls = []
    solve = trim._solve_thrust
    monkeypatch.setattr(trim, "_solve_thrust", lambda *a, **k: calls.append(1) or solve(*a, **k))
    z, _, u, tension = trim_path(m, path, a, periodic=True)
    assert calls and trim.is_rough(m, path, a)
    np.testing.assert_allclose(u, smooth[2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(tension, m.evaluate(z, u, a).tension, rtol=0, atol=1e-12)


@pytest.mark.parametrize("keys", [{"effects.thrust_momentum.disk_area": 0.006}, IMPROVED],
                         ids=["thrust_momentum", "improved"])
def test_a_smooth_circles_commands_are_the_modifiers_inverse(keys, monkeypatch):
    """Issue 39: where the interpolant of the node commands meets the thrust modifiers'
    inverse at the check (8 samples per node), every sampling of the circle takes the
    interpolant and its rate; they are the inverse's commands (and a motor lag's states and
    command ``x + tau x'`` from the implicit function theorem's rate) to ``COMMAND_TOL``
    (relative to the largest command) at 700 samples. With a tolerance below 0 the circle is
    rough and the inverse is taken at every sample (a negative one: the inverse may
    return its start unchanged)."""
    from gainsched.schedule import trim

    m = paper_model(**keys)
    v, a, n = 15.0, np.deg2rad(20.0), 700
    path = circle_path(v, m.r, np.arange(n) * (period(v, m.r) / n))
    assert not trim.is_rough(m, path, a)
    z, z_dot, u, _ = trim_path(m, path, a, periodic=True)
    m.memo.clear()
    monkeypatch.setattr(trim, "COMMAND_TOL", -1.0)  # every circle rough
    assert trim.is_rough(m, path, a)
    z_i, z_dot_i, u_i, _ = trim_path(m, path, a, periodic=True)
    tol = 1e-8 * np.abs(u_i).max()  # N
    np.testing.assert_allclose(u, u_i, rtol=0, atol=tol)
    np.testing.assert_allclose(z, z_i, rtol=0, atol=tol)


@pytest.mark.parametrize("keys", [{"effects.thrust_momentum.disk_area": 0.006}, IMPROVED],
                         ids=["thrust_momentum", "improved"])
def test_a_rough_circles_commands_are_inverted_once_per_sampling(keys, monkeypatch):
    """Issue 39: a circle whose commands are rough (momentum theory's floored inflow, 7.5
    m/s at 34 deg) takes the modifiers' inverse at its samples
    once per sampling (the grid's nominal and its linearisation both sample the N control
    steps): asked again, the commands are the first answer bit for bit, without the
    inverse, and a caller that changes them changes no later answer; another sampling
    inverts again."""
    from gainsched.schedule import trim

    m = paper_model(**keys)
    v, a, n = 7.5, np.deg2rad(34.0), 700
    path = circle_path(v, m.r, np.arange(n) * (period(v, m.r) / n))
    assert trim.is_rough(m, path, a)
    calls = []
    inputs = trim.thrust_inputs
    monkeypatch.setattr(trim, "thrust_inputs", lambda *a, **k: calls.append(1) or inputs(*a, **k))
    z, z_dot, u, _ = trim_path(m, path, a, periodic=True)
    assert len(calls) == 1
    first = [x.copy() for x in (z, z_dot, u)]
    for x in (z, z_dot, u):
        x[:] = np.nan
    again = trim_path(m, path, a, periodic=True)
    assert len(calls) == 1
    for x, y in zip(first, again, strict=False):
        np.testing.assert_array_equal(x, y)
    other = circle_path(v, m.r, np.arange(n + 1) * (period(v, m.r) / (n + 1)))
    trim_path(m, other, a, periodic=True)
    assert len(calls) == 2


def test_a_long_newton_step_is_shortened_and_a_short_one_kept(model):
    """The collocation's Newton steps are limited per circle to ``MAX_ROLL_STEP`` in roll
    and the motors' range in thrust (the longer of the two decides), the direction kept; a
    step within both is returned bit for bit."""
    from gainsched.schedule import trim

    v = model.config.vehicle
    span = v.thrust_max - v.thrust_min
    rng = np.random.default_rng(3)
    d_phi, d_T = rng.normal(size=(3, 16)) * 0.1, rng.normal(size=(3, 16, 4))
    d_phi[1, 5] = 4 * trim.MAX_ROLL_STEP  # circle 1: roll four times too long
    d_T[2, 7, 1] = 3 * span  # circle 2: a thrust three times the range
    got_phi, got_T = trim._limited(model, d_phi, d_T)
    assert np.array_equal(got_phi[0], d_phi[0]) and np.array_equal(got_T[0], d_T[0])
    for c, f in ((1, 0.25), (2, 1 / 3)):
        np.testing.assert_allclose(got_phi[c], f * d_phi[c], rtol=1e-15)
        np.testing.assert_allclose(got_T[c], f * d_T[c], rtol=1e-15)
    assert np.abs(got_phi).max() <= trim.MAX_ROLL_STEP and np.abs(got_T).max() <= span
