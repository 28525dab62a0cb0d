"""A config's gain table and C files, built and published together: ``gainsched build``."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Config
from ._report import SILENT, Reporter, config_of

__all__ = ["Build", "build", "build_into", "output_names"]  # build_into: for the studies


@dataclass(frozen=True, eq=False)
class Build:
    """What :func:`build` made and published.

    Attributes
    ----------
    config : Config
        The config as built: with the breakpoints the build chose when its grid is
        automatic (``grid.auto``), else the one given.
    grid : GridResult
        The solved grid (:func:`gainsched.build_grid`).
    choice : GridChoice or None
        How the build chose the grid (:func:`gainsched.refine_grid`); None for a grid
        the config lists.
    outputs : OutputSet
        The checked files (:func:`gainsched.firmware.outputs.output_set`): the table,
        its C header in the config's format (and the compact table's certificate), the
        runtime and the controller.
    table : Path
        The published table, ``OUT_DIR/NAME.h5``.
    c_files : tuple of Path
        The published C files, in the order of ``outputs.files``.
    seconds : float
        Wall time of the build and its publication, s.
    """

    config: Config
    grid: object
    choice: object
    outputs: object
    table: Path
    c_files: tuple
    seconds: float

    def lines(self, shown: Path | None = None) -> list[str]:
        """What ``gainsched build`` prints: the table's size, feasibility and worst
        spectral radius, the chosen grid, the C files, the firmware table's bytes and
        certificate, and the price of a time-constant bound; the files named under
        ``shown`` instead of their folder when given (``improve`` builds into its stage
        and names its output folder)."""
        from ..firmware.outputs import certificate_lines
        from ..schedule.bounds import bound_price

        cfg, grid, outputs = self.config, self.grid, self.outputs

        def name(p: Path) -> Path:
            return p if shown is None else shown / p.name

        n_pts, n_v = grid.reasons.size, cfg.grid.speeds.size
        feas = np.count_nonzero(grid.reasons == 0)
        out = [f"{name(self.table)}: {n_pts} points ({cfg.grid.tilts.size} tilts x {n_v} "
               f"speeds x {cfg.grid.azimuth_samples} azimuths), {100 * feas / n_pts:.1f}% "
               f"feasible, worst closed-loop spectral radius {_nanmax(grid.spectral_radius)}, "
               f"{self.seconds:.1f} s, {len(outputs.files[self.table.name]) / 1024:.0f} KiB"]
        if self.choice is not None:
            out += ["  " + line for line in self.choice.lines()]
        out.append("  C: " + ", ".join(str(name(p)) for p in self.c_files))
        out.append(f"  firmware table: {cfg.firmware.format}, {outputs.form.nbytes():,} bytes "
                   "of data" + (f" (dense: {outputs.form.base.nbytes():,})"
                                if outputs.certificate else ""))
        if outputs.certificate is not None:
            out += ["  " + line for line in certificate_lines(cfg, outputs.certificate)]
        if cfg.control.max_time_constant_s is not None:
            out.append("  " + bound_price(cfg.control.max_time_constant_s, grid))
        return out


def output_names(config: Config) -> list[str]:
    """The files :func:`build` writes into its folder: ``NAME.h5``, ``NAME_gains.h``,
    ``NAME_control.h``, the runtime's and the controller's.

    Examples
    --------
    >>> gs.studies.output_names(gs.load_config("configs/paper.toml"))[:3]
    ['paper.h5', 'paper_gains.h', 'paper_control.h']
    """
    from ..firmware.sources import CONTROL_FILES, RUNTIME_FILES

    return [f"{config.name}.h5", f"{config.name}_gains.h", f"{config.name}_control.h",
            *RUNTIME_FILES, *CONTROL_FILES]


def build(config, out_dir="tables", *, jobs: int = -1, backend: str = "local",
          scheduler: str | None = None, connect_timeout: float | None = None,
          reporter: Reporter = SILENT) -> Build:
    """Build the gain table of a config and its C files, and publish them together: what
    ``gainsched build CONFIG -o OUT_DIR`` does (docs/cli.md).

    The grid is solved (or chosen, for an automatic grid: docs/grid.md), the table and
    the C files rendered from it and checked in memory, then published at once: a failed
    or interrupted build leaves the old set in ``out_dir`` or the new one, never a mix
    (an earlier run killed midway is finished or cleaned up first).

    Parameters
    ----------
    config : Config or path-like
        The config, or its TOML file (or a shipped config's name, ``"paper"``).
    out_dir : path-like, default "tables"
        The output folder (created if needed): ``NAME.h5`` and the C files
        (:func:`output_names`).
    jobs : int, default -1
        Parallel workers (-1: every core).
    backend : {"local", "dask"}
        Where the speeds run: this machine's cores, or a Dask cluster; the table is
        byte-identical either way (docs/distributed.md).
    scheduler : str, optional
        The Dask scheduler's address (``"tcp://host:8786"``), with ``backend="dask"``.
    connect_timeout : float, optional
        Seconds to reach the scheduler (default: the command line's).
    reporter : Reporter, optional
        Shows the progress (:class:`~gainsched.studies.Reporter`); default: nothing.

    Returns
    -------
    Build
        The built grid, the published files and :meth:`Build.lines`, what the command
        prints.

    Raises
    ------
    InputError
        A bad config, output folder or cluster option, before any work is done.

    Examples
    --------
    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml").with_values(
    ...     {"grid.speeds": [6.0, 9.0], "grid.tilts_deg": [0.0, 20.0],
    ...      "grid.azimuth_samples": 8})
    >>> with tempfile.TemporaryDirectory() as out:
    ...     b = gs.build(cfg, out, jobs=1)
    ...     print(b.table.name, b.grid.reasons.shape, len(b.c_files))
    paper.h5 (2, 2, 8) 7
    """
    from ..firmware.outputs import check_outputs
    from ..publish import check_out_dir, recover
    from ..schedule.distributed import check_options

    check_options(backend, scheduler)
    cfg = config_of(config)
    check_outputs(cfg)  # what no table, or the firmware's, holds: before any work
    out_dir = Path(out_dir)
    check_out_dir(out_dir, names=output_names(cfg))  # a bad folder fails now, not after
    recover(out_dir)  # finish or clean up after a killed earlier run
    return build_into(cfg, out_dir, jobs=jobs, backend=backend, scheduler=scheduler,
                      connect_timeout=connect_timeout, reporter=reporter)


def build_into(cfg: Config, out_dir: Path, *, jobs: int = -1, backend: str = "local",
               scheduler: str | None = None, connect_timeout: float | None = None,
               reporter: Reporter = SILENT) -> Build:
    """:func:`build` once its arguments are checked: choose or solve the grid, publish the
    output set into ``out_dir`` (a stage of a larger set, for ``improve``)."""
    from ..firmware.outputs import output_set
    from ..publish import publish
    from ..schedule.distributed import DEFAULT_CONNECT_TIMEOUT, executor

    t0 = time.perf_counter()
    choice = None
    # the progress line first: the solver's modules take a second or two to import
    if cfg.grid.auto:  # the build chooses the breakpoints (docs/grid.md)
        bar = reporter.bar(f"choose the grid of {cfg.name}", unit="circle")
    else:
        bar = reporter.bar(f"build {cfg.name}", cfg.grid.speeds.size, "speed")
    with bar, executor(backend, scheduler, jobs, connect_timeout=DEFAULT_CONNECT_TIMEOUT
                       if connect_timeout is None else connect_timeout) as ex:
        from ..schedule.grid import build_grid
        from ..schedule.refine import refine_grid

        if backend == "dask":
            reporter.note(f"build {cfg.name} on {ex.description}", bar)
        if cfg.grid.auto:
            choice = refine_grid(cfg, n_jobs=ex.n_jobs, progress=bar.update,
                                 backend=ex.backend)
            cfg, grid = choice.config, choice.grid
        else:
            grid = build_grid(cfg, n_jobs=ex.n_jobs, progress=bar.update, backend=ex.backend)
    n_v = cfg.grid.speeds.size
    n_mid = max(n_v - 1, 1) if cfg.firmware.format == "compact" else 0
    with reporter.bar("certify compact table", n_mid, "speed", show=n_mid > 0) as bar:
        outputs = output_set(cfg, grid, out_dir, progress=bar.update,
                             grid_auto=None if choice is None else choice.record())
    table, *c_paths = publish(out_dir, outputs.files)
    return Build(cfg, grid, choice, outputs, table, tuple(c_paths), time.perf_counter() - t0)


def _nanmax(a) -> str:
    a = np.asarray(a)
    return f"{np.nanmax(a):.4f}" if np.any(np.isfinite(a)) else "n/a (no feasible circle)"
