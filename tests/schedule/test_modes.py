"""The closed loop's slowest modes (gainsched/schedule/modes.py): closed forms, a fresh
monodromy, scipy's DARE, the paper table's figures, and what inspect and plot show."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.linalg import solve_discrete_are

import gainsched as gs
from gainsched.cli import cli
from gainsched.model.reduced import Model
from gainsched.schedule.grid import discrete_at
from gainsched.schedule.lqr import monodromy
from gainsched.schedule.modes import dominant_states, floquet_modes
from gainsched.schedule.path import period
from gainsched.schedule.tables import table_bytes, table_from_bytes
from gainsched.sim.plots import tracking_errors

from support import PAPER_H5, REPO


def _rotation(r, theta):
    c, s = np.cos(theta), np.sin(theta)
    return r * np.array([[c, -s], [s, c]])


def test_modes_of_a_known_map_are_its_closed_forms():
    """A map with a real mode 0.99, a pair 0.9 e^{+-i 0.3}, a real 0.5 and a fast pair,
    in a random basis: slowest first, tau = -T/ln|lambda|, frequency = arg/T, damping =
    -ln r / |ln lambda|, one entry per pair, and the shapes are the basis columns."""
    rng = np.random.default_rng(3)
    T = 0.7
    D = np.zeros((7, 7))
    D[0, 0] = 0.99
    D[1:3, 1:3] = _rotation(0.9, 0.3)
    D[3, 3] = 0.5
    D[4:6, 4:6] = _rotation(0.1, 2.0)
    D[6, 6] = -0.05  # a real negative eigenvalue: half a turn per period
    P = rng.normal(size=(7, 7))
    m = floquet_modes(P @ D @ np.linalg.inv(P), T, count=5)
    lam_r = np.array([0.99, 0.9, 0.5, 0.1, 0.05])
    np.testing.assert_allclose(m.tau, -T / np.log(lam_r), rtol=1e-10)
    np.testing.assert_allclose(m.frequency, np.array([0, 0.3, 0, 2.0, np.pi]) / T,
                               rtol=1e-10, atol=1e-12)
    zeta_pair = -np.log(0.9) / np.hypot(np.log(0.9), 0.3)
    np.testing.assert_allclose(m.damping[:3], [1, zeta_pair, 1], rtol=1e-10)
    # shape of the real slow mode: |first basis column|, largest entry 1
    v = np.abs(P[:, 0]) / np.abs(P[:, 0]).max()
    np.testing.assert_allclose(m.shape[0], v, rtol=1e-8)
    assert m.shape.max(axis=-1) == pytest.approx(np.ones(5))
    # batched: the same per map
    mb = floquet_modes(np.stack([D, D[::-1, ::-1]]), np.array([T, 2 * T]), count=2)
    np.testing.assert_allclose(mb.tau[1], -2 * T / np.log([0.99, 0.9]), rtol=1e-10)


def test_dominant_states_are_those_near_the_largest():
    names = ["a", "b", "c", "d"]
    assert dominant_states(np.array([0.2, 1.0, 0.5, 0.49]), names) == ["b", "c"]
    assert dominant_states(np.array([1.0, 0.0, 0.0, 0.0]), names) == ["a"]


@pytest.mark.slow
@pytest.mark.parametrize("speed", [3.0, 9.0, 15.0])
def test_stored_modes_equal_a_fresh_monodromy_and_the_dare(paper_config, speed):
    """The modes a build stores equal -T/ln|eig(monodromy)| of a fresh solve keeping every
    step (the monodromy multiplied out here), and at tilt 0 -dt/ln|eig(A - B K)| of
    scipy's DARE solved here, to 1e-9 relative."""
    tilts = np.deg2rad([0.0, 20.0, 40.0])
    sol = gs.solve_circle(paper_config, speed, tilts)
    fresh, (Ad, Bd, K) = gs.solve_circle(paper_config, speed, tilts, keep_steps=True)
    feasible = np.isfinite(sol.spectral_radius)
    assert feasible[:2].all()
    T = period(speed, paper_config.radius)
    for b, i in enumerate(np.flatnonzero(feasible)):
        lam = np.linalg.eigvals(monodromy(Ad[b], Bd[b], K[b]))
        lam = lam[lam.imag >= 0]
        tau = np.sort(-T / np.log(np.abs(lam)))[::-1][:4]
        np.testing.assert_allclose(sol.mode_tau[i], tau, rtol=1e-9, err_msg=f"tilt {i}")
    # tilt 0 by the DARE: the per-step closed loop
    model = Model(paper_config)
    n = sol.K.shape[-1]
    A, B = discrete_at(model, speed, [0.0], 1, sol.dt)
    Q, R = paper_config.control.Q, paper_config.control.R
    S = solve_discrete_are(A[0, 0], B[0, 0], Q, R)
    Kd = np.linalg.solve(R + B[0, 0].T @ S @ B[0, 0], B[0, 0].T @ S @ A[0, 0])
    lam = np.linalg.eigvals(A[0, 0] - B[0, 0] @ Kd)
    lam = lam[lam.imag >= 0]
    order = np.argsort(-np.abs(lam))[:4]
    np.testing.assert_allclose(sol.mode_tau[0], -sol.dt / np.log(np.abs(lam[order])),
                               rtol=1e-9)
    np.testing.assert_allclose(sol.mode_frequency[0], np.abs(np.angle(lam[order])) / sol.dt,
                               rtol=1e-9, atol=1e-12)
    assert n == 11


