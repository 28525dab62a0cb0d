"""Commands that read a built table: ``inspect``, ``plot``, ``export-c`` and ``check``."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ._base import (
    TERMINAL,
    FilePath,
    FiniteFloat,
    cli,
    user_errors,
)


@cli.command()
@click.argument("table", type=FilePath(dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--out",
    "out_dir",
    type=FilePath(file_okay=False, path_type=Path),
    default=None,
    help="Also write envelope.png (speed x tilt: feasible / slack / thrust) and "
    "envelope.json to this folder.",
)
@click.option("--json", "as_json", is_flag=True,
              help="Print the summary as JSON (grid, feasibility, gain ranges, spectral "
              "radius per circle) instead of text.")
@user_errors
def inspect(table, out_dir, as_json):
    """Summarise a gain table: grid, feasibility map (speed m/s x tilt deg), gain ranges,
    worst closed-loop spectral radius; with --out, the flight envelope as a PNG and JSON."""
    from ..studies import inspect as run

    done = run(table, out_dir, code_size=not as_json, reporter=TERMINAL)
    for line in done.lines(as_json):
        click.echo(line)




@cli.command()
@click.argument("table", type=FilePath(dir_okay=False, path_type=Path))
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Folder for the PNGs and plots.json (written as one set).")
@click.option("--check", "with_check", is_flag=True,
              help="Also solve the LQR at the cell midpoints (as `gainsched check`) and plot "
              "the interpolation error (slower).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary (plots.json) on stdout.")
@user_errors
def plot(table, out_dir, with_check, as_json):
    """Plot a gain table: every gain K_ij over azimuth and speed per tilt (grid points
    marked), the feasibility envelope, nominal thrusts and roll, the closed-loop spectral
    radius per circle and, with --check, the midpoint interpolation error; plus a JSON
    summary (plots.json)."""
    from ..studies import plot as run

    done = run(table, out_dir, check=with_check, reporter=TERMINAL)
    for line in done.lines(as_json):
        click.echo(line)


@cli.command("export-c")
@click.argument("table", type=FilePath(dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--out",
    "out_dir",
    type=FilePath(file_okay=False, path_type=Path),
    default=None,
    help="Output folder (default: the table's folder).",
)
@click.option("--no-code-size", is_flag=True, help="Skip compiling the runtime to measure it.")
@click.option("--format", "fmt", type=click.Choice(["config", "dense", "compact"]),
              default="config", show_default=True,
              help="Table format of the header: the table's config ([firmware] format), "
              "values per azimuth (dense) or Fourier series per circle, certified at the "
              "cell midpoints (compact; docs/runtime.md).")
@click.option("--motor-order", type=click.Choice(["config", "gainsched", "px4"]),
              default="config", show_default=True,
              help="Numbering of the controller's outputs: the table's config ([firmware] "
              "motor_order), the tool's T1..T4 or PX4's quad-X (docs/runtime.md, \"PX4\").")
@click.option("--command", type=click.Choice(["config", "thrust", "normalized"]),
              default="config", show_default=True,
              help="The controller's outputs: thrusts in N or commands 0..1 through the "
              "thrust curve (with --thr-mdl-fac, --thrust-max-n).")
@click.option("--thr-mdl-fac", type=FiniteFloat(0, 1), default=None,
              help="The thrust curve's quadratic part, PX4's THR_MDL_FAC (normalized).")
@click.option("--thrust-max-n", type=FiniteFloat(0, 1e6, lo_open=True, unit="N"),
              default=None, help="Thrust at full command, N (normalized; default: the "
              "config's vehicle.thrust_max).")
@user_errors
def export_c(table, out_dir, no_code_size, fmt, motor_order, command, thr_mdl_fac,
             thrust_max_n):
    """Write the C99 header NAME_gains.h for TABLE, the controller's parameters
    NAME_control.h (from the table's config) and copy the C runtime and controller
    (gainsched_runtime.c/.h, gainsched_control.c/.h) next to them; print the flash
    footprint."""
    from ..studies import export_c as run

    done = run(table, out_dir, fmt=fmt, motor_order=motor_order, command=command,
               thr_mdl_fac=thr_mdl_fac, thrust_max_n=thrust_max_n, code_size=not no_code_size,
               reporter=TERMINAL)
    for line in done.lines():
        click.echo(line)


@cli.command()
@click.argument("table", type=FilePath(dir_okay=False, path_type=Path))
@click.option(
    "--speed-stride",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="Check every N-th speed midpoint only (faster).",
)
@click.option(
    "--max-error",
    type=FiniteFloat(0, 100, lo_open=True, unit="%"),
    default=None,
    help="Pass threshold on the max relative gain error, percent (default: the table "
    "config's grid.max_interpolation_error, 2).",
)
@click.option(
    "--compact", "azimuth_error", type=FiniteFloat(0, 100, lo_open=True, unit="%"),
    default=None, help="Check the table's compact form (Fourier series in the azimuth, "
    "docs/runtime.md) made with this error bound at the azimuth samples, percent "
    "(1: the default form). Default: the format of the table's config.")
@click.option(
    "--uncertain", "report", type=click.Path(path_type=Path), default=None,
    help="Instead: close the table's gains on plants drawn over the 95 % box of this "
    "diagnose report's fit (diagnose.json or its folder; corners, estimate, samples) and "
    "report the worst multiplier, where, at which parameter values, and the margins "
    "(docs/margins.md).")
@click.option(
    "--samples", type=click.IntRange(0), default=None,
    help="With --uncertain: random plants inside the box besides its corners "
    "[default: 8].")
@user_errors
def check(table, speed_stride, max_error, azimuth_error, report, samples):
    """Interpolation accuracy of TABLE: solve the periodic LQR directly at cell midpoints
    (speed x tilt x azimuth) and compare with the interpolated gains (max and median
    relative Frobenius error), then close the loop along each midpoint circle with the
    interpolated gains (monodromy spectral radius). Exit code 1 if the max error is above
    --max-error or a midpoint closed loop is not stable. With --compact, the same for
    the table's compact form. With --uncertain REPORT, the table's loops on the plants of
    a diagnosis's 95 % box instead: exit code 1 if one is unstable, naming the parameter."""
    if report is not None:
        from ..studies import check_uncertain

        done = check_uncertain(table, report, samples=samples, reporter=TERMINAL)
        if not done.ok:
            sys.exit(1)
        return
    from ..studies import check as run

    done = run(table, speed_stride=speed_stride, max_error=max_error,
               azimuth_error=azimuth_error, reporter=TERMINAL)  # its lines as they come
    if not done.ok:
        sys.exit(1)
