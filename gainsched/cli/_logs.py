"""Commands that read flight logs: ``compare``, ``diagnose``, ``improve`` and ``convert``."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..analysis.logs import CHECKS as LOG_CHECKS
from ..constants import MAX_FLIGHT_S, MAX_JOBS
from ..errors import InputError
from ._base import (
    CONFIG,
    TERMINAL,
    FilePath,
    FiniteFloat,
    Jobs,
    Name,
    _check_fit_arguments,
    _distinct,
    _load_for_compare,
    _not_an_input,
    _outputs_apart,
    _same_file,
    cli,
    user_errors,
)

_LOGS = click.argument("logs", nargs=-1, required=True,
                       type=FilePath(exists=True, path_type=Path))


_MAP = click.option("--map", "map_path", type=Name(), help="Channel map of PX4 ULogs and "
                    "ROS 2 bags among the logs: a TOML file or a shipped map (px4, "
                    "px4_legacy, ros2); default for a ULog: px4 (docs/flight-log.md).")


_TRUST = click.option("--trust", "trust", multiple=True, type=click.Choice(LOG_CHECKS),
                      help="Skip a consistency check of the logs where you know the log is "
                      "right (repeatable; docs/flight-log.md, \"Channels that contradict "
                      "each other\").")


def _day_options(fn):
    """``--pose``, ``--pose-map`` and ``--day``: a flight day, or a pose recorded apart,
    read as the analysis takes it (docs/flight-log.md)."""
    fn = click.option("--day", "day", is_flag=True,
                      help="Each LOG is a whole flight day: cut into its steady circles and "
                           "manoeuvres, the ground, take-offs, landings and transitions "
                           "dropped.")(fn)
    fn = click.option("--pose-map", "pose_map", type=Name(),
                      help="The channel map of --pose (position and attitude).")(fn)
    return click.option("--pose", "pose", type=FilePath(exists=True, path_type=Path),
                        help="The motion capture's recording of the flight on a clock of its "
                             "own; the one LOG is then the flight controller's log.")(fn)


def _channel_map(map_path):
    """The validated channel map of --map, or None (checked before any work)."""
    if map_path is None:
        return None
    from ..analysis.logs import load_channel_map

    return load_channel_map(map_path)


@cli.command()
@CONFIG
@_LOGS
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              help="Report folder: compare.json, compare.md and PNG plots.")
@click.option("--before", "before_path", type=FilePath(dir_okay=False, path_type=Path),
              help="An earlier config: its residual beside CONFIG's (before/after).")
@click.option("--no-paper", is_flag=True, help="Skip the paper's thrust/drag analyses.")
@_MAP
@_TRUST
@_day_options
@user_errors
def compare(config, logs, out_dir, before_path, no_paper, map_path, trust, pose, pose_map, day):
    """Compare the model of CONFIG with flight LOGS (CSV, HDF5, PX4 ULog or ROS 2 bag
    through a channel map): residual per axis
    (path frame m/s^2, body rad/s^2, tether stretch m), RMS, bias, fit %, whiteness,
    input correlation, where it fails; the paper's Sec. V.C analyses."""
    from ..resources import config_path
    from ..studies import compare as run

    _distinct("LOG", list(logs))
    if before_path is not None and _same_file(config_path(before_path), config_path(config)):
        shown = "" if str(before_path) == str(config) else f" ({config})"
        raise InputError("command line", "--before", f"{before_path} is CONFIG{shown}: give "
                         "the earlier config")
    cfg = _load_for_compare(config)
    before_cfg = None if before_path is None else _load_for_compare(before_path)
    run(cfg, logs, out_dir, before=before_cfg, paper=not no_paper,
        channel_map=_channel_map(map_path), trust=trust, pose=pose, pose_map=pose_map,
        day=day, reporter=TERMINAL)


@cli.command()
@CONFIG
@_LOGS
@click.option("--candidate", "candidates", type=Name(), multiple=True,
              help="Only these candidates (repeatable; default: the whole library).")
@click.option("--exclude", "exclude", type=Name(), multiple=True, metavar="NAME",
              help="Leave out this candidate or effect (repeatable): the library told "
                   "the effect is not there.")
@click.option("--joint", is_flag=True,
              help="Also fit the best candidates in pairs and triples when a single one "
                   "passes (they are fitted when none does); a joint fit wins when its "
                   "delta-BIC is lower by 10.")
@click.option("--no-sensors", "no_sensors", is_flag=True,
              help="Take the config's [sensors] as they are: no calibration of the gyro, "
                   "the markers and the accelerometer against the motion capture first.")
