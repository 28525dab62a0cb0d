"""A flight controller's log and a motion-capture recording made one flight log.

A lab's flight day arrives as two files on two clocks: the flight controller's (a PX4
ULog: gyro, accelerometer, motor commands, battery; stamped from boot) and the motion
capture's (a ROS 2 bag of poses; stamped in Unix time). :func:`convert_pair` reads each
through its own channel map (the pose's names position and attitude only,
``load_channel_map(..., pose_only=True)``), puts the pose on the flight controller's
clock (:func:`~gainsched.analysis.logs._clocks.align_clocks`: the offset and drift
estimated from the body rates and accelerations both hold, with their uncertainty;
or the pose map's ``time.pose_offset_s`` when the user gives it) and converts the
whole as one log (:func:`~gainsched.analysis.logs._foreign.convert_topics`): the
samples are the pose's, the sensors averaged and held onto them as for one file.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ._channelmap import ChannelMap
from ._clocks import ClockFit, align_clocks, rate_magnitude, specific_force_magnitude
from ._foreign import ConvertedLog, Topic, convert_topics, read_topics
from ._progress import report

__all__ = ["convert_pair", "clock_signals"]

_G = 9.80665


def _stack(topic: Topic, fields) -> np.ndarray:
    return np.stack([topic.fields[f] for f in fields], -1)


def clock_signals(fc_topics: dict, fc_map: ChannelMap, pose_topics: dict,
                  pose_map: ChannelMap) -> tuple[dict, dict]:
    """The signals each file holds of the same motion, by pair name, ``(t, x)`` on its
    own clock: ``"body rate"`` (the gyro's magnitude; the pose attitude's rate),
    ``"specific force"`` (the accelerometer's magnitude; ``|a - g|`` of the pose's
    positions) or, without an accelerometer, ``"thrust"`` (the sum of the motor
    commands against ``|a - g|``)."""
    att = pose_topics[pose_map.attitude.topic]
    q = _stack(att, pose_map.attitude.fields)
    if pose_map.attitude_order == "xyzw":
        q = q[:, [3, 0, 1, 2]]
    pos = pose_topics[pose_map.position.topic]
    g_world = (0.0, 0.0, _G) if pose_map.world == "NED" else (0.0, 0.0, -_G)
    force = specific_force_magnitude(pos.t, _stack(pos, pose_map.position.fields), g_world)
    fc, pose = {}, {}
    if fc_map.gyro is not None and fc_map.gyro.topic in fc_topics:
        g = fc_topics[fc_map.gyro.topic]
        fc["body rate"] = (g.t, np.linalg.norm(_stack(g, fc_map.gyro.fields), axis=1))
        pose["body rate"] = rate_magnitude(att.t, q)
    acc = fc_map.accelerometer
    if acc is not None and acc.topic in fc_topics:
        a = fc_topics[acc.topic]
        fc["specific force"] = (a.t, np.linalg.norm(_stack(a, acc.fields), axis=1))
        pose["specific force"] = force
    elif fc_map.motors is not None and fc_map.motors.topic in fc_topics:
        m = fc_topics[fc_map.motors.topic]
        fc["thrust"] = (m.t, _stack(m, fc_map.motors.fields).sum(-1))
        pose["thrust"] = force
    return fc, pose


def convert_pair(fc_path, pose_path, fc_map: ChannelMap, pose_map: ChannelMap, *,
                 thrust_max: float | None = None, day: bool = False,
                 ) -> tuple[ConvertedLog, ClockFit | None]:
    """One flight log of a flight controller's log and a pose recorded apart.

    Parameters
    ----------
    fc_path, pose_path : path-like
        The flight controller's ULog or bag, and the motion capture's bag or ULog.
    fc_map : ChannelMap
        Where the flight controller's log holds the sensors and the motors (its position
        and attitude, if it names them, are not read).
    pose_map : ChannelMap
        Where the recording holds the pose (``pose_only``); its frames, anchor and
        circle are the log's; its ``time.pose_offset_s``, when given, is the clock
        offset (no estimate).
    thrust_max : float, optional
        A motor's thrust at full command, N, when the map does not give it.
    day : bool
        A whole flight day: disarmed stretches kept with no thrust.

    Returns
    -------
    (ConvertedLog, ClockFit or None)
        The converted columns on the flight controller's clock (rows: the pose's
        samples; the report's first line the clocks), and the clock fit (None when the
        offset was given).

    Raises
    ------
    InputError
        As :func:`~gainsched.analysis.logs._foreign.read_topics` for either file, and as
        :func:`~gainsched.analysis.logs._clocks.align_clocks` (no overlap, no clear or
        an ambiguous match).
    """
    fc_path, pose_path = Path(fc_path), Path(pose_path)
    sensors = dataclasses.replace(fc_map, position=None, attitude=None)
    fc_topics, params = read_topics(fc_path, sensors)
    pose_topics, _ = read_topics(pose_path, pose_map)
    report("align clocks")
    if pose_map.pose_offset_s is not None:
        fit, shift = None, lambda t: t + pose_map.pose_offset_s  # noqa: E731
        off = pose_map.pose_offset_s
        line = (f"clocks: pose time {'-' if off < 0 else '+'} {abs(off):.6f} s "
                "(time.pose_offset_s of the pose's map)")
    else:
        fc_sig, pose_sig = clock_signals(fc_topics, fc_map, pose_topics, pose_map)
        fit = align_clocks(fc_sig, pose_sig, fc_name=str(fc_path), pose_name=str(pose_path))
        shift, line = fit.fc_from_pose, fit.line()
    key = lambda topic: f"{pose_path.name}:{topic}"  # noqa: E731
    topics = dict(fc_topics)
    for name, tp in pose_topics.items():
        topics[key(name)] = Topic(shift(tp.t), tp.fields)
    merged = dataclasses.replace(
        fc_map, name=f"{fc_map.name} + {pose_map.name}", world=pose_map.world,
        body=pose_map.body, sensor_body=fc_map.imu_body, anchor_m=pose_map.anchor_m,
        alpha_c_deg=pose_map.alpha_c_deg if pose_map.alpha_c_deg is not None
        else fc_map.alpha_c_deg,
        gamma_c_deg=pose_map.gamma_c_deg if pose_map.gamma_c_deg is not None
        else fc_map.gamma_c_deg,
        pose_offset_s=0.0,
        position=dataclasses.replace(pose_map.position, topic=key(pose_map.position.topic)),
        attitude=dataclasses.replace(pose_map.attitude, topic=key(pose_map.attitude.topic)),
        attitude_order=pose_map.attitude_order)
    conv = convert_topics(fc_path, topics, params, merged, thrust_max=thrust_max, day=day)
    meta = {**conv.meta, "pose_source": pose_path.name, "pose_channel_map": pose_map.name}
    if fit is not None:
        meta.update(clock_offset_s=repr(fit.offset_s), clock_drift=repr(fit.drift),
                    clock_ref_s=repr(fit.t_ref_s))
        if math.isfinite(fit.offset_sigma_s):
            meta["clock_offset_sigma_s"] = repr(fit.offset_sigma_s)
    return dataclasses.replace(conv, meta=meta, report=(line, *conv.report)), fit
