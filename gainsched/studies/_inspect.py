"""A built table read and summarised (``gainsched inspect``), and its interpolation checked
at the cell midpoints (``gainsched check``)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._report import SILENT, Reporter, stage, teller

__all__ = ["Inspection", "inspect", "Check", "check"]

#: what ``inspect -o`` writes
_ENVELOPE = ["envelope.png", "envelope.json"]


@dataclass(frozen=True, eq=False)
class Inspection:
    """What :func:`inspect` read and wrote.

    Attributes
    ----------
    table : Table
        The table read.
    path : Path
        Its file, as given.
    flash : tuple of str
        The runtime's flash footprint lines (empty: not measured, ``code_size`` false).
    envelope : str or None
        The line naming the envelope's files written (None: no ``out_dir``).
    """

    table: object
    path: Path
    flash: tuple = ()
    envelope: str | None = None

    def summary(self) -> dict:
        """The table's summary as plain JSON data (:func:`gainsched.table_summary`) with
        ``c_prefix``, the prefix of the C symbols ``export-c`` writes: what ``gainsched
        inspect --json`` prints."""
        from ..firmware.runtime import c_identifier
        from ..schedule.viewer import table_summary

        return {**table_summary(self.table, source=str(self.path)),
                "c_prefix": c_identifier(self.table.name)}

    def lines(self, as_json: bool = False) -> list[str]:
        """What ``gainsched inspect`` prints: the table's record, grid, feasibility map,
        gain ranges, flash footprint, worst spectral radius, slowest modes and stability
        margins (docs/margins.md), and the envelope's files; or (``as_json``) the summary
        as indented JSON, one string."""
        import json

        if as_json:
            return [json.dumps(self.summary(), indent=2, sort_keys=True)]
        return _inspect_lines(self)


def _inspect_lines(ins: Inspection) -> list[str]:
    from ..schedule.nominal import REASONS
    from ..schedule.refine import grid_auto_lines
    from ..schedule.viewer import margin_lines, mode_lines

    t = ins.table
    tilts = ", ".join(f"{x:g}" for x in np.rad2deg(t.tilt))
    out = [f"{ins.path}: {t.attrs['schema']}, config {t.name} (sha256 "
           f"{t.config_sha256[:12]}), tool {t.attrs['tool_version']}, terminal cost "
           f"{t.attrs['terminal']}",
           f"  xi: {t.xi.size} samples over 360 deg; speeds {t.speed[0]:g}..{t.speed[-1]:g} "
           f"m/s ({t.speed.size}); tilts {tilts} deg"]
    if t.reverse is not None:
        worse = (t.reverse.reasons != 0).sum() - (t.reasons != 0).sum()
        out.append(f"  both flight directions: the vehicle is not its own mirror image, its "
                   f"reversed circles read the image's half (reverse/; {worse:+d} infeasible "
                   "points against the forward half; docs/symmetry.md)")
    if t.grid_auto is not None:
        out += [f"  {line}" for line in grid_auto_lines(t.grid_auto)]
    out.append("  feasible azimuth fraction (rows: tilt deg, columns: speed m/s)")
    w = max(6, 1 + max(len(f"{v:g}") for v in t.speed))  # chosen grids have long values
    out.append("        " + "".join(f"{v:{w}g}" for v in t.speed))
    for i, a in enumerate(np.rad2deg(t.tilt)):
        frac = (t.reasons[i] == 0).mean(-1)
        out.append(f"  {a:5g} " + "".join(f"{x:{w}.2f}" for x in frac))
    for bit, text in REASONS.items():
        n = np.count_nonzero(t.reasons & bit)
        if n:
            out.append(f"  {n} points: {text}")
    K = t.K_full()
    out.append("  gain ranges over feasible points (min .. max per state column)")
    for j, nm in enumerate(t.state_names):
        col = K[..., j][np.isfinite(K[..., j])]
        if col.size:
            out.append(f"    {nm:>10s}: {col.min():9.3f} .. {col.max():9.3f}")
    out += [f"  {line}" for line in ins.flash]
    rho = t.spectral_radius
    if not np.any(np.isfinite(rho)):
        out.append("  no feasible circle: no gains, no closed loop (see the reasons above)")
    else:
        i, j = np.unravel_index(np.nanargmax(rho), rho.shape)
        out.append(f"  worst closed-loop monodromy spectral radius {rho[i, j]:.5f} "
                   f"(speed {t.speed[j]:g} m/s, tilt {np.rad2deg(t.tilt[i]):g} deg); "
                   f"all < 1: {bool(np.all(rho[np.isfinite(rho)] < 1))}")
    out += [f"  {line}" for line in mode_lines(t)]
    out += [f"  {line}" for line in margin_lines(t)]
    if ins.envelope is not None:
        out.append(ins.envelope)
    return out


def inspect(table, out_dir=None, *, code_size: bool = True,
            reporter: Reporter = SILENT) -> Inspection:
    """Summarise a gain table and, with ``out_dir``, write its flight envelope: what
    ``gainsched inspect TABLE [-o OUT_DIR] [--json]`` does.

    Parameters
    ----------
    table : path-like
        The gain table (HDF5).
    out_dir : path-like, optional
        Also write ``envelope.png`` (speed x tilt: feasible / slack / thrust) and
        ``envelope.json`` into this folder, published at once.
    code_size : bool, default True
        Compile the runtime to measure its flash footprint (``--json`` does not).
    reporter : Reporter, optional
        Shows the compilation and the envelope's drawing; default: nothing.

    Returns
    -------
    Inspection
        The table, :meth:`Inspection.summary` (``--json``) and
        :meth:`Inspection.lines`, what the command prints.

    Raises
    ------
    InputError
        An unreadable table or a bad output folder, before any work.

    Examples
    --------
    >>> ins = gs.studies.inspect("tables/paper.h5", code_size=False)
    >>> ins.summary()["c_prefix"], ins.lines()[0].startswith("tables/paper.h5: ")
    ('paper', True)
    """
    from ..firmware.host.size import flash_summary
    from ..publish import check_out_dir
    from ..schedule.envelope import write_envelope
    from ..schedule.tables import load_table

    if out_dir is not None:
        out_dir = Path(out_dir)
        check_out_dir(out_dir, "--out", names=_ENVELOPE)
    t = load_table(table)
    steps = int(code_size) + (out_dir is not None)
    with reporter.bar(f"inspect {t.name}", steps, "stage", show=steps > 0) as bar:
        flash = stage(bar, "runtime code size (compiling)", flash_summary, t) \
            if code_size else ()
        envelope = None if out_dir is None else stage(bar, "envelope.png", write_envelope,
                                                      t, table, out_dir)
    return Inspection(t, Path(table), tuple(flash), envelope)


@dataclass(frozen=True, eq=False)
class Check:
    """What :func:`check` found.

    Attributes
    ----------
    table : Path
        The table checked.
    result : MidpointCheck
        The errors and closed loops at the cell midpoints
        (:func:`gainsched.midpoint_check`).
    compact : CompactData or None
        The compact form checked instead of the dense table (None: the dense one).
    max_error : float
        The pass threshold on the relative errors, percent.
    ok : bool
        Whether the table passed: every error within ``max_error`` and every midpoint
        closed loop stable (the command exits 1 when not).
    seconds : float
        Wall time of the check, s.
    said : tuple of str
        :meth:`lines`.
    """

    table: Path
    result: object
    compact: object
    max_error: float
    ok: bool
    seconds: float
    said: tuple

    def lines(self) -> list[str]:
        """What ``gainsched check`` prints: the compact form checked, the points checked,
        the worst and median errors, by axis, the closed loops and PASS or FAIL."""
        return list(self.said)


def check(table, *, speed_stride: int = 1, max_error: float | None = None,
          azimuth_error: float | None = None, reporter: Reporter = SILENT) -> Check:
    """Check a table's interpolation at the cell midpoints: what ``gainsched check TABLE``
    does (docs/runtime.md).

    The periodic LQR is solved directly at every cell midpoint (speed x tilt x azimuth)
    and compared with the interpolated gains (relative Frobenius error), then the loop is
    closed along each midpoint circle with the interpolated gains (monodromy spectral
    radius). A grid the build chose is checked on its nominal thrusts and roll too.

    Parameters
    ----------
    table : path-like
        The gain table (HDF5).
    speed_stride : int, default 1
        Check every N-th speed midpoint only (1..the table's speed midpoints).
    max_error : float, optional
        Pass threshold on the max relative error, percent in (0, 100] (default: the
        table config's ``grid.max_interpolation_error``, else 2).
    azimuth_error : float, optional
        Check the table's compact form made with this error bound at the azimuth samples,
        percent (``--compact``; default: the compact form when the table's config has
        that format, else the dense table).
    reporter : Reporter, optional
        Shows the progress and the lines as they come; default: nothing.

    Returns
    -------
    Check
        :attr:`Check.ok`, the midpoint results and :meth:`Check.lines`, what the command
        prints.

    Raises
    ------
    InputError
        An unreadable table or a stride past its last midpoint, before any work.

    Examples
    --------
    >>> c = gs.studies.check("tables/paper.h5", speed_stride=6)
    >>> c.ok, c.lines()[-1]
    (True, '  PASS: max error <= 2% and every midpoint closed loop stable')
    """
    from ..firmware.host.check import midpoint_check
    from ..firmware.outputs import table_config
    from ..schedule.tables import load_table

    t = load_table(table)
    n_mid = max(t.speed.size - 1, 1)
    if not 1 <= speed_stride <= n_mid:  # past the last midpoint: only the first checked
        raise InputError("command line", "--speed-stride", f"{speed_stride}: {table} has "
                         f"{n_mid} speed midpoint{'s' if n_mid > 1 else ''}: give 1..{n_mid}")
    if max_error is not None and not 0 < max_error <= 100:
        raise InputError("command line", "--max-error", f"{max_error:g}: must be in (0, 100] %")
    t0 = time.perf_counter()
    said, say = teller(reporter)
    cfg = table_config(t, "config")
    if max_error is None:
        max_error = 2.0 if cfg is None else 100 * cfg.grid.max_interpolation_error
    if azimuth_error is None and cfg is not None and cfg.firmware.format == "compact":
        azimuth_error = 100 * cfg.firmware.azimuth_error
    form = lookup = None
    if azimuth_error is not None:
        from ..firmware.compact import CompactInterpolator

        form, line = _compact_form(t, table, azimuth_error)
        say([line])
        lookup = CompactInterpolator(form)
    n_v = len(range(0, max(t.speed.size - 1, 0), speed_stride))
    n_v *= 1 if t.reverse is None else 2  # and the reversed circles' midpoints
    with reporter.bar(f"check {t.name}", n_v, "speed") as bar:
        res = midpoint_check(t, speed_stride=speed_stride, progress=bar.update, lookup=lookup)
    seconds = time.perf_counter() - t0
    # a grid the build chose promised gains, nominal thrusts and roll (docs/grid.md)
    nominal = t.grid_auto is not None
    passed = res.passed(max_error / 100, nominal)
    say(_check_lines(t, table, res, n_v, seconds, max_error, passed))
    return Check(Path(table), res, form, max_error, passed, seconds, tuple(said))


def _compact_form(t, table, azimuth_error: float):
    """The compact form of table ``t`` at ``azimuth_error`` percent, and the line that
    describes it."""
    from ..firmware.compact import compact_data
    from ..firmware.runtime import runtime_data

    dense = runtime_data(t)
    form = compact_data(dense, azimuth_error / 100, source=str(table), key="--compact")
    return form, (f"{table}: compact form at {azimuth_error:g}% on the azimuth samples: "
                  f"{form.nbytes():,} bytes of table data (dense {dense.nbytes():,}); "
                  f"{int(form.harmonics.max())} harmonics at most; fit error at the "
                  f"samples max {100 * np.nanmax(form.fit_error, initial=0):.2f}%")


def _check_lines(t, table, res, n_v: int, seconds: float, max_error: float,
                 passed: bool) -> list[str]:
    """The lines of :func:`check` after the midpoint check: the errors, the closed
    loops, the table's stability margins and PASS or FAIL."""
    from ..schedule.refine import grid_auto_lines
    from ..schedule.viewer import margin_lines

    ok_pts = int(np.count_nonzero(np.isfinite(res.rel_err)))
    n_a = max(t.tilt.size - 1, 1)
    out = [f"{table}: {ok_pts} cell midpoints checked ({n_v} speeds x {n_a} tilts x "
           f"{t.xi.size} azimuths; {res.skipped} skipped as infeasible), {seconds:.1f} s"]
    if ok_pts:
        v, a, x, e = res.worst_point()
        out.append(f"  relative gain error |K_interp - K|_F / |K|_F: max {100 * e:.2f}% "
                   f"(speed {v:g} m/s, tilt {np.rad2deg(a):g} deg, xi {np.rad2deg(x):g} "
                   f"deg), median {100 * res.median_err:.2f}%")
        by_v, by_a = res.by_axis()
        out.append("  max error by speed midpoint (m/s: %): " + ", ".join(
            f"{k:g}: {100 * e:.2f}" for k, e in by_v.items() if np.isfinite(e)))
        out.append("  max error by tilt midpoint (deg: %): " + ", ".join(
            f"{np.rad2deg(k):g}: {100 * e:.2f}" for k, e in by_a.items() if np.isfinite(e)))
        out.append(f"  max nominal thrust error {np.nanmax(res.u_err):.4f} N "
                   f"({100 * np.nanmax(res.u_rel):.2f}% of the circle's largest), roll "
                   f"{100 * np.nanmax(res.phi_rel):.2f}% of the circle's largest")
    rho = [(c.rho_interp, c) for c in res.circles if np.isfinite(c.rho_interp)]
    if rho:
        r, c = max(rho)
        out.append(f"  closed loop with interpolated gains on {len(rho)} midpoint circles: "
                   f"worst spectral radius {r:.5f} (speed {c.speed:g} m/s, tilt "
                   f"{np.rad2deg(c.tilt):g} deg; direct LQR {c.rho_direct:.5f}); all < 1: "
                   f"{res.stable}")
    nominal = t.grid_auto is not None
    if nominal:
        out.append(f"  {grid_auto_lines(t.grid_auto)[0]}; checked on gains, nominal "
                   "thrusts and roll")
    out += [f"  {line}" for line in margin_lines(t, maps=False)]
    what = "gain, thrust and roll error" if nominal else "max error"
    out.append(f"  {'PASS' if passed else 'FAIL'}: {what} <= {max_error:g}% and every "
               "midpoint closed loop stable")
    return out
