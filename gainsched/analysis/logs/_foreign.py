"""Logs of the flight stacks users have: PX4 ULog (through ``pyulog``) and ROS 2 bags
(rosbag2, MCAP or SQLite storage, through ``rosbags``: pure Python, no ROS install),
turned into the columns of ``gainsched-flightlog/1`` by a channel map
(:mod:`gainsched.analysis.logs._channelmap`; docs/flight-log.md, "Logs of PX4 and ROS 2").

What the conversion does, and nothing else:

* **Time base.** The samples are the position channel's, at its own time stamps (plus
  the map's ``pose_offset_s``), in seconds.
* **Attitude** from another topic is interpolated to those times on the sphere
  (``scipy.spatial.transform.Slerp``); the positions outside the attitude's span are
  left out.
* **Commands** are held from each motor sample to the next (zero-order hold) and
  averaged over each pose interval ``(t_{k-1}, t_k]``: "held since the previous sample",
  as the format defines them (exactly the command when it did not change in between).
  They are mapped to newtons: ``N`` as they are,
  ``normalized`` ``c`` through PX4's thrust curve ``T = T_max ((1 - f) c + f c^2)``
  (``f = THR_MDL_FAC``), ``pwm`` first to ``c = (pwm - pwm_min) / (pwm_max - pwm_min)``.
  Samples before the first and after the last command that is in the curve's range
  (disarmed: NaN, or PWM below its minimum) are left out and reported; a command out of
  range between them is an error naming the topic, the field and the sample.
* **Gyro and accelerometer** are averaged over the pose interval centred on each pose
  sample, both ends included (NaN where no sample fell in it), as the simulator's logs
  define them; the
  load cell and the battery voltage are their last sample at or before each pose
  sample (a voltage of 0 or less, PX4's "unknown", is a missing sample: NaN).
* **Frames.** Positions become the tool's inertial frame: minus the map's anchor, NED
  turned to ENU (x east, y north, z up); the attitude ``R_world,body`` becomes ``R_IB``
  of the tool's FLU body; body-axis sensors FRD -> FLU; quaternions scalar first; the
  motors renumbered by the map's ``order``.
* **Circle plane.** Given in the map, or left to the reader, which estimates it from
  the positions (:func:`~gainsched.analysis.logs.fitted_plane`) and says so in the
  metadata (``plane_source``).

The result then passes every rule of the flight-log format (gaps split, never
interpolated; plausible values; the declared plane).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...actuators import thrust_from_command
from ...errors import InputError
from ._channelmap import ChannelMap
from ._progress import listener, report, watch_file
from ._ulogscan import check_ulog_formats

__all__ = ["Topic", "ConvertedLog", "FOREIGN_FORMATS", "foreign_format", "read_topics",
           "convert_topics"]

#: file extensions of the formats read here (a rosbag2 folder holds metadata.yaml)
FOREIGN_FORMATS = {".ulg": "ulog", ".mcap": "rosbag2", ".db3": "rosbag2"}
_INDEX = re.compile(r"^(.*)\[([0-9]+)\]$")
#: the tool's inertial axes (ENU) from NED, and the FLU body from FRD (both their own
#: inverses)
_NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_FRD_TO_FLU = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class Topic:
    """The samples of one topic: times ``t`` (N,), s, and each requested field (N,)."""

    t: np.ndarray
    fields: dict[str, np.ndarray]


@dataclass(frozen=True)
class ConvertedLog:
    """Columns and metadata of ``gainsched-flightlog/1`` from a foreign log.

    ``columns``: float arrays by column name; ``meta``: strings (without
    ``alpha_c_deg`` and ``gamma_c_deg`` when the map says ``"estimate"``: the reader
    fits them to the positions); ``rows``: 1-based sample numbers of the position topic;
    ``label``: how a row is named in errors; ``report``: lines saying what was mapped to
    what; ``sources``: per column the topic it came from, for errors. The metadata name
    the source: ``source_format``, ``channel_map`` (its name)
    and ``motors_order`` (its ``motors.order``, ``"[3, 2, 4, 1]"``: the compare's motor
    order check, :func:`~gainsched.analysis.compare.check_motor_order`, names it).
    """

    columns: dict[str, np.ndarray]
    meta: dict[str, str]
    rows: np.ndarray
    label: str
    report: tuple[str, ...]
    sources: dict[str, str] = dataclasses.field(default_factory=dict)


def foreign_format(path) -> str | None:
    """``"ulog"``, ``"rosbag2"`` (a .mcap or .db3 file, or a bag folder), or None."""
    p = Path(path)
    if p.is_dir() and (p / "metadata.yaml").is_file():
        return "rosbag2"
    return FOREIGN_FORMATS.get(p.suffix.lower())


def _wanted(cmap: ChannelMap) -> dict[str, set[str]]:
    topics: dict[str, set[str]] = {}
    for ch in cmap.channels().values():
        topics.setdefault(ch.topic, set()).update(ch.fields)
    return topics


def _optional(cmap: ChannelMap) -> frozenset[str]:
    """The topics a log may lack: those of optional channels only."""
    chans = cmap.channels().values()
    return frozenset(c.topic for c in chans if c.optional) - {
        c.topic for c in chans if not c.optional}


def read_topics(path, cmap: ChannelMap) -> tuple[dict[str, Topic], dict[str, float]]:
    """The topics and fields a map names, from a ULog or a rosbag2, and the ULog's
    parameters (empty for a bag).

    Raises
    ------
    InputError
        The file cannot be read as its format, or a topic or field the map names is not
        in it (listing what the log has).
    """
    if foreign_format(path) == "ulog":
        return _ulog_topics(Path(path), _wanted(cmap), _optional(cmap))
    return _bag_topics(Path(path), _wanted(cmap), cmap.stamp, _optional(cmap)), {}


def _missing_topic(path, topic, have) -> InputError:
    listed = ", ".join(sorted(have)[:40]) + (" ..." if len(have) > 40 else "")
    return InputError(path, f"topic {topic}", f"not in the log (it has: {listed})")


def _missing_field(path, topic, field, have) -> InputError:
    return InputError(path, f"topic {topic}, field {field}",
                      f"not in the topic (it has: {', '.join(sorted(have))})")


def _ulog_topics(path: Path, wanted: dict[str, set[str]], optional=frozenset()
                 ) -> tuple[dict[str, Topic], dict[str, float]]:
    ulog = open_ulog(path, sorted(wanted))
    have = {d.name: d for d in ulog.data_list if d.multi_id == 0}
    out = {}
    for topic, fields in wanted.items():
        if topic not in have and topic in optional:
            continue  # an optional channel the log lacks (convert_topics reports it)
        if topic not in have:
            raise _missing_topic(path, topic, set(ulog.message_formats))
        data = have[topic].data
        for f in fields:
            if f not in data:
                raise _missing_field(path, topic, f, [k for k in data if k != "timestamp"])
        t = np.asarray(data["timestamp"], dtype=np.float64) * 1e-6
        out[topic] = Topic(t, {f: np.asarray(data[f], dtype=np.float64) for f in fields})
    return out, {k: float(v) for k, v in ulog.initial_parameters.items()}


def open_ulog(path: Path, topics=None):
    """``pyulog.ULog`` of ``path`` (only ``topics``, default all), its declared formats
    checked first (:func:`~gainsched.analysis.logs._ulogscan.check_ulog_formats`), what
    pyulog prints about a damaged file kept off the terminal.

    Raises
    ------
    InputError
        The formats no real ULog can hold, or pyulog cannot read the file.
    """
    from pyulog import ULog

    check_ulog_formats(path)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            if listener() is None:
                return ULog(str(path), message_name_filter_list=topics)
            with open(path, "rb") as fh, watch_file(fh, path.stat().st_size, "read ULog"):
                return ULog(fh, message_name_filter_list=topics)  # the bytes parsed, watched
    except Exception as exc:  # pyulog raises several types for a damaged file
        raise InputError(path, "", f"not a readable ULog ({type(exc).__name__}: {exc})") from None


def _field_of(msg, path: str):
    v = msg
    for part in path.split("."):
        m = _INDEX.match(part)
        name, idx = (m.group(1), int(m.group(2))) if m else (part, None)
        v = getattr(v, name)
        if idx is not None:
            v = v[idx]
    return float(v)


def open_bag(path: Path):
    """An opened ``rosbags.highlevel.AnyReader`` of the bag ``path`` (its folder when
    given its ``.mcap`` or ``.db3`` beside ``metadata.yaml``; the file alone otherwise),
    the standard ROS 2 messages known for bags that do not embed their definitions
    (SQLite). The caller closes it.

    Raises
    ------
    InputError
        rosbags cannot open it.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = path.parent if path.is_file() and path.suffix in (".mcap", ".db3") and (
        path.parent / "metadata.yaml").is_file() else path
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except Exception as exc:  # rosbags raises its own error types
        raise InputError(path, "", f"not a readable ROS 2 bag ({type(exc).__name__}: "
                         f"{exc})") from None
    return reader


