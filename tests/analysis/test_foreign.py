"""PX4 ULog in through a channel map (issue 36).

A simulated flight (the paper table on the design model, 20 deg tilt, heading 30 deg,
1 kHz states) is written twice: as the project's own log at 100 Hz
(:func:`gainsched.sim.loop.log_from_result`) and as a PX4 ULog by pyulog's writer in
PX4's conventions: NED positions about an anchor that is not the origin, the FRD
attitude of ``vehicle_attitude`` at 250 Hz, ``vehicle_local_position`` at 100 Hz, the
gyro at 1 kHz, ``actuator_motors`` at 400 Hz normalised through PX4's thrust curve
(``THR_MDL_FAC`` 0.3 among the log's parameters) in PX4's motor order; and in the
older generation, ``actuator_outputs`` in PWM with ``sensor_combined``. Read through the
shipped maps, the ULog gives the CSV's columns and ``compare`` its residuals.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from gainsched.analysis.compare import MOTOR_ORDER_FACTOR, compare, motor_order_fits
from gainsched.analysis.diagnose import diagnose
from gainsched.analysis.logs import _cache as logcache
from gainsched.analysis.logs import _foreign as foreign
from gainsched.analysis.logs import read_log, write_log
from gainsched.analysis.logs._channelmap import (
    PX4_MOTOR_ORDER,
    channel_map_from_text,
    load_channel_map,
)
from gainsched.config import set_values
from gainsched.errors import InputError
from gainsched.model.effects import EFFECTS
from gainsched.model.reduced import Model
from gainsched.rotations import matrix_from_quaternion, quaternion_from_matrix
from gainsched.sim.campaign import HIDDEN, write_campaign
from gainsched.sim.loop import Scenario, Sensing, log_from_result, simulate, table_scheduler

from support import ros_types, story, write_bag, write_ulog

#: NED <-> ENU (its own inverse), FLU <-> FRD
M_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
C_FRD = np.diag([1.0, -1.0, -1.0])
ANCHOR_NED = np.array([1.5, -2.0, -0.75])  # where the anchor is in PX4's local frame, m
BOOT = 12.0  # s on the autopilot's clock when the flight starts
FAC = 0.3  # THR_MDL_FAC
TILT, HEADING = 20.0, 30.0


def normalized(T, thrust_max, fac=FAC):
    """Invert PX4's thrust curve T / T_max = (1 - f) c + f c^2 for the command c."""
    y = T / thrust_max
    return (-(1 - fac) + np.sqrt((1 - fac) ** 2 + 4 * fac * y)) / (2 * fac)


@pytest.fixture(scope="module")
def flight(paper_config, paper_table):
    scn = Scenario("ulog", math.radians(TILT), 9.0, 2.5, gamma=math.radians(HEADING))
    return simulate(paper_config, table_scheduler(paper_table), scn)


@pytest.fixture(scope="module")
def mocap_floor(paper_config, flight):
    """The scale of the residual tolerances: per axis, the noise floor of the same flight
    logged at 100 Hz by a motion capture of 0.5 mm and 0.2 deg (what the conversions'
    own differences are measured against: the 400 Hz command stream against the 1 kHz
    one, float32 fields)."""
    mocap = Sensing(False, 200.0, 0.0005, math.radians(0.2), 0.005, 0.0, 3, 0.1)
    noisy = dataclasses.replace(flight, scenario=dataclasses.replace(flight.scenario,
                                                                     sensing=mocap))
    return compare(paper_config, [log_from_result(noisy, rate_hz=100.0)]).noise


@dataclasses.dataclass(frozen=True)
class Streams:
    """A flight as the streams a flight stack logs, in the tool's frames and units, each
    at its own times (s of the flight): the pose (``t_pose``; ``p_I`` (n, 3) m and
    ``q_pose`` (n, 4)), the attitude on a topic of its own (``t_att``, ``q_att``), the IMU
    (``t_imu``; gyro ``omega_B`` rad/s and specific force ``f_B`` m/s^2, (n, 3)), the
    motor thrusts (``t_mot``, ``T_mot`` (n, 4) N, each held to the next sample) and the
    load cell (``t_load``, ``tension`` N)."""

    t_pose: np.ndarray
    p_I: np.ndarray
    q_pose: np.ndarray
    t_att: np.ndarray
    q_att: np.ndarray
    t_imu: np.ndarray
    omega_B: np.ndarray
    f_B: np.ndarray
    t_mot: np.ndarray
    T_mot: np.ndarray
    t_load: np.ndarray
    tension: np.ndarray


def streams_of_result(res) -> Streams:
    """A 1 kHz simulation at the rates of the module docstring: pose 100 Hz, attitude 250
    Hz, IMU 1 kHz, motors 400 Hz (the last command on the 1 kHz stream), load cell 200
    Hz."""
    n = res.t.size
    ip, ia, it = np.arange(0, n, 10), np.arange(0, n, 4), np.arange(0, n, 5)
    tm = np.arange(0.0, res.t[-1], 0.0025)
    return Streams(res.t[ip], res.p_I[ip], res.q_IB[ip], res.t[ia], res.q_IB[ia], res.t,
                   res.z[:, 7:10], res.f_B, tm, res.u[np.floor(tm / 1e-3 + 1e-9).astype(int)],
                   res.t[it], res.tension[it])


def streams_of_log(log) -> Streams:
    """A flight log of the project's format (a campaign's: 200 Hz, noisy) held at a flight
    stack's rates so that the conversion must give its samples back: the pose and the
    attitude at its samples; the IMU at 1 kHz, each sample's value on the five samples of
    the pose interval centred on it (what the conversion averages); the motors at 400
    Hz, each command on the two samples of the interval it was held over (and one more
    interval at each end: a commanded span around the pose); the load cell at its
    samples."""
    t, h = log.t, log.dt_median
    k = np.arange(-2, 3)
    t_imu = (t[:, None] + 1e-3 * k).ravel()
    rep = lambda x: np.repeat(x, k.size, axis=0)  # noqa: E731
    T = np.concatenate([log.T_cmd[:1], log.T_cmd, log.T_cmd[-1:]])
    t_int = np.concatenate([[t[0] - 2 * h], t - h, [t[-1]]])  # each command's interval start
    t_mot = (t_int[:, None] + np.array([0.0, 0.5 * h])).ravel()
    return Streams(t, log.p_I, log.q, t, log.q, t_imu, rep(log.optional["omega_B"]),
                   rep(log.optional["f_B"]), t_mot, np.repeat(T, 2, axis=0), t,
                   log.optional["tension"])


