"""The grid sweep (issue 3, paper Sec. IV).

- gains at every grid point equal a fresh single-point solve;
- the step count / dt convention and the azimuth sampling;
- known infeasible points are masked with the right reason bits and NaN gains.
"""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.config import config_from_text
from gainsched.model.reduced import Model
from gainsched.schedule.grid import (
    TILT_BATCH,
    build_grid,
    discrete_system,
    solve_circle,
    solve_speed,
    steps_per_period,
)
from gainsched.schedule.jobs import run_jobs
from gainsched.schedule.linearize import discretize, jacobians, lqr_system
from gainsched.schedule.nominal import REASONS, circle_nominal
from gainsched.schedule.path import period

from support import small_config, small_config_text


@pytest.fixture(scope="module")
def small():
    cfg = small_config()
    return cfg, build_grid(cfg, n_jobs=1)


def test_grid_shapes_and_axes(small):
    cfg, g = small
    n_a, n_v, n_xi = cfg.grid.tilts.size, cfg.grid.speeds.size, cfg.grid.azimuth_samples
    assert (n_a, n_v, n_xi) == (2, 2, 8)
    assert g.K.shape == (n_a, n_v, n_xi, 4, 11)
    assert g.S.shape == (n_a, n_v, n_xi, 11, 11)
    assert g.u_d.shape == (n_a, n_v, n_xi, 4)
    for name in ("phi_d", "tension", "reasons"):
        assert getattr(g, name).shape == (n_a, n_v, n_xi)
    assert g.spectral_radius.shape == g.sweeps.shape == (n_a, n_v)
    assert g.steps.shape == g.dt.shape == (n_v,)
    assert np.all(g.reasons == 0) and np.all(np.isfinite(g.K)) and np.all(g.spectral_radius < 1)


def test_grid_points_equal_single_point_solves(small):
    cfg, g = small
    for i, a in enumerate(cfg.grid.tilts):
        for j, v in enumerate(cfg.grid.speeds):
            # on the numerics the grid ran on (pinned workers if this process is not pinned:
            # other BLAS kernels move the tilt-0 DARE by ~1e-12)
            (s,) = run_jobs([(cfg, float(v), np.array([a]))], 1, None, solve_speed)
            for name, X in (("K", g.K), ("S", g.S), ("u_d", g.u_d), ("phi_d", g.phi_d),
                            ("tension", g.tension)):
                ref = getattr(s, name)[0]
                err = np.abs(X[i, j] - ref).max() / np.abs(ref).max()
                assert err <= 1e-12, (name, v, a, err)
            np.testing.assert_array_equal(g.reasons[i, j], s.reasons[0])
            assert g.spectral_radius[i, j] == pytest.approx(s.spectral_radius[0], rel=1e-12)
            assert g.steps[j] == s.steps and g.dt[j] == s.dt


def test_tilt0_dare_equals_periodic_recursion_at_every_azimuth(small):
    """Tilt 0 is stored as one DARE gain per speed; the periodic recursion run over the
    whole circle (keep_steps forces it at tilt 0 too) gives that gain at every grid
    azimuth: the time-invariance the DARE shortcut relies on, checked, not assumed."""
    cfg, g = small
    for j, v in enumerate(cfg.grid.speeds):
        sol, _ = solve_circle(cfg, float(v), np.array([0.0]), keep_steps=True)
        K_periodic = sol.K[0]  # (n_xi, 4, n), one solve per azimuth step
        K_dare = g.K[0, j]  # the DARE gain, broadcast over xi
        err = np.abs(K_periodic - K_dare).max() / np.abs(K_dare).max()
        assert err <= 1e-10, (v, err)
        assert sol.spectral_radius[0] == pytest.approx(g.spectral_radius[0, j], rel=1e-10)


def test_step_count_and_dt_convention(paper_config):
    """N = 2 round(T / (2 dt)) (even), dt_k = T / N within 0.15 % of the control period."""
    cfg = paper_config
    r, dt = cfg.radius, cfg.control.dt
    for v in cfg.grid.speeds:
        N = steps_per_period(v, r, dt)
        T = period(v, r)
        assert N % 2 == 0 and N == 2 * round(T / (2 * dt))
        assert abs(T / N - dt) / dt < 1.5e-3
        assert steps_per_period(-v, r, dt) == N  # reversed circles: same steps


