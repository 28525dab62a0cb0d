"""Attitude offsets of the nominal (issue 15): the trim with free pitch and yaw that lets
the tether carry the torque where the chi = 0 nominal runs the motors out of range."""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.config import remove_key, set_values
from gainsched.errors import InputError
from gainsched.model.reduced import Model
from gainsched.model.symmetry import REDUCED_SIGNS
from gainsched.rotations import matrix_from_euler_zyx
from gainsched.schedule import offsets as offsets_mod
from gainsched.schedule.closedform import state_from_attitude
from gainsched.schedule.nominal import circle_nominal, circle_offsets
from gainsched.schedule.path import AzimuthPath, period

from support import IMPROVED, paper_model

A40 = np.deg2rad(40.0)


@pytest.fixture(scope="module")
def free(paper_config):
    assert paper_config.feasibility.attitude_offsets == "free"
    return Model(paper_config)


@pytest.fixture(scope="module")
def zero(paper_config):
    return Model(paper_config.with_values({"feasibility.attitude_offsets": "zero"}))


def test_attitude_kinematics_match_the_rotation_matrix():
    """The body rates of state_from_attitude are R^T R' (a second formulation: central
    differences of R_CB = Rz(xi + chi) Ry(theta) Rx(phi), paper eq. 2), and their
    derivative the central difference of the rates; random smooth angle profiles."""
    t = np.linspace(0.0, 1.0, 2001)
    h = t[1] - t[0]
    f = {  # value, rate, acceleration of smooth profiles
        "xi": (3 * t + 0.4 * np.sin(2 * t), 3 + 0.8 * np.cos(2 * t), -1.6 * np.sin(2 * t)),
        "phi": (0.3 * np.sin(5 * t), 1.5 * np.cos(5 * t), -7.5 * np.sin(5 * t)),
        "theta": (0.1 * np.cos(4 * t), -0.4 * np.sin(4 * t), -1.6 * np.cos(4 * t)),
        "chi": (0.2 * np.sin(3 * t + 1), 0.6 * np.cos(3 * t + 1), -1.8 * np.sin(3 * t + 1)),
    }
    path = AzimuthPath(t, f["xi"][0], (f["xi"][1], f["xi"][2], 0 * t, 0 * t))
    s, sdot = state_from_attitude(path, f["phi"], f["theta"], f["chi"])
    R = matrix_from_euler_zyx(f["phi"][0], f["theta"][0], f["xi"][0] + f["chi"][0])
    Rdot = (R[2:] - R[:-2]) / (2 * h)
    W = np.einsum("nji,njk->nik", R[1:-1], Rdot)  # R^T R' = skew(omega_B)
    omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], -1)
    np.testing.assert_allclose(s[1:-1, 7:10], omega, rtol=0, atol=1e-5)
    np.testing.assert_allclose(sdot[1:-1, 7:10], (s[2:, 7:10] - s[:-2, 7:10]) / (2 * h),
                               rtol=0, atol=1e-4)
    np.testing.assert_array_equal(sdot[:, 4:7], np.stack([f[k][1] for k in
                                                          ("phi", "theta", "chi")], -1))
    # without offsets: the paper's eqs. 15-16 (the special form the tables use)
    zero = tuple(0 * x for x in f["chi"])
    s0, sdot0 = state_from_attitude(path, f["phi"])
    s1, sdot1 = state_from_attitude(path, f["phi"], zero, zero)
    np.testing.assert_allclose(s0, s1, rtol=0, atol=1e-14)
    np.testing.assert_allclose(sdot0, sdot1, rtol=0, atol=1e-13)


