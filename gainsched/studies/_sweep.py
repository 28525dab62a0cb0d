"""A gain table per vehicle variant and a results table: ``gainsched sweep``."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ._report import SILENT, Reporter, config_of

__all__ = ["SweepRun", "sweep"]


@dataclass(frozen=True, eq=False)
class SweepRun:
    """What :func:`sweep` built.

    Attributes
    ----------
    plan : Sweep
        The variants (:func:`gainsched.schedule.sweep.make_sweep`).
    rows : list of dict
        Per variant: feasible %, worst spectral radius, max ``|K|``, min tension margin
        (N), table SHA-256 (:func:`gainsched.schedule.sweep.run_sweep`).
    out_dir : Path
        ``NAME.toml`` and ``NAME.h5`` per variant, ``sweep.csv``, ``sweep.json``.
    seconds : float
        Wall time, s.
    """

    plan: object
    rows: list
    out_dir: Path
    seconds: float

    def lines(self) -> list[str]:
        """What ``gainsched sweep`` prints: the results table and what was written."""
        from ..schedule.sweep import format_rows

        n = len(self.rows)
        return [*format_rows(self.plan, self.rows),
                f"{self.out_dir}: {n} variants ({n} tables + configs), sweep.csv, "
                f"sweep.json; {self.seconds:.1f} s"]


def sweep(config, out_dir, *, vary=(), monte_carlo: int = 0, seed: int = 0, sigma=(),
          jobs: int = -1, backend: str = "local", scheduler: str | None = None,
          connect_timeout: float | None = None, reporter: Reporter = SILENT) -> SweepRun:
    """Build a gain table per vehicle variant or Monte Carlo sample of a config, and a
    results table: what ``gainsched sweep CONFIG -o OUT_DIR`` does (docs/distributed.md).

    Parameters
    ----------
    config : Config or path-like
        The base config.
    out_dir : path-like
        The output folder; every variant appears at once, or none.
    vary : sequence of str
        ``"KEY=v1,v2,..."``: values of one parameter (SI); several give their Cartesian
        product.
    monte_carlo : int, default 0
        Monte Carlo samples (per ``vary`` combination) of the ``sigma`` keys.
    seed : int, default 0
        Seed of the Monte Carlo draws.
    sigma : sequence of str
        ``"KEY=REL"``: relative standard deviation of a sampled parameter.
    jobs, backend, scheduler, connect_timeout
        Where the builds run, as :func:`~gainsched.studies.build` takes them.
    reporter : Reporter, optional
        Shows the builds' progress; default: nothing.

    Returns
    -------
    SweepRun
        The variants, their results and :meth:`SweepRun.lines`, what the command prints.

    Raises
    ------
    InputError
        A bad key, value or option, before any build.

    Examples
    --------
    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml").with_values(
    ...     {"grid.speeds": [6.0, 9.0], "grid.tilts_deg": [0.0, 20.0],
    ...      "grid.azimuth_samples": 8})
    >>> run = gs.sweep(cfg, tempfile.mkdtemp(), vary=["vehicle.mass=0.45,0.55"], jobs=1)
    >>> len(run.rows), sorted(p.name for p in run.out_dir.glob("sweep.*"))
    (2, ['sweep.csv', 'sweep.json'])
    """
    from ..publish import check_out_dir, staged
    from ..schedule.distributed import DEFAULT_CONNECT_TIMEOUT, check_options, executor
    from ..schedule.sweep import make_sweep, parse_sigma, parse_vary, run_sweep

    check_options(backend, scheduler)
    base = config_of(config)
    plan = make_sweep(base, [parse_vary(v) for v in vary], monte_carlo=monte_carlo, seed=seed,
                      sigma=[parse_sigma(s) for s in sigma])
    out_dir = Path(out_dir)
    # once every option passed: a refused sweep creates nothing
    check_out_dir(out_dir, names=["sweep.csv", "sweep.json"])
    t0 = time.perf_counter()
    # a grid the build chooses counts circles, of a number known only at the end
    total = None if base.grid.auto else len(plan.variants) * base.grid.speeds.size
    with executor(backend, scheduler, jobs, connect_timeout=DEFAULT_CONNECT_TIMEOUT
                  if connect_timeout is None else connect_timeout) as ex:
        if backend == "dask":
            reporter.note(f"sweep {base.name} on {ex.description}")
        with reporter.bar(f"sweep {base.name} ({len(plan.variants)} variants)", total,
                          "circle" if total is None else "speed") as bar:
            with staged(out_dir) as stage:  # every variant appears at once, or none
                rows = run_sweep(plan, stage, n_jobs=ex.n_jobs, backend=ex.backend,
                                 progress=bar.update)
    return SweepRun(plan, rows, out_dir, time.perf_counter() - t0)
