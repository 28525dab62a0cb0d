"""The table a config flies when none is given (``paper``, ``improve``)."""

from __future__ import annotations

from pathlib import Path

from ..config import Config
from ._report import SILENT, Reporter

__all__ = ["table_for"]


def table_for(config: Config, *, reporter: Reporter = SILENT):
    """The gain table of ``config`` when the user names none: ``tables/NAME.h5`` in the
    working folder when it was built from this config (where ``gainsched build CONFIG``
    writes by default), else the config's table in the cache
    (:mod:`gainsched.schedule.cached`), built there on first use (progress and a note on
    ``reporter``).

    Parameters
    ----------
    config : Config
    reporter : Reporter, optional
        Shows a first use's build; default: nothing.

    Returns
    -------
    table : Table
    path : Path
        Where it was read from.

    Examples
    --------
    >>> table, path = gs.studies.table_for(gs.load_config("configs/paper.toml"))
    >>> str(path), table.built_from(gs.load_config("configs/paper.toml"))
    ('tables/paper.h5', True)
    """
    from ..schedule.cached import cached_table, cached_table_path
    from ..schedule.tables import load_table

    local = Path("tables") / f"{config.name}.h5"
    if local.is_file():
        table = load_table(local)
        if table.built_from(config):
            return table, local
    path = cached_table_path(config)
    total = None if config.grid.auto else config.grid.speeds.size
    with reporter.bar(f"build {config.name} (first use, kept in the cache)", total,
                      "speed" if total else "circle", show=not path.is_file()) as bar:
        table, built = cached_table(config, progress=bar.update)
    if built:
        reporter.note(f"built {path}")
    return table, path