def test_free_offsets_fly_40_deg_15_mps(free, zero):
    """Issue 15's first must-show: at 40 deg / 15 m/s the chi = 0 nominal needs a motor at
    -0.85 N; with free offsets the nominal satisfies the full nonlinear model to 1e-9 at
    every control step of the period (measured 1e-11) with every motor inside
    [thrust_min + margin, thrust_max - margin], with offsets of half a degree."""
    cfg = free.config
    N = int(round(period(15.0, free.r) / cfg.control.dt))
    base = circle_nominal(zero, 15.0, A40, N)
    assert base.u.min() < -0.8 and np.any(base.reasons)
    nom = circle_nominal(free, 15.0, A40, N)
    ev = free.evaluate(nom.z, nom.u, A40)
    assert np.abs(ev.z_dot - nom.z_dot).max() < 1e-9
    lo = cfg.vehicle.thrust_min + cfg.feasibility.thrust_margin
    hi = cfg.vehicle.thrust_max - cfg.feasibility.thrust_margin
    assert nom.u.min() >= lo and nom.u.max() <= hi and not np.any(nom.reasons)
    offsets = np.abs(nom.z[:, 5:7]).max(0)
    assert 0 < offsets.max() < np.deg2rad(1.0)
    # the state's other parts are the great circle's
    np.testing.assert_allclose(nom.z[:, 0], np.pi / 2, rtol=0, atol=0)
    np.testing.assert_allclose(nom.tension, base.tension, rtol=2e-3)


def test_feasible_circles_keep_the_zero_offset_nominal(free, zero):
    """Where chi = 0 is feasible the nominal is today's, bit for bit (and "zero" keeps
    today's tables everywhere)."""
    for v, a in ((8.0, 0.0), (8.0, np.deg2rad(20)), (5.0, A40), (14.0, np.deg2rad(27))):
        assert circle_offsets(free, v, a) is None
        x, y = circle_nominal(free, v, a, 36), circle_nominal(zero, v, a, 36)
        np.testing.assert_array_equal(x.z, y.z)
        np.testing.assert_array_equal(x.u, y.u)
    assert circle_offsets(zero, 15.0, A40) is None


def test_offsets_follow_the_direction_mirror(free):
    """S2 (the other direction): the offsets of -15 m/s are the mirror of +15 m/s's
    (theta keeps its sign, chi flips, xi -> pi - xi), and so is the whole nominal state."""
    a, b = circle_offsets(free, 15.0, A40), circle_offsets(free, -15.0, A40)
    m = a.mirrored()
    np.testing.assert_allclose(b.pitch, m.pitch, rtol=0, atol=2e-6)
    np.testing.assert_allclose(b.yaw, m.yaw, rtol=0, atol=2e-6)
    n = 36
    up = circle_nominal(free, 15.0, A40, n)
    down = circle_nominal(free, -15.0, A40, n, xi0=np.pi)  # xi_k = pi - xi_k(up)
    np.testing.assert_allclose(down.z[:, :10], up.z[:, :10] * REDUCED_SIGNS
                               + np.array([0, np.pi, 0, 0, 0, 0, 0, 0, 0, 0]),
                               rtol=0, atol=5e-6)
    np.testing.assert_allclose(down.u, up.u[:, ::-1], rtol=0, atol=5e-5)


@pytest.mark.parametrize("effects", ["drag", "improved"])
def test_constraint_gradients_are_the_central_differences(free, effects):
    """The SLSQP's thrust gradients (implicit function theorem on the collocation Newton)
    equal central differences of re-solved trims, to 1e-6 of their size; with thrust
    modifiers and a motor lag (what `improve` finds) the trim solves for the actual thrusts
    and the commands' gradients go through the modifiers' inverse by the chain rule."""
    model = free if effects == "drag" else paper_model(**IMPROVED)
    speed, n = 15.0, 32
    rng = np.random.default_rng(1)
    nb = 2 * offsets_mod.HARMONICS + 1
    p = 0.2 * rng.standard_normal(2 * nb)  # degrees

    captured = {}

    def fake_minimize(fun, x0, jac, method, constraints, options):
        con = constraints[0]
        captured["g"] = con["fun"]
        captured["J"] = con["jac"]
        raise offsets_mod.TrimError("stop")

    orig = offsets_mod.minimize
    offsets_mod.minimize = fake_minimize
    try:
        offsets_mod._solve(model, speed, A40, 1.0, offsets_mod.HARMONICS, n, -10.0, 10.0)
    finally:
        offsets_mod.minimize = orig
    g, J = captured["g"], captured["J"]
    Jp = J(p)
    h = 1e-4

    def central(j, h):
        e = np.zeros_like(p)
        e[j] = h
        return (g(p + e) - g(p - e)) / (2 * h)

    for j in (0, 3, nb + 1, 2 * nb - 1):
        # Richardson's extrapolation of two steps: error O(h^4), where one central
        # difference's O(h^2) is 1e-5 N/deg in momentum theory's floored inflow
        fd = (4 * central(j, h / 2) - central(j, h)) / 3
        np.testing.assert_allclose(Jp[:, j], fd, rtol=0, atol=1e-6 * max(1.0, np.abs(fd).max()))
        assert np.abs(fd).max() > 1e-4  # the offsets do move the thrusts


