"""Model versus measurement (issue 6): residuals, statistics, where it fails, paper analyses.

Simulated campaigns (:mod:`gainsched.sim.campaign`, 2.5 s flights at 3-15 m/s, tilts
0/20/40 deg, a speed-up and a braking, motion-capture noise on) are flown once per
module; the analysis config is configs/paper.toml.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.analysis.compare import AXES, compare, load_segments, measure, residuals
from gainsched.analysis.logs import log_from_arrays, write_log
from gainsched.analysis.paperfits import paper_fits
from gainsched.cli import cli
from gainsched.config import config_from_text, load_config, set_values
from gainsched.errors import InputError
from gainsched.rotations import matrix_from_euler_zyx, quaternion_from_matrix
from gainsched.schedule.tables import load_table
from gainsched.sim.campaign import default_flights, write_campaign
from gainsched.sim.loop import table_scheduler

from support import PAPER_H5, paper_config_text
from support import PAPER_TOML as PAPER


@pytest.fixture(scope="module")
def truth(paper_config, fly):
    """The truth model (the real tether the campaigns fly on) against its own flights."""
    from gainsched.sim.campaign import plant_config

    return compare(plant_config(paper_config, "none", real_tether=True), fly("none"))


def _circle_log(v=8.0, phi=-0.3, accel=0.0, T=10.0, rate=200.0, alpha=0.0, noise=0.0, seed=0):
    """Exact pose of a circle (delta = pi/2, theta = chi = 0, constant roll) at COG speed
    v (m/s) with tangential acceleration ``accel`` (m/s^2), on the paper geometry."""
    rho, L_e = 1.5, 0.1
    r = rho + L_e
    t = np.arange(0, T, 1 / rate)
    xi = (v * t + 0.5 * accel * t * t) / r
    R_CB = matrix_from_euler_zyx(np.full_like(t, phi), np.zeros_like(t), xi)
    e = np.stack([np.cos(xi), np.sin(xi), np.zeros_like(t)], -1)
    p_C = rho * e + L_e * R_CB[:, :, 0]
    from gainsched.rotations import R_IC_from_tilt

    R_IC = R_IC_from_tilt(alpha)
    p_I = p_C @ R_IC.T
    R_IB = np.einsum("ij,njk->nik", R_IC, R_CB)
    rng = np.random.default_rng(seed)
    p_I = p_I + noise * rng.standard_normal(p_I.shape)
    q = quaternion_from_matrix(R_IB)
    meta = {"alpha_c_deg": math.degrees(alpha), "gamma_c_deg": 0, "flight_id": "circle"}
    return log_from_arrays(t, p_I, q, np.full((t.size, 4), 1.3), meta, source="circle.csv")


def test_measure_reconstructs_circle_kinematics(paper_config):
    """Exact circle: the reduced state, the COG acceleration in the path frame (0, 0,
    -r xi'^2) and the body rates (0, xi' sin phi, xi' cos phi) come back."""
    v, phi, r = 8.0, -0.3, 1.6
    m = measure(_circle_log(v, phi), paper_config)
    c = m.core
    w = v / r
    assert np.allclose(m.z[c, 0], np.pi / 2, atol=1e-9)
    assert np.allclose(m.z[c, 3], w, rtol=1e-9)
    assert np.allclose(m.z[c, 4], phi, atol=1e-9)
    assert np.allclose(m.z[c, 7:10], [0.0, w * np.sin(phi), w * np.cos(phi)], atol=1e-8)
    assert np.allclose(m.omega_dot[c], 0.0, atol=1e-6)
    a = np.einsum("nij,nj->ni", m.axes[c], m.a[c])
    assert np.allclose(a, [0.0, 0.0, -r * w * w], atol=1e-6)
    assert np.allclose(m.d[c], 1.5, atol=1e-12)


def test_measure_tangential_acceleration_and_tilt(paper_config):
    """A speed-up on a 30 deg circle: tangential acceleration = r xi''; pose in the
    inertial frame is rotated into C with the log's alpha_C."""
    m = measure(_circle_log(3.0, -0.2, accel=2.5, T=3.0, alpha=math.radians(30)),
                paper_config)
    c = m.core
    a = np.einsum("nij,nj->ni", m.axes[c], m.a[c])
    assert np.allclose(a[:, 0], 2.5, atol=1e-6)
    assert np.allclose(a[:, 1], 0.0, atol=1e-6)
    speed = np.linalg.norm(m.v[c], axis=-1)
    assert np.allclose(a[:, 2], -(speed**2) / 1.6, rtol=1e-6)


def test_truth_model_residual_at_noise_floor_and_white(truth):
    """Analysis model = plant: every axis at its noise floor, unbiased, white,
    no input correlation at the 95% (multiple-lag corrected) level on most axes."""
    assert set(truth.axes) == set(AXES)  # load cell logged: radial axis present
    for a, s in truth.stats.items():
        assert 0.8 < s.rms_over_noise < 1.2, (a, s.rms_over_noise)
        assert abs(s.bias) < 0.1 * s.noise_floor, (a, s.bias)
    assert all(s.white for s in truth.stats.values()), {
        a: s.whiteness_q for a, s in truth.stats.items()}
    sig = sum(v[3] for s in truth.stats.values() for v in s.ccf.values())
    assert sig <= 3  # of 56 axis x input pairs
    assert truth.where["sentence"].startswith("every axis is within")
    assert truth.normalized_rms() < 1.15


def test_hidden_rotor_drag_shows_where_it_fails(paper_config, fly):
    """Rotor drag hidden in the plant: tangential and normal residuals far above noise,
    not white, and the worst regime is named against airspeed."""
    c = compare(paper_config, fly("rotor_drag"))
    for a in ("tangential", "normal"):
        assert c.stats[a].rms_over_noise > 2.5 and not c.stats[a].white
        assert c.stats[a].fit_percent < 90
    for a in ("roll", "pitch", "yaw"):
        assert c.stats[a].rms_over_noise < 1.25
    assert c.stats["stretch"].rms_over_noise < 2.0  # the real tether's own 0.3 mm
    w = c.where["worst"]
    assert w["axis"] == "tangential" and w["variable"] in ("airspeed", "tension")
    assert "grows with" in c.where["sentence"]
    tab = c.where["tables"]["airspeed"]
    rms = np.array(tab["tangential"]["rms"], dtype=float)
    cnt = np.array(tab["count"])
    ok = cnt > 40
    assert rms[ok][-1] > 3 * rms[ok][0]  # grows with speed


def test_motor_lag_shows_in_input_rate_correlation(paper_config, fly):
    """A 35 ms motor lag correlates the roll residual with the roll-torque command rate at
    a small positive lag (the residual follows the input)."""
    c = compare(paper_config, fly("motor_lag"))
    peak, lag, band, sig = c.stats["roll"].ccf["tau_x_rate"]
    assert sig and peak > 3 * band
    assert 0.0 <= lag <= 0.05


def test_latency_in_config_removes_the_residual(paper_config, fly):
    """The latency candidate's home is [analysis] latency_s: with the true 15 ms the
    residual of the latency campaign falls back to the noise floor. (The on-board sensors
    share the commands' clock: the load cell against the accelerometer does not see the
    pose's lag, the gyro's roll against the commanded torque does: measured 1.92 -> 1.00
    times its floor.)"""
    before = compare(paper_config, fly("latency"))
    cfg = config_from_text(set_values(paper_config.text, {"analysis.latency_s": 0.015}))
    after = compare(cfg, fly("latency"))
    assert before.stats["roll"].rms_over_noise > 1.5
    assert after.stats["roll"].rms_over_noise < 1.2
    assert after.normalized_rms() < before.normalized_rms()


def test_tension_from_radial_equation_without_load_cell(paper_config, fly):
    """No load cell: the radial equation gives the tension, the radial axis is not
    reported, and the other axes are still at the noise floor for the true model."""
    logs = fly("none", ("v9", "tilt40-v7", "braking"), load_cell=False)
    c = compare(paper_config, logs)
    assert "radial" not in c.axes
    assert {r.tension_source for r in c.residuals} == {"radial equation"}
    for a, s in c.stats.items():
        assert s.rms_over_noise < 1.25, (a, s.rms_over_noise)
    ten = np.concatenate([r.variables["tension"] for r in c.residuals])
    assert ten.max() > 20  # the tension estimate tracks the centripetal load


def test_paper_drag_fit_recovers_mu(paper_config, truth):
    """Fig. 6: on flights with mu1 = 0.172, mu2 = 0.0025 the eq. 10 fit to the eq. 26
    drag estimates recovers both within 10%; eta_f (eq. 28) is 1 without thrust loss."""
    p = paper_fits(paper_config, truth.measured)
    assert p.mu1 == pytest.approx(0.172, rel=0.1)
    assert p.mu2 == pytest.approx(0.0025, rel=0.1)
    assert np.nanmedian(p.eta) == pytest.approx(1.0, abs=0.01)
    assert p.airspeed.max() > 13


def test_paper_thrust_efficiency_falls_with_thrust_loss(paper_config, fly):
    """Fig. 5: a hidden thrust loss with airspeed (T *= 1 - 0.01 v) shows as eta_f falling
    with airspeed by about 1% per m/s."""
    p = paper_fits(paper_config, compare(paper_config, fly("thrust_airspeed")).measured)
    slow, fast = p.airspeed < 5, p.airspeed > 12
    drop = np.median(p.eta[slow]) - np.median(p.eta[fast])
    speed_gap = np.median(p.airspeed[fast]) - np.median(p.airspeed[slow])
    assert drop / speed_gap == pytest.approx(0.01, rel=0.35)


def test_analysis_config_section(paper_config):
    base = paper_config.text
    assert paper_config.analysis.savgol_window_s == 0.1 and paper_config.analysis.savgol_order == 3
    cfg = config_from_text(set_values(base, {"analysis.savgol_window_s": 0.2,
                                             "analysis.savgol_order": 4}))
    assert (cfg.analysis.savgol_window_s, cfg.analysis.savgol_order) == (0.2, 4)
    bad = [("savgol_order", 1), ("savgol_order", 2.5), ("savgol_window_s", 0),
           ("latency_s", -0.01), ("window", 3)]
    for name, value in bad:
        key = f"analysis.{name}"
        with pytest.raises(InputError, match=key.replace(".", r"\.")):
            config_from_text(set_values(base, {key: value}), "x.toml")


def test_window_errors_name_file_and_key(paper_config, tmp_path):
    cfg = config_from_text(set_values(paper_config.text, {"analysis.savgol_window_s": 0.01}),
                           "tiny.toml")
    with pytest.raises(InputError, match=r"tiny\.toml: analysis\.savgol_window_s"):
        measure(_circle_log(T=1.0), cfg)
    short = _circle_log(T=0.2)
    path = tmp_path / "short.csv"
    write_log(path, short)
    with pytest.raises(InputError, match=r"short\.csv: column t.*differentiation window"):
        load_segments(paper_config, [path])


def test_gaps_split_and_reported(paper_config, tmp_path):
    """A gap splits the log into segments, each differentiated on its own, and is reported."""
    log = _circle_log(T=4.0, noise=0.0005)
    cols = log.columns()
    keep = (cols["t"] < 1.5) | (cols["t"] > 1.8)
    path = tmp_path / "gap.csv"
    write_log(path, {k: v[keep] for k, v in cols.items()}, log.meta)
    m, segs, notes = load_segments(paper_config, [path])
    assert len(m) == 2 and len(segs) == 2
    assert any("gap" in n for n in notes)
    res = residuals(paper_config, m)
    assert [r.name for r in res] == ["circle#1", "circle#2"]


@pytest.mark.slow
def test_cli_compare_writes_report(paper_config, fly, tmp_path):
    logs = fly("drag_quadratic")
    paths = write_campaign(tmp_path / "logs", logs[:4])
    paths += write_campaign(tmp_path / "logs", logs[4:], "h5")
    out = tmp_path / "rep"
    before = tmp_path / "before.toml"  # an earlier config: the drag of the paper halved
    before.write_text(paper_config_text(**{"effects.drag.mu2": 0.00125}))
    res = CliRunner().invoke(cli, ["compare", str(PAPER), *map(str, paths), "-o", str(out),
                                   "--before", str(before)])
    assert res.exit_code == 0, res.output
    assert "where it fails: tangential residual grows with" in res.output
    assert "Fig. 6: drag fit" in res.output
    for f in ("compare.json", "compare.md", "compare_residuals.png", "compare_acf_ccf.png",
              "compare_where.png", "paper_drag.png", "paper_thrust_efficiency.png",
              "before_after.md", "before_after.png"):
        assert (out / f).stat().st_size > 0, f
    data = json.loads((out / "compare.json").read_text())
    ax = data["axes"]["tangential"]
    assert {"rms", "bias", "fit_percent", "noise_floor", "white", "ccf_peaks", "acf"} <= set(ax)
    assert data["where_it_fails"]["worst"]["axis"] == "tangential"
    assert set(data["where_it_fails"]["tables"]) == {
        "airspeed", "tilt", "azimuth", "tension", "thrust", "time"}
    fit = data["paper_sec_v_c"]["drag_fit"]
    v = 14.0  # the simplified eq. 25-26 estimate sees the extra drag (mu2 tripled)
    assert fit["mu1"] * v + fit["mu2"] * v * v > 0.172 * v + 0.0025 * v * v + 0.3
    assert len(data["segments"]) == 7


def test_cli_compare_bad_log_exit_2(tmp_path):
    log = _circle_log(T=1.0)
    cols = log.columns()
    cols["T3"] = cols["T3"].copy()
    cols["T3"][17] = np.nan
    path = tmp_path / "bad.csv"
    write_log(path, cols, log.meta)
    res = CliRunner().invoke(cli, ["compare", str(PAPER), str(path)])
    assert res.exit_code == 2
    assert "bad.csv" in res.output and "T3" in res.output


def test_cli_campaign_writes_logs(tmp_path):
    """The example-data generator: 7 flights with the hidden effect named in the notes."""
    out = tmp_path / "flights"
    table = str(PAPER_H5)
    res = CliRunner().invoke(cli, ["campaign", str(PAPER), "--tables", table, "--hidden",
                                   "thrust_scale", "--duration", "1.0", "--no-load-cell",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    files = sorted(out.glob("*.csv"))
    assert len(files) == 7
    seg = load_segments(load_config(PAPER), files[:1])[1][0]
    assert "hidden: thrust_scale" in seg.meta["notes"] and "tension" not in seg.optional
    res = CliRunner().invoke(cli, ["campaign", str(PAPER), "--tables", table, "--hidden",
                                   "nope", "-o", str(out)])
    assert res.exit_code == 2 and "unknown hidden effect" in res.output


def test_log_without_thrust_refused(paper_config, tmp_path):
    """All-zero commanded thrust: no model prediction is possible (it gave 'RMS inf' and
    exit 0 in the thrust-efficiency analysis); refused naming the file and the columns."""
    log = _circle_log(T=3.0, noise=0.0005)
    cols = log.columns()
    for j in range(1, 5):
        cols[f"T{j}"] = np.zeros_like(cols[f"T{j}"])
    path = tmp_path / "nothrust.csv"
    write_log(path, cols, log.meta)
    with pytest.raises(InputError) as info:
        load_segments(paper_config, [path])
    assert info.value.source == str(path)
    assert info.value.where == "columns T1, T2, T3, T4, lines 6-605", info.value.where
    assert "thrust is zero on every sample" in info.value.message
    res = CliRunner().invoke(cli, ["compare", str(PAPER), str(path), "-o", str(tmp_path / "r")])
    assert res.exit_code == 2, res.output
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "columns T1, T2, T3, T4" in err[0], err
    cols["T2"] = cols["T2"].copy()
    cols["T2"][:100] = 1.3  # some thrust: compared (a motor-off stretch is a valid flight)
    write_log(path, cols, log.meta)
    assert len(load_segments(paper_config, [path])[0]) == 1


def test_onboard_sensors_lower_the_noise_floors(paper_config, fly, truth):
    """The campaign logs a gyro (0.005 rad/s noise) and an accelerometer (0.1 m/s^2): the
    rotational axes take the angular acceleration from the gyro (one differentiation
    instead of two), the translational axes the acceleration from the accelerometer (none
    instead of two). Their noise floors fall against the pose alone (roll, the fast axis,
    by >= 70 %: measured -89 %, pitch -18 %, yaw -43 %, where the pose noise in the
    predicted tether torque dominates; every translational axis by >= 50 %: measured
    -66 %, -64 %, -88 %), the report says so, and the pose-alone floors equal the floors
    a run with ``use_gyro`` and ``use_accelerometer`` off measures (second formulation,
    same noise draws: 1e-9)."""
    rot, trans = ("roll", "pitch", "yaw"), ("tangential", "normal", "radial")
    assert set(truth.pose_noise) == set(rot + trans)
    for a, p in truth.pose_noise.items():
        assert truth.noise[a] < p, a
    assert truth.noise["roll"] <= 0.3 * truth.pose_noise["roll"]
    for a in trans:
        assert truth.noise[a] <= 0.5 * truth.pose_noise[a], a
    lines = truth.sensor_lines()
    assert len(lines) == 6 and lines[0].startswith("roll: noise floor") and "-" in lines[0]
    assert any(ln.startswith("radial: noise floor") and "accelerometer" in ln for ln in lines)
    js = truth.to_json()
    assert js["gyro"]["used"] and js["accelerometer"]["used"]
    assert set(js["accelerometer"]["pose_noise_floor"]) == set(trans)
    off = compare(paper_config.with_values({"analysis.use_gyro": False,
                                            "analysis.use_accelerometer": False}), fly("none"))
    assert off.pose_noise == {} and off.sensor_lines() == []
    for a in rot + trans:
        assert off.noise[a] == pytest.approx(truth.pose_noise[a], rel=1e-9), a


def test_gyro_channel_is_exact_on_noise_free_flights(paper_config):
    """Noise-free flights, analysis model = plant: with the gyro, the predicted angular
    acceleration goes through the same filter as the measured one (the derivative of the
    running integral), so the residual is <= 0.5 % of the signal on every rotational axis
    (measured <= 0.3 %), and on roll at least 10x below the twice-differentiated pose's."""
    import dataclasses

    from gainsched.sim.campaign import fly as fly_logs
    from gainsched.sim.loop import Sensing

    sched = table_scheduler(load_table(PAPER_H5))
    quiet = Sensing(False, 200.0, 0.0, 0.0, 0.0, 0.0, 1)
    scn = [dataclasses.replace(s, sensing=quiet) for s in default_flights(2.5)
           if s.name in ("speedup", "tilt40-v7")]
    logs = fly_logs(paper_config, sched, scn, paper_config)
    rms = lambda x: float(np.sqrt(np.mean(x * x)))  # noqa: E731
    gyro = residuals(paper_config, load_segments(paper_config, logs)[0])
    off = paper_config.with_values({"analysis.use_gyro": False,
                                    "analysis.use_accelerometer": False})
    pose = residuals(off, load_segments(off, logs)[0])
    for rg, rp in zip(gyro, pose, strict=True):
        for a in ("roll", "pitch", "yaw"):
            assert rms(rg.residual[a]) <= 5e-3 * rms(rg.measured[a]), (rg.name, a)
        assert rms(rg.residual["roll"]) * 10 <= rms(rp.residual["roll"]), rg.name
        # the accelerometer (the mean specific force over the sample interval, rotated by
        # the pose's attitude, smoothed like the prediction): every translational axis
        # within 1e-3 of the acceleration's size (measured <= 5e-4)
        size = math.sqrt(sum(rms(rg.measured[a]) ** 2 for a in ("tangential", "normal",
                                                                  "radial")))
        for a in ("tangential", "normal", "radial"):
            assert rms(rg.residual[a]) <= 1e-3 * size, (rg.name, a, rms(rg.residual[a]))


@pytest.mark.parametrize("use_gyro", [True, False])
def test_fit_fast_path_equals_the_report_bit_for_bit(paper_config, fly, use_gyro):
    """``residual_axes`` (the fits' path: convolution without the end fits, the pose-smoothed
    angular acceleration skipped when a gyro supplies it) returns exactly the residual the
    report computes on the core samples (``savgol_filter``'s interior is the same
    convolution): bit for bit, with a model that has a state (motor lag) and a latency."""
    from gainsched.analysis.compare import residual_axes
    from gainsched.model.reduced import Model

    cfg = paper_config.with_values({"analysis.use_gyro": use_gyro})
    model = Model(config_from_text(paper_config_text(**{"effects.motor_lag.tau": 0.03})))
    meas = load_segments(cfg, fly("none", ("speedup", "v9")))[0]
    for m in meas:
        full = residuals(cfg, [m], model=model, latency=0.012)[0].residual
        fast = residual_axes(model, m, 0.012)
        assert set(fast) == set(full)
        for a in full:
            np.testing.assert_array_equal(fast[a], full[a], err_msg=f"{m.name} {a}")


def test_whiteness_test_holds_its_level_on_heteroscedastic_segments():
    """Seven segments of filtered white noise (correlated within the window W, like the
    residual) whose levels differ 18x, as the pitch axis' from 3 to 15 m/s: the 99 %
    whiteness test rejects at most 4 % of 200 draws (the residual standardised by its
    local RMS). Pooling the raw residual instead rejects far more often (the loudest
    segment carries the pooled correlation while the Bartlett variance counts every
    sample)."""
    from gainsched.analysis.compare import Residual, axis_stats

    W, n = 21, 431
    scales = np.geomspace(0.2, 3.6, 7)
    kernel = np.hanning(W + 2)[1:-1]
    rng = np.random.default_rng(7)
    rejected = 0
    for _ in range(200):
        res = []
        for k, sc in enumerate(scales):
            e = sc * np.convolve(rng.standard_normal(n + W - 1), kernel, "valid")
            res.append(Residual(f"s{k}", "synthetic", np.arange(n) * 0.005, {"pitch": e},
                                {"pitch": np.zeros(n)}, {"pitch": e}, {}, {}, "load cell", W))
        rejected += not axis_stats(res, "pitch").white
    assert rejected / 200 <= 0.04, rejected


def test_another_centre_of_mass_moves_the_measured_cog_as_measuring_again(paper_config, fly):
    """A second formulation: ``Measured.with_attachment`` (what diagnose's COG-offset fit
    uses instead of differentiating the pose again per evaluation) gives the COG's
    position, velocity and acceleration that ``measure`` gives with the offset in the
    config, to 1e-12 (the offset itself moves the acceleration by up to 0.3 m/s^2)."""
    from gainsched.analysis.compare import attachment_from_cog_config

    cfg = config_from_text(paper_config.text + "\n[effects.cog_offset]\nx = 0.002\n"
                           "y = 0.003\nz = -0.002\n", "cog.toml")
    for log in fly("cog_offset")[:3]:
        base, direct = measure(log, paper_config), measure(log, cfg)
        moved = base.with_attachment(attachment_from_cog_config(cfg))
        for k in ("p", "v", "a", "p_e"):
            np.testing.assert_allclose(getattr(moved, k), getattr(direct, k), rtol=0, atol=1e-12)
        assert np.abs(direct.a - base.a).max() > 0.05
