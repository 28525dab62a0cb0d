"""Commands that fly a table in simulation: ``simulate``, ``paper`` and ``campaign``."""

from __future__ import annotations

from pathlib import Path

import click

from ..constants import MAX_FLIGHT_S
from ._base import (
    _RUNTIME,
    CONFIG,
    MAX_SPEED,
    SEED,
    TERMINAL,
    FilePath,
    FiniteFloat,
    Name,
    cli,
    user_errors,
)


@cli.command()
@CONFIG
@click.option("--tables", "table_path", type=FilePath(dir_okay=False, path_type=Path),
              required=True, help="Gain table (HDF5) built from CONFIG.")
@click.option("--scenario", type=Name(), required=True,
              help="Scenario file, or the name of a shipped scenario (horizontal, tilted40, "
              "speedup, braking, staircase).")
@click.option("--plant", "plant_path", type=FilePath(dir_okay=False, path_type=Path),
              help="Truth config for the plant (default: CONFIG).")
@click.option("--speed", type=FiniteFloat(0, MAX_SPEED, lo_open=True, unit="m/s"),
              help="Override the scenario's initial speed, m/s (0 < speed <= 100).")
@_RUNTIME
@click.option("--controller", type=click.Choice(["path", "firmware"]), default="path",
              show_default=True,
              help="'path': the control law in Python with the design model's nominal "
              "along the reference; 'firmware': the firmware's whole control step, sensors "
              "in and thrusts out, with only what a firmware has: its estimator, the table's "
              "lookup plus the drag-only closed form (docs/runtime.md).")
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Output folder (log.csv/.h5, metrics.json, plots).")
@user_errors
def simulate(config, table_path, scenario, plant_path, speed, runtime, controller, out_dir):
    """Fly a scenario in closed loop on the nonlinear plant with gains from the table."""
    from ..studies import fly

    done = fly(config, table_path, scenario, out_dir, plant=plant_path, speed=speed,
               runtime=runtime, controller=controller, reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)


@cli.command()
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Output folder (report.md, report.json, one folder per "
              "experiment).")
@click.option("--config", "config", type=FilePath(dir_okay=False, path_type=Path),
              default="paper", show_default="paper, the shipped configs/paper.toml",
              help="Design config (the paper vehicle).")
@click.option("--tables", "table_path", type=FilePath(dir_okay=False, path_type=Path),
              help="Gain table built from the config [default: tables/NAME.h5 in the "
              "working folder when it is the config's, else the config's table from the "
              "cache, built there on first use].")
@click.option("--plant", "plant_path", type=FilePath(dir_okay=False, path_type=Path),
              help="Truth config for the plant (default: the design config).")
@click.option("--quick", is_flag=True, help="Short smoke flights (for tests; seconds).")
@_RUNTIME
@user_errors
def paper(out_dir, config, table_path, plant_path, quick, runtime):
    """Fly the paper's experiments (Sec. V.B, Figs. 3-4) in simulation and write a report:
    paper figure, paper value, simulated value."""
    from ..studies import paper as run

    done = run(out_dir, config, table=table_path, plant=plant_path, quick=quick,
               runtime=runtime, reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)


class _HiddenOption(click.Option):
    """``--hidden``: its help lists the hidden effects of
    :data:`gainsched.sim.campaign.HIDDEN`, read when help is asked for (the simulator is
    not imported to start a command)."""

    def get_help_record(self, ctx):
        from ..sim.campaign import HIDDEN

        self.help = f"Hidden effect of the plant: {', '.join(HIDDEN)}."
        return super().get_help_record(ctx)


@cli.command()
@CONFIG
@click.option("--tables", "table_path", type=FilePath(dir_okay=False, path_type=Path),
              required=True, help="Gain table (HDF5) built from CONFIG.")
@click.option("--hidden", type=Name(), default="none", show_default=True,
              cls=_HiddenOption, help="Hidden effect of the plant.")
@click.option("--duration", type=FiniteFloat(1.0, MAX_FLIGHT_S, unit="s"), default=3.0,
              show_default=True, help=f"Seconds per flight (1..{MAX_FLIGHT_S:g}).")
@click.option("--no-load-cell", is_flag=True, help="Drop the tether tension column.")
@click.option("--real-tether", is_flag=True,
              help="Fly on the elastic tether of a real vehicle (spring-damper, k = 2e5 N/m, "
                   "c = 25 N s/m) under the hidden effect.")
@click.option("--format", "fmt", type=click.Choice(["csv", "h5"]), default="csv",
              show_default=True)
@click.option("--seed", type=SEED, default=1, show_default=True,
              help="Seed of the sensor noise (a non-negative integer).")
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Output folder for the flight logs.")
@user_errors
def campaign(config, table_path, hidden, duration, no_load_cell, real_tether, fmt, seed,
             out_dir):
    """Fly a synthetic test campaign (speeds 3-15 m/s, tilts 0/20/40 deg, a speed-up, a
    braking; motion-capture noise) on a plant with a HIDDEN effect and write the logs."""
    from ..studies import campaign as run

    done = run(config, table_path, out_dir, hidden=hidden, duration=duration,
               load_cell=not no_load_cell, real_tether=real_tether, fmt=fmt, seed=seed,
               reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)