def test_config_keys_are_checked(paper_text):
    # the paper config without its own attitude_offsets line (the test sets its own)
    text = remove_key(paper_text, "feasibility", "attitude_offsets")
    from gainsched.config import config_from_text

    with pytest.raises(InputError, match="feasibility.attitude_offsets: must be one of zero, free"):
        config_from_text(set_values(text, {"feasibility.attitude_offsets": "maybe"}), "x.toml")
    with pytest.raises(InputError, match="feasibility.max_attitude_offset_deg: must be <= 45"):
        config_from_text(set_values(text, {"feasibility.max_attitude_offset_deg": 60}), "x.toml")
    cfg = config_from_text(set_values(text, {"feasibility.max_attitude_offset_deg": 0.05}),
                           "x.toml")
    # 0.05 deg is not enough at 40 deg / 15 m/s: the circle stays infeasible (thrust)
    cfg = cfg.with_values({"feasibility.attitude_offsets": "free"})
    assert circle_offsets(Model(cfg), 15.0, A40) is None


# --------------------------------------------------------------------------- table, runtime, loop


@pytest.fixture(scope="module")
def free_table(free, tmp_path_factory):
    """A small table of the free-offset config where the chi = 0 nominal fails: speeds
    11, 13, 15 m/s at tilts 0, 34, 40 deg."""
    from gainsched.schedule.grid import build_grid
    from gainsched.schedule.tables import table_bytes, table_from_bytes

    cfg = free.config.with_values({"grid.speeds": [11.0, 13.0, 15.0],
                                   "grid.tilts_deg": [0.0, 34.0, 40.0]})
    return cfg, table_from_bytes(table_bytes(cfg, build_grid(cfg), Model(cfg)))


@pytest.mark.slow
@pytest.mark.slow
def test_table_has_gains_where_offsets_make_the_circle_feasible(free_table):
    """Every circle of the small grid has gains (the chi = 0 nominal marks 34 deg at 13-15 m/s
    and 40 deg at 11-15 m/s thrust-infeasible); the offsets are stored per circle and are
    zero where chi = 0 was feasible (tilt 0)."""
    cfg, t = free_table
    assert not np.any(t.reasons)
    assert np.all(np.isfinite(t.K)) and np.all(t.spectral_radius < 1)
    assert t.offsets is not None and t.offsets.shape == (3, 3, 2, 7)
    assert not np.any(t.offsets[0]) and np.all(np.abs(t.offsets[2]).max(axis=(-2, -1)) > 0)


@pytest.mark.slow
def test_runtime_offsets_follow_the_symmetries(free_table):
    """The runtime's offsets at a grid circle are the trim's series (float32 coefficients),
    for both directions (S2) and both tilt signs (S1)."""
    from gainsched.firmware.runtime import Interpolator
    from gainsched.schedule.offsets import AttitudeOffsets, _basis

    cfg, t = free_table
    interp = Interpolator(t)
    xi = np.linspace(-7, 7, 101)
    r = cfg.radius
    off = AttitudeOffsets(t.offsets[2, 2, 0], t.offsets[2, 2, 1])  # 40 deg, 15 m/s
    for sgn_v, sgn_a in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
        got = interp.attitude(xi, sgn_v * 15.0 / r, sgn_a * A40)
        o = off.mirrored() if sgn_v < 0 else off
        x = xi + (np.pi if sgn_a < 0 else 0.0)
        B, B1, _ = _basis(x, o.harmonics)
        want = np.stack([B @ o.pitch, B1 @ o.pitch, B @ o.yaw, B1 @ o.yaw], -1)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-7)