def test_grid_azimuths_interpolate_the_steps(paper_config):
    """K at xi_j = 2 pi j / n_xi is the linear interpolation of the two bracketing steps."""
    cfg = config_from_text(small_config_text(grid__azimuth_samples=36), "small36.toml")
    sol, (Ad, Bd, K_steps) = solve_circle(cfg, 9.0, [np.deg2rad(20)], keep_steps=True)
    N = sol.steps
    assert K_steps.shape[1] == N and sol.dt == pytest.approx(period(9.0, cfg.radius) / N)
    for j in range(36):
        pos = j * N / 36
        k = int(np.floor(pos))
        w = pos - k
        expect = (1 - w) * K_steps[0, k] + w * K_steps[0, (k + 1) % N]
        np.testing.assert_allclose(sol.K[0, j], expect, rtol=0, atol=1e-14 * np.abs(expect).max())


def _check_infeasible_circle(sol, bit):
    reasons = sol.reasons[0]
    own = reasons & ~np.uint8(16)
    assert np.any(own & bit), f"expected bit {bit} ({REASONS[bit]}) somewhere"
    # azimuths that are feasible by themselves carry bit 16 and nothing else
    assert np.any(own == 0)
    assert np.all(reasons[own == 0] == 16)
    assert np.all(reasons[own != 0] & 16 == 0)
    assert np.all(reasons != 0)
    # no made-up gains
    assert np.all(np.isnan(sol.K[0])) and np.all(np.isnan(sol.S[0]))
    assert np.isnan(sol.spectral_radius[0])
    # the nominal is still reported
    assert np.all(np.isfinite(sol.u_d[0])) and np.all(np.isfinite(sol.tension[0]))
    return own


def test_slack_circle_masked(paper_config):
    """2 m/s at 40 deg: the tether goes slack on part of the circle (bit 1)."""
    sol = solve_circle(paper_config, 2.0, [np.deg2rad(40)])
    own = _check_infeasible_circle(sol, 1)
    slack = sol.tension[0] < paper_config.feasibility.min_tension
    np.testing.assert_array_equal((own & 1) != 0, slack)


def test_thrust_floor_circle_masked(paper_config):
    """15 m/s at 40 deg with the zero-offset nominal: motor thrusts fall below thrust_min
    (bit 2); with the paper config's free offsets the circle has gains."""
    sol = solve_circle(paper_config, 15.0, [np.deg2rad(40)])
    assert np.all(sol.reasons == 0) and np.isfinite(sol.spectral_radius[0])
    paper_config = paper_config.with_values({"feasibility.attitude_offsets": "zero"})
    sol = solve_circle(paper_config, 15.0, [np.deg2rad(40)])
    own = _check_infeasible_circle(sol, 2)
    low = np.any(sol.u_d[0] < paper_config.vehicle.thrust_min, -1)
    np.testing.assert_array_equal((own & 2) != 0, low)


def test_infeasible_tilt_does_not_affect_feasible_tilts(paper_config):
    """In a batch, an infeasible tilt is skipped without changing the others' gains (40 deg
    at 14 m/s is thrust-infeasible with the zero-offset nominal)."""
    paper_config = paper_config.with_values({"feasibility.attitude_offsets": "zero"})
    tilts = np.deg2rad([0.0, 40.0])
    both = solve_circle(paper_config, 14.0, tilts)
    alone = solve_circle(paper_config, 14.0, tilts[:1])
    assert np.all(both.reasons[0] == 0) and np.all(both.reasons[1] != 0)
    np.testing.assert_allclose(both.K[0], alone.K[0], rtol=1e-12)
    assert np.all(np.isnan(both.K[1]))