def px4_topics(flight, thrust_max, legacy=False):
    """The flight (a simulation result, :func:`streams_of_result`, or :class:`Streams`) as
    PX4 logs it (module docstring)."""
    s = flight if isinstance(flight, Streams) else streams_of_result(flight)
    us = lambda t: np.round((t + BOOT) * 1e6).astype(np.uint64)  # noqa: E731
    p_ned = s.p_I @ M_NED.T + ANCHOR_NED
    q_nf = quaternion_from_matrix(M_NED @ matrix_from_quaternion(s.q_att) @ C_FRD)
    gyro = s.omega_B @ C_FRD.T
    c = normalized(s.T_mot, thrust_max)
    px4 = np.full((s.t_mot.size, 12 if not legacy else 16), np.nan if not legacy else 900.0)
    for k, m in enumerate(PX4_MOTOR_ORDER):
        px4[:, m - 1] = c[:, k] if not legacy else 1000.0 + 1000.0 * c[:, k]
    topics = {
        "vehicle_local_position": {"timestamp": us(s.t_pose),
                                   **{a: p_ned[:, j] for j, a in enumerate("xyz")}},
        "vehicle_attitude": {"timestamp": us(s.t_att),
                             **{f"q[{j}]": q_nf[:, j] for j in range(4)}},
    }
    accel = s.f_B @ C_FRD.T  # specific force at the COG, FRD
    imu = {f"accelerometer_m_s2[{j}]": accel[:, j] for j in range(3)}
    rates = {f"xyz[{j}]": gyro[:, j] for j in range(3)}
    if legacy:
        imu = {**{f"gyro_rad[{j}]": gyro[:, j] for j in range(3)}, **imu}
    else:
        topics["vehicle_angular_velocity"] = {"timestamp": us(s.t_imu), **rates}
    topics["sensor_combined"] = {"timestamp": us(s.t_imu), **imu}
    name, field = ("actuator_outputs", "output") if legacy else ("actuator_motors", "control")
    topics[name] = {"timestamp": us(s.t_mot), **{f"{field}[{j}]": px4[:, j]
                                                  for j in range(px4.shape[1])}}
    # a load cell on a topic of the integrator's own, in grams-force (scale in the map)
    topics["tether_load"] = {"timestamp": us(s.t_load), "force": s.tension / 9.81e-3}
    params = {"THR_MDL_FAC": FAC}
    if legacy:
        params.update(PWM_MAIN_MIN=1000, PWM_MAIN_MAX=2000)
    return topics, params


def px4_map(name="px4", **keys):
    """A shipped PX4 map with the anchor and the load cell set (and ``keys``)."""
    with open(load_channel_map(name).source) as fh:
        src = fh.read()
    keys = {"frames.anchor_m": ANCHOR_NED.tolist(), "tension.topic": "tether_load",
            "tension.fields": ["force"], "tension.scale": 9.81e-3, **keys}
    return channel_map_from_text(set_values(src, keys), f"{name}.toml")


@pytest.mark.parametrize("legacy", [False, True], ids=["actuator_motors", "actuator_outputs"])
def test_ulog_gives_the_logs_columns_and_compare_its_residuals(
        paper_config, flight, mocap_floor, tmp_path, legacy):
    """Columns: positions to 1e-5 m (float32 in the ULog), the attitude to 1e-6, thrusts
    to 3 % of the largest (the 400 Hz command stream against the 1 kHz one, averaged
    over each 10 ms pose interval), body rates to 1e-4 rad/s, specific force to 1e-3
    m/s^2, the load cell (grams-force on a topic of its own) to 2 %; the plane estimated
    within 0.05 deg. compare: every axis' residual RMS equal to the CSV's within 10 % of
    the noise floor a 0.5 mm / 0.2 deg motion capture gives the same flight."""
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max, legacy)
    ulg = tmp_path / "flight.ulg"
    write_ulog(ulg, topics, params)
    csv = tmp_path / "flight.csv"
    write_log(csv, log_from_result(flight, rate_hz=100.0))
    cmap = px4_map("px4_legacy" if legacy else "px4")
    (ref,) = read_log(csv)
    (got,) = read_log(ulg, channel_map=cmap, thrust_max=paper_config.vehicle.thrust_max)
    assert got.meta["plane_source"].startswith("estimated")
    assert float(got.meta["alpha_c_deg"]) == pytest.approx(TILT, abs=0.05)
    assert float(got.meta["gamma_c_deg"]) == pytest.approx(HEADING, abs=0.05)
    i = np.clip(np.searchsorted(got.t - BOOT, ref.t - 1e-6), 0, got.t.size - 1)
    both = np.abs(got.t[i] - BOOT - ref.t) < 1e-6  # the same instants (the ULog's first
    i, j = i[both], np.flatnonzero(both)  # pose sample is left out: no command before it)
    assert j.size >= ref.t.size - 2
    np.testing.assert_allclose(got.p_I[i], ref.p_I[j], atol=1e-5)
    np.testing.assert_allclose(np.abs(np.sum(got.q[i] * ref.q[j], -1)), 1.0, atol=1e-6)
    scale = np.abs(ref.T_cmd).max()
    assert np.abs(got.T_cmd[i][1:] - ref.T_cmd[j][1:]).max() <= 0.03 * scale
    # the load cell: its last sample (200 Hz), grams-force scaled
    assert np.abs(got.optional["tension"][i] - ref.optional["tension"][j]).max() <= 0.02 * (
        ref.optional["tension"].max())
    for key in ("omega_B", "f_B"):  # rad/s, m/s^2
        np.testing.assert_allclose(got.optional[key][i][1:-1], ref.optional[key][j][1:-1],
                                   atol=1e-4 if key == "omega_B" else 1e-3, err_msg=key)
    a = compare(paper_config, [csv])
    b = compare(paper_config, [ulg], channel_map=cmap)
    assert set(a.stats) == set(b.stats)
    for axis in a.stats:
        ra, rb = a.stats[axis].rms, b.stats[axis].rms
        assert abs(rb - ra) <= 0.1 * mocap_floor[axis], (axis, ra, rb, mocap_floor[axis])


def test_a_missing_topic_or_field_is_named(paper_config, flight, tmp_path):
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    del topics["vehicle_angular_velocity"]
    ulg = tmp_path / "nogyro.ulg"
    write_ulog(ulg, topics, params)
    with pytest.raises(InputError, match=r"nogyro.ulg: topic vehicle_angular_velocity: not in "
                                         r"the log \(it has: .*actuator_motors"):
        read_log(ulg, channel_map=px4_map(), thrust_max=3.5)
    bad = px4_map(**{"gyro.fields": ["xyz[0]", "xyz[1]", "rates[2]"]})
    topics, _ = px4_topics(flight, paper_config.vehicle.thrust_max)
    write_ulog(ulg, topics, params)
    with pytest.raises(InputError, match=r"topic vehicle_angular_velocity, field rates\[2\]"):
        read_log(ulg, channel_map=bad, thrust_max=3.5)


def test_a_command_outside_the_curve_is_an_error_and_disarmed_ends_are_cut(
        paper_config, flight, tmp_path):
    """NaN (disarmed) before the first and after the last valid command: those pose
    samples are left out; a command of 1.5 in the middle: one error naming the sample."""
    thrust_max = paper_config.vehicle.thrust_max
    topics, params = px4_topics(flight, thrust_max)
    ctl = topics["actuator_motors"]
    for j in range(4):
        ctl[f"control[{j}]"] = ctl[f"control[{j}]"].copy()
        ctl[f"control[{j}]"][:40] = np.nan  # the first 0.1 s disarmed
    ulg = tmp_path / "armed.ulg"
    write_ulog(ulg, topics, params)
    (log,) = read_log(ulg, channel_map=px4_map(), thrust_max=thrust_max)
    assert log.t[0] - BOOT >= 0.0975 and log.t[0] - BOOT < 0.12
    ctl["control[2]"][500] = 1.5
    write_ulog(ulg, topics, params)
    with pytest.raises(InputError, match=r"topic actuator_motors, field control\[2\], sample "
                                         r"501: command 1.5 is outside the normalized range"):
        read_log(ulg, channel_map=px4_map(), thrust_max=thrust_max)