@pytest.mark.slow
@pytest.mark.needs_cc
def test_c_nominal_carries_the_offsets(free_table, tmp_path):
    """C gs_lookup_nominal against the Python reference on a table with offsets: theta, chi
    and the body rates with them, every symmetry branch, inside and between the circles."""
    from gainsched.firmware.feedforward import feedforward
    from gainsched.firmware.host.lookup import CRuntime, build_host
    from gainsched.firmware.runtime import Interpolator, runtime_data
    from gainsched.schedule.path import maneuver_path

    cfg, t = free_table
    data = runtime_data(t)
    c = CRuntime(build_host(data, tmp_path), data)
    assert c.verify() == 0 and c.crc32() == data.crc32()
    interp = Interpolator(data)
    T = np.arange(0.0, 2.0, 1e-3)
    path = maneuver_path(11.0, 15.0, 10.0, cfg.radius, T, 0.3)
    for alpha in (A40, -A40, np.deg2rad(37.0)):
        for p in (path, AzimuthPath(path.t, -path.xi, tuple(-d for d in path.d))):
            ff = feedforward(interp, p, alpha)
            K, U, X, ten, S = c.nominal(np.stack([p.xi, *p.d], 1), alpha)
            np.testing.assert_array_equal(S, ff.status)
            assert np.abs(ff.x_d[:, 6]).max() > 1e-3  # the offsets are there
            err = np.abs(X - ff.x_d) / (1 + np.abs(ff.x_d))
            assert err.max() <= 2e-5, (err.max(0), alpha)
            np.testing.assert_allclose(U, ff.u_d, rtol=1e-5, atol=1e-5)


# the circles the chi = 0 nominal cannot fly on configs/paper.toml; the first two unmarked
NEWLY_FEASIBLE = [(40.0, 15.0), (34.0, 13.0), (40.0, 11.0), (40.0, 12.0), (40.0, 13.0),
                  (40.0, 14.0), (34.0, 14.0), (34.0, 15.0), (37.0, 12.0), (28.0, 15.0)]


@pytest.mark.slow
@pytest.mark.parametrize(("tilt_deg", "speed", "full"), [
    pytest.param(a, v, i < 2, marks=() if i < 2 else pytest.mark.slow, id=f"tilt{a:g}-{v:g}mps")
    for i, (a, v) in enumerate(NEWLY_FEASIBLE)])
def test_newly_feasible_circles_fly(paper_config, paper_table, paper_c_scheduler, tilt_deg,
                                    speed, full):
    """Issue 15's closed-loop must-show on the committed table (configs/paper.toml,
    ``attitude_offsets = "free"``): on the design model, ideal sensing and with mocap
    noise, path mode and firmware mode on the C runtime: stable, no slack, RMS out-of-plane
    <= 2 mm, never a held gain. The first two circles fly all four combinations, the
    others (slow) path mode ideal and firmware mode with mocap noise. Measured over all
    ten and all four: RMS out-of-plane 0.24-0.87 mm."""
    from gainsched.native import find_cc
    from gainsched.sim.loop import Scenario, Sensing, metrics, simulate, table_scheduler

    cfg, t = paper_config, paper_table
    assert t.config_sha256 == cfg.sha256
    mocap = Sensing(False, 200.0, 0.0005, np.deg2rad(0.2), 0.0, 0.0, 1)
    scheds = [("path", table_scheduler(t))]
    if find_cc() is not None:
        scheds.append(("firmware", paper_c_scheduler))
    for sensing in (Sensing(), mocap):
        for mode, sched in scheds:
            if not full and (mode == "path") != sensing.ideal:
                continue
            scn = Scenario("grid", np.deg2rad(tilt_deg), speed, 3.0, sensing=sensing)
            res = simulate(cfg, sched, scn, cfg, controller=mode)
            m = metrics(res)
            assert res.slack_time is None, (mode, sensing)
            assert m["rms_out_of_plane_m"] <= 2e-3, (mode, m["rms_out_of_plane_m"])
            assert not np.any(res.held) and np.all(res.status == 0)
            print(f"{tilt_deg:g} deg {speed:g} m/s {mode:8s} {sensing.ideal!s:5s}: RMS "
                  f"out-of-plane {1e3 * m['rms_out_of_plane_m']:.3f} mm")