@click.option("--apply", "do_apply", is_flag=True,
              help="Write the accepted effect and its fitted parameters to -o NEWCONFIG.")
@click.option("-o", "--out", "new_config", type=FilePath(dir_okay=False, path_type=Path),
              help="New config file for --apply.")
@click.option("--report", "report_dir", type=FilePath(file_okay=False, path_type=Path),
              help="Report folder: diagnose.json/.md, ranking.png, before/after.")
@_MAP
@_TRUST
@_day_options
@user_errors
def diagnose(config, logs, candidates, exclude, joint, no_sensors, do_apply, new_config,
             report_dir, map_path, trust, pose, pose_map, day):
    """Which physical effect is missing: fit every candidate effect the model lacks to
    the residual on LOGS, score on held-out flights (leave one flight out), rank, check
    identifiability; --apply -o NEWCONFIG writes the accepted one (CIs as comments)."""
    from ..studies import diagnose as run

    if do_apply and new_config is None:
        raise InputError("command line", "--apply", "needs -o NEWCONFIG")
    if new_config is not None and not do_apply:
        raise InputError("command line", "-o", "is the new config of --apply: give --apply "
                         "too (or --report DIR for a report)")
    _check_fit_arguments("diagnose", logs, candidates, exclude, day)
    _outputs_apart(**{"-o": new_config, "--report": report_dir})
    if new_config is not None:
        from ..resources import config_path

        _not_an_input(new_config, "-o", CONFIG=config_path(config), LOG=list(logs),
                      **{"--map": map_path})
    cfg = _load_for_compare(config)
    run(cfg, logs, candidates=candidates, exclude=exclude, joint=joint,
        sensors=not no_sensors, new_config=new_config, report_dir=report_dir,
        channel_map=_channel_map(map_path), trust=trust, pose=pose, pose_map=pose_map,
        day=day, reporter=TERMINAL)


@cli.command()
@CONFIG
@_LOGS
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Output folder: NAME.toml (the improved config), "
              "tables/ (rebuilt from it) and report/.")
@click.option("--rounds", type=click.IntRange(1, 10), default=3, show_default=True,
              help="The most diagnose rounds (1..10).")
@click.option("--exclude", "exclude", type=Name(), multiple=True, metavar="NAME",
              help="Leave out this candidate or effect (repeatable), as diagnose.")
@click.option("--no-build", is_flag=True,
              help="Write the config and the report only (no tables, no flights).")
@click.option("--tables", "table_path", type=FilePath(dir_okay=False, path_type=Path),
              help="The old table, built from CONFIG, for the flights [default: "
              "tables/NAME.h5 in the working folder when it is CONFIG's, else CONFIG's table "
              "from the cache, built there on first use].")
@click.option("--duration", type=FiniteFloat(1.0, MAX_FLIGHT_S, unit="s"), default=3.0,
              show_default=True, help=f"Seconds per standard flight (1..{MAX_FLIGHT_S:g}).")
@click.option("-j", "--jobs", type=Jobs(), default=-1, show_default=True,
              help=f"Parallel workers of the build, 1..{MAX_JOBS} (-1 = all cores).")
@click.option("--no-sensors", "no_sensors", is_flag=True,
              help="Take the config's [sensors] as they are (diagnose --no-sensors).")
@click.option("--no-uncertain", "no_uncertain", is_flag=True,
              help="Skip the check of the rebuilt table over the last fit's 95 % box (check "
              "--uncertain: minutes on a large grid).")
@click.option("--samples", type=click.IntRange(0), default=None, metavar="N",
              help="Random plants of that check besides the estimate and the box's corners "
              "[default: 8].")
