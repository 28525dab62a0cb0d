"""A config's table built once and kept: what ``gainsched paper`` flies when no table is
given (an installed package has no ``tables/`` folder).

The table is built as ``gainsched build`` builds it (the grid of the config, or the one
the build chooses for ``[grid]`` ranges) and kept in the cache folder
(``$GAINSCHED_CACHE``, default ``~/.cache/gainsched``, beside the compiled kernels) as
``tables/<name>-<sha256 of the config, 16 hex>.h5``: another config, or an edited one,
gets its own file; a table whose bytes were damaged is refused by :func:`load_table`
and built again.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..model.reduced import Model
from ..native import cache_dir
from ..publish import write_atomic
from .grid import build_grid
from .refine import refine_grid
from .tables import Table, load_table, table_bytes

__all__ = ["cached_table_path", "cached_table"]


def cached_table_path(config) -> Path:
    """Where the cache keeps the table of ``config`` (it may not exist yet)."""
    return cache_dir() / "tables" / f"{config.name}-{config.sha256[:16]}.h5"


def cached_table(config, *, n_jobs=1, progress=None) -> tuple[Table, bool]:
    """The table of ``config`` from the cache, built and stored there on first use.

    Parameters
    ----------
    config : Config
    n_jobs : int
        Worker processes of a build (the bytes do not depend on it).
    progress : callable or None
        Called with 1 per solved speed (or circle, for a grid the build chooses) of a build.

    Returns
    -------
    (Table, bool)
        The table and whether it was built now.
    """
    path = cached_table_path(config)
    if path.is_file():
        try:
            return load_table(path), False
        except InputError:  # damaged: build it again
            pass
    if config.grid.auto:
        choice = refine_grid(config, n_jobs=n_jobs, progress=progress)
        cfg, grid, record = choice.config, choice.grid, choice.record()
    else:
        cfg, record = config, None
        grid = build_grid(config, n_jobs=n_jobs, progress=progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, table_bytes(cfg, grid, Model(cfg), record))
    return load_table(path), True
