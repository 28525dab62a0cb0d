"""A table's closed loops under the model's own uncertainty: ``gainsched check TABLE
--uncertain REPORT`` (issue 56, docs/margins.md).

A diagnosis fits the missing effect's parameters with 95 % intervals
(:mod:`gainsched.analysis.diagnose`). The table's gains were built for one model; the
vehicle is any model in that box. Each plant drawn over the box (its corners, the
estimate and random samples, seeded) is linearised along every circle of the table's
grid (its own nominal) and closed with the table's gains, interpolated in the azimuth
at every control step as the firmware does (effect states the gains do not know get no
feedback); its multipliers are those of the period's product (the margins' kernel,
:mod:`gainsched.schedule.margins`). The margins are then the worst of those of the
estimate, the corners and the plant with the worst multiplier, circle by circle (where
a margin moves monotonically with the parameters, its extreme over the box is at a
corner; the random samples are not searched for margins).

A parameter the fit did not identify (no finite interval: the diagnosis wrote the
config's own value instead of its estimate) is held at the table config's value in every
plant, and said so.

Where a loop is unstable, the parameter named is the one whose end of its interval,
the others at their estimates, gives the largest multiplier.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..model.reduced import Model
from ..schedule.certificate import xi_linear
from ..schedule.discrete import discrete_system
from ..schedule.margin_report import worst_lines, worst_margins
from ..schedule.margins import (
    MARGIN_DELAY_XTOL,
    MARGIN_XTOL,
    LoopMargins,
    loop_log_rho,
    loop_margins,
    surrogate_block,
)
from ..schedule.trim import TrimError
from .plan import focus_values, report_focus, truth_config

__all__ = ["Uncertainty", "uncertain_loops", "plant_count"]

#: random plants drawn inside the box besides its corners and the estimate
SAMPLES = 8


@dataclass(frozen=True)
class Uncertainty:
    """The table's loops on the plants of a diagnosis's 95 % box (:func:`uncertain_loops`).

    Attributes
    ----------
    focus : str
        The diagnosed effect (the report's accepted candidate).
    params : dict
        ``{name: (estimate, ci95 half-width, unit)}`` of its parameters.
    plants : ndarray, shape (P, p)
        The parameter values flown (the estimate, the corners, the samples).
    kinds : tuple of str
        ``"estimate"``, ``"corner"`` or ``"sample"`` per plant.
    rho : ndarray, shape (P, n_a, n_v)
        The largest multiplier of each plant's loop per circle (NaN: no gains there, or
        the plant has no nominal on that circle).
    speeds, tilts : ndarray
        The table's axes, m/s and rad.
    margins : LoopMargins or None
        Per circle, the worst margins of the estimate, the box's corners and the plant
        with the worst multiplier (None when a loop is unstable somewhere); the crossover
        is that of the plant with the smallest delay margin (None in a table without
        crossovers).
    culprit : tuple or None
        Where a loop is unstable: ``(parameter, value, multiplier)`` of the parameter whose
        interval's end, the others at their estimates, gives the largest multiplier.
    skipped : tuple of str
        Plants of the box that are no valid model (a parameter beyond its own limits).
    held : tuple of str
        Parameters the fit did not identify (no finite interval), held at the table
        config's value in every plant (their ``params`` entry: that value, half-width 0).
    """

    focus: str
    params: dict
    plants: np.ndarray
    kinds: tuple
    rho: np.ndarray
    speeds: np.ndarray
    tilts: np.ndarray
    margins: LoopMargins | None
    culprit: tuple | None
    skipped: tuple = ()
    held: tuple = ()

    @property
    def worst(self) -> tuple[int, int, int]:
        """``(plant, tilt index, speed index)`` of the largest multiplier."""
        return tuple(int(i) for i in np.unravel_index(np.nanargmax(self.rho), self.rho.shape))

    @property
    def stable(self) -> bool:
        """Every plant's loop stable on every circle with gains."""
        return bool(np.nanmax(self.rho) < 1.0)

    def _values(self, k: int) -> str:
        return ", ".join(f"{p} = {v:.4g}{' ' + u if u else ''}" for (p, (_, _, u)), v
                         in zip(self.params.items(), self.plants[k], strict=True))

    def lines(self, source: str = "") -> list[str]:
        """What ``gainsched check TABLE --uncertain REPORT`` prints; the last line is PASS
        or FAIL, FAIL naming the parameter."""
        box = "; ".join(f"{p} {v:.4g}{' ' + u if u else ''} held" if p in self.held else
                        f"{p} {v:.4g} +- {c:.2g}{' ' + u if u else ''}"
                        for p, (v, c, u) in self.params.items())
        n = self.rho.shape[0]
        k, i, j = self.worst
        where = f"{self.speeds[j]:g} m/s, tilt {math.degrees(self.tilts[i]):g} deg"
        out = [f"{source}: the table's loops on {n} plants of the diagnosis's 95 % box "
               f"({self.focus}: {box}; the estimate, {self.kinds.count('corner')} corners, "
               f"{self.kinds.count('sample')} samples)",
               f"  worst multiplier {self.rho[k, i, j]:.5f} (1 is unstable) at {where}, "
               f"with {self._values(k)}"]
        out += [f"  held at the table config's value, not identified by the fit (no finite "
                f"95 % interval): {', '.join(self.held)}"] if self.held else []
        out += [f"  skipped: {s}" for s in self.skipped]
        if self.margins is not None:
            out += [f"  {line}" for line in worst_lines(
                worst_margins(self.margins, self.speeds, self.tilts),
                "the stability margins of the estimate, the corners and that plant")]
        if self.stable:
            out.append("  PASS: every loop stable over the box")
        else:
            p, v, r = self.culprit
            out.append(f"  FAIL: {p} at {v:.4g} makes the loop unstable (multiplier {r:.4f} "
                       f"at its worst circle); the box's worst: {self.rho[k, i, j]:.4f}")
        return out

    def to_json(self) -> dict:
        """Every number as plain JSON data."""
        k, i, j = self.worst
        return {"focus": self.focus,
                "params": {p: {"estimate": v, "ci95": c, "unit": u}
                           for p, (v, c, u) in self.params.items()},
                "held": list(self.held),
                "plants": self.plants.tolist(), "kinds": list(self.kinds),
                "worst": {"multiplier": float(self.rho[k, i, j]), "plant": k,
                          "speed_mps": float(self.speeds[j]),
                          "tilt_deg": math.degrees(self.tilts[i])},
                "stable": self.stable,
                "culprit": None if self.culprit is None else dict(zip(
                    ("parameter", "value", "multiplier"), self.culprit, strict=True)),
                "margins": None if self.margins is None else worst_margins(
                    self.margins, self.speeds, self.tilts)}