@pytest.mark.parametrize("lag", [False, True], ids=["no-lag", "motor-lag"])
def test_one_slsqp_keeps_the_commands_in_range_between_the_nodes(lag, monkeypatch):
    """Issue 39: the SLSQP bounds the commanded thrusts at eight points per collocation node
    (the collocation's own interpolant), so the check on 1024 samples passes at the first
    attempt: one SLSQP per circle, where the node-only bounds needed two or three (each a
    third of the paper build's offsets). With a motor lag the bound is on the command
    ``T + tau T'`` (what the table's feasibility checks), not on the lagged thrust."""
    from gainsched.schedule.path import circle_path
    from gainsched.schedule.trim import trim_path

    model = paper_model(**({"effects.motor_lag.tau": 0.035} if lag else {}))
    runs = []
    orig = offsets_mod.minimize
    monkeypatch.setattr(offsets_mod, "minimize", lambda *a, **k: runs.append(1) or orig(*a, **k))
    cfg = model.config
    lo = cfg.vehicle.thrust_min + cfg.feasibility.thrust_margin
    hi = cfg.vehicle.thrust_max - cfg.feasibility.thrust_margin
    for v, a in ((15.0, A40), (13.0, np.deg2rad(37.0))):
        runs.clear()
        off = offsets_mod.solve_offsets(model, v, a, bound=cfg.feasibility.max_attitude_offset)
        assert off is not None and len(runs) == 1, (v, a, len(runs))
        T = period(v, model.r)
        path = circle_path(v, model.r, np.arange(1024) * (T / 1024))
        u = trim_path(model, path, a, periodic=True, offsets=off)[2]
        assert lo <= u.min() and u.max() <= hi
        # the safety inside the bounds is met to its own size (2 mN), not more
        assert min(u.min() - lo, hi - u.max()) < 2 * offsets_mod.NODE_SAFETY_N


@pytest.fixture(scope="module")
def improved():
    """The paper vehicle with what `improve` finds on the example flights (thrust_momentum
    + motor_lag, docs/model-vs-measurement.md): a motor's commanded thrust dips where the
    inflow meets momentum theory's floor, a dip the optimisation's 32 nodes cannot see."""

    return paper_model(**IMPROVED)


def _slsqp_starts(monkeypatch):
    starts = []
    orig = offsets_mod.minimize
    monkeypatch.setattr(offsets_mod, "minimize",
                        lambda fun, x0, **k: starts.append(np.array(x0)) or orig(fun, x0, **k))
    return starts


def test_a_dip_the_nodes_miss_costs_one_more_round_from_the_last(improved, monkeypatch):
    """Issue 39: at 14 m/s and 40 deg the first round's check finds a motor 57 mN below its
    minimum (a dip between the 32 nodes, not an interpolation bulge of a few mN). The next
    round moves the bounds in by 1.5 times what the check found and starts from the first
    round's offsets: two SLSQPs, and the nominal on 1024 samples keeps every motor in range.
    Doubling the safety (2, 4, 8, 16 mN) had failed after four rounds: the circle had no
    gains."""
    from gainsched.schedule.path import circle_path
    from gainsched.schedule.trim import trim_path

    cfg = improved.config
    lo = cfg.vehicle.thrust_min + cfg.feasibility.thrust_margin
    hi = cfg.vehicle.thrust_max - cfg.feasibility.thrust_margin
    starts = _slsqp_starts(monkeypatch)
    v = 14.0
    off = offsets_mod.solve_offsets(improved, v, A40, bound=cfg.feasibility.max_attitude_offset)
    assert off is not None and len(starts) == 2
    assert not starts[0].any() and np.abs(starts[1]).max() > 0.1  # deg: the first's offsets
    T = period(v, improved.r)
    path = circle_path(v, improved.r, np.arange(1024) * (T / 1024))
    u = trim_path(improved, path, A40, periodic=True, offsets=off)[2]
    assert lo <= u.min() and u.max() <= hi
    first = offsets_mod._solve(improved, v, A40, cfg.feasibility.max_attitude_offset,
                               offsets_mod.HARMONICS, offsets_mod.N_NODES,
                               lo + offsets_mod.NODE_SAFETY_N, hi - offsets_mod.NODE_SAFETY_N)
    u1 = trim_path(improved, path, A40, periodic=True, offsets=first)[2]
    assert lo - u1.min() > 16 * offsets_mod.NODE_SAFETY_N  # beyond what doubling covered