@pytest.mark.parametrize(("key", "value", "match"), [
    ("frames.world", "NWU", r"frames.world: must be one of NED, ENU, got 'NWU'"),
    ("motors.order", [1, 1, 2, 3], r"motors.order: must be 4 different field numbers"),
    ("motors.unit", "rpm", r"motors.unit: must be one of N, normalized, pwm"),
    ("motors.thr_mdl_fac", 1.5, r"motors.thr_mdl_fac: must be in 0..1"),
    ("attitude.order", "zyxw", r"attitude.order: must be one of wxyz, xyzw"),
    ("gyro.fields", ["xyz[0]"], r"gyro.fields: needs 3 fields, got 1"),
    ("frames.anchor", [0, 0, 0], r"frames.anchor: unknown key"),
])
def test_a_bad_map_names_the_key(key, value, match):
    with pytest.raises(InputError, match=r"^px4.toml: " + match):
        px4_map(**{key: value})


def test_cli_convert_writes_the_log_and_says_what_it_mapped(paper_config, flight, tmp_path):
    """``gainsched convert LOG.ulg -o OUT.csv --map MAP --config CFG``: the report names
    every channel and the estimated plane; OUT.csv reads back as the ULog reads; a bad
    output name or map is one line, exit 2, nothing written."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    mp = tmp_path / "mine.toml"
    mp.write_text(set_values(open(load_channel_map("px4").source).read(), {
        "frames.anchor_m": ANCHOR_NED.tolist(), "tension.topic": "tether_load",
        "tension.fields": ["force"], "tension.scale": 9.81e-3}))
    out = tmp_path / "f.csv"
    r = CliRunner().invoke(cli, ["convert", str(ulg), "-o", str(out), "--map", str(mp),
                                 "--config", "paper"])
    assert r.exit_code == 0, r.output
    for word in ("position: vehicle_local_position", "attitude: vehicle_attitude",
                 "motors: actuator_motors control[2], control[1], control[3], control[0]",
                 "gyro: vehicle_angular_velocity", "tension: tether_load"):
        assert word in r.output, (word, r.output)
    assert re.search(r"circle plane: alpha_c (19.9\d|20.0\d) deg, gamma_c (29.9\d|30.0\d) "
                     r"deg, estimated from the positions", r.output), r.output
    (back,) = read_log(out)
    (direct,) = read_log(ulg, channel_map=str(mp), thrust_max=paper_config.vehicle.thrust_max)
    np.testing.assert_array_equal(back.t, direct.t)
    np.testing.assert_array_equal(back.T_cmd, direct.T_cmd)
    np.testing.assert_allclose(back.q, direct.q, rtol=0, atol=1e-15)
    for args, key in (([str(ulg), "-o", str(tmp_path / "f.txt"), "--map", str(mp)], "f.txt"),
                      ([str(ulg), "-o", str(tmp_path / "g.csv"), "--map", "px5"], "px5")):
        r = CliRunner().invoke(cli, ["convert", *args])
        assert r.exit_code == 2 and key in r.output and "Traceback" not in r.output, r.output
        assert len(r.output.strip().splitlines()) == 1
    r = CliRunner().invoke(cli, ["convert", str(ulg), "-o", str(tmp_path / "f.txt")])
    assert r.output.strip().endswith("f.txt: -o: unknown log format (.txt): use .csv, .h5 or "
                                     ".hdf5"), r.output  # the option named (issue 55)
    assert not (tmp_path / "g.csv").exists() and not (tmp_path / "f.txt").exists()


def test_convert_checks_the_load_cell_against_the_config_and_trust_travels(
        paper_config, flight, tmp_path):
    """A map that leaves the load cell in grams-force (its scale forgotten): ``convert
    --config`` refuses it naming the column and the unit (issue 38; the checks of
    gainsched/analysis/logs/_consistency.py); ``--trust tension`` converts it and writes the trust
    into the log's metadata, so the CSV reads as the ULog did."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    mp = tmp_path / "grams.toml"
    mp.write_text(set_values(open(load_channel_map("px4").source).read(), {
        "frames.anchor_m": ANCHOR_NED.tolist(), "tension.topic": "tether_load",
        "tension.fields": ["force"], "tension.scale": 1.0}))
    out = tmp_path / "f.csv"
    args = ["convert", str(ulg), "-o", str(out), "--map", str(mp), "--config", "paper"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2, r.output
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.output
    assert re.search(rf"^gainsched: error: {re.escape(str(ulg))}: column tension: looks like "
                     r"grams-force \(gf\): 10\dx the tension the radial equation gives", r.stderr)
    assert not out.exists()
    r = CliRunner().invoke(cli, [*args, "--trust", "tension"])
    assert r.exit_code == 0, r.output
    (back,) = read_log(out, config=paper_config)
    assert back.meta["trust"] == "tension"


# --------------------------------------------------------------------------- ROS 2 bags
ANCHOR_ENU = np.array([-0.4, 2.2, 0.3])  # the anchor in the motion capture's frame, m


def ros2_messages(flight, types):
    """The flight (a simulation result, :func:`streams_of_result`, or :class:`Streams`) as
    a ROS 2 lab records it: the mocap's geometry_msgs/PoseStamped (ENU about an anchor off
    the origin, header stamps), sensor_msgs/Imu (FLU), the thrusts (N) as
    std_msgs/Float32MultiArray, the load cell as std_msgs/Float64 (no header: its bag
    time); a simulation at 100 Hz, 1 kHz, 400 Hz and 200 Hz."""
    s = flight if isinstance(flight, Streams) else streams_of_result(flight)
    T = types.types
    t_ns = lambda t: int(round((t + BOOT) * 1e9))  # noqa: E731

    def header(t):
        ns = t_ns(t)
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
            sec=ns // 10**9, nanosec=ns % 10**9), frame_id="mocap")

    vec = T["geometry_msgs/msg/Vector3"]
    pose, imu, motors, load = [], [], [], []
    p = s.p_I + ANCHOR_ENU
    for k, t in enumerate(s.t_pose):
        q = s.q_pose[k]
        msg = T["geometry_msgs/msg/PoseStamped"](header=header(t), pose=T[
            "geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](*p[k]),
                                      orientation=T["geometry_msgs/msg/Quaternion"](
                                          x=q[1], y=q[2], z=q[3], w=q[0])))
        pose.append((t_ns(t) + 3_000_000, msg))  # received 3 ms late
    zero9 = np.zeros(9)
    for k, t in enumerate(s.t_imu):
        w, f = s.omega_B[k], s.f_B[k]
        imu.append((t_ns(t), T["sensor_msgs/msg/Imu"](
            header=header(t), orientation=T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=zero9,
            angular_velocity=vec(*w), angular_velocity_covariance=zero9,
            linear_acceleration=vec(*f), linear_acceleration_covariance=zero9)))
    layout = T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    for t, u in zip(s.t_mot, s.T_mot.astype(np.float32), strict=True):
        motors.append((t_ns(t), T["std_msgs/msg/Float32MultiArray"](layout=layout, data=u)))
    for t, f in zip(s.t_load, s.tension, strict=True):
        load.append((t_ns(t), T["std_msgs/msg/Float64"](data=float(f))))
    return {"/mocap/pose": ("geometry_msgs/msg/PoseStamped", pose),
            "/imu": ("sensor_msgs/msg/Imu", imu),
            "/motor_thrusts": ("std_msgs/msg/Float32MultiArray", motors),
            "/load_cell": ("std_msgs/msg/Float64", load)}


def ros2_map(**keys):
    """A copy of the shipped ros2 template with the anchor, the load cell and the plane of
    :func:`flight` set (and ``keys``)."""
    with open(load_channel_map("ros2").source) as fh:
        src = fh.read()
    return channel_map_from_text(set_values(src, {
        "frames.anchor_m": ANCHOR_ENU.tolist(), "tension.topic": "/load_cell",
        "tension.fields": ["data"], "circle.alpha_c_deg": TILT,
        "circle.gamma_c_deg": HEADING, **keys}), "lab.toml")


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_ros2_bag_gives_the_logs_columns_and_compare_its_residuals(
        paper_config, flight, mocap_floor, tmp_path, storage):
    """A rosbag2 written by rosbags' writer, read through a copy of the shipped ros2
    template (the circle plane given): the columns and the compare residuals of the CSV
    as for the ULog (the header stamps, not the 3 ms late bag times, place the pose)."""
    bag = tmp_path / "bag"
    write_bag(bag, ros2_messages(flight, ros_types()), storage)
    csv = tmp_path / "flight.csv"
    write_log(csv, log_from_result(flight, rate_hz=100.0))
    (ref,) = read_log(csv)
    cmap = ros2_map()
    (got,) = read_log(bag, channel_map=cmap)
    assert got.meta["plane_source"] == "channel map ros2"  # the copy keeps its name
    i = np.clip(np.searchsorted(got.t - BOOT, ref.t - 1e-6), 0, got.t.size - 1)
    both = np.abs(got.t[i] - BOOT - ref.t) < 1e-6
    i, j = i[both], np.flatnonzero(both)
    assert j.size >= ref.t.size - 2
    np.testing.assert_allclose(got.p_I[i], ref.p_I[j], atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(got.q[i] * ref.q[j], -1)), 1.0, atol=1e-12)
    assert np.abs(got.T_cmd[i][1:] - ref.T_cmd[j][1:]).max() <= 0.03 * np.abs(ref.T_cmd).max()
    np.testing.assert_allclose(got.optional["omega_B"][i][1:-1],
                               ref.optional["omega_B"][j][1:-1], atol=1e-9)
    a = compare(paper_config, [csv])
    b = compare(paper_config, [bag], channel_map=cmap)
    for axis in a.stats:
        ra, rb = a.stats[axis].rms, b.stats[axis].rms
        assert abs(rb - ra) <= 0.1 * mocap_floor[axis], (axis, ra, rb, mocap_floor[axis])
    with pytest.raises(InputError, match=r"a ROS 2 bag needs a channel map"):
        read_log(bag)