def _bag_topics(path: Path, wanted: dict[str, set[str]], stamp: str,
                optional=frozenset()) -> dict[str, Topic]:
    reader = open_bag(path)
    try:
        have = {c.topic for c in reader.connections}
        wanted = {t: f for t, f in wanted.items() if t in have or t not in optional}
        for topic in wanted:
            if topic not in have:
                raise _missing_topic(path, topic, have)
        conns = [c for c in reader.connections if c.topic in wanted]
        times: dict[str, list[float]] = {t: [] for t in wanted}
        vals: dict[str, dict[str, list[float]]] = {t: {f: [] for f in wanted[t]} for t in wanted}
        checked: set[str] = set()
        total = sum(c.msgcount for c in conns)
        report("read bag", 0, total, "msg")
        for i, (conn, timestamp, raw) in enumerate(reader.messages(connections=conns)):
            if i % 1000 == 999:
                report("read bag", i + 1, total, "msg")
            msg = reader.deserialize(raw, conn.msgtype)
            topic = conn.topic
            if topic not in checked:
                for f in wanted[topic]:
                    try:
                        _field_of(msg, f)
                    except (AttributeError, IndexError, TypeError, ValueError):
                        names = [n for n in getattr(msg, "__dataclass_fields__", {})]
                        raise _missing_field(path, topic, f, names) from None
                checked.add(topic)
            header = getattr(msg, "header", None)
            if stamp == "header" and header is not None:  # the same ns -> the same float
                t = 1e-9 * (header.stamp.sec * 1_000_000_000 + header.stamp.nanosec)
            else:
                t = 1e-9 * timestamp
            times[topic].append(t)
            for f in wanted[topic]:
                vals[topic][f].append(_field_of(msg, f))
    finally:
        reader.close()
    report("read bag", total, total, "msg")
    out = {}
    for topic in wanted:
        order = np.argsort(np.asarray(times[topic]), kind="stable")
        out[topic] = Topic(np.asarray(times[topic])[order],
                           {f: np.asarray(v, dtype=np.float64)[order]
                            for f, v in vals[topic].items()})
    return out


