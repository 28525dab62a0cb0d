"""What a PX4 ULog or a ROS 2 bag holds, for writing its channel map: each topic with its
type, number of samples, rate and the numeric fields a map can name
(``gainsched convert --list LOG``).

The fields are spelled as a channel map names them (docs/flight-log.md, "Logs of PX4 and
ROS 2"): a ULog's as pyulog flattens them (``q[0]``), a bag message's as paths
(``pose.position.x``, ``orientation_covariance[0]``); runs of array elements are shown
once, ``q[0..3]``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError
from ._foreign import foreign_format, open_bag, open_ulog

__all__ = ["TopicInfo", "LogListing", "list_topics"]

_ELEMENT = re.compile(r"^(.*)\[([0-9]+)\]$")
#: the ROS base types a channel can be read from (strings are not)
_NUMERIC = frozenset({"bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32",
                      "uint32", "int64", "uint64", "float32", "float64"})
#: deepest message nesting followed (sensor_msgs and geometry_msgs nest 3-4 deep)
_MAX_DEPTH = 8


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a log.

    Attributes
    ----------
    name : str
        The topic.
    kind : str
        A bag's: the ROS message type; a ULog's: the instance (a map reads instance 0).
    samples : int
    rate_hz : float
        Samples per second over the topic's own span, Hz (NaN with fewer than 2).
    fields : tuple of str
        The numeric fields a channel map can name, array runs shortened (``q[0..3]``).
    """

    name: str
    kind: str
    samples: int
    rate_hz: float
    fields: tuple[str, ...]


@dataclass(frozen=True)
class LogListing:
    """The topics of a log (:func:`list_topics`); :meth:`lines` is what the command
    prints."""

    path: Path
    format: str
    duration_s: float
    topics: tuple[TopicInfo, ...]

    def lines(self) -> list[str]:
        """A header line, then one line per topic: name, type, samples, rate, fields."""
        kinds = {"ulog": "PX4 ULog", "rosbag2": "ROS 2 bag"}
        n = len(self.topics)
        out = [f"{self.path}: {kinds[self.format]}, {n} topic{'' if n == 1 else 's'} over "
               f"{self.duration_s:.1f} s"]
        w = max([len(t.name) for t in self.topics] + [5])
        wk = max([len(t.kind) for t in self.topics] + [4])
        out.append(f"  {'topic':<{w}}  {'type':<{wk}}  {'samples':>8}  {'rate Hz':>8}  fields")
        for t in self.topics:
            rate = "-" if not np.isfinite(t.rate_hz) else f"{t.rate_hz:.1f}"
            out.append(f"  {t.name:<{w}}  {t.kind:<{wk}}  {t.samples:>8}  {rate:>8}  "
                       + ", ".join(t.fields))
        return out


def _rate(t: np.ndarray) -> float:
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    return (t.size - 1) / span if span > 0 else float("nan")


def _shorten(fields) -> tuple[str, ...]:
    """Runs of array elements ``a[0]``, ``a[1]``, ... as ``a[0..n]``, order kept."""
    out: list[str] = []
    runs: dict[str, list[int]] = {}
    for f in fields:
        m = _ELEMENT.match(f)
        if m is None:
            out.append(f)
            continue
        base = m.group(1)
        if base not in runs:
            runs[base] = []
            out.append(base + "[]")
        runs[base].append(int(m.group(2)))
    return tuple(f"{f[:-2]}[{min(runs[f[:-2]])}..{max(runs[f[:-2]])}]"
                 if f.endswith("[]") and f[:-2] in runs else f for f in out)


def _ulog_listing(path: Path) -> tuple[float, list[TopicInfo]]:
    ulog = open_ulog(path)
    topics, t0, t1 = [], np.inf, -np.inf
    for d in sorted(ulog.data_list, key=lambda d: (d.name, d.multi_id)):
        t = np.asarray(d.data["timestamp"], dtype=np.float64) * 1e-6
        if t.size:
            t0, t1 = min(t0, t[0]), max(t1, t[-1])
        fields = [f.field_name for f in d.field_data
                  if f.field_name != "timestamp" and not f.field_name.startswith("_padding")]
        kind = "instance 0" if d.multi_id == 0 else f"instance {d.multi_id}, not read"
        topics.append(TopicInfo(d.name, kind, int(t.size), _rate(t), _shorten(fields)))
    return (float(t1 - t0) if np.isfinite(t0) else 0.0), topics


def _ros_fields(store, msgtype: str, prefix: str = "", depth: int = 0) -> list[str]:
    """The numeric leaf fields of a ROS message type, as paths."""
    if depth > _MAX_DEPTH or msgtype not in store.fielddefs:
        return []
    out = []
    for name, (node, spec) in store.fielddefs[msgtype][1]:
        path = prefix + name
        if node.name == "BASE" and spec[0] in _NUMERIC:
            out.append(path)
        elif node.name == "NAME":
            out += _ros_fields(store, spec, path + ".", depth + 1)
        elif node.name == "ARRAY":  # fixed length: its elements
            (inner, ispec), n = spec
            if inner.name == "BASE" and ispec[0] in _NUMERIC:
                out += [f"{path}[{i}]" for i in range(n)]
    return out


def _bag_listing(path: Path) -> tuple[float, list[TopicInfo]]:
    reader = open_bag(path)
    try:
        stamps: dict[int, list[int]] = {id(c): [] for c in reader.connections}
        for conn, timestamp, _ in reader.messages():  # times only: nothing deserialised
            stamps[id(conn)].append(timestamp)
        topics = []
        for c in sorted(reader.connections, key=lambda c: c.topic):
            t = np.sort(np.asarray(stamps[id(c)], dtype=np.float64)) * 1e-9
            topics.append(TopicInfo(c.topic, c.msgtype, int(t.size), _rate(t),
                                    _shorten(_ros_fields(reader.typestore, c.msgtype))))
        duration = reader.duration * 1e-9 if reader.message_count else 0.0
    finally:
        reader.close()
    return float(duration), topics


def list_topics(path) -> LogListing:
    """The topics of a PX4 ULog or a ROS 2 bag, for writing its channel map.

    Parameters
    ----------
    path : str or path-like
        A ``.ulg``, a bag's ``.mcap`` or ``.db3``, or a rosbag2 folder.

    Returns
    -------
    LogListing

    Raises
    ------
    InputError
        Naming the file: it is not a ULog or a bag, or cannot be read as one.
    """
    p = Path(path)
    fmt = foreign_format(p)
    if fmt is None:
        raise InputError(p, "", "--list reads a PX4 ULog (.ulg) or a ROS 2 bag (.mcap, .db3 "
                         "or a rosbag2 folder)")
    if not p.exists():
        raise InputError(p, "", "cannot read (No such file or directory)")
    duration, topics = _ulog_listing(p) if fmt == "ulog" else _bag_listing(p)
    return LogListing(p, fmt, duration, tuple(topics))