def test_paper_table_has_the_slow_integral_the_issue_measured():
    """configs/paper.toml's table: at tilt 0 the slowest mode is the out-of-plane integral,
    3.5 s, 22.6 s and 96.6 s at 3, 9 and 15 m/s (issue 20's figures)."""
    t = gs.load_table(PAPER_H5)
    for speed, tau in ((3.0, 3.5), (9.0, 22.6), (15.0, 96.6)):
        j = int(np.flatnonzero(t.speed == speed)[0])
        assert round(float(t.mode_tau[0, j, 0]), 1) == tau
        assert dominant_states(t.mode_shape[0, j, 0], t.state_names)[0] == "int_delta"
    feasible = np.isfinite(t.spectral_radius)
    assert np.array_equal(np.isfinite(t.mode_tau).all(-1), feasible)
    # the largest |lambda| is the spectral radius: tau_0 = -T / ln(rho)
    T = 2 * np.pi / t.xi_dot
    np.testing.assert_allclose(t.mode_tau[..., 0][feasible],
                               (-T / np.log(t.spectral_radius))[feasible], rtol=1e-9)


def test_inspect_prints_and_json_holds_the_slowest_mode_per_circle():
    t = gs.load_table(PAPER_H5)
    r = CliRunner().invoke(cli, ["inspect", str(PAPER_H5)])
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    head = next(k for k, ln in enumerate(lines) if "slowest closed-loop time constant" in ln)
    for i in range(t.tilt.size):  # one row per tilt, one column per speed
        cells = lines[head + 2 + i].split()[1:]
        want = ["-" if not np.isfinite(x) else f"{x:.3g}" for x in t.mode_tau[i, :, 0]]
        assert cells == want, i
    assert "slowest of all: 96.6 s at 15 m/s, 0 deg (int_delta" in r.output
    js = json.loads(CliRunner().invoke(cli, ["inspect", str(PAPER_H5), "--json"]).output)
    tau = np.array([[[np.nan if x is None else x for x in c] for c in row]
                    for row in js["modes"]["tau_s"]])
    np.testing.assert_array_equal(tau, t.mode_tau)
    assert js["modes"]["slowest"]["time_constant_s"] == np.nanmax(t.mode_tau)
    assert js["modes"]["dominant_states"][0][18][0][0] == "int_delta"


# --------------------------------------------------------------------------- the bound

TAU_MAX = 1.5


@pytest.fixture(scope="module")
def bounded(paper_config):
    """configs/paper.toml with every closed-loop mode bounded to 1.5 s."""
    return paper_config.with_values({"control.max_time_constant_s": TAU_MAX}, "bounded.toml")


