"""The checks of a built table on the host: its interpolation (``gainsched check``,
:func:`midpoint_check`) and that it loads into the runtime's form
(:func:`check_runtime_data`).

At every cell midpoint of the (speed, tilt, azimuth) grid the periodic LQR is
solved directly and compared with what the runtime interpolates from the table
(:class:`~gainsched.firmware.runtime.Interpolator`); along every midpoint circle the loop
is closed with the interpolated gains and its monodromy spectral radius
reported. docs/runtime.md states the accuracy the default grid meets.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ...errors import InputError
from ...schedule.grid import solve_circle
from ...schedule.lqr import monodromy, spectral_radius
from ...schedule.refine import midpoint_errors
from ...schedule.tables import config_from_table, load_table
from ..runtime import Interpolator, RuntimeData, runtime_data

__all__ = ["MidpointCheck", "MidpointCircle", "MidpointPoint", "midpoint_check",
           "check_runtime_data"]


class MidpointCircle(NamedTuple):
    """One midpoint circle of a :class:`MidpointCheck`: its loop closed at every control
    step with the interpolated gains and with the directly solved ones."""

    #: m/s
    speed: float
    #: rad
    tilt: float
    #: monodromy spectral radius with the interpolated gains (NaN: a lookup not OK)
    rho_interp: float
    #: with the directly solved gains
    rho_direct: float


class MidpointPoint(NamedTuple):
    """A checked midpoint and its error (:meth:`MidpointCheck.worst_point`)."""

    #: m/s
    speed: float
    #: rad
    tilt: float
    #: rad
    xi: float
    #: ``||K_interp - K_direct||_F / ||K_direct||_F``
    rel_err: float


class ByAxis(NamedTuple):
    """The largest error per speed midpoint and per tilt midpoint
    (:meth:`MidpointCheck.by_axis`): value -> max error."""

    speed: dict
    tilt: dict


@dataclass(frozen=True)
class MidpointCheck:
    """Interpolation versus direct LQR solves at cell midpoints.

    Attributes
    ----------
    speed, tilt : (m,) m/s, rad of the checked midpoints; xi : (m,) rad
    rel_err : (m,) ``||K_interp - K_direct||_F / ||K_direct||_F`` (NaN where skipped)
    u_err : (m,) max |u_d interp - u_d direct|, N
    u_rel : (m,) that error relative to the circle's largest nominal thrust
    phi_rel : (m,) ``|phi_d interp - phi_d direct|`` relative to the circle's largest roll
    circles : list of :class:`MidpointCircle` (speed m/s, tilt rad, rho_interp, rho_direct)
    skipped : number of midpoints skipped (direct solve infeasible or an infeasible corner)
    """

    speed: np.ndarray
    tilt: np.ndarray
    xi: np.ndarray
    rel_err: np.ndarray
    u_err: np.ndarray
    circles: list
    skipped: int
    u_rel: np.ndarray | None = None
    phi_rel: np.ndarray | None = None

    @property
    def max_err(self) -> float:
        e = self.rel_err[np.isfinite(self.rel_err)]
        return float(e.max()) if e.size else float("nan")

    @property
    def median_err(self) -> float:
        e = self.rel_err[np.isfinite(self.rel_err)]
        return float(np.median(e)) if e.size else float("nan")

    @property
    def worst_rho(self) -> float:
        r = [c.rho_interp for c in self.circles if np.isfinite(c.rho_interp)]
        return float(max(r)) if r else float("nan")

    @property
    def max_nominal_err(self) -> float:
        """The largest relative error of the nominal thrusts and roll (as the build's grid
        choice measures them, :func:`gainsched.schedule.refine.midpoint_errors`)."""
        e = np.concatenate([self.u_rel, self.phi_rel])
        e = e[np.isfinite(e)]
        return float(e.max()) if e.size else float("nan")

    @property
    def stable(self) -> bool:
        """Every midpoint circle closed with the interpolated gains is stable (spectral
        radius < 1; circles without one are not counted)."""
        return all(c.rho_interp < 1 for c in self.circles if np.isfinite(c.rho_interp))

    def passed(self, max_error: float, nominal: bool = False) -> bool:
        """The pass rule of ``gainsched check``: some midpoint checked, the largest
        relative error within ``max_error`` (a fraction: 0.02 for 2 %), and every midpoint
        circle stable. ``nominal``: the error counted is the gains' or the nominal
        thrusts' and roll's, whichever is larger (a grid the build chose promised all
        three, docs/grid.md).

        Example
        -------
        >>> res = MidpointCheck(np.zeros(1), np.zeros(1), np.zeros(1), np.array([0.01]),
        ...                     np.zeros(1), [MidpointCircle(5.0, 0.0, 0.97, 0.96)], 0)
        >>> res.passed(0.02), res.passed(0.005)
        (True, False)
        """
        worst = max(self.max_err, self.max_nominal_err) if nominal else self.max_err
        return bool(np.isfinite(self.rel_err).any() and worst <= max_error and self.stable)

    def worst_point(self) -> MidpointPoint:
        """The midpoint of the largest error: ``speed``, ``tilt``, ``xi``, ``rel_err``."""
        e = np.where(np.isfinite(self.rel_err), self.rel_err, -1)
        i = int(np.argmax(e))
        return MidpointPoint(self.speed[i], self.tilt[i], self.xi[i], self.rel_err[i])

    def by_axis(self) -> ByAxis:
        """Max error per speed-midpoint and per tilt-midpoint: ``speed`` and ``tilt``, two
        dicts value -> max."""
        out = []
        for ax in (self.speed, self.tilt):
            d = {}
            for v in np.unique(ax):
                e = self.rel_err[(ax == v) & np.isfinite(self.rel_err)]
                d[float(v)] = float(e.max()) if e.size else float("nan")
            out.append(d)
        return ByAxis(*out)


def midpoint_check(table, *, speed_stride: int = 1, progress=None,
                   lookup=None) -> MidpointCheck:
    """Check a table's interpolation error at its cell midpoints against direct LQR solves.

    At the midpoints of the (speed, tilt, azimuth) cells, where the interpolation is
    furthest from the grid, the periodic LQR is solved directly from the table's own
    config and compared with what the runtime interpolates
    (:class:`gainsched.Interpolator`); along every midpoint circle the loop is closed with
    the interpolated gains at every control step and its monodromy spectral radius
    reported. This is ``gainsched check``; docs/runtime.md states the accuracy the
    default grid meets (below 2 %).

    Parameters
    ----------
    table : Table
        A loaded table (:func:`gainsched.load_table`); its embedded ``config_text`` is
        solved again.
    speed_stride : int, default 1
        Check every ``speed_stride``-th speed midpoint (1: all ``n_v - 1``). All tilt
        midpoints (tilt 0 alone for a one-tilt table) and all ``n_xi`` azimuth
        midpoints are checked at each.
    progress : callable or None, default None
        Called with 1 after each checked speed midpoint (e.g. ``tqdm.update``).
    lookup : callable or None, default None
        What is checked: ``lookup(xi, xi_dot, alpha) -> Lookup`` on arrays of queries;
        default the table's dense lookup (``Interpolator(table)``); a
        :class:`~gainsched.firmware.compact.CompactInterpolator` checks the compact form.

    Returns
    -------
    MidpointCheck
        The checked midpoints ``speed`` (m/s; negative: reversed, see Notes), ``tilt``
        (rad), ``xi`` (rad), each (m,);
        ``rel_err`` (m,) ``||K_interp - K_direct||_F / ||K_direct||_F`` (NaN where
        skipped) and ``u_err`` (m,) the largest nominal-thrust error, N; ``u_rel`` and
        ``phi_rel`` (m,) the nominal thrust and roll errors relative to the circle's
        largest (:func:`gainsched.schedule.refine.midpoint_errors`); ``circles``:
        :class:`MidpointCircle` ``(speed m/s, tilt rad, rho_interp, rho_direct)``, the
        closed-loop spectral radii per midpoint circle; ``skipped``: midpoints without a
        comparison (the direct solve infeasible or a lookup not OK); summaries
        ``max_err``, ``median_err``, ``worst_rho``, ``worst_point()``, ``by_axis()``
        (:class:`gainsched.firmware.host.check.MidpointCheck`).

    Raises
    ------
    InputError
        The table's config cannot be loaded in this process (an effect registered in
        another one) or the table cannot be held in the runtime's float32 form.

    See Also
    --------
    gainsched.schedule_plots : Plot the errors (``midpoint_error.png``).

    Notes
    -----
    One :func:`gainsched.solve_circle` per speed midpoint, all tilt midpoints batched,
    with ``2 n_xi`` azimuth samples so that the odd ones are the azimuth midpoints: the
    cost of a check is about that of a build, divided by ``speed_stride``. A table of
    both flight directions (``Table.reverse``) is checked on the reversed circles too.

    Examples
    --------
    >>> table = gs.load_table("tables/paper.h5")
    >>> chk = gs.midpoint_check(table, speed_stride=6)   # 3 of the 18 speed midpoints
    >>> sorted(set(chk.speed.tolist()))                  # m/s
    [1.65, 4.75, 9.5]
    >>> chk.rel_err.shape, chk.skipped                   # 3 x 6 tilts x 36 azimuths
    ((648,), 216)
    >>> round(100 * chk.max_err, 1), chk.max_err < 0.02  # largest gain error, %
    (1.6, True)
    >>> chk.worst_rho < 1                                # interpolated gains: stable
    True
    """
    interp = Interpolator(table) if lookup is None else lookup
    cfg = config_from_table(table)
    n_xi = table.xi.size
    cfg2 = cfg.with_values({"grid.azimuth_samples": 2 * n_xi})
    r = cfg.radius
    v_mid = 0.5 * (table.speed[1:] + table.speed[:-1])[::speed_stride]
    a_mid = 0.5 * (table.tilt[1:] + table.tilt[:-1])
    if a_mid.size == 0:
        a_mid = table.tilt[:1]
    xi_mid = (np.arange(n_xi) + 0.5) * (2 * np.pi / n_xi)
    rows = {k: [] for k in ("speed", "tilt", "xi", "err", "uerr", "urel", "phirel")}
    circles, skipped = [], 0
    directions = (1.0,) if getattr(table, "reverse", None) is None else (1.0, -1.0)
    for v in (sign * float(v) for sign in directions for v in v_mid):
        sol, steps = solve_circle(cfg2, v, a_mid, keep_steps=True, margins=False)
        skipped += _midpoint_rows(rows, interp, sol, v, r, a_mid, np.copysign(xi_mid, v))
        if steps is not None:
            circles += _midpoint_circles(interp, sol, steps, v, r, a_mid)
        if progress is not None:
            progress(1)
    cat = {k: np.concatenate(x) if x else np.zeros(0) for k, x in rows.items()}
    return MidpointCheck(
        cat["speed"], cat["tilt"], cat["xi"], cat["err"], cat["uerr"], circles, skipped,
        cat["urel"], cat["phirel"]
    )


def _midpoint_rows(rows: dict, interp, sol, v: float, r: float, a_mid, xi_mid) -> int:
    """The errors at the azimuth midpoints of every tilt midpoint of the speed midpoint
    ``v`` (m/s; negative: reversed), appended to ``rows``: the lookup at ``xi_mid`` (rad;
    negative on a reversed circle), ``v / r`` (rad/s) against the direct solve ``sol``
    (odd samples of its ``2 n_xi``). Returns how many
    midpoints have no comparison (direct solve infeasible or lookup not OK)."""
    n_xi, skipped = xi_mid.size, 0
    for i, a in enumerate(a_mid):
        Kd = sol.K[i, 1::2]
        look = interp(xi_mid, v / r, a)
        use = np.all(np.isfinite(Kd), axis=(-2, -1)) & (look.status == 0)
        skipped += int(np.count_nonzero(~use))
        with np.errstate(invalid="ignore"):
            err, urel, phirel = midpoint_errors(
                look.K, Kd, look.u_d, sol.u_d[i, 1::2], look.phi_d, sol.phi_d[i, 1::2],
                np.abs(sol.u_d[i]).max(), np.abs(sol.phi_d[i]).max())
        uerr = np.abs(look.u_d - sol.u_d[i, 1::2]).max(-1)
        rows["speed"].append(np.full(n_xi, v))
        rows["tilt"].append(np.full(n_xi, a))
        rows["xi"].append(xi_mid)
        rows["err"].append(np.where(use, err, np.nan))
        rows["uerr"].append(np.where(use, uerr, np.nan))
        rows["urel"].append(np.where(use, urel, np.nan))
        rows["phirel"].append(np.where(use, phirel, np.nan))
    return skipped


def _midpoint_circles(interp, sol, steps, v: float, r: float, a_mid) -> list[MidpointCircle]:
    """The :class:`MidpointCircle` (speed m/s, tilt rad, rho_interp, rho_direct) of every
    feasible midpoint circle at the speed ``v``: the loop closed at every control step
    with the interpolated gains (NaN where a lookup is not OK) and with the direct ones;
    a reversed circle (``v < 0``) runs through ``-xi``."""
    Ad, Bd, _ = steps
    N = Ad.shape[-3]
    xs = np.copysign(2 * np.pi * np.arange(N) / N, v)
    out = []
    for b, i in enumerate(np.flatnonzero(np.isfinite(sol.spectral_radius))):
        look = interp(xs, v / r, a_mid[i])
        direct = float(sol.spectral_radius[i])
        if np.any(look.status != 0):
            out.append(MidpointCircle(v, float(a_mid[i]), np.nan, direct))
            continue
        interpolated = float(spectral_radius(monodromy(Ad[b], Bd[b], look.K)))
        out.append(MidpointCircle(v, float(a_mid[i]), interpolated, direct))
    return out


def check_runtime_data(table_path) -> RuntimeData:
    """Load a table file and convert it, raising InputError for problems."""
    try:
        return runtime_data(load_table(table_path))
    except ValueError as exc:  # an InputError (a ValueError too) keeps its file and key
        raise exc if isinstance(exc, InputError) else InputError(table_path, "", f"{exc}") from None