def _held(t_src, x_src, t):
    """Zero-order hold: the last source sample at or before each time, to 0.1 us (clocks
    rounded differently; NaN before the first)."""
    i = np.searchsorted(t_src, t + 1e-7, side="right") - 1
    out = np.full((t.size,) + x_src.shape[1:], np.nan)
    ok = i >= 0
    out[ok] = x_src[i[ok]]
    return out


def _edges(t):
    """Interval edges around samples t: one median interval before the first, then t."""
    h = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    return np.concatenate([[t[0] - h], t]), h


def _held_mean(t_src, x_src, t):
    """Mean over each interval (t_{k-1}, t_k] of the source held from each of its samples
    to the next (exactly: the integral of a piecewise-constant signal; NaN where the
    interval starts before the first source sample)."""
    edges, _ = _edges(t)
    steps = np.diff(t_src)
    area = np.concatenate([np.zeros((1,) + x_src.shape[1:]),
                           np.cumsum(x_src[:-1] * steps[(...,) + (None,) * (x_src.ndim - 1)],
                                     axis=0)])

    def integral(tau):
        i = np.clip(np.searchsorted(t_src, tau, side="right") - 1, 0, t_src.size - 1)
        dt = (tau - t_src[i])[(...,) + (None,) * (x_src.ndim - 1)]
        return area[i] + x_src[i] * dt

    width = np.diff(edges)[(...,) + (None,) * (x_src.ndim - 1)]
    mean = (integral(edges[1:]) - integral(edges[:-1])) / width
    mean[edges[:-1] < t_src[0]] = np.nan
    return mean


