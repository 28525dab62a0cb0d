"""Flights in simulation written as a lab would keep them: one scenario's log, metrics and
plots (``gainsched simulate``), the paper's experiments with their report (``gainsched
paper``) and a synthetic test campaign's logs (``gainsched campaign``)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Config
from ..errors import GainschedWarning, InputError
from ._report import SILENT, Reporter, config_of
from ._tables import table_for

__all__ = ["Flight", "fly", "PaperRun", "paper", "CampaignRun", "campaign"]


def _table(table):
    """``(Table, path)`` of a table or its file (path None for a table in memory)."""
    from ..schedule.tables import load_table

    if hasattr(table, "built_from"):
        return table, Path(table.source)
    return load_table(table), Path(table)


def _other_config(path, table, cfg: Config) -> None:
    """Warn, once every input passed, that ``table`` (at ``path``) was built from another
    config than ``cfg``: its flights test gains of another model."""
    if not table.built_from(cfg):
        warnings.warn(f"{path} was built from another config", GainschedWarning, stacklevel=3)


@dataclass(frozen=True, eq=False)
class Flight:
    """What :func:`fly` flew and wrote.

    Attributes
    ----------
    result : SimResult
        The flight (:func:`gainsched.simulate`).
    metrics : dict
        Its metrics (:func:`gainsched.metrics`), as ``metrics.json`` holds them.
    out_dir : Path
        The folder of ``log.csv``, ``log.h5``, ``metrics.json`` and the plots.
    table : Path
        The table flown.
    """

    result: object
    metrics: dict
    out_dir: Path
    table: Path

    def lines(self) -> list[str]:
        """What ``gainsched simulate`` prints: the flight's tracking, tension and saturation,
        and the time it spent outside the table (docs/runtime.md), if any."""
        m = self.metrics
        out = [f"{self.out_dir}: {self.result.scenario.name} {m['duration_s']:.2f} s, "
               f"RMS out-of-plane {m['rms_out_of_plane_m']:.4f} m, "
               f"RMS along-track {m['rms_along_track_m']:.3f} m (lap slips {m['lap_slips']}), "
               f"RMS speed error {m['rms_speed_error_mps']:.3f} m/s, "
               f"max tension {m['max_tension_N']:.1f} N, "
               f"saturation {100 * m['saturation_fraction']:.1f}%, "
               f"slack events {m['slack_events']}"]
        if m["clamped_speed_s"] > 0:
            out.append(f"  left the table: {m['clamped_speed_s']:.2f} s at speeds outside "
                       f"{self.table}'s range, flown on the gains of its nearest speed "
                       "(clamped_speed_s)")
        if m["held_gains_s"] > 0:
            out.append(f"  left the table: {m['held_gains_s']:.2f} s on held gains (no usable "
                       "gains at the lookup; held_gains_s)")
        if m["below_tension_margin_s"] > 0:
            out.append(f"  left the table: {m['below_tension_margin_s']:.2f} s with the "
                       f"nominal's tension below min_tension (lowest "
                       f"{m['min_nominal_tension_N']:.2f} N; below_tension_margin_s)")
        return out


def fly(config, table, scenario, out_dir, *, plant=None, speed: float | None = None,
        runtime: str = "auto", controller: str = "path",
        reporter: Reporter = SILENT) -> Flight:
    """Fly a scenario in closed loop on the nonlinear plant with gains from a table and
    write its log, metrics and plots: what ``gainsched simulate CONFIG --tables TABLE
    --scenario NAME -o OUT_DIR`` does.

    Parameters
    ----------
    config : Config or path-like
        The design config the table was built from.
    table : Table or path-like
        Its gain table.
    scenario : str or path-like
        A scenario file, or a shipped scenario's name (``"horizontal"``, ``"tilted40"``,
        ``"speedup"``, ``"braking"``, ``"staircase"``).
    out_dir : path-like
        The folder of ``log.csv``, ``log.h5``, ``metrics.json`` and the plots, published
        at once.
    plant : Config or path-like, optional
        The truth flown (default: the design config).
    speed : float, optional
        The scenario's initial speed instead of its own, m/s.
    runtime : {"auto", "c", "python"}
        The gain lookup: the compiled C runtime or its Python reference.
    controller : {"path", "firmware"}
        The control law in Python along the reference, or the firmware's whole control
        step (docs/runtime.md).
    reporter : Reporter, optional
        Shows the flight's progress; default: nothing.

    Returns
    -------
    Flight
        The flight, its metrics and :meth:`Flight.lines`, what the command prints.

    Examples
    --------
    >>> import tempfile
    >>> f = gs.fly("configs/paper.toml", "tables/paper.h5", "braking", tempfile.mkdtemp())
    >>> f.metrics["slack_events"], sorted(p.name for p in f.out_dir.glob("*.json"))
    (0, ['metrics.json'])
    """
    import dataclasses

    from ..publish import check_out_dir, staged
    from ..sim.loop import check_flight_steps, load_scenario, runtime_scheduler, write_run
    from ..sim.loop import simulate as run

    cfg = config_of(config)
    truth = None if plant is None else config_of(plant)
    tab, path = _table(table)
    scn = load_scenario(scenario)
    if speed is not None:
        scn = dataclasses.replace(scn, speed=speed)
    n = check_flight_steps(scn.duration, cfg.control.rate_hz, scenario, "duration")
    out_dir = Path(out_dir)
    check_out_dir(out_dir, names=["log.csv", "log.h5", "metrics.json"])
    _other_config(path, tab, cfg)  # once every input passed
    with reporter.bar(f"simulate {scn.name}", n, "step") as bar:
        res = run(cfg, runtime_scheduler(tab, runtime), scn, truth, progress=bar.update,
                  controller=controller)
    with staged(out_dir) as stage:
        m = write_run(res, stage)
    return Flight(res, m, out_dir, path)


@dataclass(frozen=True, eq=False)
class PaperRun:
    """What :func:`paper` flew and wrote.

    Attributes
    ----------
    report : PaperReport
        The rows (paper figure, quantity, paper value, simulated value) and the
        experiments' results (:func:`gainsched.sim.paper.run_paper`).
    out_dir : Path
        The folder of ``report.md``, ``report.json`` and one folder per experiment.
    table : Path
        The table flown.
    """

    report: object
    out_dir: Path
    table: Path

    def lines(self) -> list[str]:
        """What ``gainsched paper`` prints: a line per paper claim (ok, NO, or - for none
        to judge) and the report's files."""
        mark = {True: "ok ", False: "NO ", None: "-  "}
        out = [f"{mark[r.agrees]} {r.figure:16s} {r.quantity}: paper {r.paper}; sim "
               f"{r.simulated_text}" for r in self.report.rows]
        return out + [f"wrote {self.out_dir / 'report.md'} and {self.out_dir / 'report.json'}"]


