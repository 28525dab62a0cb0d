"""Commands that read a config and build: ``validate``, ``nominal``, ``build`` (the
tables and the C files, one published set) and ``sweep``."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from ..constants import MAX_SWEEP_VARIANTS
from ..errors import InputError
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
    from ..config import load_config
    from ..schedule.nominal import min_taut_speed

    cfg = load_config(config)
    v, t, gr = cfg.vehicle, cfg.tether, cfg.grid
    click.echo(f"{config}: ok (sha256 {cfg.sha256[:12]})")
    click.echo(
        f"  vehicle  m={v.mass:g} kg  "
        f"J=diag({', '.join(f'{x:g}' for x in np.diag(v.inertia))}) kg m^2"
    )
    click.echo(
        f"           arm {v.arm_length:g} m  kappa {v.kappa:g} m  "
        f"thrust {v.thrust_min:g}..{v.thrust_max:g} N"
    )
    click.echo(f"  tether   rho={t.length:g} m  L_e={t.attachment_offset:g} m  link={t.link}")
    effects = ", ".join(
        f"{e.name}({', '.join(f'{k}={x:g}' for k, x in e.params)})" for e in cfg.effects
    )
    click.echo(f"  effects  {effects or 'none'}")
    def axis(values, rng, what, unit):
        if rng is None:
            return f"{values.size} {what} {values[0]:g}..{values[-1]:g} {unit}"
        return f"{what} {rng.lo:g}..{rng.hi:g} {unit} (at most {rng.max_count}, chosen)"

    az = gr.azimuth_auto
    click.echo(
        f"  grid     {axis(gr.speeds, gr.speeds_auto, 'speeds', 'm/s')}, "
        f"{axis(np.rad2deg(gr.tilts), gr.tilts_auto, 'tilts', 'deg')}, "
        + (f"{gr.azimuth_samples} azimuth samples" if az is None
           else f"{az.lo}..{az.hi} azimuth samples (chosen)")
    )
    if gr.auto:
        click.echo(f"           chosen by the build for {100 * gr.max_interpolation_error:g} % "
                   "at the cell midpoints (docs/grid.md)")
    for a in gr.tilts:
        click.echo(f"  taut above {min_taut_speed(cfg, a):.2f} m/s at tilt {np.rad2deg(a):g} deg")


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
    from ..config import load_config
    from ..model.reduced import Model
    from ..publish import check_out_file, write_atomic
    from ..resources import config_path
    from ..schedule.nominal import REASONS, circle_nominal, min_taut_speed

    if csv_path is not None:
        _not_an_input(csv_path, "--csv", CONFIG=config_path(config))
    cfg = load_config(config)
    if speed == 0 or not np.isfinite(speed):
        raise InputError("command line", "--speed", "must be a finite non-zero speed in m/s")
    if not -90 < tilt < 90:
        raise InputError("command line", "--tilt", "must be in (-90, 90) deg")
    if csv_path is not None:
        check_out_file(csv_path, "--csv")  # a bad --csv fails before anything prints
    model = Model(cfg)
    nom = circle_nominal(model, speed, np.deg2rad(tilt), samples)
    g_load = speed**2 / model.r / cfg.g
    rows = []
    for k in range(samples):
        why = "; ".join(txt for bit, txt in REASONS.items() if nom.reasons[k] & bit) or "ok"
        rows.append(
            (np.rad2deg(nom.z[k, 1]) % 360, np.rad2deg(nom.phi[k]), nom.collective[k],
             *nom.u[k], nom.tension[k], g_load, why)
        )
    head = ("xi_deg", "roll_deg", "T_C_N", "T1_N", "T2_N", "T3_N", "T4_N", "tension_N", "g_load",
            "feasibility")
    click.echo(
        f"speed {speed:g} m/s (xi_dot {speed / model.r:.4g} rad/s), tilt {tilt:g} deg, "
        f"period {2 * np.pi * model.r / abs(speed):.3f} s, "
        f"taut above {min_taut_speed(cfg, np.deg2rad(tilt)):.2f} m/s"
    )
    click.echo(" ".join(f"{h:>9s}" for h in head[:-1]) + "  feasibility")
    for row in rows:
        click.echo(" ".join(f"{x:9.3f}" for x in row[:-1]) + "  " + row[-1])
    n_bad = int(np.count_nonzero(nom.reasons))
    click.echo(f"{samples - n_bad}/{samples} azimuth samples feasible")
    if csv_path is not None:
        lines = [",".join(head)] + [
            ",".join(f"{x:.9g}" for x in row[:-1]) + f",{row[-1]}" for row in rows
        ]
        write_atomic(csv_path, ("\n".join(lines) + "\n").encode(), where="--csv")
        click.echo(f"wrote {csv_path}")


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