def _centred_mean(t_src, x_src, t):
    """Mean of the source samples in the interval of one median pose interval centred on
    each pose sample, ``[t_k - h/2, t_k + h/2]`` (both ends, to rounding: the
    simulator's logs average the same samples); NaN where none fell."""
    _, h = _edges(t)
    eps = 1e-9 * h
    lo = np.searchsorted(t_src, t - 0.5 * h - eps, side="left")
    hi = np.searchsorted(t_src, t + 0.5 * h + eps, side="right")
    csum = np.concatenate([np.zeros((1,) + x_src.shape[1:]), np.cumsum(x_src, axis=0)])
    n = hi - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (csum[hi] - csum[lo]) / n[:, None]
    mean[n == 0] = np.nan
    return mean


def _param(path, params: dict[str, float], names: tuple[str, ...], key: str) -> float:
    for n in names:
        if n in params:
            return params[n]
    raise InputError(path, key, f"'log' asks for the log's parameter {' or '.join(names)}, "
                     "which it does not hold: give the value in the map")


def _thrust(path, cmap: ChannelMap, cmd: np.ndarray, params: dict, thrust_max):
    """Commands (N, 4) in the map's unit -> thrusts (N, 4), N, and their validity."""
    if cmap.unit == "N":
        return cmd, np.isfinite(cmd)
    t_max = cmap.thrust_max_N if cmap.thrust_max_N is not None else thrust_max
    if t_max is None:
        raise InputError(cmap.source, "motors.thrust_max_N", "needed for a "
                         f"{cmap.unit} command: give it in the map (or a config)")
    if cmap.unit == "pwm":
        lo = cmap.pwm_min if cmap.pwm_min != "log" else _param(
            path, params, ("PWM_MAIN_MIN", "PWM_MIN"), "motors.pwm_min")
        hi = cmap.pwm_max if cmap.pwm_max != "log" else _param(
            path, params, ("PWM_MAIN_MAX", "PWM_MAX"), "motors.pwm_max")
        c = (cmd - lo) / (hi - lo)
    else:
        c = cmd
    f = cmap.thr_mdl_fac if cmap.thr_mdl_fac != "log" else _param(
        path, params, ("THR_MDL_FAC",), "motors.thr_mdl_fac")
    tol = 1e-6
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(c) & (c >= -tol) & (c <= 1 + tol)
    return thrust_from_command(np.clip(np.where(valid, c, 0.0), 0.0, 1.0), f, t_max), valid


def convert_topics(path, topics: dict[str, Topic], params: dict[str, float],
                   cmap: ChannelMap, *, thrust_max: float | None = None,
                   day: bool = False) -> ConvertedLog:
    """The flight-log columns of the topics a map names (the module docstring says how);
    ``day``: a whole flight day, its disarmed stretches kept with no thrust (the day is
    cut into flights afterwards, :mod:`._daycut`).

    ``params``: the log's parameters (ULog; ``"log"`` values of the map read them);
    ``thrust_max`` (N): a motor's thrust at full command when the map does not give it
    (the analysis config's ``vehicle.thrust_max``).
    """
    from scipy.spatial.transform import Rotation

    report: list[str] = []
    t, rows, p_I, R_IB = _pose(topics, cmap, report)
    t, rows, p_I, R_IB, T = _commanded(path, topics, cmap, params, thrust_max,
                                       (t, rows, p_I, R_IB), report, day)
    q_IB = Rotation.from_matrix(R_IB).as_quat(scalar_first=True)
    cols = {"t": t}
    cols.update({n: p_I[:, j] for j, n in enumerate("xyz")})
    cols.update({n: q_IB[:, j] for j, n in enumerate(("qw", "qx", "qy", "qz"))})
    cols.update({f"T{j + 1}": T[:, j] for j in range(4)})
    _add_imu(topics, cmap, t, cols, report)
    _check_frames(path, cmap, t, R_IB, cols)
    _add_tension_battery(topics, cmap, t, cols, report)
    meta = {"schema": "gainsched-flightlog/1", "flight_id": Path(path).stem,
            "source_format": foreign_format(path) or "", "channel_map": cmap.name,
            "motors_order": str(list(cmap.motor_order))}
    if cmap.alpha_c_deg is not None and cmap.gamma_c_deg is not None:
        meta["alpha_c_deg"] = repr(float(cmap.alpha_c_deg))
        meta["gamma_c_deg"] = repr(float(cmap.gamma_c_deg))
        meta["plane_source"] = f"channel map {cmap.name}"
    return ConvertedLog(cols, meta, rows, f"{cmap.position.topic} sample", tuple(report),
                        _sources(cmap, cols))