@pytest.mark.slow
@pytest.mark.parametrize("speed", [3.0, 9.0, 15.0])
def test_bound_holds_on_a_fresh_monodromy_and_the_dare(paper_config, bounded, speed):
    """With max_time_constant_s = 1.5: the monodromy of the real system (A_k, B_k, not the
    scaled one) under the stored gains, multiplied out here, has every tau <= 1.5 s and
    the stored modes; at tilt 0 scipy's DARE of (c A, c B), c = exp(dt / 1.5), solved here
    gives the stored gain and modes. The feasibility is the paper config's (the bound
    changes gains, not nominal), and the gains rise: the price."""
    tilts = np.deg2rad([0.0, 20.0, 40.0])
    sol = gs.solve_circle(bounded, speed, tilts)
    free = gs.solve_circle(paper_config, speed, tilts)
    np.testing.assert_array_equal(sol.reasons, free.reasons)
    _, (Ad, Bd, K) = gs.solve_circle(bounded, speed, tilts, keep_steps=True)
    T = period(speed, bounded.radius)
    feasible = np.flatnonzero(np.isfinite(sol.spectral_radius))
    for b, i in enumerate(feasible):
        lam = np.linalg.eigvals(monodromy(Ad[b], Bd[b], K[b]))
        tau = -T / np.log(np.abs(lam))
        assert tau.max() <= TAU_MAX * (1 + 1e-9), (i, tau.max())
        lam = lam[lam.imag >= 0]
        np.testing.assert_allclose(sol.mode_tau[i], np.sort(-T / np.log(np.abs(lam)))[::-1][:4],
                                   rtol=1e-9)
    A, B = (x[0, 0] for x in discrete_at(Model(bounded), speed, [0.0], 1, sol.dt))
    c = np.exp(sol.dt / TAU_MAX)
    S = solve_discrete_are(c * A, c * B, bounded.control.Q, bounded.control.R)
    Kd = np.linalg.solve(bounded.control.R + c * c * B.T @ S @ B, c * c * B.T @ S @ A)
    np.testing.assert_allclose(sol.K[0, 0], Kd, rtol=1e-8, atol=1e-10)
    lam = np.linalg.eigvals(A - B @ Kd)
    assert (-sol.dt / np.log(np.abs(lam))).max() <= TAU_MAX
    np.testing.assert_allclose(sol.mode_tau[0, 0], (-sol.dt / np.log(np.abs(lam))).max(),
                               rtol=1e-9)
    assert np.nanmax(np.abs(sol.K)) > np.nanmax(np.abs(free.K))
    np.testing.assert_allclose(sol.gain_max_free[feasible],
                               np.abs(free.K[feasible]).max(axis=(1, 2, 3)), rtol=1e-12)
    np.testing.assert_array_equal(free.gain_max_free[feasible],
                                  np.abs(free.K[feasible]).max(axis=(1, 2, 3)))


def test_build_with_the_bound_meets_it_everywhere_and_prints_the_price(paper_config, tmp_path):
    """``gainsched build`` of a grid with max_time_constant_s = 1.5: every feasible circle's
    slowest tau in the table <= 1.5 s, the same feasibility as without the bound, and the
    price line (max |K| with and without the bound, both recomputed here)."""
    small = {"grid.speeds": [3, 9, 15], "grid.tilts_deg": [0, 20], "grid.azimuth_samples": 8}
    cfg = paper_config.with_values({**small, "name": "bounded",
                                    "control.max_time_constant_s": 1.5})
    (tmp_path / "bounded.toml").write_text(cfg.text)
    r = CliRunner().invoke(cli, ["build", str(tmp_path / "bounded.toml"), "-o", str(tmp_path)])
    assert r.exit_code == 0, r.output
    t = gs.load_table(tmp_path / "bounded.h5")
    free = gs.build_grid(paper_config.with_values(small))
    feasible = np.isfinite(t.spectral_radius)
    np.testing.assert_array_equal(feasible, np.isfinite(free.spectral_radius))
    np.testing.assert_array_equal(t.reasons, free.reasons)
    assert feasible.sum() >= 5
    assert np.nanmax(t.mode_tau) <= TAU_MAX
    k_max, k_free = np.nanmax(np.abs(t.K_full())), np.nanmax(np.abs(free.K))
    assert (f"slowest closed-loop mode {np.nanmax(t.mode_tau[..., 0]):.3g} s; the price: max |K| "
            f"{k_max:.3g}, {k_free:.3g} without the bound (x{k_max / k_free:.2f})") in r.output