def test_a_long_newton_step_of_the_search_is_shortened(improved, monkeypatch):
    """Issue 39: at 13 m/s and 37 deg the zero-offset commands reach below zero, where
    momentum theory's thrust has no slope in its command. The search's second trim, from
    the first iterate's solution, took full Newton steps of 98 rad in roll and landed on a
    spurious solution (roll 96 rad, commands to 3.7e3 N); SLSQP stayed there for 158 trims
    before giving up. With the steps limited (``trim.MAX_ROLL_STEP``, the motors' range)
    that trim does not converge, the search ends at once, and the circle has no offsets, as
    before."""
    calls = []
    newton = offsets_mod.newton
    monkeypatch.setattr(offsets_mod, "newton",
                        lambda *a, **k: calls.append(1) or newton(*a, **k))
    cfg = improved.config
    assert offsets_mod.solve_offsets(improved, 13.0, np.deg2rad(37.0),
                                     bound=cfg.feasibility.max_attitude_offset) is None
    assert len(calls) <= 10


def test_bounds_that_would_cross_end_the_search(improved, monkeypatch):
    """A check that finds the motors out by more than half the thrust range leaves no room
    between the bounds: no offsets, after one SLSQP (before: three more, the last at bounds
    of 2.5e4 N). The 64-node trim of the first round's offsets at 13 m/s, 40 deg once
    landed on a spurious branch with motors at +-1.6e4 N; the trim in actual thrusts has
    none, so here the check's trim is made to report motors 1e4 N out."""
    from gainsched.schedule import trim

    real = trim.trim_path

    def far_out(*args, **kwargs):
        z, z_dot, u, tension = real(*args, **kwargs)
        return z, z_dot, u - 1e4, tension

    monkeypatch.setattr(trim, "trim_path", far_out)
    starts = _slsqp_starts(monkeypatch)
    cfg = improved.config
    assert offsets_mod.solve_offsets(improved, 14.0, A40,
                                     bound=cfg.feasibility.max_attitude_offset) is None
    assert len(starts) == 1


def test_the_search_stops_at_its_own_accuracy(monkeypatch):
    """Issue 39: at 10 m/s and 40 deg with a motor lag the least-squares offsets (3e-3 deg)
    are found in a few SLSQP iterations; at a tolerance of 1e-10 the search took the
    rounding-level violations of its 2048 bounds for ones to remove and ran about 70
    iterations and 500 trims. At ``FTOL`` it stops within 10."""

    model = paper_model(**{"effects.motor_lag.tau": IMPROVED["effects.motor_lag.tau"]})
    cfg = model.config
    lo = cfg.vehicle.thrust_min + cfg.feasibility.thrust_margin
    hi = cfg.vehicle.thrust_max - cfg.feasibility.thrust_margin
    runs = []
    orig = offsets_mod.minimize

    def counted(fun, x0, **kwargs):
        runs.append(orig(fun, x0, **kwargs))
        return runs[-1]

    monkeypatch.setattr(offsets_mod, "minimize", counted)
    off = offsets_mod._solve(model, 10.0, A40, cfg.feasibility.max_attitude_offset,
                             offsets_mod.HARMONICS, offsets_mod.N_NODES,
                             lo + offsets_mod.NODE_SAFETY_N, hi - offsets_mod.NODE_SAFETY_N)
    (run,) = runs
    assert off is not None and run.success and run.nit <= 10, (run.nit, run.nfev)
    assert 1e-3 < np.abs(run.x).max() < 1e-2  # deg