@pytest.mark.parametrize(("keys", "match"), [
    ({"frames.world": "ENU"}, r"^px4.toml: frames: .*the logged attitude's thrust axis "
                              r"points away from what holds the vehicle up .* world frame ENU"),
    ({"frames.body": "FLU"}, r"^px4.toml: frames: .*thrust axis points away .* body frame FLU"),
    ({"frames.body": "FLU", "accelerometer": None},
     r"^px4.toml: frames: .*thrust axis points away .* body frame FLU"),
    ({"attitude.order": "xyzw", "accelerometer": None},
     r"^px4.toml: frames: .*thrust axis points away .* the quaternion xyzw\?$"),
], ids=["ENU-for-NED", "FLU-for-FRD", "FLU-for-FRD-gyro-only", "xyzw-for-wxyz"])
def test_a_frame_mistake_is_caught_not_fitted(paper_config, flight, tmp_path, keys, match):
    """A map whose frames or quaternion order contradict the log: the sensors' physics
    catches it at reading (one line naming the map and the key), before any analysis."""
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    cmap = px4_map(**{k: v for k, v in keys.items() if v is not None})
    if "accelerometer" in keys:
        cmap = dataclasses.replace(cmap, accelerometer=None)
    with pytest.raises(InputError, match=match):
        read_log(ulg, channel_map=cmap, thrust_max=paper_config.vehicle.thrust_max)


@pytest.mark.parametrize("order", [[1, 2, 3, 4], [3, 4, 2, 1], [1, 3, 2, 4]],
                         ids=["tool-order", "two-swapped", "reordered"])
def test_a_wrong_motor_order_is_caught_not_fitted(paper_config, flight, tmp_path, order):
    """The motors read in another order than PX4's (the tool's own order, two swapped,
    three moved): the commanded torques come out mirrored or swapped. compare (and so
    diagnose) refuses the log before any statistic or fit, in one line naming the log,
    ``motors.order``, the order that fits (PX4's) and how much better it fits the
    measured rotation (> 10x, the threshold); the right map's log fits best as it is."""
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    good = compare(paper_config, [ulg], channel_map=px4_map())
    ((orders, rms),) = motor_order_fits(Model(paper_config), good.measured).values()
    assert np.argmin(rms) == 0 and rms[1:].min() > 10 * rms[0]
    bad = px4_map(**{"motors.order": order})
    msg = (rf"^{re.escape(str(ulg))}: motors.order: the commands fit the measured rotation "
           r"(\d+)x better \(residual RMS .* rad/s\^2\) with motors.order = \[3, 2, 4, 1\] "
           rf"than with the order {re.escape(str(order))} of the channel map px4: check the "
           r"map's motor order$")
    with pytest.raises(InputError, match=msg) as err:
        compare(paper_config, [ulg], channel_map=bad)
    assert int(re.match(msg, str(err.value)).group(1)) > MOTOR_ORDER_FACTOR
    with pytest.raises(InputError, match=msg):
        diagnose(paper_config, [ulg, ulg], channel_map=bad)


