"""The table a config flies when none is given (``paper``, ``improve``), and a table's
pictures (``gainsched plot``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..config import Config
from ._report import SILENT, Reporter

__all__ = ["table_for", "Plots", "plot"]


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


@dataclass(frozen=True, eq=False)
class Plots:
    """What :func:`plot` drew and wrote.

    Attributes
    ----------
    table : Path
        The table plotted.
    out_dir : Path
        The folder of the PNGs and ``plots.json``.
    files : list of Path
        The files written, in the order drawn.
    summary : bytes
        ``plots.json``: the gains' ranges per tilt, the spectral radius, the files.
    """

    table: Path
    out_dir: Path
    files: list
    summary: bytes

    def lines(self, as_json: bool = False) -> list[str]:
        """What ``gainsched plot`` prints: the files written, or (``as_json``) the
        summary."""
        if as_json:
            return [self.summary.decode().removesuffix("\n")]
        return [f"{self.table}: {len(self.files)} files -> {self.out_dir}/ "
                f"({', '.join(sorted(p.name for p in self.files))})"]


def plot(table, out_dir, *, check: bool = False, reporter: Reporter = SILENT) -> Plots:
    """Plot a gain table and write the pictures with a summary: what ``gainsched plot TABLE
    -o OUT_DIR`` does (:func:`gainsched.schedule_plots`).

    Every gain over azimuth and speed per tilt, the feasibility envelope, the nominal
    thrusts and roll, the closed loop's spectral radius and slowest time constant and,
    with ``check``, the interpolation error at the cell midpoints; published at once.

    Parameters
    ----------
    table : path-like
        The gain table (HDF5).
    out_dir : path-like
        The folder of the PNGs and ``plots.json``.
    check : bool, default False
        Also solve the LQR at the cell midpoints (as ``gainsched check``) and plot the
        interpolation error (slower).
    reporter : Reporter, optional
        Shows the check's and the drawing's progress; default: nothing.

    Returns
    -------
    Plots
        The files, the summary and :meth:`Plots.lines`, what the command prints.

    Examples
    --------
    A table of two tilts (the paper's has seven: fourteen files, half a minute):

    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml").with_values(
    ...     {"grid.speeds": [6.0, 9.0], "grid.tilts_deg": [0.0, 20.0],
    ...      "grid.azimuth_samples": 8})
    >>> out = tempfile.mkdtemp()
    >>> p = gs.studies.plot(gs.build(cfg, out, jobs=1).table, f"{out}/plots")
    >>> len(p.files), "plots.json" in [f.name for f in p.files]
    (9, True)
    """
    from ..publish import check_out_dir, publish
    from ..schedule.tables import load_table
    from ..schedule.viewer import plot_count, schedule_plots

    out_dir = Path(out_dir)
    check_out_dir(out_dir, "--out", names=["plots.json"])
    t = load_table(table)
    midpoints = None
    if check:
        from ..firmware.host.check import midpoint_check

        n_mid = max(t.speed.size - 1, 0) * (1 if t.reverse is None else 2)  # both ways
        with reporter.bar(f"check {t.name}", n_mid, "speed") as bar:
            res = midpoint_check(t, progress=bar.update)
        midpoints = (res.speed, res.tilt, res.rel_err)
    with reporter.bar(f"plot {t.name}", plot_count(t, midpoints is not None), "file") as bar:
        files = schedule_plots(t, midpoints, source=str(table), progress=bar.update)
    paths = publish(out_dir, files, where="--out")
    return Plots(Path(table), out_dir, paths, files["plots.json"])