def paper(out_dir, config="paper", *, table=None, plant=None, quick: bool = False,
          runtime: str = "auto", reporter: Reporter = SILENT) -> PaperRun:
    """Fly the paper's experiments (Sec. V.B, Figs. 3-4) in simulation and write the
    report: what ``gainsched paper -o OUT_DIR`` does.

    Parameters
    ----------
    out_dir : path-like
        The output folder: ``report.md``, ``report.json``, one folder per experiment.
    config : Config or path-like, default "paper"
        The design config (the shipped paper config by default).
    table : Table or path-like, optional
        The table built from ``config``; default: as :func:`table_for` finds it (built
        into the cache on first use).
    plant : Config or path-like, optional
        The truth flown (default: the design config).
    quick : bool, default False
        Short smoke flights (seconds).
    runtime : {"auto", "c", "python"}
        The gain lookup: the compiled C runtime or its Python reference (auto: C when a
        compiler is found).
    reporter : Reporter, optional
        Shows the flights' progress; default: nothing.

    Returns
    -------
    PaperRun
        The report and :meth:`PaperRun.lines`, what the command prints.

    Examples
    --------
    >>> import tempfile
    >>> run = gs.paper(tempfile.mkdtemp(), quick=True)  # the paper table of ./tables
    >>> str(run.table), sorted(p.name for p in run.out_dir.glob("report.*"))
    ('tables/paper.h5', ['report.json', 'report.md'])
    >>> run.lines()[-1].startswith("wrote ")
    True
    """
    from ..publish import check_out_dir, staged
    from ..sim.loop import runtime_scheduler
    from ..sim.paper import experiments, run_paper

    cfg = config_of(config)
    truth = None if plant is None else config_of(plant)
    out_dir = Path(out_dir)
    # before a first use builds the table (half a minute)
    check_out_dir(out_dir, names=["report.md", "report.json"])
    tab, path = table_for(cfg, reporter=reporter) if table is None else _table(table)
    _other_config(path, tab, cfg)
    meta = {"table": str(path), "table_config_sha256": tab.config_sha256}
    with reporter.bar("paper", len(experiments(quick=quick)), "flight") as bar, \
            staged(out_dir) as stage:
        rep = run_paper(cfg, runtime_scheduler(tab, runtime), stage, quick=quick, plant=truth,
                        progress=bar.update, meta=meta, table=tab)
    return PaperRun(rep, out_dir, path)


