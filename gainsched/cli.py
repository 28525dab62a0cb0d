"""Command-line interface (thin: parsing, printing; the logic lives in the modules).

Every user error is an :class:`~gainsched.errors.InputError`, printed as one
line ``gainsched: error: FILE: KEY: what is wrong`` with exit code 2.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

import click
import numpy as np

from . import __version__
from .errors import InputError

__all__ = ["main", "cli"]


def user_errors(fn):
    """Turn InputError into one line on stderr and exit code 2 (no traceback)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except InputError as exc:
            click.echo(f"gainsched: error: {exc}", err=True)
            sys.exit(2)

    return wrapper


CONFIG = click.argument("config", type=click.Path(dir_okay=False, path_type=Path))


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gainsched")
def cli():
    """Gain-scheduling compiler for a tethered quadcopter flying great circles.

    Units: SI everywhere (m, s, N, rad/s) except tilts, which are given in degrees.
    """


@cli.command()
@CONFIG
@user_errors
def validate(config):
    """Check a config file (TOML) and print a summary of the vehicle and grid."""
    from .config import load_config
    from .nominal import min_taut_speed

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
    click.echo(
        f"  grid     {gr.speeds.size} speeds {gr.speeds[0]:g}..{gr.speeds[-1]:g} m/s, "
        f"{gr.tilts.size} tilts {np.rad2deg(gr.tilts[0]):g}..{np.rad2deg(gr.tilts[-1]):g} deg, "
        f"{gr.azimuth_samples} azimuth samples"
    )
    for a in gr.tilts:
        click.echo(f"  taut above {min_taut_speed(cfg, a):.2f} m/s at tilt {np.rad2deg(a):g} deg")


def _speed_option(fn):
    return click.option(
        "--speed", type=float, required=True, help="Tangential COG speed, m/s (negative: reversed)."
    )(fn)


@cli.command()
@CONFIG
@_speed_option
@click.option(
    "--tilt", type=float, default=0.0, show_default=True, help="Circle tilt alpha_C, deg."
)
@click.option("--samples", type=click.IntRange(4, 100000), default=12, show_default=True,
              help="Azimuth samples over one period.")  # fmt: skip
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the table as CSV (SI units, xi in deg).")  # fmt: skip
@user_errors
def nominal(config, speed, tilt, samples, csv_path):
    """Nominal constant-speed circle over the azimuth: roll (deg), collective and motor
    thrusts (N), tether tension (N), centripetal g-load, feasibility."""
    from .config import load_config
    from .model import Model
    from .nominal import REASONS, circle_nominal, min_taut_speed
    from .tables import write_atomic

    cfg = load_config(config)
    if speed == 0 or not np.isfinite(speed):
        raise InputError("command line", "--speed", "must be a finite non-zero speed in m/s")
    if not -90 < tilt < 90:
        raise InputError("command line", "--tilt", "must be in (-90, 90) deg")
    model = Model(cfg)
    nom = circle_nominal(model, speed, np.deg2rad(tilt), samples)
    g_load = speed**2 / model.r / cfg.g
    rows = []
    for k in range(samples):
        why = "; ".join(txt for bit, txt in REASONS.items() if nom.reasons[k] & bit) or "ok"
        rows.append(
            (np.rad2deg(nom.z[k, 1]) % 360, np.rad2deg(nom.phi[k]), nom.collective[k],
             *nom.u[k], nom.tension[k], g_load, why)
        )  # fmt: skip
    head = ("xi_deg", "roll_deg", "T_C_N", "T1_N", "T2_N", "T3_N", "T4_N", "tension_N", "g_load",
            "feasibility")  # fmt: skip
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
        write_atomic(csv_path, ("\n".join(lines) + "\n").encode())
        click.echo(f"wrote {csv_path}")


