"""The output set of a build: the HDF5 table, its C header and the runtime, as one unit.

Every check that can fail runs on the bytes in memory (the table is read back
through :func:`~gainsched.schedule.tables.table_from_bytes`, the header rendered from
it) before the first byte reaches the output folder; the set is then
published together (:func:`~gainsched.publish.publish`), so a failed or
interrupted build leaves the old set or the new one, never a mix.
"""

from __future__ import annotations

from pathlib import Path

from ..model.reduced import Model
from ..publish import publish
from ..schedule.tables import table_bytes, table_from_bytes
from .codegen import c_files

__all__ = ["output_files", "write_outputs"]


def output_files(config, grid, out_dir=".") -> dict[str, bytes]:
    """``{NAME.h5, NAME_gains.h, gainsched_runtime.h, gainsched_runtime.c}`` -> bytes, checked.

    Parameters
    ----------
    config : Config
    grid : GridResult
        The built grid (:func:`gainsched.schedule.grid.build_grid`).
    out_dir : path-like
        Where the files will go (only for the names in error messages).
    """
    name = f"{config.name}.h5"
    data = table_bytes(config, grid, Model(config))
    table = table_from_bytes(data, Path(out_dir) / name)
    return {name: data, **c_files(table)}


def write_outputs(out_dir, config, grid) -> list[Path]:
    """Check and publish the output set of a build in ``out_dir``; returns the paths
    (table first)."""
    return publish(out_dir, output_files(config, grid, out_dir))
