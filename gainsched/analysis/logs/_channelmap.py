"""Channel maps: how a PX4 ULog or a ROS 2 bag holds what a flight log needs.

A map (TOML, schema ``gainsched-channelmap/1``; docs/flight-log.md, "Logs of PX4 and
ROS 2") names, for each channel of ``gainsched-flightlog/1``, the topic and the
fields that carry it, and says how to turn them into the log's frames and units: the
world and body frames (NED/FRD or ENU/FLU) and where the anchor is, the quaternion's
order, the motor order and the command's unit with its map to newtons, the circle
plane (given, or estimated from the flown positions), and a time offset between the
pose's clock and the on-board clock. Shipped maps (:func:`shipped_maps`): ``px4``
(``actuator_motors``, ``vehicle_angular_velocity``), ``px4_legacy``
(``actuator_outputs`` in PWM, ``sensor_combined``) and ``ros2`` (a template for bags
of ``geometry_msgs/PoseStamped`` and ``sensor_msgs/Imu``).

Every key is checked when the map is loaded (:func:`load_channel_map`); a bad one is
one :class:`~gainsched.errors.InputError` naming the file and the key.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from ...actuators import PX4_MOTOR_ORDER
from ...errors import InputError
from ...textinput import parse_toml, read_text

__all__ = [
    "MAP_SCHEMA",
    "Channel",
    "ChannelMap",
    "load_channel_map",
    "channel_map_from_text",
    "shipped_maps",
    "PX4_MOTOR_ORDER",
]

MAP_SCHEMA = "gainsched-channelmap/1"
WORLD_FRAMES = ("NED", "ENU")
BODY_FRAMES = ("FRD", "FLU")
UNITS = ("N", "normalized", "pwm")
_PART = r"[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?"  # name or name[index]
_FIELD = re.compile(rf"^{_PART}(\.{_PART})*$")
_SECTIONS = {
    "schema": None, "name": None, "frames": ("world", "body", "anchor_m"),
    "circle": ("alpha_c_deg", "gamma_c_deg"), "time": ("pose_offset_s", "stamp"),
    "position": ("topic", "fields"), "attitude": ("topic", "fields", "order"),
    "gyro": ("topic", "fields"), "accelerometer": ("topic", "fields"),
    "motors": ("topic", "fields", "order", "unit", "thrust_max_N", "thr_mdl_fac", "pwm_min",
               "pwm_max"),
    "tension": ("topic", "fields", "scale"),
    "battery": ("topic", "fields", "scale", "optional"),
}


@dataclass(frozen=True)
class Channel:
    """Where one channel is: a topic and its fields (``"q[0]"``, ``"pose.position.x"``);
    ``optional``: a log may lack the topic (the channel is then left out)."""

    topic: str
    fields: tuple[str, ...]
    scale: float = 1.0
    optional: bool = False


@dataclass(frozen=True)
class ChannelMap:
    """A validated channel map (see the module docstring and docs/flight-log.md).

    Attributes
    ----------
    name, source : str
        The map's name and the file (or ``<name>`` of a shipped map) it came from.
    world, body : str
        The log's world frame (``"NED"`` or ``"ENU"``) and body frame (``"FRD"`` or
        ``"FLU"``): the axes of the positions and of the attitude's two frames, and the
        body axes of the gyro and the accelerometer.
    anchor_m : ndarray, shape (3,), m
        The tether anchor in the log's world frame.
    alpha_c_deg, gamma_c_deg : float or None, deg
        The circle plane; None: estimated from the flown positions (and said so).
    pose_offset_s : float or None, s
        Added to the pose channels' times to put them on the on-board clock; None: not
        given (0 for one log; a pose recorded apart has its offset estimated).
    stamp : str
        ROS 2 bags: ``"header"`` (the messages' ``header.stamp``) or ``"log"`` (the time
        the bag recorded them); ULog: always the message's ``timestamp``.
    position, attitude : Channel
        Position (3 fields, m) and attitude quaternion (4 fields in ``attitude_order``).
    attitude_order : str
        ``"wxyz"`` or ``"xyzw"``: the order of the attitude's fields.
    gyro, accelerometer, tension : Channel or None
        Optional: body rates (rad/s), specific force (m/s^2), load cell (N, times
        ``scale``).
    battery : Channel or None
        Optional: the battery voltage (V, times ``scale``), the column ``vbat``; with
        ``optional = true`` a log without its topic converts without it (PX4's
        ``battery_status``, sensor_msgs/BatteryState).
    motors : Channel or None
        The commands of the log's motors (at least the four ``motor_order`` names); None
        in the map of a pose recorded apart (``pose_only``).
    motor_order : tuple of int
        For the tool's motors 1..4: which of the ``motors`` fields (1-based).
    unit : str
        The command's unit: ``"N"``, ``"normalized"`` (0..1 through the thrust curve) or
        ``"pwm"`` (microseconds between ``pwm_min`` and ``pwm_max``, then the curve).
    thrust_max_N : float or None, N
        A motor's thrust at full command; None: the analysis config's
        ``vehicle.thrust_max``.
    thr_mdl_fac : float or str
        PX4's ``THR_MDL_FAC``, ``T / T_max = (1 - f) c + f c^2`` for the command c in
        0..1; ``"log"``: the value the ULog's parameters hold.
    pwm_min, pwm_max : float or str, us
        The PWM range (``"log"``: ``PWM_MAIN_MIN`` / ``PWM_MAIN_MAX`` of the ULog).
    sensor_body : str or None
        The body frame of the gyro and the accelerometer when it is not ``body`` (a pose
        recorded apart, whose map gives the attitude's); None: ``body``.
    """

    name: str
    source: str
    world: str
    body: str
    anchor_m: np.ndarray
    alpha_c_deg: float | None
    gamma_c_deg: float | None
    pose_offset_s: float | None
    stamp: str
    position: Channel
    attitude: Channel
    attitude_order: str
    gyro: Channel | None
    accelerometer: Channel | None
    motors: Channel | None
    motor_order: tuple[int, int, int, int]
    unit: str
    thrust_max_N: float | None
    thr_mdl_fac: float | str
    pwm_min: float | str
    pwm_max: float | str
    tension: Channel | None
    battery: Channel | None = None
    sensor_body: str | None = None

    @property
    def imu_body(self) -> str:
        """The body frame of the gyro and the accelerometer."""
        return self.sensor_body or self.body

    def channels(self) -> dict[str, Channel]:
        """The channels the map names, by channel name."""
        named = {"position": self.position, "attitude": self.attitude, "gyro": self.gyro,
                 "accelerometer": self.accelerometer, "motors": self.motors,
                 "tension": self.tension, "battery": self.battery}
        return {k: v for k, v in named.items() if v is not None}


def _maps_folder() -> Path:
    return Path(str(resources.files("gainsched.analysis.logs") / "maps"))


def shipped_maps() -> tuple[str, ...]:
    """The names of the maps the package ships (``px4``, ``px4_legacy``, ``ros2``)."""
    return tuple(sorted(p.stem for p in _maps_folder().glob("*.toml")))


def load_channel_map(path, *, pose_only: bool = False) -> ChannelMap:
    """Load and validate a channel map: a TOML file, or the name of a shipped map;
    ``pose_only``: the map of a motion-capture recording apart from the flight
    controller's log (position and attitude only, :func:`channel_map_from_text`).

    Raises
    ------
    InputError
        Naming the file and the key: unreadable, not TOML, an unknown or missing key,
        a frame, order or unit not in the lists, a value of the wrong type or range.
    """
    p = Path(path)
    if not p.exists() and len(p.parts) == 1 and not p.suffix and str(p) in shipped_maps():
        p = _maps_folder() / f"{p}.toml"
    hint = f"; the shipped maps are {', '.join(shipped_maps())}" if not p.suffix else ""
    text = read_text(p, what="channel map", hint=hint)
    return channel_map_from_text(text, str(p), default_name=p.stem, pose_only=pose_only)


def _get(src, data: dict, section: str, key: str, kind, required=True, default=None):
    where = f"{section}.{key}" if section else key
    if key not in data:
        if required:
            raise InputError(src, where, "missing required key")
        return default
    v = data[key]
    if kind is float:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise InputError(src, where, f"must be a finite number, got {v!r}")
        return float(v)
    if kind is str:
        if not isinstance(v, str):
            raise InputError(src, where, f"must be a string, got {v!r}")
        return v
    return v


def _choice(src, data, section, key, options, default=None):
    v = _get(src, data, section, key, str, default is None, default)
    if v not in options:
        raise InputError(src, f"{section}.{key}", f"must be one of {', '.join(options)}, got "
                         f"{v!r}")
    return v


def _number_or(src, data, section, key, word, default):
    """A finite number, the string ``word`` (e.g. "log", "estimate"), or the default."""
    if key not in data:
        return default
    v = data[key]
    if v == word:
        return None if word == "estimate" else word
    return _get(src, data, section, key, float)


def _channel(src, data: dict, name: str, n_fields: int | None, required: bool):
    sec = data.get(name)
    if sec is None:
        if required:
            raise InputError(src, name, "missing required section")
        return None
    if not isinstance(sec, dict):
        raise InputError(src, name, "must be a table")
    for key in sec:
        if key not in _SECTIONS[name]:
            raise InputError(src, f"{name}.{key}", f"unknown key (known: "
                             f"{', '.join(_SECTIONS[name])})")
    topic = _get(src, sec, name, "topic", str)
    if not topic:
        raise InputError(src, f"{name}.topic", "must not be empty")
    fields = sec.get("fields")
    if not isinstance(fields, list) or not all(isinstance(f, str) for f in fields):
        raise InputError(src, f"{name}.fields", f"must be a list of field names, got {fields!r}")
    if n_fields is not None and len(fields) != n_fields:
        raise InputError(src, f"{name}.fields", f"needs {n_fields} fields, got {len(fields)}")
    for f in fields:
        if not _FIELD.match(f):
            raise InputError(src, f"{name}.fields", f"{f!r} is not a field name (name, "
                             "name[index], name.sub)")
    scale = _get(src, sec, name, "scale", float, False, 1.0) if "scale" in _SECTIONS[name] else 1.0
    if scale == 0:
        raise InputError(src, f"{name}.scale", "must not be 0")
    optional = sec.get("optional", False)
    if not isinstance(optional, bool):
        raise InputError(src, f"{name}.optional", f"must be true or false, got {optional!r}")
    return Channel(topic, tuple(fields), scale, optional)


def channel_map_from_text(text: str, source: str = "<map>", default_name: str = "map", *,
                          pose_only: bool = False) -> ChannelMap:
    """Parse and validate channel-map TOML held in a string (see :func:`load_channel_map`).

    ``pose_only``: a pose recorded apart (``gainsched convert FC_LOG POSE_LOG``): the map
    names ``position`` and ``attitude`` (with its frames, anchor, circle and time) and
    no channel of the flight controller's.
    """
    data = parse_toml(text, source)
    for key in data:
        if key not in _SECTIONS:
            raise InputError(source, key, f"unknown key (known: {', '.join(_SECTIONS)})")
    schema = _get(source, data, "", "schema", str)
    if schema != MAP_SCHEMA:
        raise InputError(source, "schema", f"must be {MAP_SCHEMA!r}, got {schema!r}")
    for sec in ("frames", "circle", "time"):
        for key in data.get(sec, {}):
            if key not in _SECTIONS[sec]:
                raise InputError(source, f"{sec}.{key}", f"unknown key (known: "
                                 f"{', '.join(_SECTIONS[sec])})")
    frames, circle, time = data.get("frames", {}), data.get("circle", {}), data.get("time", {})
    anchor = frames.get("anchor_m", [0.0, 0.0, 0.0])
    if (not isinstance(anchor, list) or len(anchor) != 3 or not all(
            isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a)
            for a in anchor)):
        raise InputError(source, "frames.anchor_m", f"must be 3 finite numbers (m), got "
                         f"{anchor!r}")
    if pose_only:
        for sec in ("gyro", "accelerometer", "motors", "tension", "battery"):
            if sec in data:
                raise InputError(source, sec, "a pose map names position and attitude only "
                                 "(the flight controller's map, --map, names the rest)")
        data = {**data, "motors": {"unit": "N"}}  # no motors: their defaults
    motors = data.get("motors")
    mot = _channel(source, data, "motors", None, True) if not pose_only else None
    order = motors.get("order", [1, 2, 3, 4]) if not pose_only else [1, 2, 3, 4]
    if mot is not None and (
            not isinstance(order, list) or len(order) != 4 or sorted(order) != sorted(set(order))
            or not all(isinstance(i, int) and not isinstance(i, bool) and
                       1 <= i <= len(mot.fields) for i in order)):
        raise InputError(source, "motors.order", f"must be 4 different field numbers "
                         f"1..{len(mot.fields)} (for the tool's motors 1..4), got {order!r}")
    unit = _choice(source, motors, "motors", "unit", UNITS)
    thrust_max = _get(source, motors, "motors", "thrust_max_N", float, False, None)
    if thrust_max is not None and not thrust_max > 0:
        raise InputError(source, "motors.thrust_max_N", f"must be > 0, got {thrust_max!r}")
    fac = _number_or(source, motors, "motors", "thr_mdl_fac", "log", 0.0)
    if isinstance(fac, float) and not 0.0 <= fac <= 1.0:
        raise InputError(source, "motors.thr_mdl_fac", f"must be in 0..1, got {fac!r}")
    pwm = [_number_or(source, motors, "motors", k, "log", d)
           for k, d in (("pwm_min", 1000.0), ("pwm_max", 2000.0))]
    if all(isinstance(v, float) for v in pwm) and not pwm[1] > pwm[0]:
        raise InputError(source, "motors.pwm_max", f"must be above pwm_min ({pwm[0]:g}), got "
                         f"{pwm[1]:g}")
    att = _channel(source, data, "attitude", 4, True)
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise InputError(source, "name", f"must be a non-empty string, got {name!r}")
    return ChannelMap(
        name=name,
        source=source,
        world=_choice(source, frames, "frames", "world", WORLD_FRAMES),
        body=_choice(source, frames, "frames", "body", BODY_FRAMES),
        anchor_m=np.array(anchor, dtype=float),
        alpha_c_deg=_number_or(source, circle, "circle", "alpha_c_deg", "estimate", None),
        gamma_c_deg=_number_or(source, circle, "circle", "gamma_c_deg", "estimate", None),
        pose_offset_s=_get(source, time, "time", "pose_offset_s", float, False, None),
        stamp=_choice(source, time, "time", "stamp", ("header", "log"), "header"),
        position=_channel(source, data, "position", 3, True),
        attitude=att,
        attitude_order=_choice(source, data["attitude"], "attitude", "order",
                               ("wxyz", "xyzw"), "wxyz"),
        gyro=_channel(source, data, "gyro", 3, False),
        accelerometer=_channel(source, data, "accelerometer", 3, False),
        motors=mot,
        motor_order=tuple(order),
        unit=unit,
        thrust_max_N=thrust_max,
        thr_mdl_fac=fac,
        pwm_min=pwm[0],
        pwm_max=pwm[1],
        tension=_channel(source, data, "tension", 1, False),
        battery=_channel(source, data, "battery", 1, False),
    )