# --------------------------------------------------------------------------- in closed loop


def _lqr_error(res):
    """The LQR state error of a flight with ideal sensing: ``z - z_d`` and the delta integral
    the controller integrates (``int_delta`` of dt (delta - delta_d), the simulator's)."""
    dt = res.t[1] - res.t[0]
    e = res.z - res.z_d
    return np.column_stack([e, np.concatenate([[0.0], np.cumsum(dt * e[:-1, 0])])])


@pytest.fixture(scope="module")
def bounded_table(paper_config):
    """A table of the paper config with max_time_constant_s = 3 (slowest modes ~1.5 s) on
    the speeds and tilts the decay test flies."""
    cfg = paper_config.with_values({"control.max_time_constant_s": 3.0, "name": "bounded3",
                                    "grid.speeds": [2.5, 3, 3.5, 8, 9, 10, 14, 15],
                                    "grid.tilts_deg": [0, 10, 20, 30]})
    return cfg, table_from_bytes(table_bytes(cfg, gs.build_grid(cfg), Model(cfg)))


def _decay_time_constants(cfg, table, speed, tilt_deg, modes, fly):
    """The time constants (s) of ``modes`` (indices, slowest first) measured in closed loop:
    ``fly(scenario)`` flown started 0.01 rad off in delta and xi, minus the same flight
    started on the nominal (which removes the small periodic error every flight has),
    projected on the left eigenvectors of a fresh monodromy (sampled once per period at
    the azimuth where the period starts), and a line fitted to the log of each projection
    over the first of 8 periods until it has fallen by 100."""
    _, (Ad, Bd, K) = gs.solve_circle(cfg, speed, np.deg2rad([tilt_deg]), keep_steps=True)
    lam, W = np.linalg.eig(monodromy(Ad[0], Bd[0], K[0]).T)  # left eigenvectors
    W = W[:, np.argsort(-np.abs(lam))]
    T = period(speed, cfg.radius)
    n_per = 8
    scn = gs.Scenario("decay", np.deg2rad(tilt_deg), speed, n_per * T + 0.01,
                      initial_error=(0.01, 0.01))
    x = _lqr_error(fly(scn)) - _lqr_error(fly(dataclasses.replace(scn, initial_error=())))
    ks = np.rint(np.arange(n_per + 1) * T * cfg.control.rate_hz).astype(int)
    taus = []
    for m in modes:
        c = np.abs(x[ks] @ W[:, m])[1:]
        # the periods until the mode has fallen by 100: the firmware's float32 state
        # (positions to ~1e-7 m) puts a floor near 3e-7 under the projections, which a
        # fast mode of a slow circle reaches within three periods (3 m/s: 13x per period)
        low = c < 1e-2 * c[0]
        keep = np.arange(np.argmax(low) if low.any() else c.size)
        assert keep.size >= 2, c
        taus.append(-1 / np.polyfit((keep + 1) * T, np.log(c[keep]), 1)[0])
    return np.array(taus)


def _stored_taus(table, speed, tilt_deg, modes):
    i = int(np.flatnonzero(np.isclose(table.tilt, np.deg2rad(tilt_deg)))[0])
    j = int(np.flatnonzero(table.speed == speed)[0])
    return table.mode_tau[i, j, list(modes)]


@pytest.mark.slow
@pytest.mark.parametrize("which", ["bounded", "paper"])
@pytest.mark.parametrize("speed", [3.0, 9.0, 15.0])
@pytest.mark.parametrize("tilt_deg", [0.0, 20.0])
def test_an_offset_decays_in_the_simulator_with_the_tables_time_constants(
        paper_config, paper_table, bounded_table, which, speed, tilt_deg):
    """Closed-loop proof on the design model (the nonlinear simulator, gains looked up in
    the table): an offset in delta and xi decays mode by mode with the table's time
    constants (:func:`_decay_time_constants`): the two slowest, within 5 % (issue 20 asks
    20 %; measured <= 1.6 %). The paper's slow integral at 15 m/s (97 s) is left out
    there: 8 periods do not measure it to 5 %."""
    cfg, table = (paper_config, paper_table) if which == "paper" else bounded_table
    modes = (1,) if which == "paper" and speed == 15.0 else (0, 1)
    sched = gs.table_scheduler(table)
    taus = _decay_time_constants(cfg, table, speed, tilt_deg, modes,
                                 lambda scn: gs.simulate(cfg, sched, scn))
    np.testing.assert_allclose(taus, _stored_taus(table, speed, tilt_deg, modes), rtol=0.05)


