"""Commands that read a built table: ``inspect``, ``plot``, ``export-c`` and ``check``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click
import numpy as np

from ..errors import InputError
from ._base import (
    TERMINAL,
    FilePath,
    FiniteFloat,
    _progress,
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
    from ..analysis.progress import stage
    from ..firmware.codegen import flash_summary
    from ..publish import check_out_dir
    from ..schedule.envelope import write_envelope
    from ..schedule.nominal import REASONS
    from ..schedule.refine import grid_auto_lines
    from ..schedule.tables import load_table
    from ..schedule.viewer import mode_lines, table_summary

    if out_dir is not None:
        check_out_dir(out_dir, "--out", names=_ENVELOPE)
    t = load_table(table)
    if as_json:
        from ..firmware.runtime import c_identifier

        # c_prefix: the prefix of the C symbols export-c writes (paper_table, PAPER_N_STATE)
        summary = {**table_summary(t, source=str(table)), "c_prefix": c_identifier(t.name)}
        click.echo(json.dumps(summary, indent=2, sort_keys=True))
        if out_dir is not None:
            write_envelope(t, table, out_dir)
        return
    with _progress(f"inspect {t.name}", 1 + (out_dir is not None), "stage") as bar:
        flash = stage(bar, "runtime code size (compiling)", flash_summary, t)
        envelope = out_dir and stage(bar, "envelope.png", write_envelope, t, table, out_dir)
    click.echo(f"{table}: {t.attrs['schema']}, config {t.name} (sha256 {t.config_sha256[:12]}), "
               f"tool {t.attrs['tool_version']}, terminal cost {t.attrs['terminal']}")
    tilts = ", ".join(f"{x:g}" for x in np.rad2deg(t.tilt))
    click.echo(f"  xi: {t.xi.size} samples over 360 deg; speeds {t.speed[0]:g}..{t.speed[-1]:g} "
               f"m/s ({t.speed.size}); tilts {tilts} deg")
    if t.grid_auto is not None:
        for line in grid_auto_lines(t.grid_auto):
            click.echo(f"  {line}")
    click.echo("  feasible azimuth fraction (rows: tilt deg, columns: speed m/s)")
    w = max(6, 1 + max(len(f"{v:g}") for v in t.speed))  # chosen grids have long values
    click.echo("        " + "".join(f"{v:{w}g}" for v in t.speed))
    for i, a in enumerate(np.rad2deg(t.tilt)):
        frac = (t.reasons[i] == 0).mean(-1)
        click.echo(f"  {a:5g} " + "".join(f"{x:{w}.2f}" for x in frac))
    for bit, text in REASONS.items():
        n = np.count_nonzero(t.reasons & bit)
        if n:
            click.echo(f"  {n} points: {text}")
    K = t.K_full()
    names = list(t.state_names)
    click.echo("  gain ranges over feasible points (min .. max per state column)")
    for j, nm in enumerate(names):
        col = K[..., j][np.isfinite(K[..., j])]
        if col.size:
            click.echo(f"    {nm:>10s}: {col.min():9.3f} .. {col.max():9.3f}")
    for line in flash:
        click.echo(f"  {line}")
    rho = t.spectral_radius
    if not np.any(np.isfinite(rho)):
        click.echo("  no feasible circle: no gains, no closed loop (see the reasons above)")
    else:
        i, j = np.unravel_index(np.nanargmax(rho), rho.shape)
        click.echo(f"  worst closed-loop monodromy spectral radius {rho[i, j]:.5f} "
                   f"(speed {t.speed[j]:g} m/s, tilt {np.rad2deg(t.tilt[i]):g} deg); "
                   f"all < 1: {bool(np.all(rho[np.isfinite(rho)] < 1))}")
    for line in mode_lines(t):
        click.echo(f"  {line}")
    if out_dir is not None:
        click.echo(envelope)


_ENVELOPE = ["envelope.png", "envelope.json"]


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
@user_errors
def check(table, speed_stride, max_error, azimuth_error):
    """Interpolation accuracy of TABLE: solve the periodic LQR directly at cell midpoints
    (speed x tilt x azimuth) and compare with the interpolated gains (max and median
    relative Frobenius error), then close the loop along each midpoint circle with the
    interpolated gains (monodromy spectral radius). Exit code 1 if the max error is above
    --max-error or a midpoint closed loop is not stable. With --compact, the same for
    the table's compact form."""
    import time

    from ..firmware.check import midpoint_check
    from ..schedule.refine import grid_auto_lines
    from ..schedule.tables import load_table

    t = load_table(table)
    n_mid = max(t.speed.size - 1, 1)
    if speed_stride > n_mid:  # a stride past the last midpoint checks only the first
        raise InputError("command line", "--speed-stride", f"{speed_stride}: {table} has "
                         f"{n_mid} speed midpoint{'s' if n_mid > 1 else ''}: give 1..{n_mid}")
    t0 = time.perf_counter()
    lookup = None
    from ..firmware.outputs import table_config

    cfg = table_config(t, "config")
    if max_error is None:
        max_error = 2.0 if cfg is None else 100 * cfg.grid.max_interpolation_error
    if azimuth_error is None and cfg is not None and cfg.firmware.format == "compact":
        azimuth_error = 100 * cfg.firmware.azimuth_error
    if azimuth_error is not None:
        from ..firmware.compact import CompactInterpolator, compact_data
        from ..firmware.runtime import runtime_data

        dense = runtime_data(t)
        form = compact_data(dense, azimuth_error / 100, source=str(table), key="--compact")
        click.echo(f"{table}: compact form at {azimuth_error:g}% on the azimuth samples: "
                   f"{form.nbytes():,} bytes of table data (dense {dense.nbytes():,}); "
                   f"{int(form.harmonics.max())} harmonics at most; fit error at the "
                   f"samples max {100 * np.nanmax(form.fit_error, initial=0):.2f}%")
        lookup = CompactInterpolator(form)
    n_v = len(range(0, max(t.speed.size - 1, 0), speed_stride))
    with _progress(f"check {t.name}", n_v, "speed") as bar:
        res = midpoint_check(t, speed_stride=speed_stride, progress=bar.update, lookup=lookup)
    ok_pts = int(np.count_nonzero(np.isfinite(res.rel_err)))
    n_a = max(t.tilt.size - 1, 1)
    click.echo(
        f"{table}: {ok_pts} cell midpoints checked ({n_v} speeds x {n_a} tilts x "
        f"{t.xi.size} azimuths; {res.skipped} skipped as infeasible), "
        f"{time.perf_counter() - t0:.1f} s"
    )
    if ok_pts:
        v, a, x, e = res.worst_point()
        click.echo(
            f"  relative gain error |K_interp - K|_F / |K|_F: max {100 * e:.2f}% "
            f"(speed {v:g} m/s, tilt {np.rad2deg(a):g} deg, xi {np.rad2deg(x):g} deg), "
            f"median {100 * res.median_err:.2f}%"
        )
        by_v, by_a = res.by_axis()
        click.echo(
            "  max error by speed midpoint (m/s: %): "
            + ", ".join(f"{k:g}: {100 * e:.2f}" for k, e in by_v.items() if np.isfinite(e))
        )
        click.echo(
            "  max error by tilt midpoint (deg: %): "
            + ", ".join(
                f"{np.rad2deg(k):g}: {100 * e:.2f}" for k, e in by_a.items() if np.isfinite(e)
            )
        )
        click.echo(f"  max nominal thrust error {np.nanmax(res.u_err):.4f} N "
                   f"({100 * np.nanmax(res.u_rel):.2f}% of the circle's largest), roll "
                   f"{100 * np.nanmax(res.phi_rel):.2f}% of the circle's largest")
    rho = [(c[2], c) for c in res.circles if np.isfinite(c[2])]
    if rho:
        r, c = max(rho)
        click.echo(
            f"  closed loop with interpolated gains on {len(rho)} midpoint circles: "
            f"worst spectral radius {r:.5f} (speed {c[0]:g} m/s, tilt "
            f"{np.rad2deg(c[1]):g} deg; direct LQR {c[3]:.5f}); all < 1: {res.stable}"
        )
    # a grid the build chose promised gains, nominal thrusts and roll (docs/grid.md)
    nominal = t.grid_auto is not None
    if nominal:
        click.echo(f"  {grid_auto_lines(t.grid_auto)[0]}; checked on gains, nominal "
                   "thrusts and roll")
    passed = res.passed(max_error / 100, nominal)
    what = "gain, thrust and roll error" if nominal else "max error"
    click.echo(
        f"  {'PASS' if passed else 'FAIL'}: {what} <= {max_error:g}% and every "
        "midpoint closed loop stable"
    )
    if not passed:
        sys.exit(1)
