"""Flight logs, as the command line reports them: the comparison of a model with its
report (``gainsched compare``), the diagnosis with its report and the config it writes
(``gainsched diagnose``), and a foreign log converted (``gainsched convert``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ._report import SILENT, Reporter, config_of, on_bar, teller

__all__ = ["ComparisonReport", "compare", "DiagnosisReport", "diagnose", "Conversion", "topics",
           "convert"]


@dataclass(frozen=True, eq=False)
class ComparisonReport:
    """What :func:`compare` found and wrote.

    Attributes
    ----------
    comparison : Comparison
        The model against the logs (:func:`gainsched.compare`).
    paper : dict or None
        The paper's thrust and drag analyses (Sec. V.C; None: not asked for).
    before : Comparison or None
        An earlier config against the same logs (before/after).
    files : list of Path
        The report's files (none without a report folder).
    said : tuple of str
        :meth:`lines`.
    """

    comparison: object
    paper: object
    before: object
    files: list = field(default_factory=list)
    said: tuple = ()

    def lines(self) -> list[str]:
        """What ``gainsched compare`` prints: the residual per axis, where it fails, the
        paper's analyses, the before/after, and the report's files."""
        return list(self.said)


def _as_read(cfg, logs, channel_map, trust, pose, pose_map, day: bool) -> list:
    """The logs as the analysis takes them: the paths as given, or, for a flight day or a
    pose recorded apart (``--day``, ``--pose``), the segments of its flights read here
    (:func:`gainsched.analysis.logs.read_log`)."""
    if pose is None and not day:
        return list(logs)
    if pose is not None and len(logs) != 1:
        raise InputError("command line", "--pose", f"goes with one LOG, the flight "
                         f"controller's log of the flight the pose recorded ({len(logs)} given)")
    from ..analysis.logs import read_log

    return [seg for item in logs for seg in read_log(
        item, channel_map=channel_map, thrust_max=cfg.vehicle.thrust_max, config=cfg,
        trust=trust, pose=pose, pose_map=pose_map, day=day)]


def compare(config, logs, out_dir=None, *, before=None, paper: bool = True,
            channel_map=None, trust=(), pose=None, pose_map=None, day: bool = False,
            reporter: Reporter = SILENT) -> ComparisonReport:
    """Compare a model with flight logs and write the report: what ``gainsched compare
    CONFIG LOGS -o OUT_DIR`` does (docs/model-vs-measurement.md).

    Parameters
    ----------
    config : Config or path-like
        The model.
    logs : list of path or FlightLog
        The flights (CSV, HDF5, PX4 ULog or ROS 2 bag through ``channel_map``).
    out_dir : path-like, optional
        The report folder (``compare.json``, ``compare.md``, plots), published at once;
        None: no report.
    before : Config or path-like, optional
        An earlier config: its residual beside ``config``'s.
    paper : bool, default True
        The paper's thrust and drag analyses (Sec. V.C).
    channel_map, trust
        As :func:`gainsched.compare` takes them.
    pose, pose_map : path-like, optional
        The motion capture's recording on a clock of its own and its map (the one LOG
        is then the flight controller's; :func:`gainsched.analysis.logs.read_log`).
    day : bool
        The logs are whole flight days: each cut into its circles and manoeuvres.
    reporter : Reporter, optional
        Shows the reading's progress and the lines as they come; default: nothing.

    Returns
    -------
    ComparisonReport
        The comparison(s), the report's files and :meth:`ComparisonReport.lines`.

    Examples
    --------
    >>> rep = gs.studies.compare("configs/paper.toml", ["examples/flights/v9.csv",
    ...                                                  "examples/flights/v15.csv"])
    >>> rep.comparison.normalized_rms() > 1, rep.files
    (True, [])
    """
    from ..analysis.compare import compare as run
    from ..analysis.paperfits import paper_fits
    from ..analysis.reports import (
        before_after_lines,
        compare_lines,
        write_before_after,
        write_compare,
    )
    from ..publish import check_out_dir, staged

    cfg = config_of(config)
    before_cfg = None if before is None else config_of(before)
    if out_dir is not None:
        out_dir = Path(out_dir)
        check_out_dir(out_dir, names=["compare.json", "compare.md"])
    logs = _as_read(cfg, logs, channel_map, trust, pose, pose_map, day)
    said, say = teller(reporter)

    # steps: each log read and the statistics, per config; the paper's fits
    steps = (len(logs) + 1) * (1 if before is None else 2) + (1 if paper else 0)
    with reporter.bar(f"compare {cfg.name}", steps, "step") as bar:
        cmp = run(cfg, logs, channel_map=channel_map, trust=trust, progress=bar.update)
        fits = paper_fits(cfg, cmp.measured) if paper else None
        bar.update(1 if paper else 0)
        earlier = None if before_cfg is None else run(
            before_cfg, logs, channel_map=channel_map, trust=trust, progress=bar.update)
    say(compare_lines(cmp, fits))
    if earlier is not None:
        say(["", *before_after_lines(earlier, cmp)])
    files = []
    if out_dir is not None:
        with staged(out_dir) as stage:  # the report appears whole, or not at all
            files = write_compare(cmp, stage, fits)
            if earlier is not None:
                files += write_before_after(earlier, cmp, stage)
        files = [out_dir / p.name for p in files]
        say([f"wrote {len(files)} files to {out_dir} ({files[1].name})"])
    return ComparisonReport(cmp, fits, earlier, files, tuple(said))


@dataclass(frozen=True, eq=False)
class DiagnosisReport:
    """What :func:`diagnose` found and wrote.

    Attributes
    ----------
    diagnosis : Diagnosis
        The ranked candidates and the verdict (:func:`gainsched.diagnose`).
    new_config : Path or None
        The config written with the accepted effect (None: none written).
    after : Comparison or None
        The written config against the same logs.
    files : list of Path
        The report's files (none without a report folder).
    said : tuple of str
        :meth:`lines`.
    """

    diagnosis: object
    new_config: Path | None = None
    after: object = None
    files: list = field(default_factory=list)
    said: tuple = ()

    def lines(self) -> list[str]:
        """What ``gainsched diagnose`` prints: the comparison, the ranking and the verdict,
        what was written and the before/after."""
        return list(self.said)


def diagnose(config, logs, *, candidates=None, exclude=(), joint: bool = False,
             sensors: bool = True, new_config=None, report_dir=None, channel_map=None,
             trust=(), pose=None, pose_map=None, day: bool = False,
             reporter: Reporter = SILENT) -> DiagnosisReport:
    """Find which physical effect the model misses, write the config with it and the
    report: what ``gainsched diagnose CONFIG LOGS [--apply -o NEWCONFIG] [--report DIR]``
    does (docs/model-vs-measurement.md).

    Parameters
    ----------
    config : Config or path-like
        The model.
    logs : list of path or FlightLog
        Two or more flights.
    candidates, exclude, joint, sensors, channel_map, trust
        As :func:`gainsched.diagnose` takes them.
    new_config : path-like, optional
        Where to write the config with the accepted effect (``--apply -o``); None: none
        written.
    report_dir : path-like, optional
        The report folder (``diagnose.json``, ``diagnose.md``, plots; before and after),
        published at once.
    pose, pose_map, day
        A flight day, or a pose recorded apart, as :func:`compare` takes them.
    reporter : Reporter, optional
        Shows the fits' progress and the lines as they come; default: nothing.

    Returns
    -------
    DiagnosisReport
        The diagnosis, what was written and :meth:`DiagnosisReport.lines`.

    Examples
    --------
    >>> import glob
    >>> rep = gs.studies.diagnose("configs/paper.toml",
    ...                           sorted(glob.glob("examples/flights/*.csv")),
    ...                           candidates=["drag_quadratic", "thrust_momentum"])
    >>> rep.diagnosis.accepted.name, rep.new_config
    ('thrust_momentum', None)
    """
    from ..analysis.compare import compare as run
    from ..analysis.diagnose import diagnose as run_diagnose
    from ..analysis.reports import compare_lines, diagnose_lines
    from ..publish import check_out_dir, check_out_file

    cfg = config_of(config)
    if new_config is not None:
        new_config = Path(new_config)
        check_out_file(new_config, "-o")
    if report_dir is not None:
        report_dir = Path(report_dir)
        check_out_dir(report_dir, "--report", names=["diagnose.json", "diagnose.md"])
    logs = _as_read(cfg, logs, channel_map, trust, pose, pose_map, day)
    said, say = teller(reporter)

    base = run(cfg, logs, channel_map=channel_map, trust=trust)
    say([*compare_lines(base), ""])
    with reporter.bar("diagnose", unit="fit") as bar:
        def fitted(name):
            bar.set_postfix_str(name, refresh=False)
            bar.update()

        d = run_diagnose(cfg, logs, candidates=candidates or None, comparison=base,
                         joint=joint, exclude=exclude, progress=fitted, sensors=sensors)
    say(diagnose_lines(d))
    after = (_apply(d, base, new_config, logs, channel_map, trust, say) if new_config
             else None)
    files = [] if report_dir is None else _report(d, base, after, report_dir, say)
    return DiagnosisReport(d, new_config if after is not None else None, after, files,
                           tuple(said))


def _apply(d, base, new_config: Path, logs, channel_map, trust, say):
    """Write the config with the accepted effect of ``d`` to ``new_config`` (None: nothing
    accepted) and compare it with the logs (beside ``base``, the comparison before): the
    new comparison, or None."""
    from ..analysis.compare import compare as run
    from ..analysis.diagnose import apply_diagnosis
    from ..analysis.reports import before_after_lines
    from ..config import config_from_text
    from ..errors import InputError
    from ..firmware.outputs import check_outputs
    from ..publish import write_atomic

    text = apply_diagnosis(d)
    if text is None:
        say(["nothing applied: no candidate cleared the thresholds"])
        return None
    what = " + ".join(d.applied)
    write_atomic(new_config, text.encode(), where="-o")
    new_cfg = config_from_text(text, str(new_config))
    try:  # the build's own check: a wind, flight time, unequal motors
        check_outputs(new_cfg)
    except InputError as held:
        say([f"wrote {new_config} ({what}); no table can hold {held.where}: {held.message}"])
    else:
        say([f"wrote {new_config} ({what}); rebuild the tables with "
             f"`gainsched build {new_config}`"])
    after = run(new_cfg, logs, channel_map=channel_map, trust=trust)
    say(["", *before_after_lines(base, after)])
    return after


def _report(d, base, after, report_dir: Path, say) -> list[Path]:
    """The diagnose report published at once in ``report_dir``: the diagnosis, the
    comparison before and, with a config written, after."""
    from ..analysis.reports import write_before_after, write_compare, write_diagnose
    from ..publish import staged

    with staged(report_dir, where="--report") as stage:
        paths = write_diagnose(d, stage) + write_compare(base, stage, prefix="before")
        if after is not None:
            paths += write_compare(after, stage, prefix="after")
            paths += write_before_after(base, after, stage, d)
    say([f"wrote {len(paths)} files to {report_dir}"])
    return [report_dir / p.name for p in paths]


@dataclass(frozen=True, eq=False)
class Conversion:
    """What :func:`convert` read and wrote.

    Attributes
    ----------
    out_path : Path
        The converted log (``.csv`` or ``.h5``).
    segments : list of FlightLog
        Its segments (split at gaps).
    mapped : list of str
        What was mapped to what (the channel map's report).
    day : DayCut or None
        With ``day``: the day's pieces (``out_path`` is then the folder of its flights).
    """

    out_path: Path
    segments: list
    mapped: list
    day: object = None

    def lines(self) -> list[str]:
        """What ``gainsched convert`` prints: the mapping, then the samples, the span and
        the circle's plane (with ``--day``: the day's pieces and the files written)."""
        segs = self.segments
        if self.day is not None:
            return [*("  " + line for line in self.mapped), *self.day.lines(),
                    f"wrote {self.out_path}: {len(self.day.kept)} flights (NN-KIND.csv), "
                    "day.json, day.md, day.png"]
        span = (f"{segs[0].duration:.3g} s" if len(segs) == 1 else
                f"{len(segs)} segments (split at gaps)")
        meta = segs[0].meta
        alpha, gamma = float(meta["alpha_c_deg"]), float(meta["gamma_c_deg"])
        return [*("  " + line for line in self.mapped),
                f"wrote {self.out_path}: {sum(len(s) for s in segs)} samples, {span}, "
                f"alpha_c {alpha:.2f} deg, gamma_c {gamma:.2f} deg"]


def convert(log, out_path, *, channel_map=None, config=None, trust=(), pose=None,
            pose_map=None, day: bool = False, reporter: Reporter = SILENT) -> Conversion:
    """Convert a PX4 ULog or a ROS 2 bag to the project's flight-log format and say what
    was mapped to what: what ``gainsched convert LOG -o OUT`` does (docs/flight-log.md).

    Parameters
    ----------
    log : path-like
        The ULog or the bag.
    out_path : path-like
        The converted log, ``.csv`` or ``.h5``.
    channel_map : ChannelMap, str or path-like, optional
        The channel map (a shipped one's name: ``"px4"``, ``"ros2"``; default for a ULog:
        ``"px4"``).
    config : Config or path-like, optional
        A config whose ``vehicle.thrust_max`` is a motor's thrust at full command (for
        normalised or PWM commands) and whose vehicle the thrust and the load cell are
        checked against.
    trust : iterable of str
        Consistency checks to skip (docs/flight-log.md).
    pose : path-like, optional
        The motion capture's recording of the flight on a clock of its own (``log`` is
        then the flight controller's); the clocks are aligned from the motion both hold.
    pose_map : ChannelMap, str or path-like
        With ``pose``: where it holds the position and the attitude (``--pose-map``).
    day : bool
        The log is a whole flight day: cut into its circles and manoeuvres
        (:func:`gainsched.analysis.logs.read_day`, needs ``config``); ``out_path`` is a
        folder, published at once with ``NN-KIND.csv`` per kept flight, ``day.json``,
        ``day.md`` and ``day.png``.
    reporter : Reporter, optional
        Shows the reading's progress; default: nothing.

    Returns
    -------
    Conversion
        The segments, the mapping and :meth:`Conversion.lines`, what the command prints.

    Examples
    --------
    A ULog of a pose and the commands only (PX4's NED and FRD, the shipped ``px4`` map)
    is refused in one line when it holds no tethered circle:

    >>> import tempfile
    >>> try:
    ...     gs.studies.convert("no-such.ulg", tempfile.mktemp(suffix=".csv"))
    ... except gs.InputError as e:
    ...     print(str(e).split(":")[0])
    no-such.ulg
    """
    from ..analysis.logs import convert_log, log_format, reporting
    from ..publish import check_out_file

    cfg = None if config is None else config_of(config)
    thrust_max = cfg.vehicle.thrust_max if cfg is not None else None
    out_path = Path(out_path)
    if day:
        return _convert_day(log, out_path, channel_map, cfg, trust, pose, pose_map, reporter)
    log_format(out_path, "-o")
    check_out_file(out_path, "-o")
    with reporter.bar(f"convert {Path(log).name}") as bar, reporting(on_bar(bar)):
        mapped, segs = convert_log(log, out_path, channel_map=channel_map,
                                   thrust_max=thrust_max, config=cfg, trust=trust, pose=pose,
                                   pose_map=pose_map)
        bar.set_postfix_str("written")
    return Conversion(out_path, segs, list(mapped))


def _convert_day(log, out_dir: Path, channel_map, cfg, trust, pose, pose_map,
                 reporter) -> Conversion:
    """``convert --day``: the day read and cut, its flights and report published in
    ``out_dir`` at once."""
    from ..analysis.dayreport import day_files
    from ..analysis.logs import read_day, reporting
    from ..publish import check_out_dir, publish

    if cfg is None:
        raise InputError("command line", "--day", "needs --config CONFIG (the tether and the "
                         "weight the day is cut with)")
    check_out_dir(out_dir, "-o", names=["day.json", "day.md", "day.png"])
    with reporter.bar(f"convert {Path(log).name}") as bar, reporting(on_bar(bar)):
        d = read_day(log, config=cfg, channel_map=channel_map, pose=pose, pose_map=pose_map,
                     trust=trust)
        publish(out_dir, day_files(d))
        bar.set_postfix_str("written")
    return Conversion(out_dir, d.logs, list(d.report), d.cut)


def topics(log):
    """What a PX4 ULog or a ROS 2 bag holds, for writing its channel map: what
    ``gainsched convert --list LOG`` prints (docs/flight-log.md).

    Parameters
    ----------
    log : path-like
        The ULog, a bag's ``.mcap`` or ``.db3``, or a rosbag2 folder.

    Returns
    -------
    LogListing
        Per topic its type, samples, rate and the fields a map can name;
        :meth:`~gainsched.analysis.logs.LogListing.lines` is what the command prints.

    Examples
    --------
    A text file is no log to list:

    >>> try:
    ...     gs.studies.topics("flight.csv")
    ... except gs.InputError as e:
    ...     print(str(e))
    flight.csv: --list reads a PX4 ULog (.ulg) or a ROS 2 bag (.mcap, .db3 or a rosbag2 folder)
    """
    from ..analysis.logs import list_topics

    return list_topics(log)