def test_tilts_beyond_one_batch_equal_single_tilt_solves(paper_config):
    """More tilts than one batch (TILT_BATCH) are solved batch by batch, each as if alone:
    the working set per batch is bounded and the gains do not depend on the batching."""
    tilts = np.deg2rad(np.linspace(4.0, 40.0, TILT_BATCH + 3))
    sol = solve_circle(paper_config, 9.0, tilts)
    assert np.all(sol.reasons == 0)
    for i in (0, TILT_BATCH - 1, TILT_BATCH, tilts.size - 1):
        alone = solve_circle(paper_config, 9.0, tilts[i : i + 1])
        np.testing.assert_allclose(sol.K[i], alone.K[0], rtol=1e-10, atol=1e-10)
        assert sol.spectral_radius[i] == pytest.approx(alone.spectral_radius[0], rel=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize(("speed", "tilt_deg"), [(2.5, 20), (9.0, 40), (15.0, 40)])
def test_interpolated_linearization_equals_every_step(paper_config, speed, tilt_deg):
    """The trigonometric interpolation of the exact samples reproduces the exact
    (complex-step, zero-order-hold) system at every control step."""
    model = Model(paper_config)
    a = np.deg2rad(tilt_deg)
    N = steps_per_period(speed, model.r, paper_config.control.dt)
    dt = period(speed, model.r) / N
    Ad, Bd, M, err = discrete_system(model, speed, [a], N, dt)
    assert M < N / 4 and err <= 1e-10
    nom = circle_nominal(model, speed, a, N)
    A, B = jacobians(model, nom.z, nom.u, a)
    Ad_ref, Bd_ref = discretize(*lqr_system(A, B), dt)
    I = np.eye(Ad.shape[-1])
    assert np.abs(Ad[0] - Ad_ref).max() / np.abs(Ad_ref - I).max() <= 1e-12
    assert np.abs(Bd[0] - Bd_ref).max() / np.abs(Bd_ref).max() <= 1e-12


@pytest.mark.parametrize("speed", [3.0, 15.0])
def test_tilt0_dare_equals_periodic_recursion(paper_config, speed):
    """Tilt-0 circles are solved by the DARE; the periodic recursion agrees."""
    dare = solve_circle(paper_config, speed, [0.0])
    rec = solve_circle(paper_config, speed, [0.0], dare_tilt0=False)
    assert dare.sweeps[0] == -1 and rec.sweeps[0] > 1
    for name in ("K", "S"):
        X, Y = getattr(dare, name), getattr(rec, name)
        assert np.abs(X - Y).max() / np.abs(Y).max() <= 1e-8, name
    assert dare.spectral_radius[0] == pytest.approx(rec.spectral_radius[0], rel=1e-6)


#: issue 39: the nominal and gains of momentum theory's circles (paper vehicle,
#: disk_area 0.006 m^2) as the trim gave them before its rework (commit 86b2e9d): per
#: circle (speed m/s, tilt deg), T1..T4 (N) at the grid azimuths 0 and 180 deg, the roll
#: (rad) there, the closed-loop spectral radius and max |K| (N per state unit)
MOMENTUM_REFERENCE = {
    (6.0, 20): ([[1.5040329914011779, 1.504032991401179, 1.5179747849264282, 1.5179747849264293],
                 [0.9291089266873995, 0.9291089266874007, 0.9679963206140807,
                  0.9679963206140808]],
                [-0.5458406031457874, 0.11996481103305483], 0.8336883355119924,
                4.344387428102001),
    (9.0, 40): ([[2.025312623875298, 2.0253126238752945, 2.0543383052083977, 2.0543383052083937],
                 [0.46253560418083767, 0.46253560418083683, 0.5407040005872197,
                  0.5407040005872186]],
                [-0.9169454617547561, 0.357213527982977], 0.9463249766287501,
                6.712829727221583),
    # (15, 40) since the offsets' adaptive rounds (issue 39, later): the first round's
    # check finds a motor below its minimum by 2.3 mN, and the second round (bounds 1.5x
    # that further in, from the first's offsets) replaces the old third doubling; the
    # offsets moved by up to 0.003 deg, the thrusts by up to 2.5 mN (every motor stays
    # inside its range), the spectral radius by 1.3e-7 (before: 2.7012094048001862,
    # 2.9375448021430883, ...; rho 0.9925579442095606, max |K| 11.098649896095719); and
    # since the offsets' SLSQP stops at ftol 1e-8 (it stalled at 1e-10 on rounding-level
    # violations of its 2048 bounds): the thrusts by up to 5.8 uN, rho by 2e-10 (before:
    # 2.7019186228484604, ...; rho 0.9925580708878834, max |K| 11.109192363379693)
    (15.0, 40): ([[2.701914269715307, 2.9368884587209823, 2.84086839701295,
                   2.9590371858883135],
                  [0.2692731444374241, 0.19389537690264544, 0.739462461512563,
                   0.6769085285911414]],
                 [-1.0398493762136845, 0.02457361698549454], 0.9925580706964203,
                 11.109191840191524),
}


@pytest.fixture(scope="module")
def momentum_config(paper_config):
    return paper_config.with_values({"effects.thrust_momentum.disk_area": 0.006})


@pytest.mark.parametrize("circle", list(MOMENTUM_REFERENCE))
def test_momentum_circles_equal_the_trim_before_issue_39(momentum_config, circle):
    """Issue 39's faster momentum-theory trim (plain Newton for the induced velocity, the
    per-sample thrust solve point by point and cached, the rough circles linearised at every
    step) gives the nominal of the trim before it to 1e-9 relative (measured 7e-15), and its
    spectral radius and largest gain to 1e-9 (measured 4e-13). The 40 deg circles are in
    the floored inflow: their thrusts are solved sample by sample."""
    speed, tilt = circle
    u, phi, rho, kmax = MOMENTUM_REFERENCE[circle]
    sol = solve_circle(momentum_config, speed, np.deg2rad([tilt]))
    np.testing.assert_allclose(sol.u_d[0, [0, 18]], u, rtol=1e-9)
    np.testing.assert_allclose(sol.phi_d[0, [0, 18]], phi, rtol=1e-9)
    assert sol.spectral_radius[0] == pytest.approx(rho, rel=1e-9)
    assert np.abs(sol.K[0]).max() == pytest.approx(kmax, rel=1e-9)


def test_rough_and_smooth_tilts_in_one_batch_equal_single_tilt_solves(momentum_config):
    """A batch with a smooth circle (20 deg: interpolated linearisation) and a rough one
    (40 deg: every step, the nominal not smooth at the trim's nodes) gives each the
    solution of its own batch, to 1e-12 in the gains."""
    from gainsched.schedule.nominal import circle_is_rough

    model = Model(momentum_config)
    N = steps_per_period(9.0, model.r, momentum_config.control.dt)
    tilts = np.deg2rad([40.0, 20.0])
    assert [circle_is_rough(model, 9.0, a) for a in tilts] == [True, False]
    both = solve_circle(momentum_config, 9.0, tilts)
    assert both.lin_samples.tolist()[0] == N and both.lin_samples[1] < N / 4
    for i, a in enumerate(tilts):
        alone = solve_circle(momentum_config, 9.0, [a])
        assert both.lin_samples[i] == alone.lin_samples[0]
        np.testing.assert_allclose(both.K[i], alone.K[0], rtol=0,
                                   atol=1e-12 * np.abs(alone.K[0]).max())


@pytest.mark.slow
def test_momentum_build_is_bit_identical_for_any_worker_count(momentum_config):
    """The momentum-theory build (rough circles, per-sample thrusts, their cache) gives the
    same bits on one worker and on two."""
    from dataclasses import fields

    cfg = momentum_config.with_values({"grid.speeds": [9, 15], "grid.tilts_deg": [0, 20, 40],
                                       "name": "momentum"})
    one, two = build_grid(cfg, n_jobs=1), build_grid(cfg, n_jobs=2)
    for f in fields(one):
        a, b = np.asarray(getattr(one, f.name)), np.asarray(getattr(two, f.name))
        assert a.tobytes() == b.tobytes(), f.name
