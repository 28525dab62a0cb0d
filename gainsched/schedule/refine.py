"""Automatic breakpoints: speed and tilt axes refined until every cell midpoint meets a bound.

A ``[grid]`` axis given as a range (``speeds = {min = 3, max = 20, max_count = 40}``,
the same for ``tilts_deg``; :class:`gainsched.config.AxisRange`) is chosen by the
build (docs/grid.md):

1. **Seeds.** The range's ends and its middle.
2. **Breakpoint circles.** Every (speed, tilt) pair of breakpoints not solved yet is
   solved (:func:`~.grid.solve_circle`, one job per speed), once: later rounds reuse it.
3. **Plan from what is solved.** A breakpoint that halved an interval measures that
   interval's interpolation error at its midpoint for free (its hierarchical
   surplus): the linear interpolation between the ends against the circle there. The
   error of linear interpolation shrinks with the square of the width, so each half is
   estimated at a quarter of it, and a cell's centre at the sum of its speed and tilt
   estimates. Where that exceeds the bound, the cell is halved along the axis with the
   larger estimate (as many times as the square law says) and the round starts again,
   without any other solve. Cells the envelope's edge runs through (a feasible and an
   infeasible corner along the speed) are halved until they span at most
   :data:`EDGE_SHARE` of the range, so that the usable table reaches that close to it.
4. **Certificate.** At the centre of every cell (mid speed, mid tilt) the periodic LQR
   is solved at twice the azimuth samples, so that its odd samples are the azimuth
   midpoints: where the runtime's trilinear interpolation is furthest from its
   corners. The errors there (:func:`midpoint_errors`: gains as ``gainsched check``
   measures them, nominal thrusts and roll) and the loop closed along the centre
   circle with the interpolated gains (monodromy spectral radius) decide. A cell with
   an infeasible corner has no usable lookup and is skipped, as ``check`` skips it. A
   cell that fails is halved along the axis with the larger estimate, back to 2; a
   cell's certificate is kept until the cell is split. The build ends when every cell
   passes, or fails with an :class:`~gainsched.errors.InputError` naming the key and
   the worst cell when an axis would exceed its ``max_count`` (or when the azimuth
   interpolation alone exceeds the bound: no speed or tilt can mend that).

An azimuth count given as a range (``azimuth_samples = {min = 12, max = 96}``) starts at
``min``. Each centre solve also measures the interpolation along the azimuth alone;
where that takes more than :data:`AZIMUTH_SHARE` of the bound (checked first at the
seed cells' centres, then at every certificate), the count is doubled as often as the
square law asks, up to ``max``, and every circle is solved again at the new azimuths
(the speed and tilt breakpoints are kept).

The result does not depend on the machine: the circles are solved on pinned numerics
(as every build), and every decision compares errors rounded to
:data:`ERROR_QUANTUM` (0.01 %) with the bound less one quantum (so ``check``, which
interpolates the float32 table, passes too).
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import astuple, dataclass, field, fields, replace

import numpy as np

from ..errors import InputError
from ..model.effects import registered_effects
from ..model.reduced import Model
from ..native.reproducible import blas_single_thread
from .bounds import check_gain_cap, check_margin_bounds
from .certificate import (
    ERROR_QUANTUM,
    STABLE_RADIUS,
    Centre,
    check_centres,
    midpoint_errors,
    quanta,
)
from .choice import GridChoice, grid_auto_lines
from .grid import (
    CircleSolution,
    GridResult,
    check_effect_symmetries,
    grid_from_solutions,
    level_circle_invariant,
    mirror_config,
    solve_speed,
    solve_speed_and_image,
)
from .jobs import run_jobs

__all__ = ["refine_grid", "GridChoice", "midpoint_errors", "grid_auto_lines", "ERROR_QUANTUM"]

#: cells the envelope's edge runs through are halved until they span at most this share of
#: their axis's range (the usable table then reaches that close to the edge)
EDGE_SHARE = 1 / 16
#: share of the bound the interpolation along the azimuth alone may take at a cell centre
#: when the build chooses the azimuth count (the speed and tilt take the rest)
AZIMUTH_SHARE = 0.5
@dataclass
class _Axis:
    """One axis during refinement: breakpoints in the config's unit (m/s or deg)."""

    key: str  # "speeds" or "tilts_deg"
    values: list
    auto: object  # AxisRange or None
    parent: dict = field(default_factory=dict)  # interval -> the interval it halves

    def intervals(self):
        v = self.values
        return list(zip(v[:-1], v[1:], strict=True)) if len(v) > 1 else [(v[0], v[0])]

    def room(self) -> int:
        """Breakpoints still allowed (0 on a list axis)."""
        return self.auto.max_count - len(self.values) if self.auto else 0

    @staticmethod
    def halves(intervals, levels=None):
        """The breakpoints that halve ``intervals`` ``levels[iv]`` times (default once),
        with the parent of every new half: ``(new values, {half: parent})``."""
        new, parent = [], {}
        for iv in intervals:
            todo = [iv]
            for _ in range(1 if levels is None else levels[iv]):
                nxt = []
                for lo, hi in todo:
                    mid = 0.5 * (lo + hi)
                    parent[lo, mid] = parent[mid, hi] = (lo, hi)
                    new.append(mid)
                    nxt += [(lo, mid), (mid, hi)]
                todo = nxt
        return new, parent

    def split(self, intervals, levels=None) -> None:
        """Insert the breakpoints of :meth:`halves`."""
        new, parent = self.halves(intervals, levels)
        self.parent.update(parent)
        self.values = sorted(self.values + new)