def test_cli_refuses_a_wrong_motor_order_in_one_line(paper_config, flight, tmp_path):
    """``gainsched compare`` and ``gainsched diagnose`` with a map of the wrong motor
    order: exit 2, one line naming the log and motors.order, no traceback."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = [tmp_path / "f.ulg", tmp_path / "g.ulg"]
    for p in ulg:
        write_ulog(p, topics, params)
    mp = tmp_path / "mine.toml"
    mp.write_text(set_values(open(load_channel_map("px4").source).read(), {
        "frames.anchor_m": ANCHOR_NED.tolist(), "motors.order": [1, 2, 3, 4]}))
    for cmd in ("compare", "diagnose"):
        r = CliRunner().invoke(cli, [cmd, "paper", *map(str, ulg), "--map", str(mp)])
        assert r.exit_code == 2, r.output
        assert "Traceback" not in r.output and len(r.output.strip().splitlines()) == 1, r.output
        assert f"{ulg[0]}: motors.order: " in r.output and "[3, 2, 4, 1]" in r.output, r.output


def test_thrust_columns_in_a_wrong_order_are_caught(paper_config, flight, tmp_path):
    """The project's own format: a CSV whose thrust columns are in PX4's order instead
    of the tool's is refused naming the columns and the order that fits."""
    log = log_from_result(flight, rate_hz=100.0)
    csv = tmp_path / "flight.csv"
    cols = dict(log.columns())
    cols.update({f"T{k + 1}": log.T_cmd[:, m - 1] for k, m in enumerate(PX4_MOTOR_ORDER)})
    write_log(csv, cols, log.meta)
    with pytest.raises(InputError, match=r"flight.csv: columns T1, T2, T3, T4: the commands "
                                         r"fit the measured rotation \d+x better .* as the "
                                         r"tool's motors 1..4 = columns T4, T2, T1, T3: "):
        compare(paper_config, [csv])


def test_a_gyro_turned_against_the_attitude_is_caught(paper_config, flight, tmp_path):
    """A gyro mounted upside down (its y and z negated) against a right attitude: the
    body rates from the attitude turn the other way: one line naming frames.body."""
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    rates = topics["vehicle_angular_velocity"]
    for j in (1, 2):
        rates[f"xyz[{j}]"] = -rates[f"xyz[{j}]"]
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    with pytest.raises(InputError, match=r"^px4.toml: frames.body: .*the gyro's [qr] turns "
                                         r"against the logged attitude"):
        read_log(ulg, channel_map=px4_map(), thrust_max=paper_config.vehicle.thrust_max)