#: the columns each channel of a map gives
_COLUMNS_OF = {"position": "xyz", "attitude": ("qw", "qx", "qy", "qz"), "gyro": "pqr",
               "accelerometer": ("ax", "ay", "az"), "motors": ("T1", "T2", "T3", "T4"),
               "tension": ("tension",), "battery": ("vbat",)}


def _sources(cmap: ChannelMap, cols: dict) -> dict[str, str]:
    """Column -> the topic it came from, for the columns not of the position's topic
    (whose sample numbers the errors give)."""
    return {c: ch.topic for name, ch in cmap.channels().items() for c in _COLUMNS_OF[name]
            if c in cols and ch.topic != cmap.position.topic}


def _pose(topics, cmap: ChannelMap, report: list) -> tuple:
    """``(t, rows, p_I, R_IB)`` of the pose topics: time (s, with the map's pose offset),
    the position topic's sample numbers (from 1), the COG position in the anchor's ENU
    frame (m) and the body's FLU attitude (the attitude slerped to the position's times
    when it has a topic of its own)."""
    from scipy.spatial.transform import Rotation, Slerp

    pos_ch, att_ch = cmap.position, cmap.attitude
    pos = topics[pos_ch.topic]
    t = pos.t + (cmap.pose_offset_s or 0.0)
    rows = np.arange(1, t.size + 1)
    p = np.stack([pos.fields[f] for f in pos_ch.fields], -1)
    att = topics[att_ch.topic]
    q_raw = np.stack([att.fields[f] for f in att_ch.fields], -1)
    if cmap.attitude_order == "xyzw":
        q_raw = q_raw[:, [3, 0, 1, 2]]
    report.append(f"position: {pos_ch.topic} {', '.join(pos_ch.fields)} ({t.size} samples, "
                  f"{_rate(pos.t)}), {cmap.world} -> ENU at the anchor "
                  f"{cmap.anchor_m.tolist()} m")
    t_att = att.t + (cmap.pose_offset_s or 0.0)
    if att_ch.topic == pos_ch.topic:
        R_wb = Rotation.from_quat(q_raw, scalar_first=True).as_matrix()
    else:
        inside = (t >= t_att[0]) & (t <= t_att[-1])
        t, p, rows = t[inside], p[inside], rows[inside]
        slerp = Slerp(t_att, Rotation.from_quat(q_raw, scalar_first=True))
        R_wb = slerp(t).as_matrix()
    report.append(f"attitude: {att_ch.topic} {', '.join(att_ch.fields)} ({cmap.attitude_order}"
                  f", {_rate(att.t)}{'' if att_ch.topic == pos_ch.topic else ', slerp'}), "
                  f"{cmap.world}/{cmap.body} -> ENU/FLU")
    C_w = _NED_TO_ENU if cmap.world == "NED" else np.eye(3)
    C_b = _FRD_TO_FLU if cmap.body == "FRD" else np.eye(3)
    return t, rows, (p - cmap.anchor_m) @ C_w.T, C_w @ R_wb @ C_b