@cli.command()
@CONFIG
@click.option("-o", "--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("tables"), show_default=True, help="Output folder.")  # fmt: skip
@click.option("-j", "--jobs", type=int, default=-1, show_default=True,
              help="Parallel workers (joblib; -1 = all cores).")  # fmt: skip
@click.option("--backend", type=click.Choice(["loky", "threading", "sequential"]),
              default="loky", show_default=True, help="joblib backend.")  # fmt: skip
@user_errors
def build(config, out_dir, jobs, backend):
    """Build the gain table OUT/NAME.h5 from CONFIG: nominal, linearisation and periodic
    LQR at every (speed m/s, tilt deg, azimuth) grid point."""
    import time

    from tqdm import tqdm

    from .config import load_config
    from .grid import build_grid
    from .model import Model
    from .tables import write_table

    cfg = load_config(config)
    t0 = time.perf_counter()
    n_v = cfg.grid.speeds.size
    with tqdm(total=n_v, unit="speed", desc=f"build {cfg.name}", disable=None) as bar:
        grid = build_grid(cfg, n_jobs=jobs, progress=bar.update,
                          backend=None if backend == "sequential" else backend)  # fmt: skip
    out = out_dir / f"{cfg.name}.h5"
    size = write_table(out, cfg, grid, Model(cfg))
    n_pts = grid.reasons.size
    feas = np.count_nonzero(grid.reasons == 0)
    click.echo(
        f"{out}: {n_pts} points ({cfg.grid.tilts.size} tilts x {n_v} speeds x "
        f"{cfg.grid.azimuth_samples} azimuths), {100 * feas / n_pts:.1f}% feasible, "
        f"worst closed-loop spectral radius {np.nanmax(grid.rho):.4f}, "
        f"{time.perf_counter() - t0:.1f} s, {size / 1024:.0f} KiB"
    )


@cli.command()
@click.argument("table", type=click.Path(dir_okay=False, path_type=Path))
@user_errors
def inspect(table):
    """Summarise a gain table: grid, feasibility map (speed m/s x tilt deg), gain ranges,
    worst closed-loop spectral radius."""
    from .nominal import REASONS
    from .tables import load_table

    t = load_table(table)
    click.echo(f"{table}: {t.attrs['schema']}, config {t.name} (sha256 {t.config_sha256[:12]}), "
               f"tool {t.attrs['tool_version']}, terminal cost {t.attrs['terminal']}")  # fmt: skip
    tilts = ", ".join(f"{x:g}" for x in np.rad2deg(t.tilt))
    click.echo(f"  xi: {t.xi.size} samples over 360 deg; speeds {t.speed[0]:g}..{t.speed[-1]:g} "
               f"m/s ({t.speed.size}); tilts {tilts} deg")  # fmt: skip
    click.echo("  feasible azimuth fraction (rows: tilt deg, columns: speed m/s)")
    click.echo("        " + "".join(f"{v:6g}" for v in t.speed))
    for i, a in enumerate(np.rad2deg(t.tilt)):
        frac = (t.reasons[i] == 0).mean(-1)
        click.echo(f"  {a:5g} " + "".join(f"{x:6.2f}" for x in frac))
    for bit, text in REASONS.items():
        n = np.count_nonzero(t.reasons & bit)
        if n:
            click.echo(f"  {n} points: {text}")
    K = t.K_full()
    names = t.attrs["state_names"].split(",")
    click.echo("  gain ranges over feasible points (min .. max per state column)")
    for j, nm in enumerate(names):
        col = K[..., j][np.isfinite(K[..., j])]
        if col.size:
            click.echo(f"    {nm:>10s}: {col.min():9.3f} .. {col.max():9.3f}")
    rho = t.spectral_radius
    i, j = np.unravel_index(np.nanargmax(rho), rho.shape)
    click.echo(f"  worst closed-loop monodromy spectral radius {rho[i, j]:.5f} "
               f"(speed {t.speed[j]:g} m/s, tilt {np.rad2deg(t.tilt[i]):g} deg); "
               f"all < 1: {bool(np.all(rho[np.isfinite(rho)] < 1))}")  # fmt: skip


def main():
    cli()


if __name__ == "__main__":
    main()
