"""A lab's flight day: the flight controller's log and the motion capture's recording,
two files on two clocks (issue 55).

A simulated flight of 30 s (the paper table, 20 deg tilt, a speed-up and a braking) is
written as a lab records it: the flight controller's PX4 ULog (gyro and accelerometer
at 1 kHz in FRD with noise, the motors at 400 Hz normalised, stamped from boot) and the
motion capture's ROS 2 bag (PoseStamped at 100 Hz, ENU about an anchor off the origin,
0.5 mm and 0.2 deg of noise, stamped in Unix time). The clocks are aligned from the
motion both hold; the offset is checked against the truth the files were written with,
and the converted log against the one converted with the true offset given by hand.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gainsched.analysis.logs import read_log
from gainsched.analysis.logs._channelmap import PX4_MOTOR_ORDER, channel_map_from_text
from gainsched.analysis.logs._clocks import (
    BIN_S,
    align_clocks,
    rate_magnitude,
)
from gainsched.errors import InputError

from support import ros_types, write_bag, write_ulog

BOOT = 12.0  # s on the flight controller's clock when the flight starts
EPOCH = 1_764_000_000.2347  # s, Unix time of the motion capture when the flight starts
M_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
C_FRD = np.diag([1.0, -1.0, -1.0])
ANCHOR_ENU = np.array([-0.4, 2.2, 0.3])
FAC = 0.3


@pytest.fixture(scope="module")
def day(paper_config, paper_table):
    """A 30 s flight with a speed-up at 8 s and a braking at 18 s (the true states)."""
    from gainsched.sim.loop import Maneuver, Scenario, simulate, table_scheduler

    scn = Scenario("day", math.radians(20.0), 6.0, 30.0,
                   maneuvers=(Maneuver(8.0, 10.0, 2.0), Maneuver(18.0, 5.0, 2.0)))
    return simulate(paper_config, table_scheduler(paper_table), scn)


def fc_ulog(path, res, thrust_max, seed=0):
    """The flight controller's ULog of ``res``: gyro and accelerometer (FRD, noise) at
    1 kHz, motors at 400 Hz normalised through PX4's curve, stamped from boot."""
    rng = np.random.default_rng(seed)
    us = lambda t: np.round((t + BOOT) * 1e6).astype(np.uint64)  # noqa: E731
    gyro = res.z[:, 7:10] @ C_FRD.T + 0.005 * rng.standard_normal((res.t.size, 3))
    acc = res.f_B @ C_FRD.T + 0.05 * rng.standard_normal((res.t.size, 3))
    tm = np.arange(0.0, res.t[-1], 0.0025)
    T = res.u[np.floor(tm / 1e-3 + 1e-9).astype(int)]
    y = T / thrust_max
    c = (-(1 - FAC) + np.sqrt((1 - FAC) ** 2 + 4 * FAC * y)) / (2 * FAC)
    ctl = np.full((tm.size, 8), np.nan)
    for k, m in enumerate(PX4_MOTOR_ORDER):
        ctl[:, m - 1] = c[:, k]
    write_ulog(path, {
        "vehicle_angular_velocity": {"timestamp": us(res.t),
                                     **{f"xyz[{j}]": gyro[:, j] for j in range(3)}},
        "sensor_combined": {"timestamp": us(res.t),
                            **{f"accelerometer_m_s2[{j}]": acc[:, j] for j in range(3)}},
        "actuator_motors": {"timestamp": us(tm),
                            **{f"control[{j}]": ctl[:, j] for j in range(8)}},
    }, {"THR_MDL_FAC": FAC})