def _commanded(path, topics, cmap: ChannelMap, params, thrust_max, pose, report: list,
               day: bool = False):
    """The pose samples ``pose = (t, rows, p_I, R_IB)`` while the motors were commanded,
    with ``T`` (n, 4) N, the motor thrusts T1..T4 held and averaged over each pose
    interval; a command outside the thrust curve's range inside that span is an error
    naming its field and sample. ``day``: a whole day, disarmed stretches (a command
    outside the range: NaN, PWM below its minimum) included with no thrust."""
    t, rows, p_I, R_IB = pose
    mot = topics[cmap.motors.topic]
    fields = [cmap.motors.fields[i - 1] for i in cmap.motor_order]
    cmd = np.stack([mot.fields[f] for f in fields], -1)
    T_all, valid = _thrust(path, cmap, cmd, params, thrust_max)
    if day:
        off = int(np.count_nonzero(~valid.all(-1)))
        T_all = np.where(valid, T_all, 0.0)
        inside = t - _edges(t)[1] >= mot.t[0]
        t, rows, p_I, R_IB = t[inside], rows[inside], p_I[inside], R_IB[inside]
        report.append(f"motors: {cmap.motors.topic} {', '.join(fields)} as T1..T4 "
                      f"({cmap.unit}, {_rate(mot.t)}, held, the mean over each pose interval; "
                      f"the whole day: {off} samples disarmed, no thrust)")
        return t, rows, p_I, R_IB, _held_mean(mot.t, T_all, t)
    ok = np.flatnonzero(valid.all(-1))
    if ok.size == 0:
        raise InputError(path, f"topic {cmap.motors.topic}", "no sample with every motor "
                         f"command in the {cmap.unit} range (disarmed all along?)")
    first, last = ok[0], ok[-1]
    bad = np.flatnonzero(~valid[first:last + 1].all(-1))
    if bad.size:
        k = first + bad[0]
        j = int(np.flatnonzero(~valid[k])[0])
        raise InputError(path, f"topic {cmap.motors.topic}, field {fields[j]}, sample {k + 1}",
                         f"command {float(cmd[k, j])!r} is outside the {cmap.unit} range of "
                         "the thrust curve")
    t_mot = mot.t
    _, h_pose = _edges(t)
    h_mot = float(np.median(np.diff(t_mot))) if t_mot.size > 1 else 0.0
    # a pose sample needs the whole interval before it commanded (its mean command)
    armed = (t - h_pose >= t_mot[first]) & (t <= t_mot[last] + h_mot)
    left = int(np.count_nonzero(~armed))
    t, p_I, R_IB, rows = t[armed], p_I[armed], R_IB[armed], rows[armed]
    if t.size == 0:
        raise InputError(path, f"topic {cmap.position.topic}", "no pose sample while the "
                         "motors were commanded")
    T = _held_mean(t_mot[first:last + 1], T_all[first:last + 1], t)
    report.append(f"motors: {cmap.motors.topic} {', '.join(fields)} as T1..T4 ({cmap.unit}"
                  f"{'' if cmap.unit == 'N' else ' through the thrust curve'}, {_rate(t_mot)}, "
                  "held, the mean over each pose interval)"
                  + (f"; {left} pose samples outside the commanded span left out" if left
                     else ""))
    return t, rows, p_I, R_IB, T


def _add_imu(topics, cmap: ChannelMap, t, cols: dict, report: list) -> None:
    """The gyro (p, q, r) and accelerometer (ax, ay, az) columns the map names, in FLU,
    each the mean over a pose interval centred on each pose sample."""
    C_b = _FRD_TO_FLU if cmap.imu_body == "FRD" else np.eye(3)
    for ch, names in ((cmap.gyro, ("p", "q", "r")), (cmap.accelerometer, ("ax", "ay", "az"))):
        if ch is None:
            continue
        src = topics[ch.topic]
        x = np.stack([src.fields[f] for f in ch.fields], -1) @ C_b.T
        mean = _centred_mean(src.t, x, t)
        cols.update({n: mean[:, j] for j, n in enumerate(names)})
        report.append(f"{'gyro' if names[0] == 'p' else 'accelerometer'}: {ch.topic} "
                      f"{', '.join(ch.fields)} ({_rate(src.t)}, the mean over a pose "
                      f"interval centred on each pose sample), {cmap.imu_body} -> FLU")


def _add_tension_battery(topics, cmap: ChannelMap, t, cols: dict, report: list) -> None:
    """The load cell's ``tension`` (N) and the battery's ``vbat`` (V, unknown samples
    NaN) columns when the map names them, each held at the pose samples."""
    if cmap.tension is not None:
        src = topics[cmap.tension.topic]
        x = src.fields[cmap.tension.fields[0]] * cmap.tension.scale
        cols["tension"] = _held(src.t, x, t)
        report.append(f"tension: {cmap.tension.topic} {cmap.tension.fields[0]} x "
                      f"{cmap.tension.scale:g} (held)")
    bat = cmap.battery
    if bat is not None and bat.topic not in topics:
        report.append(f"battery: {bat.topic} not in the log (optional): no vbat column")
    elif bat is not None:
        src = topics[bat.topic]
        x = src.fields[bat.fields[0]] * bat.scale
        unknown = ~(x > 0)  # PX4: 0 if unknown
        x = np.where(unknown, np.nan, x)
        cols["vbat"] = _held(src.t, x, t)
        report.append(f"battery: {bat.topic} {bat.fields[0]} x {bat.scale:g} as vbat (held"
                      + (f"; {int(np.count_nonzero(unknown))} samples of 0 or less, unknown, "
                         "left out" if unknown.any() else "") + ")")


