"""Commands that read a config and build: ``validate``, ``nominal``, ``build`` (the
tables and the C files, one published set) and ``sweep``."""

from __future__ import annotations

from pathlib import Path

import click

from ..constants import MAX_SWEEP_VARIANTS
from ._base import (
    CONFIG,
    SEED,
    TERMINAL,
    FilePath,
    FiniteFloat,
    _cluster_options,
    _not_an_input,
    _speed_option,
    cli,
    user_errors,
)


@cli.command()
@CONFIG
@user_errors
def validate(config):
    """Check a config file (TOML) and print a summary of the vehicle and grid."""
    from ..studies import validate as run

    for line in run(config).lines():
        click.echo(line)


@cli.command()
@CONFIG
@_speed_option
@click.option(
    "--tilt", type=FiniteFloat(-90, 90, unit="deg"), default=0.0, show_default=True,
    help="Circle tilt alpha_C, deg."
)
@click.option("--samples", type=click.IntRange(4, 3600), default=12, show_default=True,
              help="Azimuth samples over one period (4-3600).")
@click.option("--csv", "csv_path", type=FilePath(dir_okay=False, path_type=Path),
              help="Also write the table as CSV (SI units, xi in deg).")
@user_errors
def nominal(config, speed, tilt, samples, csv_path):
    """Nominal constant-speed circle over the azimuth: roll (deg), collective and motor
    thrusts (N), tether tension (N), centripetal g-load, feasibility."""
    from ..resources import config_path
    from ..studies import nominal as run

    if csv_path is not None:
        _not_an_input(csv_path, "--csv", CONFIG=config_path(config))
    for line in run(config, speed, tilt, samples, csv=csv_path).lines():
        click.echo(line)


@cli.command()
@CONFIG
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              default=Path("tables"), show_default=True, help="Output folder.")
@_cluster_options
@user_errors
def build(config, out_dir, jobs, backend, scheduler, connect_timeout):
    """Build the gain table OUT/NAME.h5 from CONFIG: nominal, linearisation and periodic
    LQR at every (speed m/s, tilt deg, azimuth) grid point. With --backend dask the
    speeds run on a Dask cluster; the table is byte-identical to the local build."""
    from ..studies import build as run

    done = run(config, out_dir, jobs=jobs, backend=backend, scheduler=scheduler,
               connect_timeout=connect_timeout, reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)


@cli.command()
@CONFIG
@click.option("--vary", multiple=True, metavar="KEY=v1,v2,...",
              help="Values of one parameter, SI (e.g. vehicle.mass=0.45,0.5,0.55); repeat "
              "for a Cartesian product. Keys: docs/distributed.md.")
@click.option("--monte-carlo", type=click.IntRange(0, MAX_SWEEP_VARIANTS), default=0,
              metavar="N", help="Monte Carlo samples (per --vary combination) of the --sigma "
              f"keys; at most {MAX_SWEEP_VARIANTS} variants in all.")
@click.option("--seed", type=SEED, default=0, show_default=True,
              help="Seed of the Monte Carlo draws (a non-negative integer).")
@click.option("--sigma", multiple=True, metavar="KEY=REL",
              help="Relative standard deviation of a sampled parameter (e.g. "
              "vehicle.mass=0.05): value = nominal (1 + REL z), z ~ N(0, 1).")
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Output folder (NAME.toml, NAME.h5 per variant; "
              "sweep.csv, sweep.json).")
@_cluster_options
@user_errors
def sweep(config, vary, monte_carlo, seed, sigma, out_dir, jobs, backend, scheduler,
          connect_timeout):
    """Build a gain table per vehicle variant (--vary) or Monte Carlo sample (--monte-carlo,
    --sigma) of CONFIG, and a results table: feasible %, worst monodromy spectral radius,
    max |K|, min tension margin (N) and table SHA-256 per variant."""
    from ..studies import sweep as run

    done = run(config, out_dir, vary=vary, monte_carlo=monte_carlo, seed=seed, sigma=sigma,
               jobs=jobs, backend=backend, scheduler=scheduler,
               connect_timeout=connect_timeout, reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)
