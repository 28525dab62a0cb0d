"""Look at a gain schedule: the plots a control engineer makes first.

:func:`schedule_figures` draws, from a loaded :class:`~gainsched.schedule.tables.Table`:

- ``gains_tilt<deg>.png``, one per tilt: every gain entry ``K_ij`` (4 inputs x n
  states) as a small map over azimuth (x) and speed (y), the grid points marked, one
  colour scale per entry (its range in the title); infeasible circles blank;
- ``envelope.png``: speed x tilt, feasible / with offsets / slack / thrust limits
  (:func:`~gainsched.schedule.envelope.envelope_png`);
- ``nominal.png``: the nominal motor thrusts ``u_d`` and roll ``phi_d`` over azimuth
  and speed, one row per tilt;
- ``spectral_radius.png``: the closed-loop monodromy spectral radius per circle
  (speed x tilt);
- ``time_constant.png``: the slowest closed-loop time constant per circle (speed x
  tilt; :mod:`~gainsched.schedule.modes`), the slowest of all and its states in the title;
- ``midpoint_error.png`` when a midpoint check is given (``gainsched check``, the
  firmware layer computes it): the largest relative gain error of the interpolation
  per speed x tilt midpoint.

:func:`schedule_plots` renders them to PNG bytes with a sorted-key JSON summary
(``plots.json``: :func:`table_summary`, the grid, per-entry gain ranges, the spectral
radius, plus the files) for
:func:`gainsched.publish.publish`. Every map draws the table's own arrays (no
resampling), so a test can read the values back from the figure.
"""

from __future__ import annotations

import functools
import io
import json
import textwrap
from collections import Counter

import numpy as np

from .envelope import envelope_from_table, envelope_png
from .margin_report import factor_db, worst_lines, worst_margins, worst_text
from .margins import G_MAX, TAU_MAX_S
from .modes import dominant_states

__all__ = ["schedule_figures", "schedule_plots", "table_summary", "slowest_mode",
           "mode_lines", "gain_file_name", "gain_unit", "state_unit"]

INPUT_NAMES = ("T1", "T2", "T3", "T4")


def gain_file_name(tilt_rad: float) -> str:
    """``gains_tilt<deg>.png`` for a tilt in rad (degrees rounded to 0.01)."""
    return f"gains_tilt{round(float(np.rad2deg(tilt_rad)), 2):g}.png"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _feasible(table) -> np.ndarray:
    """(n_a, n_v, n_xi) bool: the azimuth samples with gains."""
    return table.reasons == 0