def mocap_bag(path, res, *, drift=0.0, seed=1, start=0.0, stop=None):
    """The motion capture's bag of ``res`` at 100 Hz (from ``start`` to ``stop`` s):
    PoseStamped in ENU about ANCHOR_ENU with noise, stamped ``EPOCH + t (1 + drift)``."""
    rng = np.random.default_rng(seed)
    T = ros_types().types
    k = np.arange(0, res.t.size, 10)
    k = k[(res.t[k] >= start) & (res.t[k] <= (res.t[-1] if stop is None else stop))]
    p = res.p_I[k] + ANCHOR_ENU + 0.0005 * rng.standard_normal((k.size, 3))
    q = (Rotation.from_quat(res.q_IB[k], scalar_first=True) * Rotation.from_rotvec(
        math.radians(0.2) * rng.standard_normal((k.size, 3)))).as_quat(scalar_first=True)
    msgs = []
    for j, t in enumerate(res.t[k]):
        ns = int(round((EPOCH + t * (1 + drift)) * 1e9))
        head = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
            sec=ns // 10**9, nanosec=ns % 10**9), frame_id="mocap")
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](*p[j]),
            orientation=T["geometry_msgs/msg/Quaternion"](x=q[j, 1], y=q[j, 2], z=q[j, 3],
                                                          w=q[j, 0]))
        msgs.append((ns, T["geometry_msgs/msg/PoseStamped"](header=head, pose=pose)))
    write_bag(path, {"/mocap/pose": ("geometry_msgs/msg/PoseStamped", msgs)})


POSE_MAP = f"""schema = "gainsched-channelmap/1"
name = "mocap"
[frames]
world = "ENU"
body = "FLU"
anchor_m = {ANCHOR_ENU.tolist()}
[circle]
alpha_c_deg = 20.0
gamma_c_deg = 0.0
[position]
topic = "/mocap/pose"
fields = ["pose.position.x", "pose.position.y", "pose.position.z"]
[attitude]
topic = "/mocap/pose"
fields = ["pose.orientation.w", "pose.orientation.x", "pose.orientation.y",
          "pose.orientation.z"]
"""


def pose_map(**time):
    text = POSE_MAP + ("[time]\n" + "".join(f"{k} = {v!r}\n" for k, v in time.items())
                       if time else "")
    return channel_map_from_text(text, "mocap.toml", pose_only=True)


@pytest.fixture(scope="module")
def files(day, paper_config, tmp_path_factory):
    """The day's two files, once: ``(fc.ulg, mocap bag)``."""
    folder = tmp_path_factory.mktemp("day")
    fc, bag = folder / "fc.ulg", folder / "mocap"
    fc_ulog(fc, day, paper_config.vehicle.thrust_max)
    mocap_bag(bag, day)
    return fc, bag


def test_two_files_on_two_clocks_convert_as_one(files, paper_config, tmp_path):
    """The offset found is the truth (the pose at Unix time EPOCH + t is the flight
    controller's BOOT + t) within three of its standard errors and 2 ms; the converted
    log is the one converted with the true offset given by hand, but for its times,
    which move by the offset's error and no more."""
    from gainsched.analysis.logs import convert_log

    fc, bag = files
    report, (log,) = convert_log(fc, tmp_path / "day.csv", channel_map="px4", pose=bag,
                                 pose_map=pose_map(), thrust_max=paper_config.vehicle.thrust_max)
    assert report[0].startswith("clocks: pose time - 1763999988.23"), report
    truth = BOOT - EPOCH
    offset = float(log.meta["clock_offset_s"])
    sigma = float(log.meta["clock_offset_sigma_s"])
    assert abs(offset - truth) <= max(3 * sigma, 2e-3), (offset - truth, sigma)
    assert 0 < sigma < 2e-3
    _, (hand,) = convert_log(fc, tmp_path / "hand.csv", channel_map="px4", pose=bag,
                             pose_map=pose_map(pose_offset_s=truth),
                             thrust_max=paper_config.vehicle.thrust_max)
    n = min(log.t.size, hand.t.size)
    shift = log.t[:n] - hand.t[:n]
    assert np.ptp(shift) < 1e-6 and abs(shift[0]) < 2e-3  # one shift, the offset's error
    np.testing.assert_array_equal(log.p_I[:n], hand.p_I[:n])
    np.testing.assert_allclose(log.T_cmd[:n], hand.T_cmd[:n], atol=0.05)
    assert log.meta["pose_source"] == "mocap" and "clock_offset_s" not in hand.meta


