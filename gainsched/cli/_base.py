"""The command group and what every command shares: one-line errors, the parameter
types that check values where they come in, progress and notes on stderr, outputs kept
apart from inputs and from each other."""

from __future__ import annotations

import functools
import os
import sys
import warnings
from pathlib import Path

import click
import numpy as np

from .. import __version__
from ..constants import MAX_JOBS, MAX_SEED
from ..errors import GainschedWarning, InputError
from ..native import shm
from ..studies._report import Reporter


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


def _check_fit_arguments(command: str, logs, candidates, exclude, day: bool = False) -> None:
    """The checks diagnose and improve make of their arguments before any work: each log
    once and at least two (held-out scores; one day of several flights will do, --day),
    each --candidate and --exclude name once, and something left to fit."""
    from ..analysis.diagnose import select_candidates

    _distinct("LOG", list(logs))
    if len(logs) < 2 and not day:
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


class _Terminal(Reporter):
    """The studies' reporter of the command line (:class:`gainsched.studies.Reporter`):
    its progress lines (:func:`_progress`), its notes (:func:`_note`) and the result's
    lines on stdout as they come."""

    def bar(self, desc, total=None, unit="it", *, show=True):
        return _progress(desc, total, unit, show=show)

    def note(self, text, bar=None):
        _note(text, bar)

    def line(self, text):
        click.echo(text)


#: what a command gives the study it calls to show its progress
TERMINAL = _Terminal()


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
    # every command, before its work: what builds killed with their whole process group
    # left in /dev/shm goes, also when this run makes no worker pool (one job, a cached
    # table, another command); gainsched.native.shm
    shm.sweep()


def _speed_option(fn):
    return click.option(
        "--speed", type=FiniteFloat(-MAX_SPEED, MAX_SPEED, unit="m/s"), required=True,
        help="Tangential COG speed, m/s (negative: reversed; 0 < |speed| <= 100)."
    )(fn)


def _cluster_options(fn):
    """--jobs, --backend, --scheduler, --connect-timeout (``distributed.executor``)."""
    from ..schedule.distributed import BACKENDS, DEFAULT_CONNECT_TIMEOUT

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


_RUNTIME = click.option(
    "--runtime", type=click.Choice(["auto", "c", "python"]), default="auto", show_default=True,
    help="Where the firmware's gains, feed-forward and (--controller firmware) whole "
    "control step come from: compiled C (c: the runtime and controller, in the loop), "
    "their Python reference (python), or C when a C compiler is found (auto).")


def _load_for_compare(config):
    from ..config import load_config

    return load_config(config)