#: the per-tilt arrays of a CircleSolution (the others, steps and dt, are per speed)
_PER_TILT = tuple(f.name for f in fields(CircleSolution) if f.name not in ("steps", "dt"))


def _one(sol: CircleSolution, i: int) -> CircleSolution:
    """Tilt ``i`` of a solution, as a one-tilt solution."""
    return replace(sol, **{k: getattr(sol, k)[i:i + 1] for k in _PER_TILT})


def _rad(a_deg) -> np.ndarray:
    """Tilts as the config holds them (``np.deg2rad`` of the file's degrees)."""
    return np.deg2rad(np.asarray(a_deg, dtype=float))


def _feasible(sol: CircleSolution) -> bool:
    return bool(np.isfinite(sol.spectral_radius[0]))


class _Refiner:
    """The state of one refinement (module docs): the axes, every circle solved, the
    surpluses measured and the cells certified; one method per step."""

    def __init__(self, config, n_jobs, progress, backend):
        g = config.grid
        self.config, self.n_jobs, self.progress, self.backend = config, n_jobs, progress, backend
        self.bound = g.max_interpolation_error
        self.limit = quanta(self.bound) - 1  # one quantum of margin to the bound
        self.speeds = _Axis("speeds", [float(v) for v in g.speeds], g.speeds_auto)
        tilt_deg = g.tilts_auto.seeds() if g.tilts_auto else np.rad2deg(g.tilts)
        self.tilts = _Axis("tilts_deg", [float(a) for a in tilt_deg], g.tilts_auto)
        # a list tilt axis is kept in the config's radians exactly
        self.rad_of = {} if g.tilts_auto else dict(zip(self.tilts.values, g.tilts.tolist(),
                                                       strict=True))
        for axis in (self.speeds, self.tilts):
            if axis.auto is not None and len(axis.values) == 3:  # the seeds halve the range
                lo, mid, hi = axis.values
                axis.parent[lo, mid] = axis.parent[mid, hi] = (lo, hi)
        self.effects = registered_effects({s.name for s in config.effects})
        self.invariant = level_circle_invariant(Model(config))
        # a vehicle that is not its own mirror image: its image is solved and certified
        # beside it, circle for circle, and a cell holds when both halves hold
        self.image = mirror_config(config)
        self.azimuth = g.azimuth_auto  # AzimuthRange or None
        self.reused = self.centre_solves = self.rounds = self.restarts = self.dropped = 0
        self._start(g.azimuth_samples)

    def set_azimuth(self, n_xi: int) -> None:
        """Solve at ``n_xi`` azimuth samples from now on: every circle solved so far is
        dropped (its samples are at the old azimuths); the axes are kept."""
        self.restarts += 1
        self.dropped += len(self.points)
        self._start(n_xi)

    def _start(self, n_xi: int) -> None:
        """No circle solved yet, at ``n_xi`` azimuth samples."""
        self.n_xi = n_xi
        self.solve_config = self.config.with_values({"grid.azimuth_samples": n_xi})
        self.config2 = self.config.with_values({"grid.azimuth_samples": 2 * n_xi})
        image = self.image
        self.image_config = None if image is None else (
            image.with_values({"grid.azimuth_samples": n_xi}),
            image.with_values({"grid.azimuth_samples": 2 * n_xi}))
        self.points = {}  # (v, a_deg) -> CircleSolution of one tilt
        self.image_points = {}  # the same of the mirror image (self.image)
        self.meta = {}  # v -> (steps, dt)
        self.centres = {}  # (v_lo, v_hi, a_lo, a_hi) -> Centre
        self.surpluses = {}  # (axis key, parent interval, other breakpoint) -> error

    # ------------------------------------------------------------------ solving

    def rad(self, a) -> float:
        return self.rad_of.get(a, float(_rad(a)))

    def _run(self, job, args):
        with blas_single_thread():
            for a, res in zip(args, run_jobs(args, self.n_jobs, self.backend, job),
                              strict=True):
                yield a, res
                if self.progress is not None:
                    self.progress(len(a[2]))

    def solve_points(self, pts) -> None:
        """Solve the breakpoint circles ``pts`` ((v, a_deg)) not solved yet."""
        todo = defaultdict(list)
        for v, a in sorted(set(pts)):
            if (v, a) in self.points:
                self.reused += 1
            else:
                todo[v].append(a)
        args = [(self.solve_config, v, np.array([self.rad(a) for a in ts]), self.effects,
                 self.invariant) for v, ts in todo.items()]
        if self.image_config is not None:
            args = [(*a, self.image_config[0]) for a in args]
        job = solve_speed if self.image is None else solve_speed_and_image
        for (_, v, *_), sol in self._run(job, args):
            own, img = (sol, None) if self.image is None else sol
            self.meta[v] = (own.steps, own.dt)
            for i, a in enumerate(todo[v]):
                self.points[v, a] = _one(own, i)
                if img is not None:
                    self.image_points[v, a] = _one(img, i)

    def certify(self, cells) -> None:
        """Solve the centres of the cells not certified yet (a cell with an infeasible
        corner gets an empty certificate: it is skipped)."""
        todo = defaultdict(list)
        for cell in cells:
            if cell in self.centres:
                continue
            if not all(self.feasible(p) for p in _corners(cell)):
                self.centres[cell] = Centre()
                continue
            data = [tuple(np.stack([getattr(pts[p], k)[0] for p in _corners(cell)])
                          for k in ("K", "u_d", "phi_d"))
                    for pts in ((self.points,) if self.image is None
                                else (self.points, self.image_points))]
            todo[0.5 * (cell[0] + cell[1])].append((cell, data))
            self.centre_solves += 1
        args = [(self.config2, v, np.array([self.rad(0.5 * (c[2] + c[3])) for c, _ in items]),
                 [d[0] for _, d in items], self.effects, self.invariant)
                for v, items in todo.items()]
        if self.image_config is not None:
            args = [(*a, self.image_config[1], [d[1] for _, d in todo[a[1]]]) for a in args]
        job = check_centres if self.image is None else _centres_with_image
        for (_, v, *_), res in self._run(job, args):
            for (cell, _), centre in zip(todo[v], res, strict=True):
                self.centres[cell] = centre

    def feasible(self, p) -> bool:
        """Whether the circle ``p`` ((v, a_deg)) is feasible, for the mirror image too."""
        return _feasible(self.points[p]) and (self.image is None
                                               or _feasible(self.image_points[p]))

    def fails(self, cell) -> bool:
        c = self.centres[cell]
        return c.usable and (quanta(c.error) > self.limit or not c.rho < STABLE_RADIUS)

    # ------------------------------------------------------------------ estimates

    def edge_error(self, p_lo, p_hi, p_mid) -> float:
        """Largest error of the linear interpolation between two circles at the middle
        one, at the grid azimuths (NaN when one of them is infeasible)."""
        if not all(self.feasible(p) for p in (p_lo, p_hi, p_mid)):
            return math.nan
        out = []
        for pts in (self.points,) if self.image is None else (self.points, self.image_points):
            a, b, m = pts[p_lo], pts[p_hi], pts[p_mid]
            errs = midpoint_errors(0.5 * (a.K[0] + b.K[0]), m.K[0],
                                   0.5 * (a.u_d[0] + b.u_d[0]), m.u_d[0],
                                   0.5 * (a.phi_d[0] + b.phi_d[0]), m.phi_d[0],
                                   np.abs(m.u_d[0]).max(), np.abs(m.phi_d[0]).max())
            out.append(float(max(e.max() for e in errs)))
        return out[0] if len(out) == 1 else float(np.fmax(*out))

    def estimate(self, axis, iv, others) -> float:
        """Estimated error at the midpoint of the interval ``iv`` of ``axis`` along the
        other axis's breakpoints ``others``: a quarter (h^2) of the error its parent
        interval had at its midpoint, a breakpoint now (the hierarchical surplus); 0 on
        a list axis, inf where unknown (no parent, or its circles infeasible)."""
        if axis.auto is None or iv[0] == iv[1]:
            return 0.0
        parent = axis.parent.get(iv)
        if parent is None:
            return math.inf
        lo, hi = parent
        mid = 0.5 * (lo + hi)
        errs = []
        for o in others:
            key = (axis.key, parent, o)
            if key not in self.surpluses:
                pts = ([(lo, o), (hi, o), (mid, o)] if axis is self.speeds
                       else [(o, lo), (o, hi), (o, mid)])
                self.surpluses[key] = self.edge_error(*pts)
            errs.append(self.surpluses[key])
        # unknown where the parent's circles are infeasible: halve to learn it
        return max((e for e in errs if not math.isnan(e)), default=math.inf) / 4

    def cell_estimates(self, cell):
        """``(speed, tilt)`` estimates of a cell's edge errors."""
        v0, v1, a0, a1 = cell
        return (self.estimate(self.speeds, (v0, v1), {a0, a1}),
                self.estimate(self.tilts, (a0, a1), {v0, v1}))

    def edge_interval(self, cell):
        """For a cell with feasible and infeasible corners along the speed (the
        envelope's edge, a slowest or fastest speed per tilt, runs through it) on an
        automatic speed axis: its speed interval; else None."""
        v0, v1, a0, a1 = cell
        if self.speeds.auto is None:
            return None
        f = {p: self.feasible(p) for p in _corners(cell)}
        if any(f[v0, a] != f[v1, a] for a in (a0, a1)):
            return v0, v1
        return None

    def choose(self, cell):
        """``(axis, e_split, e_other)``: the axis to halve a cell along (the larger
        estimate among the axes with room; ties to the speed), or None."""
        e_v, e_a = self.cell_estimates(cell)
        opts = [(e, ax, o) for e, ax, o in ((e_v, self.speeds, e_a), (e_a, self.tilts, e_v))
                if ax.auto is not None and ax.room() > 0]
        if not opts:
            return None
        return max(opts, key=lambda t: (quanta(t[0]), t[1] is self.speeds))

    # ------------------------------------------------------------------ rounds

    def cells(self):
        return [(v0, v1, a0, a1) for v0, v1 in self.speeds.intervals()
                for a0, a1 in self.tilts.intervals()]

    def plan(self) -> bool:
        """Halve the cells the estimates (no solve) say fail, and the envelope's edge
        cells wider than :data:`EDGE_SHARE`; False when there is none."""
        want = {"speeds": {}, "tilts_deg": {}}
        target = self.limit * ERROR_QUANTUM
        for cell in self.cells():
            edge = self.edge_interval(cell)
            if edge is not None:
                rng = self.speeds.auto
                if edge[1] - edge[0] > EDGE_SHARE * (rng.hi - rng.lo):
                    want["speeds"].setdefault(edge, 1)
                continue
            if (not all(self.feasible(p) for p in _corners(cell))
                    or quanta(sum(self.cell_estimates(cell))) <= self.limit):
                continue
            pick = self.choose(cell)
            if pick is None:
                continue
            e, axis, other = pick
            iv = (cell[0], cell[1]) if axis is self.speeds else (cell[2], cell[3])
            k = _halvings(e, max(target - other, 0.5 * target))
            want[axis.key][iv] = max(k, want[axis.key].get(iv, 0))
        planned = False
        for axis in (self.speeds, self.tilts):
            free, take = axis.room(), {}
            for iv in sorted(want[axis.key]):
                n = 2 ** want[axis.key][iv] - 1
                if n <= free:
                    take[iv], free = want[axis.key][iv], free - n
            if take:
                new, _ = axis.halves(sorted(take), take)
                _check_float32(self.config, axis, new, self.bound,
                               "the cells' surpluses ask for them")
                axis.split(sorted(take), take)
                planned = True
        return planned

    def mend(self, failing) -> None:
        """Halve every failing cell along its :meth:`choose` axis; raise when no axis has
        room or a split would exceed ``max_count`` or collapse in float32."""
        worst = max(failing, key=lambda c: (quanta(self.centres[c].error), c))
        pick = {"speeds": set(), "tilts_deg": set()}
        for cell in failing:
            _check_azimuth(self.config, self.n_xi, cell, self.centres[cell], self.bound,
                           self.limit)
            choice = self.choose(cell)
            if choice is None:  # every automatic axis is at its max_count
                axis = self.speeds if self.speeds.auto is not None else self.tilts
                _refuse_count(self.config, axis, cell, self.centres[cell], self.bound)
            axis = choice[1]
            pick[axis.key].add((cell[0], cell[1]) if axis is self.speeds
                               else (cell[2], cell[3]))
        for axis in (self.speeds, self.tilts):
            if pick[axis.key]:
                new, _ = axis.halves(sorted(pick[axis.key]))
                _check_split(self.config, axis, new, worst, self.centres[worst], self.bound)
                axis.split(sorted(pick[axis.key]))

    def choose_azimuth(self, worst: float) -> bool:
        """For an automatic azimuth count: when the interpolation along the azimuth
        alone is above :data:`AZIMUTH_SHARE` of the bound at a cell centre (``worst``),
        double the count (as often as the square law asks, up to the range's largest)
        and start the circles again; False when the count stays."""
        if self.azimuth is None:
            return False
        target = AZIMUTH_SHARE * self.limit * ERROR_QUANTUM
        top = self.azimuth.lo * 2 ** int(math.log2(self.azimuth.hi // self.azimuth.lo))
        if quanta(worst) <= math.floor(AZIMUTH_SHARE * self.limit) or self.n_xi >= top:
            return False
        self.set_azimuth(min(self.n_xi * 2 ** _halvings(worst, target), top))
        return True

    def azimuth_at(self, cells) -> float:
        """Certify ``cells``; the largest error of the azimuth interpolation alone at
        their centres."""
        self.certify(cells)
        return max((self.centres[c].azimuth for c in cells if self.centres[c].usable),
                   default=0.0)

    def run(self) -> GridChoice:
        probed = self.azimuth is None
        while True:
            self.rounds += 1
            self.solve_points([(v, a) for v in self.speeds.values for a in self.tilts.values])
            if not probed:  # the seed cells' centres tell the azimuth count first
                probed = True
                if self.choose_azimuth(self.azimuth_at(self.cells())):
                    continue
            if self.plan():
                continue
            cells = self.cells()
            if self.choose_azimuth(self.azimuth_at(cells)):
                continue
            failing = [c for c in cells if self.fails(c)]
            if not failing:
                return self.result(cells)
            self.mend(failing)

    # ------------------------------------------------------------------ the result

    def grid(self, points) -> GridResult:
        """The grid of the chosen axes assembled from the solved circles ``points``."""
        sols = []
        for v in self.speeds.values:
            parts = [points[v, a] for a in self.tilts.values]
            steps, dt = self.meta[v]
            sols.append(CircleSolution(
                **{k: np.concatenate([getattr(p, k) for p in parts]) for k in _PER_TILT},
                steps=steps, dt=dt))
        return grid_from_solutions(sols, self.invariant)

    def result(self, cells) -> GridChoice:
        """The chosen config (the axes as lists, the ranges kept as comments), the grid
        assembled from the solved circles, and the certificate's figures."""
        from ..config import config_from_text, set_value

        text = self.config.text
        for key, value, rng in ((a.key, a.values, a.auto) for a in (self.speeds, self.tilts)):
            if rng is not None:
                text = set_value(text, "grid", key, value, comment=(
                    f"chosen by the build from {rng.spec()} (docs/grid.md)"))
        if self.azimuth is not None:
            text = set_value(text, "grid", "azimuth_samples", self.n_xi, comment=(
                f"chosen by the build from {self.azimuth.spec()} (docs/grid.md)"))
        chosen = config_from_text(text, self.config.source)
        assert chosen.grid.azimuth_samples == self.n_xi
        assert chosen.grid.speeds.tolist() == self.speeds.values
        assert chosen.grid.tilts.tolist() == [self.rad(a) for a in self.tilts.values]
        grid = self.grid(self.points)
        if self.image is not None:
            grid = replace(grid, reverse=self.grid(self.image_points))
            check_gain_cap(chosen, grid.reverse)
            check_margin_bounds(chosen, grid.reverse)
        check_gain_cap(chosen, grid)
        check_margin_bounds(chosen, grid)
        live = [(c, self.centres[c]) for c in cells if self.centres[c].usable]

        def worst_of(attr):
            return max((getattr(c, attr) for _, c in live), default=math.nan)

        worst = max(live, key=lambda x: (x[1].error, x[0]))[0] if live else (math.nan,) * 4
        return GridChoice(
            config=chosen, grid=grid, bound=self.bound, source_sha256=self.config.sha256,
            speeds_spec=self.speeds.auto.spec() if self.speeds.auto else None,
            tilts_spec=self.tilts.auto.spec() if self.tilts.auto else None,
            azimuth_spec=self.azimuth.spec() if self.azimuth else None,
            azimuth_error=worst_of("azimuth"), restarts=self.restarts, dropped=self.dropped,
            gain_error=worst_of("gain"), thrust_error=worst_of("thrust"),
            roll_error=worst_of("roll"), worst_rho=worst_of("rho"),
            worst_cell=tuple(float(x) for x in worst), cells=len(live),
            skipped=len(cells) - len(live), rounds=self.rounds, circles=len(self.points),
            reused=self.reused, centres=self.centre_solves, centres_final=len(live))


def _corners(cell):
    v0, v1, a0, a1 = cell
    return (v0, a0), (v1, a0), (v0, a1), (v1, a1)


def refine_grid(config, *, n_jobs=1, progress=None, backend=None) -> GridChoice:
    """Choose the breakpoints of the axes ``[grid]`` gives as ranges, and solve the grid.

    Refines ``grid.speeds`` and ``grid.tilts_deg`` (those given as ``{min, max,
    max_count}``) until the largest relative error of the interpolated gains, nominal
    thrusts and roll at every usable cell midpoint is within ``grid.max_interpolation_error``
    and the loop closed with interpolated gains along every midpoint circle is stable
    (module docs; docs/grid.md). Deterministic: the same config gives the same
    breakpoints and the same grid on every machine, with any ``n_jobs``.

    Parameters
    ----------
    config : Config
        A config with at least one axis as a range (``config.grid.auto``).
    n_jobs : int, default 1
        Worker processes (-1: all cores).
    progress : callable or None, default None
        Called with the number of circles solved after each job.
    backend : str, optional
        The joblib backend, as for :func:`~.grid.build_grid`.

    Returns
    -------
    GridChoice
        The config with the chosen axes, the grid, the errors met and the cost.

    Raises
    ------
    InputError
        An axis needs more than its ``max_count`` breakpoints, its cells would collapse
        in float32, or the azimuth interpolation alone exceeds the bound; naming the
        key and the worst cell.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> auto = cfg.with_values({"grid.speeds": {"min": 6, "max": 9, "max_count": 8},
    ...                         "grid.tilts_deg": {"min": 0, "max": 20, "max_count": 8},
    ...                         "grid.azimuth_samples": 16})
    >>> choice = gs.refine_grid(auto)
    >>> choice.config.grid.speeds.tolist()                  # m/s, chosen
    [6.0, 7.5, 9.0]
    >>> np.rad2deg(choice.config.grid.tilts).round(3).tolist()  # deg, chosen
    [0.0, 5.0, 10.0, 15.0, 20.0]
    >>> round(100 * choice.max_error, 2), choice.bound     # %, at the cell midpoints
    (1.93, 0.02)
    >>> choice.circles, choice.centres                      # solved: grid, certificate
    (15, 8)
    """
    if not config.grid.auto:
        raise InputError(config.source, "grid.speeds", "refine_grid needs an axis given as "
                         "a range {min, max, max_count}; a list grid is built by build_grid")
    check_effect_symmetries(config)  # the refiner solves both halves, as build_grid
    return _Refiner(config, n_jobs, progress, backend).run()


def _centres_with_image(config2, speed, tilts, corners, effects, dare_tilt0, image2,
                        image_corners):
    """One certificate job of a vehicle and its mirror image: per tilt, the worse of
    the two :class:`Centre` (each error and loop; unusable when either is)."""
    own = check_centres(config2, speed, tilts, corners, effects, dare_tilt0)
    img = check_centres(image2, speed, tilts, image_corners, effects, dare_tilt0)
    return [Centre(*(float(np.fmax(x, y)) for x, y in zip(astuple(a), astuple(b), strict=True)))
            if a.usable and b.usable else Centre() for a, b in zip(own, img, strict=True)]


def _halvings(estimate: float, target: float) -> int:
    """Halvings of an interval whose midpoint error is ``estimate`` until the error
    (quartered by each, h^2) meets ``target``; 1 for an unknown (inf) estimate, at most 3."""
    k = 1
    while k < 3 and math.isfinite(estimate) and estimate / 4 ** k > target:
        k += 1
    return k


def _where(cell) -> str:
    v0, v1, a0, a1 = cell
    return f"the cell {v0:g}-{v1:g} m/s x {a0:g}-{a1:g} deg"


def _check_azimuth(config, n_xi: int, cell, c: Centre, bound: float, limit: int) -> None:
    """Refuse a cell that no speed or tilt breakpoint can mend: the azimuth interpolation
    alone exceeds the bound there."""
    if quanta(c.azimuth) > limit:
        key = "azimuth_samples" + (".max" if config.grid.azimuth_auto else "")
        raise InputError(config.source, f"grid.{key}",
                         f"{n_xi} samples are too few for {100 * bound:g} %: the "
                         f"interpolation along the azimuth alone has {100 * c.azimuth:.2f} "
                         f"% at the centre of {_where(cell)}; raise grid.{key}")


def _why(cell, c: Centre) -> str:
    return (f"{_where(cell)} has {100 * c.error:.2f} % at its centre (gains "
            f"{100 * c.gain:.2f}, thrusts {100 * c.thrust:.2f}, roll {100 * c.roll:.2f}; "
            f"closed loop {c.rho:.5f})")


def _refuse_count(config, axis: _Axis, cell, c: Centre, bound: float) -> None:
    """The error when a cell fails and its axes are at their ``max_count`` (or lists)."""
    if axis.auto is None:
        raise InputError(config.source, f"grid.{axis.key}",
                         f"the listed breakpoints do not meet {100 * bound:g} %: "
                         f"{_why(cell, c)}; give grid.speeds or grid.tilts_deg as a range")
    raise InputError(config.source, f"grid.{axis.key}.max_count",
                     f"{axis.auto.max_count} breakpoints are not enough for {100 * bound:g} "
                     f"%: {_why(cell, c)}; raise max_count or grid.max_interpolation_error")


def _check_split(config, axis: _Axis, new, worst, c: Centre, bound: float) -> None:
    """Refuse a split beyond ``max_count`` or one that collapses in float32."""
    why = _why(worst, c)
    if len(axis.values) + len(new) > axis.auto.max_count:
        _refuse_count(config, axis, worst, c, bound)
    _check_float32(config, axis, new, bound, why)


def _check_float32(config, axis: _Axis, new, bound: float, why: str) -> None:
    """Refuse breakpoints the table's float32 axes cannot tell apart."""
    values = np.array(sorted(axis.values + list(new)))
    # as the table stores the axis: tilts in rad, speeds and azimuth rates speed / r
    stored = [_rad(values)] if axis.key == "tilts_deg" else [values, values / config.radius]
    for x in stored:
        if np.any(np.diff(x.astype(np.float32)) <= 0):
            raise InputError(config.source, f"grid.{axis.key}",
                             f"breakpoints closer than float32 resolves are needed for "
                             f"{100 * bound:g} %: {why}; raise grid.max_interpolation_error")