def test_the_clock_fit_finds_a_drift_over_a_long_day():
    """Ten minutes of a band-limited motion seen by two clocks 40 ppm apart (24 ms by
    the end), with independent noise: the drift within three standard errors of the
    truth and better than 5 ppm; the offset at the reference time within 1 ms."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 600.0, 0.001)
    from scipy.ndimage import gaussian_filter1d

    w = np.abs(gaussian_filter1d(rng.standard_normal(t.size), 40.0) * 40 + 2.0)
    d, off = 40e-6, 1234.5678
    t_pose = np.arange(0.0, 600.0, 0.005)
    w_pose = np.interp(t_pose, t, w) + 0.02 * rng.standard_normal(t_pose.size)
    fit = align_clocks({"body rate": (t, w + 0.02 * rng.standard_normal(t.size))},
                       {"body rate": (t_pose * (1 + d) + off, w_pose)})
    assert abs(fit.drift - (-d / (1 + d))) <= 3 * fit.drift_sigma and fit.drift_sigma < 5e-6
    t_ref = fit.t_ref_s
    truth = (t_ref - off) / (1 + d) - t_ref
    assert abs(fit.offset_s - truth) < 1e-3, (fit.offset_s - truth)
    assert "drift -40" in fit.line() or "drift -39" in fit.line(), fit.line()


def test_a_recording_of_another_flight_is_refused(day, paper_config, paper_table, files,
                                                   tmp_path):
    """The motion capture of another flight (another speed and tilt): no clock offset
    makes the motions match; one line, nothing written."""
    from gainsched.analysis.logs import convert_log
    from gainsched.sim.loop import Maneuver, Scenario, simulate, table_scheduler

    other = simulate(paper_config, table_scheduler(paper_table), Scenario(
        "other", 0.0, 9.0, 30.0, maneuvers=(Maneuver(12.0, 5.0, 3.0),)))
    bag = tmp_path / "other"
    mocap_bag(bag, other, seed=5)
    with pytest.raises(InputError, match=r"other: its motion does not match .*fc.ulg's at any "
                                         r"clock offset \(best correlation 0\.\d\d"):
        convert_log(files[0], tmp_path / "x.csv", channel_map="px4", pose=bag,
                    pose_map=pose_map(), thrust_max=paper_config.vehicle.thrust_max)
    assert not (tmp_path / "x.csv").exists()


def test_a_motion_that_repeats_is_ambiguous():
    """Body rates of a pure 1 Hz oscillation: every whole period matches as well; the
    offset is refused as ambiguous, not guessed."""
    t = np.arange(0.0, 60.0, 0.001)
    w = 2.0 + np.sin(2 * np.pi * t)
    with pytest.raises(InputError, match=r"the clock offset to .* is ambiguous"):
        align_clocks({"body rate": (t, w)}, {"body rate": (t[::5] + 100.0, w[::5])})


def test_the_pose_rate_is_the_rotation_rate():
    """A body turning at 1.3 rad/s about a tilted axis: the rate from the attitudes is
    1.3 rad/s (the bins are what the correlation sees)."""
    t = np.arange(0.0, 2.0, 0.005)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    q = Rotation.from_rotvec(1.3 * t[:, None] * axis).as_quat(scalar_first=True)
    tm, w = rate_magnitude(t, q)
    np.testing.assert_allclose(w, 1.3, rtol=1e-9)
    assert tm[0] == pytest.approx(0.01) and BIN_S == 0.01


def test_cli_convert_takes_the_two_files(files, paper_config, tmp_path):
    """``gainsched convert FC.ulg MOCAP -o OUT --pose-map MAP``: the clocks line first;
    --pose-map without POSE, and a pose map naming a motor, are one line each."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    fc, bag = files
    mp = tmp_path / "mocap.toml"
    mp.write_text(POSE_MAP)
    out = tmp_path / "day.csv"
    r = CliRunner().invoke(cli, ["convert", str(fc), str(bag), "-o", str(out), "--pose-map",
                                 str(mp), "--config", "paper"])
    assert r.exit_code == 0, r.output
    assert r.output.splitlines()[0].startswith("  clocks: pose time - "), r.output
    assert read_log(out)[0].meta["pose_channel_map"] == "mocap"
    r = CliRunner().invoke(cli, ["convert", str(fc), "-o", str(out), "--pose-map", str(mp)])
    assert r.exit_code == 2 and "--pose-map is the map of POSE" in r.output
    mp.write_text(POSE_MAP + '[gyro]\ntopic = "/imu"\nfields = ["a", "b", "c"]\n')
    r = CliRunner().invoke(cli, ["convert", str(fc), str(bag), "-o", str(tmp_path / "b.csv"),
                                 "--pose-map", str(mp), "--config", "paper"])
    assert r.exit_code == 2 and r.output.strip() == (
        f"gainsched: error: {mp}: gyro: a pose map names position and attitude only (the "
        "flight controller's map, --map, names the rest)"), r.output