@pytest.fixture(scope="module")
def bounded_c_runtime(bounded_table):
    """The bounded table's C runtime compiled for the host (the firmware's own lookup; its
    tests are marked ``needs_cc``)."""
    return gs.runtime_scheduler(bounded_table[1], "c")


@pytest.mark.slow
@pytest.mark.needs_cc
@pytest.mark.parametrize("speed", [3.0, 9.0, 15.0])
@pytest.mark.parametrize("tilt_deg", [0.0, 20.0])
def test_an_offset_decays_on_the_firmware_path_with_the_tables_time_constants(
        bounded_table, bounded_c_runtime, speed, tilt_deg):
    """The same closed-loop proof flown as the firmware flies it
    (``simulate(controller="firmware")``): gains and nominal from the compiled C runtime
    (``gs_lookup_nominal``, float32), no trim of the design model. The bounded table's two
    slowest modes decay with the stored time constants within 5 % (measured <= 1.6 %)."""
    cfg, table = bounded_table
    assert bounded_c_runtime.source.startswith("C runtime")
    taus = _decay_time_constants(
        cfg, table, speed, tilt_deg, (0, 1),
        lambda scn: gs.simulate(cfg, bounded_c_runtime, scn, controller="firmware"))
    np.testing.assert_allclose(taus, _stored_taus(table, speed, tilt_deg, (0, 1)), rtol=0.05)


def test_the_bound_removes_the_out_of_plane_offset_of_a_weaker_thrust(paper_config):
    """On a plant whose thrust is 7 % below the model's (k_T = 0.93), the 20 deg circle at
    9 m/s starts with an out-of-plane offset (mean over the first period -8 mm); with
    max_time_constant_s = 1.5 it is gone after 3 tau_max (mean over the next period below
    5 % of it), while the paper's weights still carry more than half of it."""
    plant = paper_config.with_values({"effects.thrust_scale.k_T": 0.93})
    small = {"grid.speeds": [8, 9, 10], "grid.tilts_deg": [0, 10, 20, 30]}
    speed, T = 9.0, period(9.0, paper_config.radius)
    offsets = {}
    for tau_max in (None, 1.5):
        keys = small if tau_max is None else {**small, "control.max_time_constant_s": tau_max}
        cfg = paper_config.with_values(keys)
        table = table_from_bytes(table_bytes(cfg, gs.build_grid(cfg), Model(cfg)))
        scn = gs.Scenario("weak", np.deg2rad(20.0), speed, 3 * 1.5 + T + 0.01)
        res = gs.simulate(cfg, gs.table_scheduler(table), scn, plant)
        assert not res.saturated.any()
        e = tracking_errors(res)["out_of_plane_m"]
        first = e[res.t < T].mean()
        after = e[(res.t >= 4.5) & (res.t < 4.5 + T)].mean()
        offsets[tau_max] = first, after
    first, after = offsets[1.5]
    assert first < -0.005
    assert abs(after) < 0.05 * abs(first)
    first, after = offsets[None]
    assert abs(after) > 0.5 * abs(first)


# --------------------------------------------------------------------------- recommended


