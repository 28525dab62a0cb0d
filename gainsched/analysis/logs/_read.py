"""Reading a flight log file into its gap-free segments, :func:`read_log`, and converting a
PX4 ULog or a ROS 2 bag, :func:`convert_log`.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np

from ...errors import GainschedWarning, InputError
from ._checks import _canonical, _check_plane, fitted_plane
from ._consistency import _plane_angles, check_log, thrust_units
from ._daycut import DayCut
from ._files import _check_file, _read_file, log_format
from ._flightlog import FlightLog, _make, _readonly
from ._schema import DEFAULT_MIN_SAMPLES, GAP_FACTOR
from ._write import write_log


class LogWarning(GainschedWarning):
    """A log problem that is reported but not fatal (a gap, a dropped short segment)."""


def read_log(
    path, *, channel_map=None, thrust_max: float | None = None,
    min_samples: int = DEFAULT_MIN_SAMPLES, gap_factor: float = GAP_FACTOR,
    config=None, trust=(), pose=None, pose_map=None, day: bool = False,
) -> list[FlightLog]:
    """Read a flight log file into its gap-free segments, checked against the spec.

    The format is docs/flight-log.md (``gainsched-flightlog/1``, CSV or HDF5), chosen by
    the file extension; a PX4 ULog (``.ulg``) or a ROS 2 bag (a rosbag2 folder, or its
    ``.mcap`` / ``.db3`` file) is converted to it first through a channel map
    (:mod:`gainsched.analysis.logs._foreign`). Every bad-data rule of the spec is enforced; the
    reader normalises only the quaternions (rows off unit norm by more than 1e-12
    divided by their norm, signs made continuous) and splits the log at gaps, never
    interpolating across them (the docstring of :mod:`gainsched.analysis.logs` has the
    details).

    Parameters
    ----------
    path : str or path-like
        The log file: ``.csv``, ``.h5``, ``.hdf5``, ``.ulg``, ``.mcap``, ``.db3`` or a
        rosbag2 folder.
    channel_map : ChannelMap, str or path-like, optional
        How a ULog or a bag holds the channels (:func:`gainsched.analysis.logs._channelmap.
        load_channel_map`: a file or a shipped map's name). Default for a ULog: the
        shipped ``px4``; a bag needs one.
    thrust_max : float, optional
        A motor's thrust at full command, N, for normalised or PWM commands when the map
        does not give it (the analysis config's ``vehicle.thrust_max``).
    min_samples : int, default 31
        Fewest samples of a segment (the differentiation window): shorter segments are
        dropped with a warning (:data:`DEFAULT_MIN_SAMPLES`).
    gap_factor : float, default 1.5
        A sample interval more than ``gap_factor`` times the file's median interval is a
        gap: the log is split there.
    config : Config, optional
        The config of the analysis: its vehicle (mass, g, thrust scale) is what the
        commanded thrust and the load cell are checked against
        (:mod:`gainsched.analysis.logs._consistency`); without it those two checks are skipped.
    trust : iterable of str, default ()
        Consistency checks to skip, by name (:data:`~gainsched.analysis.logs._consistency.
        CHECKS`: ``plane``, ``quaternion``, ``gyro``, ``thrust``, ``tension``,
        ``xi_ref``, ``radius``), where the user knows the log is right; the log's
        metadata ``trust`` adds to them.
    pose, pose_map : path-like, optional
        The motion capture's recording of the flight on a clock of its own and its map
        (:func:`convert_log`): ``path`` is then the flight controller's log.
    day : bool, default False
        ``path`` is a whole flight day: cut into its circles and manoeuvres first
        (:func:`read_day`, needs ``config``), the segments of those returned.

    Returns
    -------
    list of FlightLog
        The segments kept, in time order: one for a log without gaps.

    Raises
    ------
    InputError
        Naming the file, the column or key and the row (``line 17`` in CSV, ``sample 17``
        in HDF5): an unknown extension, an unreadable file, a missing required column or
        metadata key, an unknown schema, an incomplete group of optional columns (``p``,
        ``q`` without ``r``), a cell that is not a number, NaN or inf in a required
        column, a value outside the plausible range (:data:`PLAUSIBLE`), time that does not
        strictly increase, a quaternion norm off unit by more than 0.01, a declared
        circle plane the positions do not lie in, channels that contradict each other
        or the model (:func:`~gainsched.analysis.logs._consistency.check_log`), fewer than
        ``min_samples`` samples, or no segment left after splitting.

    Warns
    -----
    LogWarning
        For each gap (the log is split there) and each dropped short segment.

    Examples
    --------
    >>> segs = gs.read_log("examples/flights/v9.csv")
    >>> log = segs[0]
    >>> len(segs), len(log), log.duration, round(1 / log.dt_median)
    (1, 551, 2.75, 200)
    >>> sorted(log.optional)  # gyro, load cell, reference azimuth
    ['omega_B', 'tension', 'xi_dot_ref', 'xi_ref']
    >>> speed = np.linalg.norm(np.diff(log.p_I, axis=0), axis=1) / np.diff(log.t)
    >>> print(f"mean COG speed {speed.mean():.1f} m/s, "
    ...       f"tension {np.mean(log.optional['tension']):.0f} N")
    mean COG speed 8.9 m/s, tension 25 N
    """
    path = Path(path)
    if day:
        return read_day(path, config=config, channel_map=channel_map, pose=pose,
                        pose_map=pose_map, trust=trust, min_samples=min_samples,
                        gap_factor=gap_factor).logs
    _check_file(path)
    foreign = _foreign(path, channel_map, thrust_max, pose, pose_map)
    if foreign is not None:
        return _segments(path, foreign.meta, foreign.columns, foreign.rows, foreign.label,
                         min_samples, gap_factor, config=config, trust=trust,
                         sources=foreign.sources)
    meta, cols, rows, label = _read_file(path)
    return _segments(path, meta, cols, rows, label, min_samples, gap_factor, config=config,
                     trust=trust)


def convert_log(path, out, *, channel_map=None, thrust_max: float | None = None,
                config=None, trust=(), pose=None, pose_map=None,
                ) -> tuple[tuple[str, ...], list[FlightLog]]:
    """Convert a PX4 ULog or a ROS 2 bag to ``gainsched-flightlog/1`` at ``out``.

    The whole converted log is written (gaps included, as the format allows), after it
    passed every rule :func:`read_log` applies; nothing is written otherwise.

    Parameters
    ----------
    path : str or path-like
        The ULog (``.ulg``) or bag (a rosbag2 folder, ``.mcap`` or ``.db3``).
    out : str or path-like
        ``.csv``, ``.h5`` or ``.hdf5``.
    channel_map, thrust_max, config
        As for :func:`read_log`.
    trust : iterable of str, default ()
        Consistency checks to skip (:func:`read_log`); written to the converted log's
        metadata ``trust``, so that it is read as it was converted.
    pose : str or path-like, optional
        The motion capture's recording of the same flight, on a clock of its own: ``path``
        is then the flight controller's log, and the pose comes from this file, its clock
        aligned to the flight controller's (:mod:`._pair`).
    pose_map : ChannelMap, str or path-like
        With ``pose``: where it holds the position and the attitude (a ``pose_only`` map).

    Returns
    -------
    (tuple of str, list of FlightLog)
        What was mapped to what (one line per channel, the plane, the left-out samples;
        the clocks first with ``pose``), and the segments as :func:`read_log` gives them.
    """
    path, out = Path(path), Path(out)
    log_format(out)  # a bad output name fails before any reading
    _check_file(path)
    if pose is not None:
        _check_file(Path(pose))
    conv = _foreign(path, channel_map, thrust_max, pose, pose_map)
    if conv is None:
        raise InputError(path, "", "not a PX4 ULog (.ulg) or a ROS 2 bag (.mcap, .db3, or a "
                         "rosbag2 folder): nothing to convert")
    meta = dict(conv.meta)
    if trust:
        meta["trust"] = ", ".join(dict.fromkeys(trust))
    segs = _segments(path, meta, conv.columns, conv.rows, conv.label,
                     DEFAULT_MIN_SAMPLES, GAP_FACTOR, config=config, trust=trust,
                     sources=conv.sources)
    write_log(out, conv.columns, meta)
    return conv.report, segs


#: most gaps (and dropped segments) warned of one by one; more are one summary line
MAX_EACH = 3


def _warn_gaps(path, t, rows, label, cuts, med: float, n_pieces: int) -> None:
    """A warning per gap where the log is split, or one line for more than
    :data:`MAX_EACH` of them."""
    if cuts.size > MAX_EACH:
        lengths = t[cuts] - t[cuts - 1]
        k = cuts[0]
        warnings.warn(
            f"{path}: column t: {cuts.size} gaps of {lengths.min():.3g}-{lengths.max():.3g} s "
            f"(median interval {med:.6g} s), the first at {label} {rows[k]} (t = "
            f"{float(t[k - 1])!r}); log split there into {n_pieces} segments",
            LogWarning, stacklevel=3)
        return
    for k in cuts:
        warnings.warn(
            f"{path}: column t, {label} {rows[k]}: gap of {t[k] - t[k - 1]:.6g} s "
            f"(median interval {med:.6g} s) from t = {float(t[k - 1])!r} to {float(t[k])!r}; "
            "log split there",
            LogWarning,
            stacklevel=3,
        )


def _pair(path: Path, pose: Path, cmap, pose_map, thrust_max, day=False):
    """The converted columns of a flight controller's log and a pose recorded apart."""
    from ._channelmap import ChannelMap, load_channel_map
    from ._foreign import foreign_format
    from ._pair import convert_pair

    if foreign_format(pose) is None:
        if pose.is_dir():
            raise _not_a_bag_folder(pose)
        raise InputError(pose, "", "a pose recording is a ROS 2 bag (.mcap, .db3, a rosbag2 "
                         "folder) or a ULog (.ulg)")
    if pose_map is None:
        raise InputError(pose, "", "a pose recorded apart needs its channel map (--pose-map: "
                         "position and attitude, its frames and anchor)")
    pmap = pose_map if isinstance(pose_map, ChannelMap) else load_channel_map(
        pose_map, pose_only=True)
    return convert_pair(path, pose, cmap, pmap, thrust_max=thrust_max, day=day)[0]


def _bag_files(path: Path) -> list[str]:
    """The names of the bag files (``.mcap``, ``.db3``) in the folder ``path``."""
    return sorted(p.name for p in path.iterdir() if p.suffix.lower() in (".mcap", ".db3"))


def _not_a_bag_folder(path: Path) -> InputError:
    """The refusal of a folder that is no rosbag2 (no ``metadata.yaml``), saying what it
    holds and what can be given instead."""
    files = _bag_files(path)
    if not files:
        return InputError(path, "", "a folder without a rosbag2 metadata.yaml or a .mcap or "
                          ".db3 file: nothing to convert (give a log file or a bag)")
    first = path / files[0]
    more = f" (and {len(files) - 1} more)" if len(files) > 1 else ""
    return InputError(path, "", f"a folder of bag files without the rosbag2 metadata.yaml: "
                      f"give the file itself ({first}{more}), or restore metadata.yaml")


def _foreign(path: Path, channel_map, thrust_max, pose=None, pose_map=None, day=False):
    """The converted columns of a ULog or a bag (None for the project's own formats);
    with ``pose``, of the flight controller's ``path`` and the pose recorded apart;
    ``day``: a whole day (disarmed stretches kept, no thrust)."""
    from ._foreign import foreign_format

    fmt = foreign_format(path)
    if fmt is None and path.is_dir() and _bag_files(path):
        raise _not_a_bag_folder(path)
    if fmt is None:
        return None
    from ._channelmap import ChannelMap, load_channel_map

    if channel_map is None:
        if fmt != "ulog":
            raise InputError(path, "", "a ROS 2 bag needs a channel map (--map; the "
                             "shipped ros2 map is a template to copy)")
        channel_map = "px4"
    cmap = channel_map if isinstance(channel_map, ChannelMap) else load_channel_map(
        channel_map)
    if not path.exists():
        raise InputError(path, "", "cannot read (No such file or directory)")
    if pose is not None:
        conv = _pair(path, Path(pose), cmap, pose_map, thrust_max, day)
    else:
        from ._cache import converted_log

        conv = converted_log(path, cmap, thrust_max, day)
    if "alpha_c_deg" in conv.meta:
        return conv
    alpha, gamma = _plane_angles(fitted_plane(np.stack([conv.columns[c] for c in "xyz"],
                                                       -1))[0])
    meta = {**conv.meta, "alpha_c_deg": repr(alpha), "gamma_c_deg": repr(gamma),
            "plane_source": "estimated from the logged positions"}
    line = (f"circle plane: alpha_c {alpha:.2f} deg, gamma_c {gamma:.2f} deg, estimated "
            "from the positions")
    return dataclasses.replace(conv, meta=meta, report=(*conv.report, line))


def _segments(path, meta, cols, rows, label, min_samples, gap_factor, *, config=None,
              trust=(), sources=None) -> list[FlightLog]:
    """The common half of reading: the numeric rules, the plane, the channels' consistency
    (:mod:`._consistency`), the split at gaps. ``sources``: per column of a converted
    log the topic it came from (errors name it)."""
    deferred: list[InputError] = []
    arrays, optional, extra = _canonical(path, cols, rows, label, deferred, sources)
    if deferred:  # thrust out of range: in other units? (else the range error as such)
        thrust_units(path, arrays, optional, meta, config=config, trust=trust,
                     gap_factor=gap_factor)
        raise deferred[0]
    t = arrays["t"]
    n = t.shape[0]
    if n == 0:
        raise InputError(path, "column t", "no data rows")
    if n < min_samples:
        raise InputError(
            path,
            f"column t, {label}s {rows[0]}-{rows[-1]}",
            f"{n} samples, fewer than the differentiation window ({min_samples})",
        )
    _check_plane(path, meta, arrays["p_I"])
    check_log(path, t, arrays["p_I"], arrays["q"], arrays["T_cmd"], optional, meta,
              config=config, trust=trust, gap_factor=gap_factor)
    dt = np.diff(t)
    med = float(np.median(dt)) if dt.size else 0.0
    cuts = np.flatnonzero(dt > gap_factor * med) + 1
    gaps = tuple((float(t[k - 1]), float(t[k])) for k in cuts)
    bounds = [0, *cuts.tolist(), n]
    pieces = list(zip(bounds[:-1], bounds[1:], strict=True))
    _warn_gaps(path, t, rows, label, cuts, med, len(pieces))
    keep = [(i, a, b) for i, (a, b) in enumerate(pieces) if b - a >= min_samples]
    if not keep:
        i, (a, b) = max(enumerate(pieces), key=lambda p: p[1][1] - p[1][0])
        raise InputError(
            path,
            f"column t, {label}s {rows[a]}-{rows[b - 1]}",
            f"after splitting at {len(gaps)} gap(s) no segment has {min_samples} samples "
            f"(the differentiation window); the longest has {b - a}",
        )
    short = [(i, a, b) for i, (a, b) in enumerate(pieces) if b - a < min_samples]
    if len(short) > MAX_EACH:  # one line for many (a day's log has hundreds)
        warnings.warn(f"{path}: column t: {len(short)} segments between gaps have fewer "
                      f"samples than the differentiation window ({min_samples}), "
                      f"{sum(b - a for _, a, b in short)} samples in all; dropped",
                      LogWarning, stacklevel=2)
        short = []
    for i, a, b in short:
        warnings.warn(
            f"{path}: column t, {label}s {rows[a]}-{rows[b - 1]}: segment {i} has "
            f"{b - a} samples, fewer than the differentiation window ({min_samples}); "
            "dropped",
            LogWarning,
            stacklevel=2,
        )
    return [
        _make(
            arrays,
            optional,
            extra,
            meta,
            path,
            slice(a, b),
            segment=i,
            n_segments=len(pieces),
            gaps=gaps,
            rows=_readonly(rows[a:b].copy()),
            row_label=label,
        )
        for i, a, b in keep
    ]


@dataclasses.dataclass(frozen=True, eq=False)
class Day:
    """A flight day read (:func:`read_day`).

    Attributes
    ----------
    cut : DayCut
        Its pieces, kept and dropped, with their reasons.
    logs : list of FlightLog
        The segments of the kept flights, each read and checked as a log of its own (its
        plane the piece's; ``flight_id`` ``STEM-NN``, metadata ``day_piece`` the piece).
    columns : dict
        The day's columns (the converted ones of a ULog or a bag), for a picture.
    meta : dict
        The day's metadata.
    report : tuple of str
        What was mapped to what (a ULog's or a bag's conversion; empty for a log of the
        project's format).
    """

    cut: DayCut
    logs: list
    columns: dict
    meta: dict
    report: tuple = ()


def read_day(path, *, config, channel_map=None, pose=None, pose_map=None, trust=(),
             min_samples: int = DEFAULT_MIN_SAMPLES, gap_factor: float = GAP_FACTOR) -> Day:
    """Read a whole flight day and cut it into the flights the analysis can use.

    The day's columns (a log of the project's format, a ULog or a bag, or a flight
    controller's log with the pose recorded apart, ``pose``) are cut by
    :func:`~gainsched.analysis.logs._daycut.cut_day` with the config's tether radius and
    weight; each kept circle and manoeuvre is then read as :func:`read_log` reads a log
    (every rule, the consistency checks), with the plane it flew.

    Parameters
    ----------
    path : path-like
        The day's log (or the flight controller's, with ``pose``).
    config : Config
        The analysis config: the tether's radius and the weight the cut needs, the
        vehicle the checks need.
    channel_map, pose, pose_map, trust, min_samples, gap_factor
        As for :func:`read_log`.

    Returns
    -------
    Day

    Raises
    ------
    InputError
        As :func:`read_log`, and when no flight of the day is left to keep.
    """
    from ._daycut import cut_day

    path = Path(path)
    if config is None:
        raise InputError(path, "", "a flight day is cut with the config's tether and weight: "
                         "give the config")
    _check_file(path)
    conv = _foreign(path, channel_map, config.vehicle.thrust_max, pose, pose_map, day=True)
    report: tuple = ()
    if conv is None:
        meta, cols, rows, label = _read_file(path)
        sources = {}
    else:
        report = conv.report
        meta, cols, rows, label, sources = (conv.meta, conv.columns, conv.rows, conv.label,
                                            conv.sources)
    radius = config.tether.length + config.tether.attachment_offset
    cut = cut_day(cols["t"], np.stack([cols[c] for c in "xyz"], -1),
                  np.stack([cols[f"T{j}"] for j in range(1, 5)], -1),
                  radius=radius, weight=config.vehicle.mass * config.g)
    if not cut.kept:
        raise InputError(path, "", f"no circle or manoeuvre in the day ({len(cut.pieces)} "
                         "pieces, none on the tether's sphere at a steady speed for "
                         "3 s): " + "; ".join(f"{q.kind} {q.t1 - q.t0:.1f} s" for q in
                                              cut.pieces[:6]))
    logs = []
    for i, piece in enumerate(cut.kept, 1):
        sl = slice(piece.start, piece.stop)
        pm = {**meta, "alpha_c_deg": repr(piece.tilt_deg),
              "gamma_c_deg": repr(piece.heading_deg), "plane_source": "the day's cut",
              "flight_id": f"{path.stem}-{i:02d}", "day_piece": piece.name}
        # each flight its own source (``DAY#NN``): the analysis holds out flights by it,
        # and an error names the flight of the day
        logs += _segments(Path(f"{path}#{i:02d}"), pm, {k: v[sl] for k, v in cols.items()},
                          rows[sl], label, min_samples, gap_factor, config=config,
                          trust=trust, sources=sources)
    return Day(cut, logs, cols, meta, report)