@dataclass(frozen=True, eq=False)
class CampaignRun:
    """What :func:`campaign` flew and wrote.

    Attributes
    ----------
    logs : list of FlightLog
        The flights' logs, as a lab would have recorded them.
    files : list of Path
        Their files, ``OUT_DIR/<flight>.<format>``.
    out_dir : Path
    hidden : HiddenEffect
        The plant's hidden effect (:data:`gainsched.sim.campaign.HIDDEN`).
    real_tether : bool
        Flown on the elastic tether of a real vehicle.
    """

    logs: list
    files: list
    out_dir: Path
    hidden: object
    real_tether: bool

    def lines(self) -> list[str]:
        """What ``gainsched campaign`` prints."""
        return [f"{self.out_dir}: {len(self.files)} flights, hidden effect: {self.hidden.doc}"
                + ("; on a real (elastic) tether" if self.real_tether else "")]


def campaign(config, table, out_dir, *, hidden: str = "none", duration: float = 3.0,
             load_cell: bool = True, real_tether: bool = False, fmt: str = "csv",
             seed: int = 1, reporter: Reporter = SILENT) -> CampaignRun:
    """Fly a synthetic test campaign on a plant with a hidden effect and write its logs:
    what ``gainsched campaign CONFIG --tables TABLE -o OUT_DIR`` does.

    The default flights (speeds 3-15 m/s, tilts 0/20/40 deg, a speed-up, a braking) flown
    in closed loop with ``table``'s gains on the plant that differs from ``config`` by
    ``hidden``, with motion-capture and IMU noise (:mod:`gainsched.sim.campaign`).

    Parameters
    ----------
    config : Config or path-like
        The design config the table was built from.
    table : Table or path-like
        Its gain table.
    out_dir : path-like
        The folder of the logs (one file per flight), published at once.
    hidden : str, default "none"
        The plant's hidden effect, a name of :data:`gainsched.sim.campaign.HIDDEN`.
    duration : float, default 3.0
        Seconds per flight.
    load_cell : bool, default True
        Log the tether tension.
    real_tether : bool, default False
        Fly on the elastic tether of a real vehicle (k = 2e5 N/m, c = 25 N s/m).
    fmt : {"csv", "h5"}
        The logs' format.
    seed : int, default 1
        Seed of the sensor noise (each flight the next).
    reporter : Reporter, optional
        Shows the flights' progress; default: nothing.

    Returns
    -------
    CampaignRun
        The logs, their files and :meth:`CampaignRun.lines`, what the command prints.

    Raises
    ------
    InputError
        An unknown hidden effect or a flight too long for the control rate, before any
        flight.

    Examples
    --------
    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> run = gs.campaign(cfg, "tables/paper.h5", tempfile.mkdtemp(), hidden="motor_lag",
    ...                   duration=1.0)
    >>> [p.name for p in run.files][:3], len(run.logs)
    (['v3.csv', 'v9.csv', 'v15.csv'], 7)
    >>> run.lines()[0].split(": ", 1)[1]
    '7 flights, hidden effect: first-order motor lag tau = 35 ms'
    """
    from ..publish import check_out_dir, staged
    from ..sim.campaign import HIDDEN, default_flights, outside_table, write_campaign
    from ..sim.campaign import campaign as fly
    from ..sim.loop import check_flight_steps, table_scheduler

    if hidden not in HIDDEN:
        raise InputError("command line", "--hidden",
                         f"unknown hidden effect {hidden!r} (known: {', '.join(HIDDEN)})")
    cfg = config_of(config)
    check_flight_steps(duration, cfg.control.rate_hz, "command line", "--duration")
    tab, path = _table(table)
    out_dir = Path(out_dir)
    check_out_dir(out_dir)
    _other_config(path, tab, cfg)  # as simulate and paper say it, before the work
    flights = default_flights(duration, seed)
    if outside := outside_table(flights, tab):
        warnings.warn(f"{path} covers speeds {tab.speed.min():.3g}-{tab.speed.max():.3g} m/s, "
                      f"tilts up to {np.rad2deg(tab.tilt.max()):.0f} deg: "
                      f"{', '.join(outside)} fly outside it, on the gains of its nearest "
                      "circle", GainschedWarning, stacklevel=2)
    with reporter.bar(f"campaign {hidden}", len(flights), "flight") as bar:
        logs = fly(cfg, table_scheduler(tab), hidden, scenarios=flights, duration=duration,
                   load_cell=load_cell, seed=seed, real_tether=real_tether,
                   progress=bar.update)
    with staged(out_dir) as stage:
        files = [out_dir / p.name for p in write_campaign(stage, logs, fmt)]
    return CampaignRun(logs, files, out_dir, HIDDEN[hidden], real_tether)
