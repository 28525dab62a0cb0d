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
    """Write a built grid as its output set: the HDF5 table, its C header and the runtime.

    Every check runs on the bytes in memory first (the table is read back through the
    checks of :func:`gainsched.load_table` and the C header rendered from it); the set
    is then published together (:func:`gainsched.publish.publish`): a failed or
    interrupted write leaves the old set or the new one in ``out_dir``, never a mix.
    This is what ``gainsched build CONFIG -o OUT_DIR`` writes.

    Parameters
    ----------
    out_dir : str or path-like
        Output folder, created if needed. Files of the same names there are replaced.
    config : Config
        The config the grid was built from (:func:`gainsched.load_config`); its ``name``
        names the files, its text and SHA-256 are embedded in them.
    grid : GridResult
        The built grid (:func:`gainsched.build_grid` of ``config``).

    Returns
    -------
    list of Path
        The written files, ``out_dir / name``: ``NAME.h5`` (the table,
        docs/table-format.md), ``NAME_gains.h`` (the float32 tables for the firmware),
        ``gainsched_runtime.h`` and ``gainsched_runtime.c`` (the C lookup,
        docs/runtime.md).

    Raises
    ------
    InputError
        ``out_dir`` cannot be written (read-only, disk full, under a regular file, no
        permission), or the table cannot be held by the C runtime (e.g. a value that
        overflows float32 at a feasible point); nothing is written then.

    See Also
    --------
    gainsched.build_grid : The grid to write.
    gainsched.load_table : Read the table back.

    Examples
    --------
    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> small = cfg.with_values({"grid.speeds": [6, 9], "grid.tilts_deg": [0, 20],
    ...                          "grid.azimuth_samples": 8, "name": "small"})
    >>> out = tempfile.mkdtemp()
    >>> paths = gs.write_outputs(out, small, gs.build_grid(small))
    >>> [p.name for p in paths]
    ['small.h5', 'small_gains.h', 'gainsched_runtime.h', 'gainsched_runtime.c']
    >>> table = gs.load_table(paths[0])
    >>> table.name, table.K.shape, table.config_sha256 == small.sha256
    ('small', (1, 2, 8, 4, 11), True)
    """
    return publish(out_dir, output_files(config, grid, out_dir))