def _check_frames(path, cmap: ChannelMap, t, R_IB, cols) -> None:
    """The map's frames against the physics the sensors see (the mistakes a new logging
    setup makes once: a NED log read as ENU, FRD as FLU, a wrong quaternion order):

    * what holds the vehicle, the acceleration of the positions minus gravity, is
      rotor thrust plus the tether's pull, both along the body's up axis ``z_B`` on
      average (the tether pulls towards the anchor, where the thrust axis leans): its
      mean projection on ``z_B`` must be positive (a flipped world frame turns gravity
      over, a flipped body frame the thrust axis);
    * the accelerometer, turned into the inertial frame by the attitude and averaged,
      holds the weight up: its mean must point within 60 deg of the inertial up;
    * the gyro must turn the attitude the way the attitude turns: the body rates from
      consecutive quaternions, ``R_k^T R_{k+1}``, must agree in sign with the logged
      ones on the axes that move (a quaternion read in the wrong order does not).
    """
    p = np.stack([cols[n] for n in "xyz"], -1)
    if t.size > 10:
        h = np.diff(t)
        acc = 2 * ((p[2:] - p[1:-1]) / h[1:, None] - (p[1:-1] - p[:-2]) / h[:-1, None]) / (
            h[1:] + h[:-1])[:, None]
        hold = acc - np.array([0.0, 0.0, -9.80665])
        along = float(np.mean(np.einsum("ki,ki->k", hold, R_IB[1:-1, :, 2])))
        if along < 0:
            raise InputError(cmap.source, "frames", f"{path}: the logged attitude's thrust "
                             f"axis points away from what holds the vehicle up (the positions' "
                             f"acceleration minus gravity, {along:.3g} m/s^2 along z_B): is "
                             f"the log's world frame {cmap.world} and its body frame "
                             f"{cmap.body}, and the quaternion {cmap.attitude_order}?")
    if "ax" in cols:
        f_B = np.stack([cols[n] for n in ("ax", "ay", "az")], -1)
        ok = np.all(np.isfinite(f_B), -1)
        if np.count_nonzero(ok) > 10:
            f_I = np.einsum("kij,kj->ki", R_IB[ok], f_B[ok]).mean(0)
            up = f_I[2] / max(float(np.linalg.norm(f_I)), 1e-12)
            if up < 0.5:
                off = math.degrees(math.acos(max(-1.0, min(1.0, up))))
                raise InputError(cmap.source, "frames", f"{path}: the accelerometer, turned "
                                 f"by the logged attitude, holds the vehicle up {off:.0f} deg "
                                 f"away from the inertial up: is the log's world frame "
                                 f"{cmap.world} and its body frame {cmap.body}, and the "
                                 f"quaternion {cmap.attitude_order}?")
    if "p" in cols and t.size > 3:
        w = np.stack([cols[n] for n in ("p", "q", "r")], -1)
        dR = np.einsum("kji,kjl->kil", R_IB[:-1], R_IB[1:])  # R_k^T R_{k+1}
        rot = np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0],
                        dR[:, 1, 0] - dR[:, 0, 1]], -1) / (2 * np.diff(t)[:, None])
        mid = 0.5 * (w[:-1] + w[1:])
        ok = np.all(np.isfinite(mid), -1)
        for j, axis in enumerate("pqr"):
            a, b = rot[ok, j], mid[ok, j]
            if a.size > 10 and np.sqrt(np.mean(b * b)) > 0.2:  # the axis moves: rad/s
                if float(np.mean(a * b)) < 0:
                    raise InputError(cmap.source, "frames.body", f"{path}: the gyro's {axis} "
                                     "turns against the logged attitude: is the body frame "
                                     f"{cmap.body} (and the quaternion "
                                     f"{cmap.attitude_order})?")


def _rate(t) -> str:
    return f"{1.0 / float(np.median(np.diff(t))):.0f} Hz" if t.size > 1 else "one sample"