def plant_count(report: dict, samples: int, source: str = "report") -> int:
    """The plants :func:`uncertain_loops` flies for ``report``: the estimate, a corner per
    sign of each identified parameter, ``samples`` (a progress bar's total)."""
    _, params, _ = report_focus(report, source)
    return 1 + 2 ** sum(bool(np.isfinite(c)) for _, c, _ in params.values()) + samples


def _box(params, samples: int, seed: int):
    """The plants' parameter values (P, p) and their kinds: the estimate, the corners,
    the random samples."""
    est = np.array([v for v, _, _ in params.values()])
    half = np.array([c for _, c, _ in params.values()])
    vary = half > 0  # a held parameter (half-width 0) has no corners of its own
    corners = []
    for s in itertools.product((-1, 1), repeat=int(vary.sum())):
        theta = est.copy()
        theta[vary] += half[vary] * np.array(s)
        corners.append(theta)
    rng = np.random.default_rng(seed)
    draws = est + half * rng.uniform(-1, 1, (samples, est.size))
    plants = np.vstack([est[None], *corners, draws]) if samples else np.vstack([est, *corners])
    return plants, ("estimate",) + ("corner",) * len(corners) + ("sample",) * samples


def _plant_loops(table, model, *, with_margins=False):
    """The largest multiplier per circle (n_a, n_v) of the table's gains on ``model``,
    and, ``with_margins``, the loops' margins (else None); each speed's tilts at once.
    Each loop's crossover is the alias nearest the table's own crossover of that circle
    (:func:`~gainsched.schedule.margins.crossover_frequency`; the plants of a fit's box
    move it by far less than the aliases' spacing), none in a table without them."""
    K_all = table.K_full()
    n_a, n_v = table.spectral_radius.shape
    rho = np.full((n_a, n_v), np.nan)
    stored = table.loop_margins
    guess = None if stored is None else stored.crossover
    gd, gu, dl, w = (np.full((n_a, n_v), np.nan) for _ in range(4))
    per_input = np.full((2, n_a, n_v, 4), np.nan)
    for j, v in enumerate(table.speed):
        dt = float(table.dt[j])
        N = int(round(2 * math.pi * model.r / v / dt))
        ok = np.flatnonzero(np.isfinite(table.spectral_radius[:, j]))
        try:
            Ad, Bd, _, _ = discrete_system(model, float(v), table.tilt[ok], N, dt)
        except TrimError:  # the plant has no nominal on one of them: each alone
            parts = [_one_circle(model, float(v), table.tilt[i], N, dt) for i in ok]
            ok = np.array([i for i, p in zip(ok, parts, strict=True) if p is not None], int)
            if not ok.size:
                continue
            Ad, Bd = (np.concatenate([p[k] for p in parts if p is not None]) for k in (0, 1))
        xs = 2 * np.pi * np.arange(N) / N  # the steps' azimuths
        K = np.stack([xi_linear(K_all[i, j], xs) for i in ok])
        K = np.pad(K, [(0, 0)] * 3 + [(0, Ad.shape[-1] - K.shape[-1])])  # unknown states
        rho[ok, j] = np.exp(loop_log_rho(Ad, Bd, K))
        if with_margins:
            lm = loop_margins(Ad, Bd, K, dt, xtol=MARGIN_XTOL, delay_xtol=MARGIN_DELAY_XTOL,
                              block=surrogate_block(dt),
                              crossover_guess=None if guess is None else guess[ok, j])
            gd[ok, j], gu[ok, j], dl[ok, j] = lm.gain_down, lm.gain_up, lm.delay
            per_input[0, ok, j], per_input[1, ok, j] = lm.input_down, lm.input_up
            w[ok, j] = lm.crossover
    margins = LoopMargins(gd, gu, *per_input, dl, None if guess is None else w) \
        if with_margins else None
    return rho, margins