@pytest.mark.slow
def test_recommended_config_is_the_paper_with_the_integral_and_the_bound(paper_config):
    """configs/recommended.toml differs from configs/paper.toml in the name, the along-track
    integral (and its Q entry) and max_time_constant_s = 3, nothing else; on the paper's
    speeds and tilts x {3, 9, 15} m/s every feasible circle's slowest mode is <= 1.5 s and
    the feasibility is the paper's."""
    import tomllib

    rec = gs.load_config(REPO / "configs/recommended.toml")
    assert rec.control.integrators == ("int_delta", "int_xi")
    assert rec.control.max_time_constant_s == 3.0
    a, b = tomllib.loads(paper_config.text), tomllib.loads(rec.text)
    ca, cb = a.pop("control"), b.pop("control")
    assert (a.pop("name"), b.pop("name")) == ("paper", "recommended")
    assert a == b
    assert cb.pop("Q") == ca.pop("Q") + [1]
    assert (cb.pop("azimuth_integral"), cb.pop("max_time_constant_s")) == (True, 3.0)
    assert ca == cb
    for speed in (3.0, 9.0, 15.0):
        sol = gs.solve_circle(rec, speed, rec.grid.tilts)
        ref = gs.solve_circle(paper_config, speed, paper_config.grid.tilts)
        np.testing.assert_array_equal(sol.reasons, ref.reasons)
        feasible = np.isfinite(sol.spectral_radius)
        assert feasible.any()
        assert np.all(sol.mode_tau[feasible, 0] <= 1.5), (speed, sol.mode_tau[feasible, 0])


@pytest.mark.slow
def test_tradeoff_script_measures_what_the_bound_costs(tmp_path, monkeypatch):
    """examples/closed_loop_tradeoff.py on a coarse grid: the recommended config's slowest
    mode is <= 1.5 s against the paper's 97 s, its gains and command noise are larger; the
    JSON holds what the table prints."""
    import runpy
    import sys

    monkeypatch.chdir(REPO)
    out = tmp_path / "tradeoff.json"
    monkeypatch.setattr(sys, "argv", [
        "closed_loop_tradeoff.py", "configs/paper.toml", "configs/recommended.toml",
        "--speeds", "2.5,3,3.5,8,9,10,14,15", "--tilts", "0,20,40", "--json", str(out)])
    runpy.run_path(str(REPO / "examples/closed_loop_tradeoff.py"), run_name="__main__")
    paper_row, rec_row = json.loads(out.read_text())
    assert paper_row["slowest_mode_s"] > 90 and rec_row["slowest_mode_s"] <= 1.5
    assert rec_row["max_abs_K"] > 3 * paper_row["max_abs_K"]
    for flight, f in rec_row["flights"].items():
        assert f["command_noise_N"] > paper_row["flights"][flight]["command_noise_N"]
        assert f["out_of_plane_rms_mm"] < 5.0


def test_a_gain_cap_the_bound_exceeds_is_an_error_naming_the_circle(paper_config, tmp_path):
    """``[control] max_gain``: a bound that needs larger gains fails the build with one
    line naming the config, the key, the circle with the largest gain and both gains, exit
    code 2, and no table written; a cap above the gains builds."""
    small = {"grid.speeds": [3, 9, 15], "grid.tilts_deg": [0, 20], "grid.azimuth_samples": 8,
             "name": "capped", "control.max_time_constant_s": 1.5}
    grid = gs.build_grid(paper_config.with_values(small))
    k = np.nanmax(np.abs(grid.K), axis=(2, 3, 4))
    i, j = np.unravel_index(np.nanargmax(k), k.shape)
    cfg = paper_config.with_values({**small, "control.max_gain": 50.0})
    path = tmp_path / "capped.toml"
    path.write_text(cfg.text)
    r = CliRunner().invoke(cli, ["build", str(path), "-o", str(tmp_path / "out")])
    assert r.exit_code == 2, r.output
    line = r.output.strip()
    assert "\n" not in line and "Traceback" not in line
    speed, tilt = (3, 9, 15)[j], (0, 20)[i]
    assert speed == 15  # the fastest circle needs the largest gains
    assert line == (f"gainsched: error: {path}: control.max_gain: 50 is exceeded: max |K| "
                    f"{k[i, j]:.3g} at {speed} m/s, tilt {tilt} deg with max_time_constant_s 1.5 s "
                    f"({grid.gain_max_free[i, j]:.3g} without the bound): raise max_gain or "
                    "the bound")
    assert not (tmp_path / "out").exists()  # nothing published, no folder made
    ok = paper_config.with_values({**small, "control.max_gain": float(np.ceil(k.max()))})
    assert np.array_equal(gs.build_grid(ok).K, grid.K, equal_nan=True)