# --------------------------------------------------------------------------- a whole day


def _hermite(p0, p1, v0, v1, t):
    """A cubic Hermite path from (p0, v0) to (p1, v1) at the times ``t`` (from 0)."""
    h = t[-1] + (t[1] - t[0])
    s = (t + (t[1] - t[0])) / h
    return ((2 * s**3 - 3 * s**2 + 1)[:, None] * p0 + (s**3 - 2 * s**2 + s)[:, None] * h * v0
            + (-2 * s**3 + 3 * s**2)[:, None] * p1 + (s**3 - s**2)[:, None] * h * v1)


@pytest.fixture(scope="module")
def whole_day(day, paper_config):
    """The flight of ``day`` inside a lab's day at 1 kHz: 6 s on the ground (disarmed), a
    4 s take-off onto the sphere, the 30 s flight, a 4 s landing, 6 s on the ground; on
    the ground and the bridges the attitude held, the rates 0, the specific force from
    the path, the thrust the weight's quarter (disarmed on the ground: NaN)."""
    from types import SimpleNamespace

    dt = 1e-3
    ground = np.array([1.0, 0.0, -0.2])
    g = np.array([0.0, 0.0, -paper_config.g])
    w4 = paper_config.vehicle.mass * paper_config.g / 4

    def still(n, p, q, T):
        return (np.repeat(p[None], n, 0), np.repeat(q[None], n, 0), np.full((n, 4), T))

    v0 = (day.p_I[1] - day.p_I[0]) / dt
    v1 = (day.p_I[-1] - day.p_I[-2]) / dt
    tb = np.arange(4000) * dt
    parts = [still(6000, ground, day.q_IB[0], np.nan),  # disarmed: PX4 logs NaN
             (_hermite(ground, day.p_I[0], np.zeros(3), v0, tb),
              np.repeat(day.q_IB[:1], 4000, 0), np.full((4000, 4), w4)),
             (day.p_I, day.q_IB, day.u),
             (_hermite(day.p_I[-1], ground, v1, np.zeros(3), tb),
              np.repeat(day.q_IB[-1:], 4000, 0), np.full((4000, 4), w4)),
             still(6000, ground, day.q_IB[-1], np.nan)]
    p = np.concatenate([a for a, _, _ in parts])
    q = np.concatenate([b for _, b, _ in parts])
    u = np.concatenate([c for _, _, c in parts])
    t = np.arange(p.shape[0]) * dt
    R = Rotation.from_quat(q, scalar_first=True)
    f_B = R.inv().apply(np.gradient(np.gradient(p, dt, axis=0), dt, axis=0) - g)
    rates = np.zeros((t.size, 3))
    k0 = 10000  # where the flight starts
    f_B[k0:k0 + day.t.size] = day.f_B
    rates[k0:k0 + day.t.size] = day.z[:, 7:10]
    z = np.zeros((t.size, 10))
    z[:, 7:10] = rates
    return SimpleNamespace(t=t, p_I=p, q_IB=q, u=u, f_B=f_B, z=z, flight=(k0 * dt, (
        k0 + day.t.size) * dt))