def _one_circle(model, speed, tilt, N, dt):
    """``(A_d, B_d)`` of one circle, or None where the plant has no nominal."""
    try:
        return discrete_system(model, speed, [tilt], N, dt)[:2]
    except TrimError:
        return None


def uncertain_loops(table, report: dict, *, samples: int = SAMPLES, seed: int = 0,
                    source: str = "report", progress=None) -> Uncertainty:
    """The table's closed loops on plants drawn over a diagnosis's 95 % box (module
    docstring).

    Parameters
    ----------
    table : Table
        The gain table.
    report : dict
        A diagnose report's JSON (``diagnose.json``): its accepted candidate's
        parameters, estimates and 95 % half-widths.
    samples : int
        Random plants inside the box besides its corners and the estimate.
    seed : int
        Seed of the samples.
    source : str
        The report's file, for errors.
    progress : callable, optional
        ``progress(1)`` per plant done.

    Returns
    -------
    Uncertainty

    Raises
    ------
    InputError
        The report holds no fit, or its focus is no library candidate.
    """
    from ..schedule.tables import config_from_table

    cfg = config_from_table(table)
    focus, params, _ = report_focus(report, source)
    held = tuple(p for p, (_, c, _) in params.items() if not np.isfinite(c))
    if held:  # at the config's own value, as the diagnosis wrote them
        own = focus_values(cfg, focus)
        params = {p: (float(own[q]), 0.0, u) if p in held else (v, c, u)
                  for q, (p, (v, c, u)) in enumerate(params.items())}
    plants, kinds = _box(params, samples, seed)
    step = progress or (lambda n: None)
    rho, kept, kept_kinds, skipped, models = [], [], [], [], []
    # the margins of the estimate and the corners, from their one linearisation (unused,
    # and their cost lost, where another plant turns out unstable)
    found = {}
    for theta, kind in zip(plants, kinds, strict=True):
        try:
            model = Model(truth_config(cfg, focus, theta, held))
        except InputError as exc:
            skipped.append(f"{kind} {', '.join(f'{v:.4g}' for v in theta)}: {exc.message}")
            step(1)
            continue
        r, m = _plant_loops(table, model, with_margins=kind != "sample")
        if m is not None:
            found[len(rho)] = m
        rho.append(r)
        kept.append(theta)
        kept_kinds.append(kind)
        models.append(model)
        step(1)
    rho = np.array(rho)
    k = int(np.unravel_index(np.nanargmax(rho), rho.shape)[0])
    margins = culprit = None
    if np.nanmax(rho) < 1.0:  # the margins of the estimate, the corners and the worst
        if k not in found:
            found[k] = _plant_loops(table, models[k], with_margins=True)[1]
        margins = _worst_of([found[q] for q in sorted(found)])
    else:
        culprit = _culprit(table, cfg, focus, params, held)
    return Uncertainty(focus, params, np.array(kept), tuple(kept_kinds), rho, table.speed,
                       table.tilt, margins, culprit, tuple(skipped), held)


def _worst_of(margins: list) -> LoopMargins:
    """Per circle, the worst of several plants' margins: the largest down factor, the
    smallest up factor and delay (NaN where a plant has no loop there), and the crossover
    of the plant with that smallest delay (its phase margin, ``crossover * delay``)."""
    def pick(attr, worst):
        a = np.stack([getattr(m, attr) for m in margins])
        return np.where(np.all(np.isnan(a), 0), np.nan, worst(np.where(
            np.isnan(a), -np.inf if worst is np.max else np.inf, a), axis=0))
    crossover = None
    if all(m.crossover is not None for m in margins):
        d = np.stack([m.delay for m in margins])
        first = np.argmin(np.where(np.isnan(d), np.inf, d), axis=0)[None]
        crossover = np.take_along_axis(np.stack([m.crossover for m in margins]), first, 0)[0]
    return LoopMargins(pick("gain_down", np.max), pick("gain_up", np.min),
                       pick("input_down", np.max), pick("input_up", np.min),
                       pick("delay", np.min), crossover)


def _culprit(table, cfg, focus, params, held=()) -> tuple:
    """``(parameter, value, multiplier)``: the end of one parameter's interval, the others
    at their estimates, with the largest multiplier (``held`` parameters not varied)."""
    est = np.array([v for v, _, _ in params.values()])
    best = None
    for q, (name, (v, c, _)) in enumerate(params.items()):
        for end in (v - c, v + c) if name not in held else ():
            theta = est.copy()
            theta[q] = end
            try:
                model = Model(truth_config(cfg, focus, theta, held))
            except InputError:
                continue
            r = float(np.nanmax(_plant_loops(table, model)[0]))
            if best is None or r > best[2]:
                best = (f"{focus}.{name}", float(end), r)
    return best