@_MAP
@_TRUST
@_day_options
@user_errors
def improve(config, logs, out_dir, rounds, exclude, no_build, table_path, duration, jobs,
            no_sensors, no_uncertain, samples, map_path, trust, pose, pose_map, day):
    """The model loop in one command: compare CONFIG with LOGS, diagnose and apply in
    rounds until no effect is missing, rebuild the tables from the improved config (its
    name kept: the same C symbols), fly the standard flights on the improved model with
    the old and the new table, check the new table's loops over the last fit's 95 % box,
    and write the report: the error round by round, the tracking old against new and the
    worst multiplier and margins under the fit's uncertainty. Each step is what compare,
    diagnose --apply, build, simulate and check --uncertain do."""

    from ..publish import check_out_dir
    from ..studies import improve as run

    _check_fit_arguments("improve", logs, (), exclude, day)
    if no_build and table_path is not None:
        raise InputError("command line", "--tables", "is the old table of the flights, and "
                         "--no-build flies none: give one of them")
    cfg = _load_for_compare(config)
    cmap = _channel_map(map_path)
    check_out_dir(out_dir, names=[f"{cfg.name}.toml", "tables", "report"])
    # the improved config and the rebuilt table replace files of these names in DIR
    _not_an_input(out_dir / f"{cfg.name}.toml", "-o", CONFIG=config, LOG=list(logs))
    _not_an_input(out_dir / "tables" / f"{cfg.name}.h5", "-o", **{"--tables": table_path})
    done = run(cfg, logs, out_dir, rounds=rounds, exclude=exclude, build=not no_build,
               old_table=table_path, duration=duration, jobs=jobs, channel_map=cmap,
               trust=trust, sensors=not no_sensors, pose=pose, pose_map=pose_map, day=day,
               uncertain=not no_uncertain, samples=samples, reporter=TERMINAL)
    if done.failed is not None:  # the study kept what was done before it
        kept = "" if done.out_dir is None else f" (what was done before it is in {out_dir})"
        click.echo(f"gainsched: error: improve: the step '{done.failed.name}' failed: "
                   f"{done.failed.why}{kept}", err=True)
        sys.exit(1)


@cli.command()
@click.argument("log", type=FilePath(exists=True, path_type=Path))
@click.argument("pose", type=FilePath(exists=True, path_type=Path), required=False)
@click.option("-o", "--out", "out_path", type=FilePath(path_type=Path),
              help="The converted log: OUT.csv or OUT.h5 (required but with --list); with "
                   "--day, the folder of the day's flights.")
@click.option("--pose-map", "pose_map", type=Name(),
              help="With POSE: the channel map of the motion capture's recording (position "
                   "and attitude, their frames and anchor; time.pose_offset_s to give the "
                   "clock offset instead of estimating it).")
@click.option("--day", "day", is_flag=True,
              help="LOG is a whole flight day: cut into its circles and manoeuvres, each "
                   "written to -o DIR as NN-KIND.csv with day.json, day.md and day.png "
                   "(needs --config).")
@click.option("--list", "listing", is_flag=True,
              help="List the log's topics, their types, samples, rates and fields (what a "
                   "channel map can name), and convert nothing.")
@_MAP
@click.option("--config", "config_path", type=FilePath(dir_okay=False, path_type=Path),
              help="A config whose vehicle.thrust_max is a motor's thrust at full command "
                   "(normalised or PWM commands, when the map gives no thrust_max_N); "
                   "its vehicle is what the thrust and the load cell are checked against.")
@_TRUST
@user_errors
def convert(log, pose, out_path, pose_map, day, listing, map_path, config_path, trust):
    """Convert a PX4 ULog or a ROS 2 bag to the project's flight-log format
    (docs/flight-log.md) for inspection, and say what was mapped to what; or list its
    topics (--list) to write its channel map. With POSE, LOG is the flight controller's
    log and POSE the motion capture's recording of the same flight on another clock:
    the clocks are aligned from the motion both hold, and the offset reported."""
    from ..resources import config_path as shipped
    from ..studies import convert as run
    from ..studies import topics

    if listing:
        for line in topics(log).lines():
            click.echo(line)
        return
    if out_path is None:
        raise click.UsageError("Missing option '-o' / '--out' (or --list).")
    if pose is None and pose_map is not None:
        raise click.UsageError("--pose-map is the map of POSE, the second file: give it.")

    _not_an_input(out_path, "-o", LOG=log, POSE=pose, **{
        "--config": config_path and shipped(config_path), "--map": map_path,
        "--pose-map": pose_map})
    done = run(log, out_path, channel_map=_channel_map(map_path), config=config_path,
               trust=trust, pose=pose, pose_map=pose_map, day=day, reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)


@cli.command()
@CONFIG
@click.argument("report", type=FilePath(exists=True, path_type=Path))
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              help="Folder: plan.md, plan.json, and per flight NN.toml (a scenario "
                   "gainsched simulate flies) and NN-reference.csv (the reference a "
                   "firmware controller is given).")
@click.option("--duration", type=FiniteFloat(2.0, MAX_FLIGHT_S, unit="s"), default=10.0,
              show_default=True, help=f"Seconds per flight (2..{MAX_FLIGHT_S:g}).")
@user_errors
def plan(config, report, out_dir, duration):
    """The next flight: from a diagnose REPORT (diagnose.json, or its folder), the flights
    that would tell its look-alike candidates apart or shrink its widest interval the
    most, each flown in simulation on the fitted model and diagnosed, with the interval
    it is expected to give; best first."""
    from ..studies import plan as run

    cfg = _load_for_compare(config)
    done = run(cfg, report, out_dir, duration=duration, reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)
