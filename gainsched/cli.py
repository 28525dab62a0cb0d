"""Command-line interface (thin: parsing, printing; the logic lives in the modules).

Every user error is an :class:`~gainsched.errors.InputError`, printed as one
line ``gainsched: error: FILE: KEY: what is wrong`` with exit code 2.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import sys
import warnings
from pathlib import Path

import click
import numpy as np

from . import __version__
from .analysis.logchecks import CHECKS as LOG_CHECKS
from .constants import MAX_FLIGHT_S, MAX_JOBS, MAX_SEED, MAX_SWEEP_VARIANTS
from .errors import GainschedWarning, InputError

__all__ = ["main", "cli"]


def user_errors(fn):
    """Turn InputError into one line on stderr and exit code 2 (no traceback)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except InputError as exc:  # one line, whatever a library's message held
            click.echo(f"gainsched: error: {' '.join(str(exc).split())}", err=True)
            sys.exit(2)

    return wrapper


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    """gainsched's own warnings as one line on stderr; others as Python shows them."""
    if issubclass(category, GainschedWarning):
        click.echo(f"gainsched: warning: {' '.join(str(message).split())}", err=True)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


class _OneLineErrors(click.Group):
    """click's usage errors (bad option value, unknown option, missing argument) as one
    line ``gainsched: error: command line: ...`` with exit code 2, like every other user
    error; Ctrl-C as ``gainsched: interrupted`` with exit code 130."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True,
             **extra):
        try:
            with warnings.catch_warnings():
                warnings.showwarning = _one_line_warning
                rv = super().main(args, prog_name, complete_var, standalone_mode=False,
                                  **extra)
        except click.UsageError as exc:
            msg = " ".join(exc.format_message().split())
            click.echo(f"gainsched: error: command line: {msg}", err=True)
            return self._exit(2, standalone_mode)
        except click.ClickException as exc:
            click.echo(f"gainsched: error: {' '.join(exc.format_message().split())}", err=True)
            return self._exit(exc.exit_code, standalone_mode)
        except (click.Abort, KeyboardInterrupt):
            click.echo("gainsched: interrupted", err=True)
            return self._exit(130, standalone_mode)
        return self._exit(rv if isinstance(rv, int) else 0, standalone_mode)

    @staticmethod
    def _exit(code, standalone_mode):
        if standalone_mode:
            sys.exit(code)
        return code


class FiniteFloat(click.ParamType):
    """A finite float in ``[lo, hi]`` (``lo_open``: ``lo`` excluded); nan and inf rejected
    (click's FloatRange lets nan through)."""

    name = "number"

    def __init__(self, lo=None, hi=None, *, lo_open=False, unit=""):
        self.lo, self.hi, self.lo_open, self.unit = lo, hi, lo_open, unit

    def convert(self, value, param, ctx):
        try:
            x = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        low = self.lo is not None and (x <= self.lo if self.lo_open else x < self.lo)
        if not np.isfinite(x) or low or (self.hi is not None and x > self.hi):
            lo = "" if self.lo is None else f"{'(' if self.lo_open else '['}{self.lo:g}, "
            hi = "" if self.hi is None else f"{self.hi:g}]"
            rng = f" in {lo}{hi}" if lo and hi else f" >= {self.lo:g}" if lo else ""
            unit = f" {self.unit}" if self.unit else ""
            self.fail(f"{value!r}: must be a finite number{rng}{unit}", param, ctx)
        return x


class FilePath(click.Path):
    """click's Path that refuses an empty name (``-o ""`` would be the current folder)."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and not value.strip():
            self.fail("an empty name: give a file or folder", param, ctx)
        return super().convert(value, param, ctx)


class Jobs(click.ParamType):
    """``-j``: -1 (every core) or 1..MAX_JOBS workers (joblib reads -1000 as "all cores
    but 999", 0 as an error deep in a pool)."""

    name = "N"

    def convert(self, value, param, ctx):
        try:
            n = int(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not an integer", param, ctx)
        if n != -1 and not 1 <= n <= MAX_JOBS:
            self.fail(f"{value!r}: must be -1 (all cores) or a number of workers in "
                      f"[1, {MAX_JOBS}]", param, ctx)
        return n


class Name(click.ParamType):
    """A name or a path given as text (``--scenario``, ``--map``, ``--hidden``,
    ``--candidate``): refuses an empty one (``--scenario ""`` would read the current
    folder)."""

    name = "TEXT"

    def convert(self, value, param, ctx):
        if not isinstance(value, str) or not value.strip():
            self.fail("an empty name", param, ctx)
        return value


def _same_file(a, b) -> bool:
    """Whether two spellings name one file: ``a.csv`` and ``./a.csv``, a path through a
    symbolic link, or (both existing) a hard link; compared resolved, not as text."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()
    except (OSError, RuntimeError):  # a link loop: not a file to compare
        return False


def _distinct(what: str, paths) -> None:
    """Refuse one file given twice among ``paths`` (the argument ``what``), however spelled."""
    for i, b in enumerate(paths):
        for a in paths[:i]:
            if _same_file(a, b):
                same = "given twice" if str(a) == str(b) else f"is {a}"
                raise InputError("command line", what, f"{b} {same}: each file once")


def _check_fit_arguments(command: str, logs, candidates, exclude) -> None:
    """The checks diagnose and improve make of their arguments before any work: each log
    once and at least two (held-out scores), each --candidate and --exclude name once,
    and something left to fit."""
    from .analysis.diagnose import select_candidates

    _distinct("LOG", list(logs))
    if len(logs) < 2:
        raise InputError("command line", "LOG", f"{command} needs at least two flights (log "
                         "files) for held-out scores")
    for option, names in (("--candidate", candidates), ("--exclude", exclude)):
        if dup := next((n for i, n in enumerate(names) if n in names[:i]), None):
            raise InputError("command line", option, f"{dup!r} given twice: each name once")
    if not select_candidates(candidates or None, exclude):
        raise InputError("command line", "--exclude", f"leaves out every candidate "
                         f"({', '.join(exclude)}): nothing to fit")


def _quiet() -> bool:
    """Whether ``gainsched --quiet`` was given (read from the command line's root)."""
    ctx = click.get_current_context(silent=True)
    return ctx is not None and bool(ctx.find_root().params.get("quiet"))


def _progress(desc: str, total=None, unit: str = "it", *, show: bool = True):
    """The progress line of a command that can run for more than a few seconds, the one
    place every command makes it: tqdm on stderr, drawn only when stderr is a terminal
    (so never in a pipe, a file or a test's runner), never under ``gainsched --quiet``,
    nor when ``show`` is false. ``total`` None counts without an ETA; the bar's
    ``update`` is the ``progress`` callback the library functions take."""
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=desc, file=sys.stderr,
                disable=True if not show or _quiet() else None)


def _note(text: str, bar=None) -> None:
    """A line of chatter on stderr (what runs where, what was built on the way): not a
    result, not a warning, so ``--quiet`` drops it; written above a live ``bar``."""
    if _quiet():
        return
    if bar is not None:
        bar.write(text, file=sys.stderr)
    else:
        click.echo(text, err=True)


@contextlib.contextmanager
def _fit_progress(desc: str):
    """A progress line of diagnose's fits (:func:`_progress`): yields the
    ``progress(name)`` callback that counts a fit and names its candidate."""
    with _progress(desc, unit="fit") as bar:
        def fitted(name):
            bar.set_postfix_str(name, refresh=False)
            bar.update()

        yield fitted


def _inside(a, b) -> bool:
    """Whether path ``a`` is inside folder ``b`` (at any depth), however spelled: through
    ``..`` or a symbolic link (compared resolved, not as text)."""
    try:
        return Path(b).resolve() in Path(a).resolve().parents
    except (OSError, RuntimeError):  # a link loop: nothing to compare
        return False


def _outputs_apart(**outputs) -> None:
    """Refuse the outputs of one command (option: path, or None when not given) that
    overlap: two options naming one path, however spelled, or one output inside the
    other's folder (a file written into a report folder, a folder under a new config's
    name). Every command with several outputs calls it before any work."""
    given = [(o, p) for o, p in outputs.items() if p is not None]
    for i, (ob, b) in enumerate(given):
        for oa, a in given[:i]:
            if _same_file(a, b):
                same = "" if str(a) == str(b) else f" ({b})"
                raise InputError("command line", ob, f"{b} is {oa} {a}{same}: each output "
                                 "its own path")
            for (o1, p1), (o2, p2) in (((ob, b), (oa, a)), ((oa, a), (ob, b))):
                if _inside(p1, p2):
                    raise InputError("command line", o1, f"{p1} is inside {o2} {p2}: "
                                     "each output its own path, none inside another")


def _not_an_input(out, option: str, **inputs) -> None:
    """Refuse an output file ``out`` (of ``option``) that is one of the ``inputs`` (label:
    path, list of paths or None), however spelled: an input is never overwritten."""
    for label, paths in inputs.items():
        paths = [] if paths is None else paths if isinstance(paths, (list, tuple)) else [paths]
        for path in paths:
            if Path(path).exists() and _same_file(out, path):
                shown = "" if str(path) == str(out) else f" ({path})"
                raise InputError("command line", option, f"{out} is the input "
                                 f"{label}{shown}: give a new file (an input is never "
                                 "overwritten)")


CONFIG = click.argument("config", type=FilePath(dir_okay=False, path_type=Path))
#: seeds of the noise: non-negative integers (numpy refuses negative ones)
SEED = click.IntRange(0, MAX_SEED)


#: the fastest circle a command accepts, m/s (the config's grid.speeds bound)
MAX_SPEED = 100.0


@click.group(cls=_OneLineErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gainsched")
@click.option("-q", "--quiet", is_flag=True,
              help="No progress lines and no notes on stderr (results, warnings and errors "
              "stay). Progress shows only on a terminal anyway.")
def cli(quiet):
    """Gain-scheduling compiler for a tethered quadcopter flying great circles.

    Units: SI everywhere (m, s, N, rad/s) except tilts, which are given in degrees.
    """


@cli.command()
@CONFIG
@user_errors
def validate(config):
    """Check a config file (TOML) and print a summary of the vehicle and grid."""
    from .config import load_config
    from .schedule.nominal import min_taut_speed

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


def _speed_option(fn):
    return click.option(
        "--speed", type=FiniteFloat(-MAX_SPEED, MAX_SPEED, unit="m/s"), required=True,
        help="Tangential COG speed, m/s (negative: reversed; 0 < |speed| <= 100)."
    )(fn)


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
    from .config import load_config
    from .model.reduced import Model
    from .publish import check_out_file, write_atomic
    from .resources import config_path
    from .schedule.nominal import REASONS, circle_nominal, min_taut_speed

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


def _cluster_options(fn):
    """--jobs, --backend, --scheduler, --connect-timeout (``distributed.executor``)."""
    from .schedule.distributed import BACKENDS, DEFAULT_CONNECT_TIMEOUT

    options = [
        click.option("-j", "--jobs", type=Jobs(), default=-1, show_default=True,
                     help=f"Parallel workers, 1..{MAX_JOBS} (joblib; -1 = all cores, or every "
                     "Dask worker thread)."),
        click.option("--backend", type=click.Choice(BACKENDS), default="local",
                     show_default=True, help="Where the grid runs: local (= loky processes), "
                     "threading, sequential, or dask (needs --scheduler; docs/distributed.md)."),
        click.option("--scheduler", metavar="tcp://HOST:PORT",
                     help="Dask scheduler address (with --backend dask)."),
        click.option("--connect-timeout", type=FiniteFloat(0, 3600, lo_open=True, unit="s"),
                     default=DEFAULT_CONNECT_TIMEOUT,
                     show_default=True, metavar="SECONDS",
                     help="How long to wait for the Dask scheduler and a first worker."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def _build_names(cfg) -> list[str]:
    """The files ``build`` writes into its folder (firmware.outputs.output_files)."""
    from .firmware.codegen import CONTROL_FILES, RUNTIME_FILES

    return [f"{cfg.name}.h5", f"{cfg.name}_gains.h", f"{cfg.name}_control.h", *RUNTIME_FILES,
            *CONTROL_FILES]


def _nanmax(a) -> str:
    a = np.asarray(a)
    return f"{np.nanmax(a):.4f}" if np.any(np.isfinite(a)) else "n/a (no feasible circle)"


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
    from .config import load_config
    from .publish import check_out_dir, recover
    from .schedule.distributed import check_options

    check_options(backend, scheduler)
    cfg = load_config(config)
    check_out_dir(out_dir, names=_build_names(cfg))  # a bad -o fails now, not after the build
    recover(out_dir)  # finish or clean up after a killed earlier run
    _build_into(cfg, out_dir, jobs, backend, scheduler, connect_timeout)


def _build_into(cfg, out_dir: Path, jobs, backend="local", scheduler=None,
                connect_timeout=None, shown: Path | None = None) -> None:
    """What ``build`` does once its arguments are checked: choose or solve the grid, write
    the output set into ``out_dir`` and print the summary, naming ``shown`` for
    ``out_dir`` (``improve`` builds into its stage and names its output folder)."""
    import time

    from .publish import publish
    from .schedule.distributed import DEFAULT_CONNECT_TIMEOUT, executor

    def name(p):
        return p if shown is None else shown / Path(p).relative_to(out_dir)

    t0 = time.perf_counter()
    choice = None
    # the progress line first: the solver's modules take a second or two to import
    if cfg.grid.auto:  # the build chooses the breakpoints (docs/grid.md)
        bar = _progress(f"choose the grid of {cfg.name}", unit="circle")
    else:
        bar = _progress(f"build {cfg.name}", cfg.grid.speeds.size, "speed")
    with bar, executor(backend, scheduler, jobs, connect_timeout=DEFAULT_CONNECT_TIMEOUT
                       if connect_timeout is None else connect_timeout) as ex:
        from .schedule.grid import build_grid
        from .schedule.refine import refine_grid

        if backend == "dask":
            _note(f"build {cfg.name} on {ex.description}", bar)
        if cfg.grid.auto:
            choice = refine_grid(cfg, n_jobs=ex.n_jobs, progress=bar.update,
                                 backend=ex.backend)
            cfg, grid = choice.config, choice.grid
        else:
            grid = build_grid(cfg, n_jobs=ex.n_jobs, progress=bar.update, backend=ex.backend)
    from .firmware.outputs import certificate_lines, output_set
    from .schedule.grid import bound_price
    n_v = cfg.grid.speeds.size
    n_mid = max(n_v - 1, 1) if cfg.firmware.format == "compact" else 0
    with _progress("certify compact table", n_mid, "speed", show=n_mid > 0) as bar:
        outputs = output_set(cfg, grid, out_dir, progress=bar.update,
                             grid_auto=None if choice is None else choice.record())
    out, *c_paths = publish(out_dir, outputs.files)
    n_pts = grid.reasons.size
    feas = np.count_nonzero(grid.reasons == 0)
    click.echo(
        f"{name(out)}: {n_pts} points ({cfg.grid.tilts.size} tilts x {n_v} speeds x "
        f"{cfg.grid.azimuth_samples} azimuths), {100 * feas / n_pts:.1f}% feasible, "
        f"worst closed-loop spectral radius {_nanmax(grid.spectral_radius)}, "
        f"{time.perf_counter() - t0:.1f} s, {out.stat().st_size / 1024:.0f} KiB"
    )
    if choice is not None:
        for line in choice.lines():
            click.echo("  " + line)
    click.echo("  C: " + ", ".join(str(name(p)) for p in c_paths))
    click.echo(f"  firmware table: {cfg.firmware.format}, {outputs.form.nbytes():,} bytes of data"
               + (f" (dense: {outputs.form.base.nbytes():,})" if outputs.certificate else ""))
    if outputs.certificate is not None:
        for line in certificate_lines(cfg, outputs.certificate):
            click.echo("  " + line)
    if cfg.control.max_time_constant_s is not None:
        click.echo("  " + bound_price(cfg.control.max_time_constant_s, grid))


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
    import time

    from .config import load_config
    from .publish import check_out_dir, staged
    from .schedule.distributed import check_options, executor
    from .schedule.sweep import format_rows, make_sweep, parse_sigma, parse_vary, run_sweep

    check_options(backend, scheduler)
    base = load_config(config)
    plan = make_sweep(base, [parse_vary(v) for v in vary], monte_carlo=monte_carlo, seed=seed,
                      sigma=[parse_sigma(s) for s in sigma])
    # once every option passed: a refused sweep creates nothing
    check_out_dir(out_dir, names=["sweep.csv", "sweep.json"])
    t0 = time.perf_counter()
    # a grid the build chooses counts circles, of a number known only at the end
    total = None if base.grid.auto else len(plan.variants) * base.grid.speeds.size
    with executor(backend, scheduler, jobs, connect_timeout=connect_timeout) as ex:
        if backend == "dask":
            _note(f"sweep {base.name} on {ex.description}")
        with _progress(f"sweep {base.name} ({len(plan.variants)} variants)", total,
                       "circle" if total is None else "speed") as bar:
            with staged(out_dir) as stage:  # every variant appears at once, or none
                rows = run_sweep(plan, stage, n_jobs=ex.n_jobs, backend=ex.backend,
                                 progress=bar.update)
    for line in format_rows(plan, rows):
        click.echo(line)
    click.echo(f"{out_dir}: {len(rows)} variants ({len(rows)} tables + configs), sweep.csv, "
               f"sweep.json; {time.perf_counter() - t0:.1f} s")


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
    from .firmware.codegen import flash_summary
    from .publish import check_out_dir
    from .schedule.nominal import REASONS
    from .schedule.refine import grid_auto_lines
    from .schedule.tables import load_table
    from .schedule.viewer import mode_lines, table_summary

    if out_dir is not None:
        check_out_dir(out_dir, "--out", names=_ENVELOPE)
    t = load_table(table)
    if as_json:
        from .firmware.runtime import c_identifier

        # c_prefix: the prefix of the C symbols export-c writes (paper_table, PAPER_N_STATE)
        summary = {**table_summary(t, source=str(table)), "c_prefix": c_identifier(t.name)}
        click.echo(json.dumps(summary, indent=2, sort_keys=True))
        if out_dir is not None:
            _write_envelope(t, table, out_dir, quiet=True)
        return
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
    for line in flash_summary(t):
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
        _write_envelope(t, table, out_dir)


_ENVELOPE = ["envelope.png", "envelope.json"]


def _write_envelope(t, table, out_dir, quiet=False) -> None:
    """envelope.png and envelope.json of the loaded table ``t`` into ``out_dir`` (one set)."""
    from .publish import publish
    from .schedule.envelope import envelope_from_table, envelope_png

    env = envelope_from_table(t)
    summary = {"table": str(table), "config": t.name, **env.to_json()}
    paths = publish(out_dir, {
        "envelope.png": envelope_png(env),
        "envelope.json": (json.dumps(summary, indent=2, sort_keys=True) + "\n").encode(),
    }, where="--out")
    if not quiet:
        counts = ", ".join(f"{n} {c}" for c, n in env.counts().items())
        click.echo(f"  envelope: {counts} -> {', '.join(str(p) for p in paths)}")


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
    from .publish import check_out_dir, publish
    from .schedule.tables import load_table
    from .schedule.viewer import plot_count, schedule_plots

    check_out_dir(out_dir, "--out", names=["plots.json"])
    t = load_table(table)
    midpoints = None
    if with_check:
        from .firmware.check import midpoint_check

        with _progress(f"check {t.name}", max(t.speed.size - 1, 0), "speed") as bar:
            res = midpoint_check(t, progress=bar.update)
        midpoints = (res.speed, res.tilt, res.rel_err)
    with _progress(f"plot {t.name}", plot_count(t, midpoints is not None), "file") as bar:
        files = schedule_plots(t, midpoints, source=str(table), progress=bar.update)
    paths = publish(out_dir, files, where="--out")
    if as_json:
        click.echo(files["plots.json"].decode(), nl=False)
    else:
        click.echo(f"{table}: {len(paths)} files -> {out_dir}/ "
                   f"({', '.join(sorted(p.name for p in paths))})")


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
    from .firmware.codegen import CONTROL_FILES, RUNTIME_FILES, c_files, flash_summary
    from .firmware.controller import controller_params, outputs_from_config
    from .firmware.outputs import certificate_lines, firmware_form, table_config
    from .publish import check_out_dir, publish
    from .schedule.tables import load_table

    out_dir = Path(table).parent if out_dir is None else out_dir
    t = load_table(table)
    cfg = table_config(t, fmt)
    outputs = {k: v for k, v in (("firmware.motor_order", motor_order),
                                 ("firmware.command", command),
                                 ("firmware.thr_mdl_fac", thr_mdl_fac),
                                 ("firmware.thrust_max_N", thrust_max_n))
               if v not in (None, "config")}
    if outputs and cfg is None:
        raise InputError(str(table), "config_text", "the controller's outputs need the "
                         "table's config, which this installation cannot load")
    if outputs:
        cfg = cfg.with_values(outputs, source=f"{table} (export-c options)")
    fmt = "dense" if cfg is None else cfg.firmware.format
    # a bad -o fails before the certification
    check_out_dir(out_dir, names=[*RUNTIME_FILES, *CONTROL_FILES])
    n_mid = max(t.speed.size - 1, 1) if fmt == "compact" else 0
    with _progress("certify compact table", n_mid, "speed", show=n_mid > 0) as bar:
        form, cert = firmware_form(cfg, t, progress=bar.update)
    params = controller_params(t, **(outputs_from_config(cfg) if outputs else {}))
    paths = publish(out_dir, c_files(form, params))
    for p in paths:
        click.echo(f"wrote {p}")
    click.echo(f"  {form.name}: {fmt}, CRC-32 0x{form.crc32():08x}, config "
               f"sha256 {t.config_sha256[:12]}")
    for line in flash_summary(form, compile_code=not no_code_size):
        click.echo(f"  {line}")
    if cert is not None:
        for line in certificate_lines(cfg, cert):
            click.echo(f"  {line}")


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

    from .firmware.check import midpoint_check
    from .schedule.refine import grid_auto_lines
    from .schedule.tables import load_table

    t = load_table(table)
    n_mid = max(t.speed.size - 1, 1)
    if speed_stride > n_mid:  # a stride past the last midpoint checks only the first
        raise InputError("command line", "--speed-stride", f"{speed_stride}: {table} has "
                         f"{n_mid} speed midpoint{'s' if n_mid > 1 else ''}: give 1..{n_mid}")
    t0 = time.perf_counter()
    lookup = None
    from .firmware.outputs import table_config

    cfg = table_config(t, "config")
    if max_error is None:
        max_error = 2.0 if cfg is None else 100 * cfg.grid.max_interpolation_error
    if azimuth_error is None and cfg is not None and cfg.firmware.format == "compact":
        azimuth_error = 100 * cfg.firmware.azimuth_error
    if azimuth_error is not None:
        from .firmware.compact import CompactInterpolator, compact_data
        from .firmware.runtime import runtime_data

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


_RUNTIME = click.option(
    "--runtime", type=click.Choice(["auto", "c", "python"]), default="auto", show_default=True,
    help="Where the firmware's gains, feed-forward and (--controller firmware) whole "
    "control step come from: compiled C (c: the runtime and controller, in the loop), "
    "their Python reference (python), or C when a C compiler is found (auto).")


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
    import dataclasses

    from .config import load_config
    from .publish import check_out_dir, staged
    from .schedule.tables import load_table
    from .sim.loop import check_flight_steps, load_scenario, runtime_scheduler, write_run
    from .sim.loop import simulate as run

    cfg = load_config(config)
    plant = load_config(plant_path) if plant_path else None
    table = load_table(table_path)
    scn = load_scenario(scenario)
    if speed is not None:
        scn = dataclasses.replace(scn, speed=speed)
    n = check_flight_steps(scn.duration, cfg.control.rate_hz, scenario, "duration")
    check_out_dir(out_dir, names=["log.csv", "log.h5", "metrics.json"])
    if not table.built_from(cfg):  # once every input passed
        click.echo(f"gainsched: warning: {table_path} was built from another config", err=True)
    with _progress(f"simulate {scn.name}", n, "step") as bar:
        res = run(cfg, runtime_scheduler(table, runtime), scn, plant, progress=bar.update,
                  controller=controller)
    with staged(out_dir) as stage:
        m = write_run(res, stage)
    click.echo(
        f"{out_dir}: {scn.name} {m['duration_s']:.2f} s, "
        f"RMS out-of-plane {m['rms_out_of_plane_m']:.4f} m, "
        f"RMS along-track {m['rms_along_track_m']:.3f} m (lap slips {m['lap_slips']}), "
        f"RMS speed error {m['rms_speed_error_mps']:.3f} m/s, "
        f"max tension {m['max_tension_N']:.1f} N, "
        f"saturation {100 * m['saturation_fraction']:.1f}%, slack events {m['slack_events']}"
    )
    for line in _left_the_table(m, table_path):
        click.echo(line)


def _left_the_table(m: dict, table_path) -> list[str]:
    """What a flight's metrics say about leaving the table (docs/runtime.md, the policy
    the simulator flies): time on gains clamped to the table's speed range, on held gains,
    or with the nominal's tension below ``feasibility.min_tension``; none when it stayed
    inside."""
    out = []
    if m["clamped_speed_s"] > 0:
        out.append(f"  left the table: {m['clamped_speed_s']:.2f} s at speeds outside "
                   f"{table_path}'s range, flown on the gains of its nearest speed "
                   "(clamped_speed_s)")
    if m["held_gains_s"] > 0:
        out.append(f"  left the table: {m['held_gains_s']:.2f} s on held gains (no usable "
                   "gains at the lookup; held_gains_s)")
    if m["below_tension_margin_s"] > 0:
        out.append(f"  left the table: {m['below_tension_margin_s']:.2f} s with the nominal's "
                   f"tension below min_tension (lowest {m['min_nominal_tension_N']:.2f} N; "
                   "below_tension_margin_s)")
    return out


_REPO = Path(__file__).resolve().parents[1]


def _table_of(cfg):
    """``(table, path)`` of a config when no table is given: the checkout's
    ``tables/NAME.h5`` when it was built from this config, else the cached table
    (:mod:`gainsched.schedule.cached`), built there on first use."""
    from .schedule.cached import cached_table, cached_table_path
    from .schedule.tables import load_table

    local = _REPO / "tables" / f"{cfg.name}.h5"
    if local.is_file():
        table = load_table(local)
        if table.built_from(cfg):
            return table, local
    path = cached_table_path(cfg)
    total = None if cfg.grid.auto else cfg.grid.speeds.size
    with _progress(f"build {cfg.name} (first use, kept in the cache)", total,
                   "speed" if total else "circle", show=not path.is_file()) as bar:
        table, built = cached_table(cfg, progress=bar.update)
    if built:
        _note(f"built {path}")
    return table, path


@cli.command()
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Output folder (report.md, report.json, one folder per "
              "experiment).")
@click.option("--config", "config", type=FilePath(dir_okay=False, path_type=Path),
              default="paper", show_default="paper, the shipped configs/paper.toml",
              help="Design config (the paper vehicle).")
@click.option("--tables", "table_path", type=FilePath(dir_okay=False, path_type=Path),
              help="Gain table built from the config [default: the checkout's "
              "tables/NAME.h5 when it is the config's, else the config's table from the cache, "
              "built there on first use].")
@click.option("--plant", "plant_path", type=FilePath(dir_okay=False, path_type=Path),
              help="Truth config for the plant (default: the design config).")
@click.option("--quick", is_flag=True, help="Short smoke flights (for tests; seconds).")
@_RUNTIME
@user_errors
def paper(out_dir, config, table_path, plant_path, quick, runtime):
    """Fly the paper's experiments (Sec. V.B, Figs. 3-4) in simulation and write a report:
    paper figure, paper value, simulated value."""
    from .config import load_config
    from .publish import check_out_dir, staged
    from .schedule.tables import load_table
    from .sim.loop import runtime_scheduler
    from .sim.paper import experiments, run_paper

    cfg = load_config(config)
    plant = load_config(plant_path) if plant_path else None
    # before a first use builds the table (half a minute)
    check_out_dir(out_dir, names=["report.md", "report.json"])
    if table_path is None:
        table, table_path = _table_of(cfg)
    else:
        table = load_table(table_path)
    if not table.built_from(cfg):
        click.echo(f"gainsched: warning: {table_path} was built from another config", err=True)
    n = len(experiments(quick=quick))
    meta = {"table": str(table_path), "table_config_sha256": table.config_sha256}
    with _progress("paper", n, "flight") as bar, \
            staged(out_dir) as stage:
        rep = run_paper(cfg, runtime_scheduler(table, runtime), stage, quick=quick, plant=plant,
                        progress=bar.update, meta=meta, table=table)
    for r in rep.rows:
        mark = {True: "ok ", False: "NO ", None: "-  "}[r.agrees]
        click.echo(f"{mark} {r.figure:16s} {r.quantity}: paper {r.paper}; sim {r.simulated_text}")
    click.echo(f"wrote {out_dir / 'report.md'} and {out_dir / 'report.json'}")


_LOGS = click.argument("logs", nargs=-1, required=True,
                       type=FilePath(exists=True, path_type=Path))
_MAP = click.option("--map", "map_path", type=Name(), help="Channel map of PX4 ULogs and "
                    "ROS 2 bags among the logs: a TOML file or a shipped map (px4, "
                    "px4_legacy, ros2); default for a ULog: px4 (docs/flight-log.md).")


_TRUST = click.option("--trust", "trust", multiple=True, type=click.Choice(LOG_CHECKS),
                      help="Skip a consistency check of the logs where you know the log is "
                      "right (repeatable; docs/flight-log.md, \"Channels that contradict "
                      "each other\").")


def _channel_map(map_path):
    """The validated channel map of --map, or None (checked before any work)."""
    if map_path is None:
        return None
    from .analysis.channelmap import load_channel_map

    return load_channel_map(map_path)


def _load_for_compare(config):
    from .config import load_config

    return load_config(config)


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
@user_errors
def compare(config, logs, out_dir, before_path, no_paper, map_path, trust):
    """Compare the model of CONFIG with flight LOGS (CSV, HDF5, PX4 ULog or ROS 2 bag
    through a channel map): residual per axis
    (path frame m/s^2, body rad/s^2, tether stretch m), RMS, bias, fit %, whiteness,
    input correlation, where it fails; the paper's Sec. V.C analyses."""
    from .analysis.compare import compare as run
    from .analysis.paperfits import paper_fits
    from .analysis.reports import (
        before_after_lines,
        compare_lines,
        write_before_after,
        write_compare,
    )
    from .publish import check_out_dir, staged
    from .resources import config_path

    _distinct("LOG", list(logs))
    if before_path is not None and _same_file(config_path(before_path), config_path(config)):
        shown = "" if str(before_path) == str(config) else f" ({config})"
        raise InputError("command line", "--before", f"{before_path} is CONFIG{shown}: give "
                         "the earlier config")
    cfg = _load_for_compare(config)
    before_cfg = None if before_path is None else _load_for_compare(before_path)
    cmap = _channel_map(map_path)
    if out_dir is not None:
        check_out_dir(out_dir, names=["compare.json", "compare.md"])
    # steps: each log read and the statistics, per config; the paper's fits
    steps = (len(logs) + 1) * (1 if before_path is None else 2) + (0 if no_paper else 1)
    with _progress(f"compare {cfg.name}", steps, "step") as bar:
        cmp = run(cfg, logs, channel_map=cmap, trust=trust, progress=bar.update)
        paper = None if no_paper else paper_fits(cfg, cmp.measured)
        bar.update(0 if no_paper else 1)
        before = None
        if before_path is not None:
            before = run(before_cfg, logs, channel_map=cmap, trust=trust,
                         progress=bar.update)
    for line in compare_lines(cmp, paper):
        click.echo(line)
    if before is not None:
        click.echo("")
        for line in before_after_lines(before, cmp):
            click.echo(line)
    if out_dir is not None:
        with staged(out_dir) as stage:  # the report appears whole, or not at all
            paths = write_compare(cmp, stage, paper)
            if before is not None:
                paths += write_before_after(before, cmp, stage)
        click.echo(f"wrote {len(paths)} files to {out_dir} ({paths[1].name})")


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
@click.option("--apply", "do_apply", is_flag=True,
              help="Write the accepted effect and its fitted parameters to -o NEWCONFIG.")
@click.option("-o", "--out", "new_config", type=FilePath(dir_okay=False, path_type=Path),
              help="New config file for --apply.")
@click.option("--report", "report_dir", type=FilePath(file_okay=False, path_type=Path),
              help="Report folder: diagnose.json/.md, ranking.png, before/after.")
@_MAP
@_TRUST
@user_errors
def diagnose(config, logs, candidates, exclude, joint, do_apply, new_config, report_dir,
             map_path, trust):
    """Which physical effect is missing: fit every candidate effect the model lacks to
    the residual on LOGS, score on held-out flights (leave one flight out), rank, check
    identifiability; --apply -o NEWCONFIG writes the accepted one (CIs as comments)."""
    from .analysis.compare import compare as run
    from .analysis.diagnose import apply_candidate
    from .analysis.diagnose import diagnose as run_diagnose
    from .analysis.reports import (
        before_after_lines,
        compare_lines,
        diagnose_lines,
        write_before_after,
        write_compare,
        write_diagnose,
    )
    from .config import config_from_text
    from .publish import check_out_dir, check_out_file, staged, write_atomic

    if do_apply and new_config is None:
        raise InputError("command line", "--apply", "needs -o NEWCONFIG")
    if new_config is not None and not do_apply:
        raise InputError("command line", "-o", "is the new config of --apply: give --apply "
                         "too (or --report DIR for a report)")
    _check_fit_arguments("diagnose", logs, candidates, exclude)
    _outputs_apart(**{"-o": new_config, "--report": report_dir})
    if new_config is not None:
        from .resources import config_path

        _not_an_input(new_config, "-o", CONFIG=config_path(config), LOG=list(logs),
                      **{"--map": map_path})
    cfg = _load_for_compare(config)
    cmap = _channel_map(map_path)
    if new_config is not None:
        check_out_file(new_config, "-o")
    if report_dir is not None:
        check_out_dir(report_dir, "--report", names=["diagnose.json", "diagnose.md"])
    base = run(cfg, logs, channel_map=cmap, trust=trust)
    for line in compare_lines(base):
        click.echo(line)
    click.echo("")

    with _fit_progress("diagnose") as fitted:
        d = run_diagnose(cfg, logs, candidates=candidates or None, comparison=base,
                         joint=joint, exclude=exclude, progress=fitted)
    for line in diagnose_lines(d):
        click.echo(line)
    after = None
    if do_apply:
        if d.accepted is None:
            click.echo("nothing applied: no candidate cleared the thresholds")
        else:
            from .schedule.grid import check_effect_symmetries

            text = apply_candidate(cfg, d.accepted)
            write_atomic(new_config, text.encode(), where="-o")
            new_cfg = config_from_text(text, str(new_config))
            try:  # the build's own check: a wind, flight time, unequal motors
                check_effect_symmetries(new_cfg)
            except InputError as held:
                click.echo(f"wrote {new_config} ({d.accepted.name}); no table can hold "
                           f"{held.where}: {held.message}")
            else:
                click.echo(f"wrote {new_config} ({d.accepted.name}); rebuild the tables with "
                           f"`gainsched build {new_config}`")
            after = run(new_cfg, logs, channel_map=cmap, trust=trust)
            click.echo("")
            for line in before_after_lines(base, after):
                click.echo(line)
    if report_dir is not None:
        with staged(report_dir, where="--report") as stage:
            paths = write_diagnose(d, stage) + write_compare(base, stage, prefix="before")
            if after is not None:
                paths += write_compare(after, stage, prefix="after")
                paths += write_before_after(base, after, stage, d)
        click.echo(f"wrote {len(paths)} files to {report_dir}")


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
              help="The old table, built from CONFIG, for the flights [default: the "
              "checkout's tables/NAME.h5 when it is CONFIG's, else CONFIG's table from the "
              "cache, built there on first use].")
@click.option("--duration", type=FiniteFloat(1.0, MAX_FLIGHT_S, unit="s"), default=3.0,
              show_default=True, help=f"Seconds per standard flight (1..{MAX_FLIGHT_S:g}).")
@click.option("-j", "--jobs", type=Jobs(), default=-1, show_default=True,
              help=f"Parallel workers of the build, 1..{MAX_JOBS} (-1 = all cores).")
@_MAP
@_TRUST
@user_errors
def improve(config, logs, out_dir, rounds, exclude, no_build, table_path, duration, jobs,
            map_path, trust):
    """The model loop in one command: compare CONFIG with LOGS, diagnose and apply in
    rounds until no effect is missing, rebuild the tables from the improved config (its
    name kept: the same C symbols), fly the standard flights on the improved model with
    the old and the new table, and write the report: the error round by round and the
    tracking old against new. Each step is what compare, diagnose --apply, build and
    simulate do."""

    from .analysis.improve import improve as run
    from .analysis.improve import write_improve
    from .config import config_from_text
    from .publish import check_out_dir, staged

    _check_fit_arguments("improve", logs, (), exclude)
    if no_build and table_path is not None:
        raise InputError("command line", "--tables", "is the old table of the flights, and "
                         "--no-build flies none: give one of them")
    cfg = _load_for_compare(config)
    cmap = _channel_map(map_path)
    check_out_dir(out_dir, names=[f"{cfg.name}.toml", "tables", "report"])
    # the improved config and the rebuilt table replace files of these names in DIR
    _not_an_input(out_dir / f"{cfg.name}.toml", "-o", CONFIG=config, LOG=list(logs))
    _not_an_input(out_dir / "tables" / f"{cfg.name}.h5", "-o", **{"--tables": table_path})
    old_table = None
    if table_path is not None:
        from .schedule.tables import load_table

        old_table = load_table(table_path)
        if not old_table.built_from(cfg):
            raise InputError(table_path, "", f"was built from another config than {config}: "
                             "the old table of the flights must be CONFIG's")
    with _fit_progress("improve") as fitted:
        imp = run(cfg, logs, rounds=rounds, exclude=exclude, channel_map=cmap, trust=trust,
                  progress=fitted)
    for k, r in enumerate(imp.rounds):
        verdict = "" if r.diagnosis is None else f": {r.diagnosis.verdict[:160]}"
        click.echo(f"round {k}: normalised RMS {r.rms:.3g}{verdict}")
    new = imp.config
    flights = None
    with staged(out_dir) as stage:
        path = stage / f"{new.name}.toml"
        path.write_text(new.text)
        report = stage / "report"
        report.mkdir()
        refusal = None
        if not no_build:
            from .schedule.grid import check_effect_symmetries

            try:
                check_effect_symmetries(config_from_text(new.text, str(path)))
            except InputError as held:
                refusal = f"no table can hold {held.where}: {held.message}"
            else:  # what build does; its lines name the output folder, not the stage
                (stage / "tables").mkdir()
                _build_into(config_from_text(new.text, str(out_dir / path.name)),
                            stage / "tables", jobs, shown=out_dir / "tables")
                # the standard flights on the improved model, old table and new (simulate's)
                from .schedule.tables import load_table
                from .sim.oldnew import N_FLIGHTS, fly_old_new

                if old_table is None:  # CONFIG's, as paper finds it
                    old_table, table_path = _table_of(cfg)
                new_table = load_table(stage / "tables" / f"{new.name}.h5")
                meta = {"old_table": str(table_path),
                        "old_table_config_sha256": old_table.config_sha256,
                        "new_table": str(out_dir / "tables" / f"{new.name}.h5"),
                        "new_table_config_sha256": new_table.config_sha256}
                with _progress("fly old and new tables", 2 * N_FLIGHTS, "flight") as bar:
                    flights = fly_old_new(cfg, old_table, new, new_table, duration=duration,
                                          progress=bar.update, meta=meta)
        write_improve(imp, report, flights, not_flown=(
            "--no-build" if no_build else refusal and f"the tables were not rebuilt: {refusal}"))
    if flights is not None:
        for line in flights.lines():
            click.echo(line)
    applied = ", ".join(imp.applied) or "nothing"
    click.echo(f"{out_dir}: {new.name}.toml ({applied} applied), report/"
               + (f"; tables not rebuilt: {refusal}" if refusal else
                  "" if no_build else ", tables/"))


@cli.command()
@click.argument("log", type=FilePath(exists=True, path_type=Path))
@click.option("-o", "--out", "out_path", type=FilePath(dir_okay=False, path_type=Path),
              required=True, help="The converted log: OUT.csv or OUT.h5.")
@_MAP
@click.option("--config", "config_path", type=FilePath(dir_okay=False, path_type=Path),
              help="A config whose vehicle.thrust_max is a motor's thrust at full command "
                   "(normalised or PWM commands, when the map gives no thrust_max_N); "
                   "its vehicle is what the thrust and the load cell are checked against.")
@_TRUST
@user_errors
def convert(log, out_path, map_path, config_path, trust):
    """Convert a PX4 ULog or a ROS 2 bag to the project's flight-log format
    (docs/flight-log.md) for inspection, and say what was mapped to what."""
    from .analysis.logs import convert_log
    from .config import load_config
    from .publish import check_out_file
    from .resources import config_path as shipped

    _not_an_input(out_path, "-o", LOG=log, **{"--config": config_path and
                                               shipped(config_path), "--map": map_path})
    cmap = _channel_map(map_path)
    cfg = load_config(config_path) if config_path else None
    thrust_max = cfg.vehicle.thrust_max if cfg is not None else None
    check_out_file(out_path, "-o")
    report, segs = convert_log(log, out_path, channel_map=cmap, thrust_max=thrust_max,
                               config=cfg, trust=trust)
    for line in report:
        click.echo("  " + line)
    n = sum(len(s) for s in segs)
    span = (f"{segs[0].duration:.3g} s" if len(segs) == 1 else
            f"{len(segs)} segments (split at gaps)")
    meta = segs[0].meta
    alpha, gamma = float(meta["alpha_c_deg"]), float(meta["gamma_c_deg"])
    click.echo(f"wrote {out_path}: {n} samples, {span}, alpha_c {alpha:.2f} deg, "
               f"gamma_c {gamma:.2f} deg")


class _HiddenOption(click.Option):
    """``--hidden``: its help lists the hidden effects of
    :data:`gainsched.sim.campaign.HIDDEN`, read when help is asked for (the simulator is
    not imported to start a command)."""

    def get_help_record(self, ctx):
        from .sim.campaign import HIDDEN

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
@click.option("--format", "fmt", type=click.Choice(["csv", "h5"]), default="csv",
              show_default=True)
@click.option("--seed", type=SEED, default=1, show_default=True,
              help="Seed of the sensor noise (a non-negative integer).")
@click.option("-o", "--out", "out_dir", type=FilePath(file_okay=False, path_type=Path),
              required=True, help="Output folder for the flight logs.")
@user_errors
def campaign(config, table_path, hidden, duration, no_load_cell, fmt, seed, out_dir):
    """Fly a synthetic test campaign (speeds 3-15 m/s, tilts 0/20/40 deg, a speed-up, a
    braking; motion-capture noise) on a plant with a HIDDEN effect and write the logs."""
    from .publish import check_out_dir, staged
    from .schedule.tables import load_table
    from .sim.campaign import HIDDEN, default_flights, outside_table, write_campaign
    from .sim.campaign import campaign as fly
    from .sim.loop import check_flight_steps, table_scheduler

    if hidden not in HIDDEN:
        known = ", ".join(HIDDEN)
        raise InputError("command line", "--hidden",
                         f"unknown hidden effect {hidden!r} (known: {known})")
    cfg = _load_for_compare(config)
    check_flight_steps(duration, cfg.control.rate_hz, "command line", "--duration")
    table = load_table(table_path)
    check_out_dir(out_dir)
    if not table.built_from(cfg):  # as simulate and paper say it, before the work
        click.echo(f"gainsched: warning: {table_path} was built from another config", err=True)
    flights = default_flights(duration, seed)
    if outside := outside_table(flights, table):
        click.echo(f"gainsched: warning: {table_path} covers speeds "
                   f"{table.speed.min():.3g}-{table.speed.max():.3g} m/s, tilts up to "
                   f"{np.rad2deg(table.tilt.max()):.0f} deg: {', '.join(outside)} fly outside "
                   "it, on the gains of its nearest circle", err=True)
    with _progress(f"campaign {hidden}", len(flights), "flight") as bar:
        logs = fly(cfg, table_scheduler(table), hidden, scenarios=flights, duration=duration,
                   load_cell=not no_load_cell, seed=seed, progress=bar.update)
    with staged(out_dir) as stage:
        paths = write_campaign(stage, logs, fmt)
    click.echo(f"{out_dir}: {len(paths)} flights, hidden effect: {HIDDEN[hidden].doc}")


def main():
    cli.main(prog_name="gainsched")


if __name__ == "__main__":
    main()