def _map(ax, xi_deg, speed, values, title, cmap="viridis"):
    """One map of ``values`` (n_v, n_xi) over azimuth (deg) and speed (m/s), the grid
    points marked; NaN blank. Returns the QuadMesh."""
    mesh = ax.pcolormesh(xi_deg, speed, np.ma.masked_invalid(values), shading="nearest",
                         cmap=cmap)
    X, V = np.meshgrid(xi_deg, speed)
    ax.plot(X.ravel(), V.ravel(), ",", color="k", alpha=0.35)
    ax.set_title(title, fontsize=7)
    # few fixed ticks: matplotlib's tick machinery is most of the drawing time of ~300 maps
    ax.set_xticks([0, 120, 240])
    ax.set_yticks(np.unique(np.round([speed[0], speed[speed.size // 2], speed[-1]], 1)))
    ax.tick_params(labelsize=6, length=2)
    return mesh


def _colorbar(fig, mesh, ax, labelsize: int = 6, label: str = "", bins: int = 4) -> None:
    """A slim colorbar beside ``ax`` with at most ``bins`` ticks (their labels, beside ~50
    maps, would otherwise crowd into the next map), none at its ends (a label there runs
    past the bar, over the next map or off the figure)."""
    from matplotlib.ticker import MaxNLocator

    bar = fig.colorbar(mesh, ax=ax, pad=0.01, fraction=0.08, aspect=15, label=label)
    bar.locator = MaxNLocator(bins, prune="both")
    bar.update_ticks()
    bar.ax.tick_params(labelsize=labelsize, length=1.5)


def _outer_labels(axes) -> None:
    """Axis labels on the outer maps only, tick labels on the left column and bottom row."""
    for (r, c), ax in np.ndenumerate(axes):
        if r == axes.shape[0] - 1:
            ax.set_xlabel("azimuth xi (deg)", fontsize=7)
        else:
            ax.tick_params(labelbottom=False)
        if c == 0:
            ax.set_ylabel("speed (m/s)", fontsize=7)
        else:
            ax.tick_params(labelleft=False)


def state_unit(name: str) -> str:
    """The unit of an LQR state by its name (``Table.state_names``): rad for the angles,
    rad/s for their rates and the body rates, rad s for the integrals, N for an effect's
    thrust states (motor lag)."""
    if name.startswith("int_"):
        return "rad s"
    if name.endswith("_dot") or name.startswith("omega_"):
        return "rad/s"
    if name in ("delta", "xi", "phi", "theta", "chi"):
        return "rad"
    return "N"


def gain_unit(name: str) -> str:
    """The unit of a gain ``K[T_i, name]`` (a thrust in N per unit of the state)."""
    unit = state_unit(name)
    return "N/N" if unit == "N" else f"N/({unit})" if " " in unit or "/" in unit else f"N/{unit}"


def _gain_figure(plt, table, i: int):
    K = table.K_full()[i]  # (n_v, n_xi, 4, n)
    ok = _feasible(table)[i]
    names = list(table.state_names)
    n = K.shape[-1]
    xi_deg = np.rad2deg(table.xi)
    # not shared axes: sharing 44 maps makes every limit change visit all of them; a fixed
    # layout (the constrained one doubles the drawing time of 44 maps) with room between
    # the columns for each colorbar's labels
    fig, axes = plt.subplots(4, n, figsize=(1.9 * n + 1, 7.8), squeeze=False)
    for r in range(4):
        for c in range(n):
            vals = np.where(ok, K[..., r, c], np.nan)
            fin = vals[np.isfinite(vals)]
            rng = f"{fin.min():.3g}..{fin.max():.3g}" if fin.size else "no gains"
            # a diverging map centred on 0 for gains of both signs, a sequential one else
            both = fin.size and fin.min() < 0 < fin.max()
            mesh = _map(axes[r, c], xi_deg, table.speed, vals,
                        f"K[{INPUT_NAMES[r]}, {names[c]}] {gain_unit(names[c])}\n{rng}",
                        cmap="coolwarm" if both else "viridis")
            if both:
                top = float(np.abs(fin).max())
                mesh.set_clim(-top, top)
            mesh.set_gid(f"K_{r}_{c}")
            _colorbar(fig, mesh, axes[r, c], labelsize=5)
    _outer_labels(axes)
    tilt = np.rad2deg(table.tilt[i])
    fig.suptitle(f"{table.name}: gains K (u = u_d - K (x - x_d)) at tilt {tilt:g} deg, "
                 f"{int(ok.any(-1).sum())} of {ok.shape[0]} speeds with gains "
                 "(blank: infeasible; dots: grid points)", fontsize=9)
    fig.subplots_adjust(left=0.035, right=0.975, bottom=0.065, top=0.9, wspace=0.5,
                        hspace=0.55)
    return fig


def _nominal_figure(plt, table):
    n_a = table.tilt.size
    xi_deg = np.rad2deg(table.xi)
    ok = _feasible(table)
    fig, axes = plt.subplots(n_a, 5, figsize=(14, 2.4 * n_a + 0.8), squeeze=False,
                             layout="constrained")
    for i in range(n_a):
        tilt = np.rad2deg(table.tilt[i])
        for m in range(4):
            mesh = _map(axes[i, m], xi_deg, table.speed,
                        np.where(ok[i], table.u_d[i, ..., m], np.nan),
                        f"tilt {tilt:g} deg: nominal {INPUT_NAMES[m]} (N)")
            mesh.set_gid(f"u_d_{i}_{m}")
            _colorbar(fig, mesh, axes[i, m])
        mesh = _map(axes[i, 4], xi_deg, table.speed,
                    np.where(ok[i], np.rad2deg(table.phi_d[i]), np.nan),
                    f"tilt {tilt:g} deg: nominal roll phi_d (deg)", cmap="coolwarm")
        mesh.set_gid(f"phi_d_{i}")
        _colorbar(fig, mesh, axes[i, 4])
    _outer_labels(axes)
    fig.suptitle(f"{table.name}: nominal motor thrusts and roll (blank: infeasible)",
                 fontsize=9)
    return fig


def _speed_tilt_figure(plt, table, values, title, label, gid, speeds=None, tilts=None):
    """A map over speed x tilt (deg) of ``values`` (n_a, n_v), NaN blank, with the values
    printed in the cells."""
    speeds = table.speed if speeds is None else speeds
    tilts = np.rad2deg(table.tilt if tilts is None else tilts)
    # one equal cell per grid point (the breakpoints are not uniform), labelled by value
    fig, ax = plt.subplots(figsize=(max(7.0, 0.6 * speeds.size + 2.5),
                                    0.45 * tilts.size + 2.2), layout="constrained")
    mesh = ax.pcolormesh(np.arange(speeds.size), np.arange(tilts.size),
                         np.ma.masked_invalid(values), shading="nearest", cmap="magma_r")
    mesh.set_gid(gid)
    for (a, v), x in np.ndenumerate(values):
        if np.isfinite(x):  # black on a light cell, white on a dark one
            r, g, b, _ = mesh.cmap(mesh.norm(x))
            ink = "black" if 0.299 * r + 0.587 * g + 0.114 * b > 0.5 else "white"
            ax.text(v, a, f"{x:.3g}", ha="center", va="center", fontsize=6, color=ink)
    _colorbar(fig, mesh, ax, labelsize=8, label=label, bins=6)
    ax.set_xticks(np.arange(speeds.size), [f"{v:g}" for v in speeds], fontsize=7)
    ax.set_yticks(np.arange(tilts.size), [f"{a:g}" for a in tilts], fontsize=7)
    ax.set_xlabel("speed (m/s)")
    ax.set_ylabel("circle tilt alpha_C (deg)")
    ax.set_title("\n".join(textwrap.wrap(title, 80)), fontsize=9)
    return fig


def _midpoint_grid(midpoints):
    """(speeds, tilts, max error (n_a, n_v)) of a midpoint check's points; a reversed
    circle's (negative speed: a table of both flight directions) counts at its speed, the
    worse of the two directions shown."""
    speed, tilt, err = (np.asarray(x, dtype=float) for x in midpoints)
    speed = np.abs(speed)
    vs, ts = np.unique(speed), np.unique(tilt)
    grid = np.full((ts.size, vs.size), np.nan)
    for k in range(err.size):
        if np.isfinite(err[k]):
            a, v = np.searchsorted(ts, tilt[k]), np.searchsorted(vs, speed[k])
            grid[a, v] = np.fmax(grid[a, v], err[k])
    return vs, ts, grid


def schedule_figures(table, midpoints=None) -> dict:
    """Draw the figures a control engineer looks at first in a gain table, by file name.

    One ``gains_tilt<deg>.png`` per tilt (every gain entry ``K_ij`` as a map over
    azimuth and speed, infeasible circles blank), ``nominal.png`` (the nominal motor
    thrusts and roll), ``spectral_radius.png`` (closed-loop monodromy spectral radius per
    speed x tilt circle), ``time_constant.png`` (the slowest closed-loop time constant per
    circle, when the table has modes), ``gain_margin.png`` and ``delay_margin.png`` (the
    all-motor gain margin down, dB, and the delay margin, ms, per circle, when the table
    has margins: docs/margins.md) and, given a midpoint check, ``midpoint_error.png`` (the
    largest relative gain error of the interpolation per speed x tilt midpoint). Every
    map draws the table's own arrays, no resampling.

    Parameters
    ----------
    table : Table
        A loaded table (:func:`gainsched.load_table`).
    midpoints : tuple of three ndarray, shape (m,), optional
        ``(speed m/s, tilt rad, relative gain error)`` of checked cell midpoints, e.g.
        ``(chk.speed, chk.tilt, chk.rel_err)`` of ``chk = gs.midpoint_check(table)``;
        NaN errors are left out.

    Returns
    -------
    dict of str to matplotlib.figure.Figure
        File name -> figure (the envelope, already a PNG, is left to
        :func:`schedule_plots`). The maps' ``QuadMesh`` carry gids (``K_r_c``,
        ``u_d_i_m``, ``phi_d_i``, ``spectral_radius``, ``time_constant``, ``gain_margin``,
        ``delay_margin``, ``midpoint_error``) so that their
        values can be read back. The figures stay open: close them
        (``matplotlib.pyplot.close``) when done.

    See Also
    --------
    schedule_plots : The same as PNG bytes, with the envelope and a JSON summary.

    Examples
    --------
    The figures of a small table of the paper vehicle (``tables/paper.h5`` has 7 gain
    figures of 44 maps each and takes a few seconds):

    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> small = cfg.with_values({"grid.speeds": [6, 9], "grid.tilts_deg": [0, 20],
    ...                          "grid.azimuth_samples": 8, "name": "small"})
    >>> out = tempfile.mkdtemp()
    >>> table = gs.load_table(gs.write_outputs(out, small, gs.build_grid(small))[0])
    >>> chk = gs.midpoint_check(table)
    >>> figs = gs.schedule_figures(table, (chk.speed, chk.tilt, chk.rel_err))
    >>> sorted(figs)
    ['delay_margin.png', 'gain_margin.png', 'gains_tilt0.png', 'gains_tilt20.png',
     'midpoint_error.png', 'nominal.png', 'spectral_radius.png', 'time_constant.png']
    >>> len(figs["gains_tilt20.png"].axes)        # 4 inputs x 11 states, a colorbar each
    88
    >>> figs["spectral_radius.png"].savefig(f"{out}/spectral_radius.png")
    >>> import matplotlib.pyplot as plt
    >>> plt.close("all")
    """
    plt = _pyplot()
    return {name: make() for name, make in _figure_makers(plt, table, midpoints).items()}


def _figure_makers(plt, table, midpoints) -> dict:
    """File name -> a function that draws that figure of :func:`schedule_figures`: one
    figure at a time (drawn, rendered and closed before the next, and counted by a
    progress line)."""
    makers = {gain_file_name(a): functools.partial(_gain_figure, plt, table, i)
              for i, a in enumerate(table.tilt)}
    makers["nominal.png"] = functools.partial(_nominal_figure, plt, table)
    rho = table.spectral_radius
    fin = rho[np.isfinite(rho)]
    worst = f"worst {fin.max():.5f}" if fin.size else "no feasible circle"
    makers["spectral_radius.png"] = functools.partial(
        _speed_tilt_figure,
        plt, table, rho, f"{table.name}: closed-loop monodromy spectral radius per circle "
        f"({worst}; < 1 is stable; blank: infeasible)", "spectral radius per period",
        "spectral_radius")
    if table.mode_tau is not None:
        slow = slowest_mode(table)
        worst = (f"slowest {slow['time_constant_s']:.3g} s at {slow['speed_mps']:g} m/s, "
                 f"{slow['tilt_deg']:g} deg: {', '.join(slow['dominant_states'])}"
                 if slow else "no feasible circle")
        makers["time_constant.png"] = functools.partial(
            _speed_tilt_figure,
            plt, table, table.mode_tau[..., 0], f"{table.name}: slowest closed-loop time "
            f"constant per circle, s\n({worst}; blank: infeasible)",
            "tau = -T / ln|lambda| (s)", "time_constant")
    makers.update(_margin_makers(plt, table))
    makers.update(_margin_makers(plt, table))
    if midpoints is not None:
        vs, ts, grid = _midpoint_grid(midpoints)
        fin = grid[np.isfinite(grid)]
        worst = f"max {100 * fin.max():.2f} %" if fin.size else "nothing checked"
        makers["midpoint_error.png"] = functools.partial(
            _speed_tilt_figure,
            plt, table, 100 * grid, f"{table.name}: interpolation error at cell midpoints, "
            f"max over azimuth ({worst})", "|K_interp - K|_F / |K|_F (%)",
            "midpoint_error", speeds=vs, tilts=ts)
    return makers


def _margin_makers(plt, table) -> dict:
    """The margin maps of :func:`schedule_figures` (none for a table without margins):
    the all-motor gain margin down (dB) and the delay margin (ms) per circle."""
    lm = table.loop_margins
    if lm is None:
        return {}
    w = worst_margins(lm, table.speed, table.tilt)
    down, delay = (worst_text(w[k], "worst", "none", unit=u).removeprefix("worst ")
                   for k, u in (("gain_down", "dB"), ("delay", "ms")))
    return {
        "gain_margin.png": functools.partial(
            _speed_tilt_figure, plt, table, factor_db(lm.gain_down),
            f"{table.name}: gain margin down per circle, all motors' commands (worst "
            f"{down}; blank: infeasible)", "20 log10 g_down (dB)", "gain_margin"),
        "delay_margin.png": functools.partial(
            _speed_tilt_figure, plt, table, 1e3 * lm.delay,
            f"{table.name}: delay margin per circle, extra delay on the commands (worst "
            f"{delay}; blank: infeasible)", "delay margin (ms)", "delay_margin"),
    }


def _png(fig) -> bytes:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


def _json_grid(a) -> list:
    """A float array as nested lists, NaN as None (JSON has no NaN)."""
    return np.where(np.isfinite(a), a, None).tolist()


def slowest_mode(table) -> dict | None:
    """The slowest closed-loop mode of the whole table and where it is.

    Parameters
    ----------
    table : Table
        A table with modes (``table.mode_tau`` not None).

    Returns
    -------
    dict or None
        ``time_constant_s``, ``frequency_rad_s``, ``damping``, ``speed_mps``, ``tilt_deg``
        and ``dominant_states`` (:func:`~gainsched.schedule.modes.dominant_states`); None
        when no circle is feasible.
    """
    tau = table.mode_tau[..., 0]
    if not np.any(np.isfinite(tau)):
        return None
    i, j = np.unravel_index(np.nanargmax(tau), tau.shape)
    return {
        "time_constant_s": float(tau[i, j]),
        "frequency_rad_s": float(table.mode_frequency[i, j, 0]),
        "damping": float(table.mode_damping[i, j, 0]),
        "speed_mps": float(table.speed[j]),
        "tilt_deg": float(np.rad2deg(table.tilt[i])),
        "dominant_states": dominant_states(table.mode_shape[i, j, 0], table.state_names),
    }


def _mode_states(table) -> list:
    """The dominant states of every stored mode, nested (tilt, speed, mode): a list of state
    names, or None for an infeasible circle."""
    names = table.state_names
    return [[[dominant_states(sh, names) if np.all(np.isfinite(sh)) else None for sh in circle]
             for circle in row] for row in table.mode_shape]


def mode_lines(table) -> list[str]:
    """The slowest closed-loop time constant per circle as text, and the states of those
    modes (what ``gainsched inspect`` prints).

    Parameters
    ----------
    table : Table
        A loaded table.

    Returns
    -------
    list of str
        A tau map (rows: tilt, deg; columns: speed, m/s; s), the dominant states of the
        slowest modes counted over the circles, and the slowest mode of all; one line
        asking for a rebuild when the table stores no modes.
    """
    if table.mode_tau is None:
        return ["no closed-loop modes stored (a table built before they were): rebuild it"]
    slow = slowest_mode(table)
    if slow is None:
        return []
    out = _text_map(table, table.mode_tau[..., 0],
                    "slowest closed-loop time constant per circle, s")
    states = Counter(", ".join(circle[0]) for row in _mode_states(table) for circle in row
                     if circle[0] is not None)
    out.append("  the slowest mode lives in: " + "; ".join(
        f"{s} ({n} circles)" for s, n in states.most_common()))
    out.append(f"  slowest of all: {slow['time_constant_s']:.3g} s at {slow['speed_mps']:g} m/s, "
               f"{slow['tilt_deg']:g} deg ({', '.join(slow['dominant_states'])})")
    return out


def _text_map(table, values, title: str) -> list[str]:
    """A speed x tilt map of ``values`` (n_a, n_v) as text lines: a title, the speeds,
    one row per tilt (NaN: -)."""
    out = [f"{title} (rows: tilt deg, columns: speed m/s; -: infeasible)",
           "        " + "".join(f"{v:6g}" for v in table.speed)]
    for i, a in enumerate(np.rad2deg(table.tilt)):
        out.append(f"  {a:5g} " + "".join(f"{x:6.3g}" if np.isfinite(x) else "     -"
                                          for x in values[i]))
    return out


def margin_lines(table, maps: bool = True) -> list[str]:
    """The table's stability margins as text (docs/margins.md): the worst of each and
    where, and (``maps``) the all-motor down margin (dB) and the delay margin (ms) per
    circle; one line asking for a rebuild when the table stores none.

    Parameters
    ----------
    table : Table
        A loaded table.
    maps : bool, default True
        Also the speed x tilt maps.

    Returns
    -------
    list of str
    """
    if table.loop_margins is None:
        return ["no stability margins stored (built with [control] margins = false, or "
                "before they were): rebuild the table to see them"]
    lm = table.loop_margins
    w = worst_margins(lm, table.speed, table.tilt)
    if not w["circles"]:
        return []
    out = worst_lines(w, "stability margins at the thrust commands")
    if maps:
        out += _text_map(table, factor_db(lm.gain_down), "gain margin down, all motors, dB")
        out += _text_map(table, 1e3 * lm.delay, "delay margin, ms")
    return out


def _margins_summary(table) -> dict | None:
    """The margins as JSON data: every circle's and the worst (None: a table without)."""
    lm = table.loop_margins
    if lm is None:
        return None
    def grid(a):  # NaN (infeasible) None, inf (beyond the search) "inf"
        return np.where(np.isnan(a), None, np.where(np.isinf(a), "inf", a.astype(object))
                        ).tolist()

    out = {"gain_down": grid(lm.gain_down), "gain_up": grid(lm.gain_up),
           "input_down": grid(lm.input_down), "input_up": grid(lm.input_up),
           "delay_s": grid(lm.delay), "search": {"gain_max": G_MAX, "delay_max_s": TAU_MAX_S},
           "worst": worst_margins(lm, table.speed, table.tilt)}
    if lm.crossover is not None:
        out |= {"crossover_rad_s": grid(lm.crossover), "phase_deg": grid(np.degrees(lm.phase))}
    return out


def _modes_summary(table) -> dict | None:
    """Every circle's modes as JSON data (None: a table without modes)."""
    if table.mode_tau is None:
        return None
    return {
        "tau_s": _json_grid(table.mode_tau),
        "frequency_rad_s": _json_grid(table.mode_frequency),
        "damping": _json_grid(table.mode_damping),
        "dominant_states": _mode_states(table),
        "slowest": slowest_mode(table),
    }


def table_summary(table, *, source: str = "") -> dict:
    """Summarise a gain table as plain JSON data: grid, feasibility, gain ranges, stability.

    What ``gainsched inspect --json`` prints; :func:`schedule_plots` writes it to
    ``plots.json``. Every value is a str, int, float, None, list or dict, so
    ``json.dumps`` takes it as it is.

    Parameters
    ----------
    table : Table
        A loaded table (:func:`gainsched.load_table`).
    source : str, default ""
        The file name to report as ``"table"`` (default: ``table.source``).

    Returns
    -------
    dict
        ``table``, ``config`` (the config's name), ``config_sha256``, ``schema``,
        ``tool_version``; the grid: ``speeds_mps`` (n_v, m/s), ``tilts_deg`` (n_a, deg),
        ``azimuth_samples``; ``feasible_fraction`` (n_a, n_v) nested lists: the fraction
        of each circle's azimuth samples with gains; ``reasons``: reason text -> number of
        samples with that bit; ``state_names``; ``gains[tilt_deg][input][state] = [min,
        max]`` over the feasible samples (N per state unit; None without any);
        ``nominal_thrust_N`` and ``nominal_roll_deg``: ``[min, max]``;
        ``spectral_radius`` (n_a, n_v) per circle (None: infeasible) and its
        ``worst_spectral_radius``; ``modes``; ``margins`` (None: not stored): the gain
        margins ``gain_down``, ``gain_up`` (n_a, n_v) and per motor ``input_down``,
        ``input_up`` (n_a, n_v, 4) as factors, ``delay_s`` (n_a, n_v), s (None where
        infeasible, ``"inf"`` beyond the range searched), ``crossover_rad_s`` and
        ``phase_deg`` (n_a, n_v), the phase margin at the crossover (None where none, or
        in a table that stores no crossovers: no keys), the ``search`` ranges and the
        ``worst`` of each (:func:`~gainsched.schedule.margin_report.worst_margins`).

    See Also
    --------
    schedule_plots : The table's figures and this summary as files.

    Examples
    --------
    >>> table = gs.load_table("tables/paper.h5")
    >>> s = gs.table_summary(table)
    >>> s["config"], s["azimuth_samples"], s["tilts_deg"]
    ('paper', 36, [0.0, 10.0, 20.0, 28.0, 34.0, 37.0, 40.0])
    >>> s["reasons"]                                       # samples per reason
    {'tether slack': 256, 'circle infeasible elsewhere': 464}
    >>> [round(k, 2) for k in s["gains"]["20"]["T1"]["phi"]]  # K[T1, phi] at 20 deg, N/rad
    [0.88, 4.94]
    >>> round(s["worst_spectral_radius"], 3)                # < 1: every circle stable
    0.993
    """
    from .nominal import REASONS

    names = list(table.state_names)
    K = table.K_full()
    ok = _feasible(table)

    def rng(x):
        x = x[np.isfinite(x)]
        return [float(x.min()), float(x.max())] if x.size else None

    gains = {}
    for i, a in enumerate(table.tilt):
        gains[f"{np.rad2deg(a):g}"] = {
            INPUT_NAMES[r]: {names[c]: rng(K[i, ..., r, c][ok[i]]) for c in range(len(names))}
            for r in range(4)}
    rho = table.spectral_radius
    fin = rho[np.isfinite(rho)]
    return {
        "table": source or table.source,
        "config": table.name,
        "config_sha256": table.config_sha256,
        "schema": str(table.attrs.get("schema", "")),
        "tool_version": str(table.attrs.get("tool_version", "")),
        "speeds_mps": table.speed.tolist(),
        "tilts_deg": np.rad2deg(table.tilt).tolist(),
        "azimuth_samples": int(table.xi.size),
        "grid_auto": table.grid_auto,
        "feasible_fraction": ok.mean(-1).tolist(),
        "reasons": {text: int(np.count_nonzero(table.reasons & bit))
                    for bit, text in REASONS.items() if np.any(table.reasons & bit)},
        "state_names": names,
        "gains": gains,
        "nominal_thrust_N": rng(np.where(ok[..., None], table.u_d, np.nan)),
        "nominal_roll_deg": rng(np.where(ok, np.rad2deg(table.phi_d), np.nan)),
        "spectral_radius": _json_grid(rho),
        "worst_spectral_radius": float(fin.max()) if fin.size else None,
        "modes": _modes_summary(table),
        "margins": _margins_summary(table),
    }


def plot_count(table, midpoints: bool = False) -> int:
    """How many PNG files :func:`schedule_plots` renders for ``table`` (with the
    midpoint-error figure when ``midpoints``): the length of its progress."""
    return (table.tilt.size + 2 + (table.mode_tau is not None) + bool(midpoints)
            + 2 * (table.loop_margins is not None) + 1)  # + envelope.png


def schedule_plots(table, midpoints=None, *, source: str = "",
                   progress=None) -> dict[str, bytes]:
    """Render a gain table's figures to PNG files plus a JSON summary (plots.json), as bytes.

    The figures of :func:`schedule_figures` (at 90 dpi, without a timestamp) and
    ``envelope.png`` (speed x tilt: feasible, with attitude offsets, slack, thrust
    limits; with the lowest taut speed, paper eq. 19), ready for
    :func:`gainsched.publish.publish` (what ``gainsched plot TABLE -o DIR`` writes).

    Parameters
    ----------
    table : Table
        A loaded table (:func:`gainsched.load_table`).
    midpoints : tuple of three ndarray, shape (m,), optional
        ``(speed m/s, tilt rad, relative gain error)`` of checked cell midpoints
        (:func:`gainsched.midpoint_check`): adds ``midpoint_error.png`` and the errors to
        the JSON.
    source : str, default ""
        The file name the JSON reports as ``"table"`` (default: ``table.source``).
    progress : callable or None, default None
        Called with 1 after each file rendered (:func:`plot_count` of them; e.g. a
        progress bar's ``update``).

    Returns
    -------
    dict of str to bytes
        File name -> contents: the PNG files and ``plots.json``, the
        :func:`table_summary` (grid, per-tilt gain ranges ``gains[tilt_deg][input][state]
        = [min, max]``, nominal thrust and roll ranges, spectral radius per circle) plus
        ``files`` (every file name) and, with ``midpoints``, ``midpoint_error``
        (``speeds_mps``, ``tilts_deg`` and the ``max_relative_error`` over the azimuth per
        midpoint); sorted keys.

    See Also
    --------
    schedule_figures : The figures as matplotlib objects.

    Examples
    --------
    The plots of a small level-circle table, written to a folder:

    >>> import json, tempfile
    >>> from gainsched.publish import publish
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> small = cfg.with_values({"grid.speeds": [6, 9], "grid.tilts_deg": [0],
    ...                          "grid.azimuth_samples": 8, "name": "small"})
    >>> out = tempfile.mkdtemp()
    >>> table = gs.load_table(gs.write_outputs(out, small, gs.build_grid(small))[0])
    >>> files = gs.schedule_plots(table)
    >>> sorted(files)
    ['delay_margin.png', 'envelope.png', 'gain_margin.png', 'gains_tilt0.png', 'nominal.png',
     'plots.json', 'spectral_radius.png', 'time_constant.png']
    >>> summary = json.loads(files["plots.json"])
    >>> summary["speeds_mps"], [round(x, 3) for x in summary["spectral_radius"][0]]
    ([6.0, 9.0], [0.84, 0.952])
    >>> paths = publish(f"{out}/plots", files)
    """
    files = {}
    for name, make in _figure_makers(_pyplot(), table, midpoints).items():
        files[name] = _png(make())
        if progress is not None:
            progress(1)
    files["envelope.png"] = envelope_png(envelope_from_table(table))
    if progress is not None:
        progress(1)
    summary = table_summary(table, source=source)
    summary["files"] = sorted([*files, "plots.json"])
    if midpoints is not None:
        vs, ts, grid = _midpoint_grid(midpoints)
        summary["midpoint_error"] = {
            "speeds_mps": vs.tolist(), "tilts_deg": np.rad2deg(ts).tolist(),
            "max_relative_error": _json_grid(grid)}
    files["plots.json"] = (json.dumps(summary, indent=2, sort_keys=True) + "\n").encode()
    return files