def test_an_empty_or_truncated_log_is_one_line(paper_config, flight, tmp_path):
    """An empty file, a ULog cut in its header, a ULog cut in its data (pyulog reads what
    is whole: too few pose samples then), a folder that is no bag: one line each."""
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    whole = tmp_path / "whole.ulg"
    write_ulog(whole, topics, params)
    data = whole.read_bytes()
    cases = {"empty.ulg": b"", "header.ulg": data[:40], "cut.ulg": data[: len(data) // 40]}
    for name, blob in cases.items():
        (tmp_path / name).write_bytes(blob)
        with pytest.raises(InputError) as err:
            read_log(tmp_path / name, channel_map=px4_map(), thrust_max=3.5)
        assert str(err.value).startswith(str(tmp_path / name)), err.value
        assert "\n" not in str(err.value)
    (tmp_path / "nobag").mkdir()
    (tmp_path / "nobag" / "metadata.yaml").write_text("not: a bag\n")
    with pytest.raises(InputError, match=r"nobag: not a readable ROS 2 bag"):
        read_log(tmp_path / "nobag", channel_map=ros2_map())


# --------------------------------------------------------------------------- diagnose
#: candidates of an effect of flight time: they read the log's time axis, whose origin
#: a ULog sets at boot (here BOOT s before the flight) and the project's CSVs at the start
TIME_CANDIDATES = frozenset(k for k, cls in EFFECTS.items() if cls.time_varying)
ROUND_TRIP_HIDDEN = "motor_lag"  # 35 ms: the commands' timing must survive the conversion


@pytest.mark.slow
def test_diagnose_finds_the_hidden_effect_in_ulogs_and_bags_as_in_the_csvs(
        paper_config, fly, tmp_path):
    """Issue 36's must-show: the default campaign (seven 2.5 s flights, 200 Hz motion
    capture with noise, gyro, accelerometer, load cell) on a plant with a 35 ms motor lag,
    each flight written as a PX4 ULog (NED about an off-origin anchor, FRD, PX4's motor
    order, ``actuator_motors`` normalised through THR_MDL_FAC 0.3 at 400 Hz, the gyro and
    accelerometer at 1 kHz, the circle plane left to be estimated) and as a ROS 2 bag
    (MCAP; ENU, FLU, header stamps, thrusts in N; the plane estimated too), each stream
    holding the CSV's samples (:func:`streams_of_log`); the bags in both storages, MCAP
    and SQLite. ``diagnose`` on the ULogs (the shipped px4 map) and on the bags (the ros2
    template) accepts the candidate it accepts on the CSVs, motor_lag, and every fitted
    parameter of every candidate, the accepted one and the others, is within the CSV
    fit's 95 % CI of the CSV's estimate (tolerance: that CI, e.g. 0.56 ms on tau = 34.88
    ms). The converted logs differ from the CSVs by float32 fields and the estimated
    planes only: measured, tau agrees to 2e-11 s. The CI catches a command stream half
    a pose interval late (tau 37.3 ms) and THR_MDL_FAC 10 % off (thrust_airspeed's c1
    moves by 1.7 CI). Not compared: the fits of effects of flight time
    (:data:`TIME_CANDIDATES`), which see the ULog's clock start at boot."""
    thrust_max = paper_config.vehicle.thrust_max
    logs = fly(ROUND_TRIP_HIDDEN)
    csvs = write_campaign(tmp_path / "csv", logs)
    ulogs, bags = [], []
    for log, csv in zip(logs, csvs, strict=True):
        streams = streams_of_log(log)
        ulogs.append(tmp_path / f"{csv.stem}.ulg")
        write_ulog(ulogs[-1], *px4_topics(streams, thrust_max))
        msgs = ros2_messages(streams, ros_types())
        bags.append([tmp_path / storage / csv.stem for storage in ("mcap", "sqlite3")])
        for bag, storage in zip(bags[-1], ("mcap", "sqlite3"), strict=True):
            write_bag(bag, msgs, storage)
    ref = diagnose(paper_config, csvs)
    assert ref.accepted is not None and story(ref.accepted) == HIDDEN[ROUND_TRIP_HIDDEN].truth[0]
    estimate = {"circle.alpha_c_deg": "estimate", "circle.gamma_c_deg": "estimate"}
    for what, paths, cmap in (("ulog", ulogs, px4_map()),
                              ("mcap", [b[0] for b in bags], ros2_map(**estimate)),
                              ("sqlite3", [b[1] for b in bags], ros2_map(**estimate))):
        got = diagnose(paper_config, paths, channel_map=cmap)
        assert got.accepted is not None and got.accepted.name == ref.accepted.name, (
            what, got.verdict)
        fits = {r.name: r for r in got.results}
        assert set(fits) == {r.name for r in ref.results}, what
        for r in ref.results:  # the accepted candidate and every other fit
            if r.name in TIME_CANDIDATES:
                continue  # the ULog's clock starts at boot, BOOT s before the CSV's
            for p, a, b, ci in zip(r.params, r.theta, fits[r.name].theta, r.ci, strict=True):
                assert abs(b - a) <= ci, (what, r.name, p.name, a, b, ci)


def test_ros2_time_stamps_and_the_pose_clock_offset(paper_config, flight, tmp_path):
    """``time.stamp = "log"`` places each message at the time the bag recorded it (the
    pose 3 ms late against its header stamp); ``time.pose_offset_s`` moves the pose
    channels by that much, back onto the on-board clock: then the log is the header
    stamps' log again (the commands and the IMU agree to rounding)."""
    bag = tmp_path / "bag"
    write_bag(bag, ros2_messages(flight, ros_types()), "mcap")
    (header,) = read_log(bag, channel_map=ros2_map())
    late = dataclasses.replace(ros2_map(), stamp="log")
    (recorded,) = read_log(bag, channel_map=late)
    n = min(len(header), len(recorded))
    np.testing.assert_allclose(recorded.t[:n] - header.t[:n], 0.003, atol=1e-9)
    back = dataclasses.replace(late, pose_offset_s=-0.003)
    (fixed,) = read_log(bag, channel_map=back)
    i = np.searchsorted(fixed.t, header.t[1:-1] - 1e-7)
    np.testing.assert_allclose(fixed.t[i], header.t[1:-1], atol=1e-9)
    np.testing.assert_allclose(fixed.T_cmd[i], header.T_cmd[1:-1], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(fixed.optional["omega_B"][i], header.optional["omega_B"][1:-1],
                               atol=1e-9)

# ---------------------------------------------------------------- the cache of converted logs
# gainsched/analysis/logs/_cache.py: a log converted once is read from the cache with the
# same columns, and converted again whenever its bytes, the map, the full-command thrust
# or a cache entry change; errors are not kept.


@pytest.fixture
def cache(monkeypatch, tmp_path):
    """The cache on, in a folder of this test's; counts the conversions from the log."""
    monkeypatch.setenv("GAINSCHED_LOG_CACHE", "1")
    monkeypatch.setenv("GAINSCHED_CACHE", str(tmp_path / "cache"))
    calls = []
    real = foreign.read_topics

    def counted(path, cmap):
        calls.append(path)
        return real(path, cmap)

    monkeypatch.setattr(logcache, "read_topics", counted)
    return calls


@pytest.fixture
def ulog_file(paper_config, flight, tmp_path):
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    path = tmp_path / "flight.ulg"
    write_ulog(path, topics, params)
    return path


def _read_cached(path, cmap=None, thrust_max=3.5):
    (log,) = read_log(path, channel_map=cmap or px4_map(), thrust_max=thrust_max)
    return log


def _same_log(a, b):
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.p_I, b.p_I)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.T_cmd, b.T_cmd)
    for k in a.optional:
        np.testing.assert_array_equal(a.optional[k], b.optional[k])
    assert a.meta == b.meta


def test_a_log_read_again_comes_from_the_cache_bit_for_bit(cache, ulog_file, tmp_path):
    first = _read_cached(ulog_file)
    assert len(cache) == 1 and len(list((tmp_path / "cache" / "logs").glob("*.npz"))) == 1
    again = _read_cached(ulog_file)
    assert len(cache) == 1  # not parsed again
    _same_log(first, again)


def test_another_map_thrust_or_log_converts_again(cache, ulog_file):
    base = _read_cached(ulog_file)
    other = _read_cached(ulog_file, px4_map(**{"motors.thr_mdl_fac": 0.2}))
    assert len(cache) == 2 and not np.array_equal(other.T_cmd, base.T_cmd)
    _read_cached(ulog_file, thrust_max=3.6)
    assert len(cache) == 3
    data = bytearray(ulog_file.read_bytes())
    data[-5] ^= 0x01  # one bit of the last message's payload
    ulog_file.write_bytes(bytes(data))
    _read_cached(ulog_file)
    assert len(cache) == 4


def test_a_damaged_entry_is_converted_again(cache, ulog_file, tmp_path):
    first = _read_cached(ulog_file)
    (entry,) = (tmp_path / "cache" / "logs").glob("*.npz")
    entry.write_bytes(entry.read_bytes()[:100])
    _same_log(first, _read_cached(ulog_file))
    assert len(cache) == 2


def test_errors_are_not_kept(cache, ulog_file, tmp_path):
    bad = px4_map(**{"gyro.topic": "no_such_topic"})
    for _ in range(2):
        with pytest.raises(InputError, match="no_such_topic"):
            _read_cached(ulog_file, bad)
    assert len(cache) == 2 and not (tmp_path / "cache" / "logs").exists()


def test_the_cache_can_be_turned_off(cache, ulog_file, monkeypatch):
    monkeypatch.setenv("GAINSCHED_LOG_CACHE", "0")
    _read_cached(ulog_file), _read_cached(ulog_file)
    assert len(cache) == 2


# --------------------------------------------------------------------------- battery
def _battery(t):
    """A sagging battery sampled at 100 Hz over the flight: 12.3 V falling 0.2 V/s, V."""
    t_bat = np.arange(-0.05, t[-1] + 0.01, 0.01)
    return t_bat, 12.3 - 0.2 * t_bat


def test_px4_battery_status_gives_vbat(paper_config, flight, tmp_path):
    """Issue 37: PX4's battery_status.voltage_v (msg/BatteryStatus.msg: "Battery voltage
    in volts, 0 if unknown") through the shipped px4 map becomes the column vbat, its
    last sample at or before each pose sample (float32 in the ULog: to 1e-5 V); the
    samples of 0 (unknown) at the start are missing samples, NaN, and the conversion
    says how many. A ULog without battery_status converts without vbat (the map's
    battery channel is optional) and says so."""
    thrust_max = paper_config.vehicle.thrust_max
    topics, params = px4_topics(flight, thrust_max)
    t_bat, v = _battery(flight.t)
    v[:10] = 0.0  # not known yet
    topics["battery_status"] = {"timestamp": np.round((t_bat + BOOT) * 1e6).astype(np.uint64),
                                "voltage_v": v}
    ulg = tmp_path / "bat.ulg"
    write_ulog(ulg, topics, params)
    cmap = px4_map()
    conv = foreign.convert_topics(ulg, *foreign.read_topics(ulg, cmap), cmap,
                                  thrust_max=thrust_max)
    assert ("battery: battery_status voltage_v x 1 as vbat (held; 10 samples of 0 or less, "
            "unknown, left out)") in conv.report
    (log,) = read_log(ulg, channel_map=cmap, thrust_max=thrust_max)
    tp = log.t - BOOT
    i = np.searchsorted(t_bat, tp + 1e-7, side="right") - 1
    known = i >= 10
    assert known.sum() > 0.9 * tp.size and (~known).sum() > 0
    np.testing.assert_allclose(log.optional["vbat"][known], 12.3 - 0.2 * t_bat[i[known]],
                               atol=1e-5)
    assert np.all(np.isnan(log.optional["vbat"][~known]))
    del topics["battery_status"]
    write_ulog(ulg, topics, params)
    conv = foreign.convert_topics(ulg, *foreign.read_topics(ulg, cmap), cmap,
                                  thrust_max=thrust_max)
    assert "vbat" not in conv.columns
    assert "battery: battery_status not in the log (optional): no vbat column" in conv.report
    with pytest.raises(InputError, match=r"battery.optional: must be true or false"):
        px4_map(**{"battery.optional": "yes"})
    # not optional: a log without the topic is refused, naming it
    with pytest.raises(InputError, match=r"bat.ulg: topic battery_status: not in the log"):
        read_log(ulg, channel_map=px4_map(**{"battery.optional": False}), thrust_max=thrust_max)


def test_ros2_battery_state_gives_vbat(paper_config, flight, tmp_path):
    """sensor_msgs/BatteryState ``voltage`` on /battery (the shipped ros2 template's
    battery channel), written by rosbags' writer: the column vbat, held, exact (float32
    values); a bag without the topic converts without it."""
    types = ros_types()
    T = types.types
    msgs = ros2_messages(flight, types)
    t_bat, v = _battery(flight.t)
    v = v.astype(np.float32)
    bat = []
    for t, x in zip(t_bat, v, strict=True):
        ns = int(round((t + BOOT) * 1e9))
        header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
            sec=ns // 10**9, nanosec=ns % 10**9), frame_id="battery")
        bat.append((ns, T["sensor_msgs/msg/BatteryState"](
            header=header, voltage=float(x), temperature=float("nan"), current=-7.0,
            charge=float("nan"), capacity=float("nan"), design_capacity=1.3,
            percentage=float("nan"), power_supply_status=2, power_supply_health=1,
            power_supply_technology=3, present=True,
            cell_voltage=np.array([], dtype=np.float32),
            cell_temperature=np.array([], dtype=np.float32), location="", serial_number="")))
    write_bag(tmp_path / "bag", {**msgs, "/battery": ("sensor_msgs/msg/BatteryState", bat)})
    (log,) = read_log(tmp_path / "bag", channel_map=ros2_map())
    tp = log.t - BOOT
    i = np.searchsorted(t_bat, tp + 1e-7, side="right") - 1
    np.testing.assert_array_equal(log.optional["vbat"], v[i].astype(float))
    write_bag(tmp_path / "nobat", msgs)
    (log,) = read_log(tmp_path / "nobat", channel_map=ros2_map())
    assert "vbat" not in log.optional


def test_reading_reports_its_stages_to_a_listener(paper_config, flight, ulog_file, tmp_path,
                                                   monkeypatch):
    """Issue 39, progress of ``convert``: with a listener (gainsched.analysis.logs.reporting) a
    ULog's read reports its bytes from 0 to the file's size, a bag's its messages from 0
    to the count written, then the conversion and the channel checks, in that order; the
    log read is the one read without a listener."""
    from gainsched.analysis.logs import reporting

    monkeypatch.setenv("GAINSCHED_LOG_CACHE", "0")
    bag = tmp_path / "bag"
    messages = ros2_messages(flight, ros_types())
    write_bag(bag, messages, "mcap")
    n_msg = sum(len(m[1]) for m in messages.values())
    for path, cmap, stage, total, unit in (
            (ulog_file, px4_map(), "read ULog", ulog_file.stat().st_size, "B"),
            (bag, ros2_map(), "read bag", n_msg, "msg")):
        calls = []
        with reporting(lambda *a: calls.append(a)):  # noqa: B023 (used inside the loop)
            (got,) = read_log(path, channel_map=cmap, thrust_max=3.5)
        (quiet,) = read_log(path, channel_map=cmap, thrust_max=3.5)
        _same_log(got, quiet)
        reads = [c for c in calls if c[0] == stage]
        assert reads[0] == (stage, 0, total, unit) and reads[-1] == (stage, total, total, unit)
        assert all(a[1] <= b[1] for a, b in zip(reads, reads[1:], strict=False)), reads
        assert [c[0] for c in calls[len(reads):]] == ["convert", "check channels"], calls


def test_cli_convert_shows_progress_on_a_terminal_only(ulog_file, tmp_path, monkeypatch):
    """``gainsched convert`` of a ULog draws its progress line (the bytes read, the stage)
    on a terminal's stderr; piped, stderr has nothing; with --quiet the terminal shows
    nothing."""
    import subprocess
    import sys

    from support import on_terminal

    monkeypatch.setenv("GAINSCHED_LOG_CACHE", "0")
    mp = tmp_path / "mine.toml"  # the anchor where the flight's is (else off the sphere)
    mp.write_text(set_values(open(load_channel_map("px4").source).read(),
                             {"frames.anchor_m": ANCHOR_NED.tolist()}))
    args = lambda i: [sys.executable, "-m", "gainsched", *(["--quiet"] if i == 3 else []),  # noqa: E731
                      "convert", str(ulog_file), "-o", f"out{i}.csv", "--config", "paper",
                      "--map", str(mp)]
    code, shown = on_terminal(args(1), tmp_path)
    assert code == 0 and re.search(r"convert flight\.ulg: 100%\|.*\| ([\d.]+[kM])/\1 "
                                   r"\[.*B/s, written\]", shown), shown
    piped = subprocess.run(args(2), capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert piped.returncode == 0 and piped.stderr == "", piped.stderr
    code, shown = on_terminal(args(3), tmp_path)
    assert code == 0 and shown == "", shown


# --------------------------------------------------------------------------- what a lab gives
# issue 55: the files a new user gives as they are, and files made to hurt


def test_a_ulog_that_declares_more_than_a_message_can_carry_is_refused_unparsed(
        tmp_path, monkeypatch):
    """148 bytes whose formats declare a topic of 65535 x 65535 bytes (pyulog builds it
    field by field and never answers): refused in one line naming the format, before
    pyulog sees the file."""
    import struct

    import pyulog

    def msg(kind, payload):
        return struct.pack("<HB", len(payload), ord(kind)) + payload

    forged = (b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + msg("B", bytes(40))
              + msg("F", b"inner:uint8_t[65535] a;")
              + msg("F", b"big:uint64_t timestamp;inner[65535] b;")
              + msg("A", struct.pack("<BH", 0, 1) + b"big") + msg("D", bytes(18)))
    ulg = tmp_path / "forged.ulg"
    ulg.write_bytes(forged)

    def never(*a, **k):
        raise AssertionError("pyulog parsed a file the scan refuses")

    monkeypatch.setattr(pyulog, "ULog", never)
    with pytest.raises(InputError, match=r"forged.ulg: format inner: declares more than 65,533 "
                                         r"bytes per sample, more than a ULog message can"):
        read_log(ulg, channel_map=px4_map(), thrust_max=3.5)
    ulg.write_bytes(forged.replace(b"uint8_t[65535]", b"uint8_t[65533]"))  # inner fits,
    with pytest.raises(InputError, match=r"format big: declares more than 65,533"):  # big not
        read_log(ulg, channel_map=px4_map(), thrust_max=3.5)


def test_an_honest_ulog_passes_the_scan(paper_config, flight, tmp_path):
    """The scan reads the formats pyulog's writer wrote, with their sizes, and lets the
    file through."""
    from gainsched.analysis.logs._ulogscan import check_ulog_formats, ulog_formats

    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    formats = ulog_formats(ulg)
    assert set(formats) == set(topics)
    assert ("float", "q", 4) in formats["vehicle_attitude"]
    check_ulog_formats(ulg)


def test_a_log_given_where_text_belongs_is_named_as_what_it_is(paper_config, flight,
                                                                 tmp_path):
    """A ULog given as the channel map, a gain table as the config: each named as what
    it is (not "UTF-16 text" or "larger than 1 MiB"), one line, exit 2."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    h5 = tmp_path / "t.h5"
    import h5py
    with h5py.File(h5, "w") as f:
        f["x"] = np.zeros(3)
    for args, expect in (
            (["convert", str(ulg), "-o", str(tmp_path / "o.csv"), "--map", str(ulg)],
             f"{ulg}: a PX4 ULog flight log, not a channel map (a channel map is TOML text)"),
            (["validate", str(h5)],
             f"{h5}: an HDF5 file (a gain table or a flight log), not a config (a config is "
             "TOML text)")):
        r = CliRunner().invoke(cli, args)
        assert r.exit_code == 2 and r.output.strip() == f"gainsched: error: {expect}", r.output


def test_a_bag_folder_without_its_metadata_says_what_to_give(flight, tmp_path):
    """A folder of MCAP files without rosbag2's metadata.yaml: the refusal names the file
    to give instead, and that file alone reads; a folder of neither says so."""
    bag = tmp_path / "bag"
    write_bag(bag, ros2_messages(flight, ros_types()))
    (bag / "metadata.yaml").unlink()
    (mcap,) = bag.glob("*.mcap")
    with pytest.raises(InputError, match=rf"^{bag}: a folder of bag files without the rosbag2 "
                                         rf"metadata.yaml: give the file itself \({mcap}\)"):
        read_log(bag, channel_map=ros2_map())
    (log,) = read_log(mcap, channel_map=ros2_map())
    assert log.t.size > 100
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"empty: a folder, not a log"):
        read_log(tmp_path / "empty", channel_map=ros2_map())


def test_convert_list_gives_each_topic_its_type_rate_and_fields(paper_config, flight,
                                                                 tmp_path):
    """``convert --list``: a ULog's topics with their samples, rates (the writer's: pose
    100 Hz, attitude 250 Hz, motors 400 Hz) and fields as a map names them; a bag's with
    the message type and the numeric field paths; no -o needed, and none given without
    --list is one line."""
    from click.testing import CliRunner

    from gainsched.analysis.logs import list_topics
    from gainsched.cli import cli

    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max)
    ulg = tmp_path / "f.ulg"
    write_ulog(ulg, topics, params)
    listing = list_topics(ulg)
    by = {t.name: t for t in listing.topics}
    assert set(by) == set(topics)
    for name, rate in (("vehicle_local_position", 100.0), ("vehicle_attitude", 250.0),
                       ("actuator_motors", 400.0)):
        assert by[name].rate_hz == pytest.approx(rate, rel=1e-3), name
        assert by[name].samples == topics[name]["timestamp"].size
    assert by["vehicle_attitude"].fields == ("q[0..3]",)
    assert by["actuator_motors"].fields == ("control[0..11]",)
    assert by["vehicle_local_position"].fields == ("x", "y", "z")
    r = CliRunner().invoke(cli, ["convert", str(ulg), "--list"])
    assert r.exit_code == 0 and r.output.splitlines() == listing.lines(), r.output
    assert r.output.splitlines()[0] == f"{ulg}: PX4 ULog, 6 topics over 2.5 s"

    bag = tmp_path / "bag"
    write_bag(bag, ros2_messages(flight, ros_types()))
    by = {t.name: t for t in list_topics(bag).topics}
    assert by["/mocap/pose"].kind == "geometry_msgs/msg/PoseStamped"
    assert by["/mocap/pose"].rate_hz == pytest.approx(100.0, rel=1e-3)
    assert "pose.position.x" in by["/mocap/pose"].fields
    assert "angular_velocity.z" in by["/imu"].fields
    assert "orientation_covariance[0..8]" in by["/imu"].fields
    r = CliRunner().invoke(cli, ["convert", str(ulg)])
    assert r.exit_code == 2 and "Missing option '-o'" in r.output
    assert len(r.output.strip().splitlines()) == 1


def test_rc_values_mapped_as_thrust_name_their_topic_and_look_like_pwm(paper_config, flight,
                                                                        tmp_path):
    """Pulse widths (1000-2000 us: RC sticks, PWM outputs) mapped as newtons: the refusal
    names the topic the value came from (not the pose topic whose samples number the
    rows) and says the values look like PWM."""
    topics, params = px4_topics(flight, paper_config.vehicle.thrust_max, legacy=True)
    ulg = tmp_path / "rc.ulg"
    write_ulog(ulg, topics, params)
    cmap = px4_map("px4_legacy", **{"motors.unit": "N"})
    with pytest.raises(InputError, match=r"column T\d \(from topic actuator_outputs\), "
                                         r"vehicle_local_position sample \d+: 1\d\d\d\.\d+ N "
                                         r"is not plausible .*looks like a PWM pulse width in "
                                         r"microseconds"):
        read_log(ulg, channel_map=cmap)


def test_a_log_off_the_tethers_sphere_is_refused(paper_config, flight, tmp_path):
    """Positions 1.6x as far from the anchor as the tether holds the vehicle (an anchor
    elsewhere, motion capture of a vehicle that is not tethered): one line naming the
    check, the distances and the tether; ``--trust radius`` lets it through to the
    other checks."""
    log = log_from_result(flight, rate_hz=100.0)
    cols = dict(log.columns())
    for c in "xyz":
        cols[c] = 1.6 * cols[c]
    csv = tmp_path / "far.csv"
    write_log(csv, cols, log.meta)
    r = paper_config.tether.length + paper_config.tether.attachment_offset
    with pytest.raises(InputError, match=rf"far.csv: columns x, y, z: the positions are "
                                         rf"{1.6 * r:.3g} m from the anchor .* where the tether "
                                         rf"holds the vehicle {r:g} m from it .*--trust radius"):
        read_log(csv, config=paper_config)
    try:
        read_log(csv, config=paper_config, trust=("radius",))
    except InputError as e:  # another check may see the scaled motion: not this one
        assert "radius" not in str(e) and "from the anchor" not in str(e)
    (same,) = read_log(csv)  # without a config: no tether to hold it to


#: real PX4 logs no one here wrote (tests/data/real_px4/README.md)
REAL_PX4 = sorted((Path(__file__).parents[1] / "data" / "real_px4").glob("*.ulg"))


@pytest.mark.parametrize("ulg", REAL_PX4, ids=[p.stem for p in REAL_PX4])
def test_real_px4_logs_are_listed_and_refused_in_one_line(ulg, tmp_path):
    """A real PX4 log (not a tethered flight): ``convert --list`` lists its topics with
    their rates and fields; converting it is one line naming the topic the map needs
    and the log lacks, exit 2, nothing written."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    r = CliRunner().invoke(cli, ["convert", str(ulg), "--list"])
    assert r.exit_code == 0, r.output
    head, *rows = r.output.splitlines()
    assert re.fullmatch(rf"{re.escape(str(ulg))}: PX4 ULog, \d+ topics over [\d.]+ s", head)
    assert any(row.split()[0] == "vehicle_attitude" and "q[0..3]" in row for row in rows)
    out = tmp_path / "o.csv"
    r = CliRunner().invoke(cli, ["convert", str(ulg), "-o", str(out), "--config", "paper"])
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output
    assert re.match(rf"gainsched: error: {re.escape(str(ulg))}: topic \w+: not in the log "
                    r"\(it has: ", r.output), r.output
    assert not out.exists()