def test_a_whole_day_in_two_files_gives_its_flights(whole_day, paper_config, tmp_path):
    """The day as a lab records it (the ULog from boot, disarmed on the ground; the bag
    in Unix time): its three circles and two manoeuvres found inside the flight, the
    ground, take-off and landing dropped; ``convert --day -o DIR`` writes each kept
    flight, a summary (JSON, Markdown) and a picture of the day; ``compare --day`` takes
    the same two files, holds the five flights apart and finds the residual at the noise
    (the design model is the truth here)."""
    import json

    from click.testing import CliRunner

    from gainsched.cli import cli

    thrust_max = paper_config.vehicle.thrust_max
    fc, bag = tmp_path / "fc.ulg", tmp_path / "mocap"
    whole = whole_day
    fc_ulog(fc, whole, thrust_max)
    mocap_bag(bag, whole)
    mp = tmp_path / "mocap.toml"
    mp.write_text(POSE_MAP.replace("alpha_c_deg = 20.0", 'alpha_c_deg = "estimate"')
                  .replace("gamma_c_deg = 0.0", 'gamma_c_deg = "estimate"'))
    from gainsched.analysis.logs import read_day

    d = read_day(fc, config=paper_config, channel_map="px4", pose=bag, pose_map=str(mp))
    kinds = [q.kind for q in d.cut.kept]
    assert kinds == ["circle", "manoeuvre", "circle", "manoeuvre", "circle"], d.cut.lines()
    t0, t1 = whole.flight
    assert all(t0 + BOOT - 0.05 <= q.t0 and q.t1 <= t1 + BOOT + 0.05 for q in d.cut.kept)
    assert [q.kind for q in d.cut.pieces if not q.kept] == ["ground", "off the sphere",
                                                           "off the sphere", "ground"]
    assert [round(q.speed) for q in d.cut.kept] == [6, 6, 10, 10, 5]
    assert len(d.logs) == 5 and d.logs[1].meta["day_piece"] == "manoeuvre 6.0->10.0 m/s"

    out = tmp_path / "day"
    r = CliRunner().invoke(cli, ["convert", str(fc), str(bag), "--day", "-o", str(out),
                                 "--pose-map", str(mp), "--config", "paper"])
    assert r.exit_code == 0, r.output
    names = sorted(p.name for p in out.iterdir())
    assert names == ["01-circle.csv", "02-manoeuvre.csv", "03-circle.csv",
                     "04-manoeuvre.csv", "05-circle.csv", "day.json", "day.md", "day.png"]
    summary = json.loads((out / "day.json").read_text())
    assert [p["kind"] for p in summary["pieces"]][:2] == ["ground", "off the sphere"]
    (first,) = read_log(out / "01-circle.csv", config=paper_config)
    assert first.t.size == d.logs[0].t.size

    r = CliRunner().invoke(cli, ["compare", "paper", str(fc), "--pose", str(bag),
                                 "--pose-map", str(mp), "--day"])
    assert r.exit_code == 0, r.output
    assert "on 5 flight(s), 5 segment(s)" in r.output, r.output
    rms = float(re.search(r"normalised RMS \(1 = noise\): ([\d.]+)", r.output).group(1))
    assert rms < 1.2, r.output  # the model of the truth, read through two clocks: noise


def test_day_options_refused_in_one_line(files, tmp_path):
    """``convert --day`` without the config it is cut with, ``--pose`` beside two logs:
    one line each, exit 2, nothing written."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    fc, bag = files
    mp = tmp_path / "mocap.toml"
    mp.write_text(POSE_MAP)
    r = CliRunner().invoke(cli, ["convert", str(fc), str(bag), "--day", "-o",
                                 str(tmp_path / "d"), "--pose-map", str(mp)])
    assert r.exit_code == 2 and r.output.strip() == (
        "gainsched: error: command line: --day: needs --config CONFIG (the tether and the "
        "weight the day is cut with)"), r.output
    r = CliRunner().invoke(cli, ["compare", "paper", str(fc), str(fc.with_name("x.ulg")),
                                 "--pose", str(bag), "--pose-map", str(mp)])
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output
    fc.with_name("x.ulg").write_bytes(fc.read_bytes())
    r = CliRunner().invoke(cli, ["compare", "paper", str(fc), str(fc.with_name("x.ulg")),
                                 "--pose", str(bag), "--pose-map", str(mp)])
    assert r.exit_code == 2 and "--pose: goes with one LOG" in r.output, r.output
    assert not (tmp_path / "d").exists()


def test_diagnose_takes_the_days_two_files(whole_day, paper_config, tmp_path):
    """``diagnose CONFIG FC --pose BAG --pose-map MAP --day``: one day of five flights is
    enough for held-out scores; on the model's own truth nothing is missing."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    fc, bag = tmp_path / "fc.ulg", tmp_path / "mocap"
    fc_ulog(fc, whole_day, paper_config.vehicle.thrust_max)
    mocap_bag(bag, whole_day)
    mp = tmp_path / "mocap.toml"
    mp.write_text(POSE_MAP)
    r = CliRunner().invoke(cli, ["diagnose", "paper", str(fc), "--pose", str(bag),
                                 "--pose-map", str(mp), "--day", "--candidate", "motor_lag",
                                 "--candidate", "mass"])
    assert r.exit_code == 0, r.output
    assert "on 5 flight(s)" in r.output and "verdict: no effect needed" in r.output, r.output
