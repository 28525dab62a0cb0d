"""Fitting one candidate to the residual and scoring it on held-out flights.

:func:`_fit_candidate` runs one of two algorithms, by the candidate:

- :func:`_fit_gauss_newton`, no searched parameter: where the residual is affine in the
  parameters (drag, rotor drag, thrust scale, thrust polynomial, tether length, tether
  compliance) one bounded linear least-squares step (:func:`~._lsq._qp`) is exact; mass
  and attachment offset take a few Gauss-Newton steps. Each fold (a flight left out)
  is one more step from the estimate on the normal equations without that flight.
- :func:`_fit_search`, a parameter found by a bounded 1-D search (motor time constant,
  latency, momentum-theory disk area, tether damping time): a grid, refined by
  :func:`scipy.optimize.minimize_scalar` between the neighbours of its best point, the
  other parameters solved linearly at each search value (:func:`_profile`); each fold's
  search value from a parabola through its training SSE.

:func:`_score` then gives what both share: 95 % confidence intervals and the parameter
correlation from the Jacobian at the estimate, the held-out RMS reduction and the share
of the residual above noise explained, delta-BIC with ``n_eff = samples x axes /
window`` (G. Schwarz, "Estimating the dimension of a model", Annals of Statistics 6,
1978), plausibility, fold stability and the binned structure left. A series
candidate's order is chosen before it is fitted (:func:`_choose_order`, the
one-standard-error rule).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from ...config import Config
from ...model.effects import EFFECTS, Effect
from ...model.reduced import Model
from ._candidates import Candidate
from ._lsq import _qp, _sq, _stats
from ._problem import _Problem
from ._results import THRESHOLDS, CandidateResult


def _bounds(cand: Candidate, cfg: Config, start):
    if getattr(cand, "bounds", None) is not None:
        return cand.bounds
    if hasattr(cand, "fit_bounds"):  # bounds of its own (a moment of inertia's)
        return cand.fit_bounds(cfg, start)
    lo = np.array([p.lower for p in cand.params], float)
    hi = np.array([p.upper for p in cand.params], float)
    rel = getattr(cand, "bounds_rel", None)
    if rel is not None:
        lo, hi = np.array([rel[0] * start[0]]), np.array([rel[1] * start[0]])
        if hi[0] <= lo[0]:  # zero start (e.g. no attachment offset)
            lo, hi = np.array([0.0]), np.array([0.5])
    return lo, hi


def _jacobian(prob: _Problem, cand: Candidate, theta, base_vecs, cols, lo, hi):
    """Forward-difference columns of the weighted residual for parameters ``cols``."""
    out = []
    for j in cols:
        h = 1e-3 * (hi[j] - lo[j]) if cand.affine else 1e-4 * max(abs(theta[j]), hi[j] - lo[j])
        sgn = 1.0 if theta[j] + h <= hi[j] else -1.0
        th = theta.copy()
        th[j] += sgn * h
        v = prob.vectors(cand.variant(prob.config, th))
        out.append([{a: (f1[a] - f0[a]) / (sgn * h) for a in f0}
                    for f0, f1 in zip(base_vecs, v, strict=True)])
    return out  # [col][flight][axis]


def _profile(prob, cand, theta_search, lin, lo, hi, start):
    """Linear parameters solved at a fixed search value: (theta, vecs at theta, stats)."""
    th = start.copy()
    th[cand.search] = theta_search
    vecs = prob.vectors(cand.variant(prob.config, th))
    if not lin:
        return th, vecs, None
    jac = _jacobian(prob, cand, th, vecs, lin, lo, hi)
    A, b, c = _stats(vecs, jac)
    d, _ = _qp(A.sum((0, 1)), b.sum((0, 1)), lo[lin] - th[lin], hi[lin] - th[lin])
    th2 = th.copy()
    th2[lin] += d
    return th2, None, (A, b, c, d, vecs, jac)


def _grid(prob, cand, values, lin, lo, hi, start, nf, na, k):
    """Per search value: training SSE with each flight left out (G, nf), held-out SSE per
    axis (G, nf, na), fold parameters (G, nf, k) and the all-data SSE (G,)."""
    G = len(values)
    sse_tr = np.zeros((G, nf))
    held_g = np.zeros((G, nf, na))
    th_g = np.zeros((G, nf, k))
    sse_all = np.zeros(G)
    for gi, sv in enumerate(values):
        th, vecs, st = _profile(prob, cand, float(sv), lin, lo, hi, start)
        if st is None:
            sq = _sq(vecs)
            sse_all[gi] = sq.sum()
            for i in range(nf):
                sse_tr[gi, i] = sq.sum() - sq[i].sum()
                held_g[gi, i] = sq[i]
                th_g[gi, i] = th
            continue
        A, b, c, d_all, _, _ = st
        sse_all[gi] = float(c.sum() + 2 * b.sum((0, 1)) @ d_all + d_all @ A.sum((0, 1)) @ d_all)
        base_th = th.copy()
        base_th[lin] -= d_all
        for i in range(nf):
            m_ = np.arange(nf) != i
            d, val = _qp(A[m_].sum((0, 1)), b[m_].sum((0, 1)),
                         lo[lin] - base_th[lin], hi[lin] - base_th[lin])
            sse_tr[gi, i] = c[m_].sum() + val
            held_g[gi, i] = c[i] + 2 * b[i] @ d + np.einsum("j,ajk,k->a", d, A[i], d)
            th_g[gi, i] = base_th
            th_g[gi, i, lin] += d
    return sse_tr, held_g, th_g, sse_all


def _choose_order(prob: _Problem, cand: Candidate):
    """The order of a series candidate (its ``orders``: nested fits of the first n
    parameters): the lowest whose held-out SSE (leave-one-flight-out) is within one
    standard error of the best order's, the one-standard-error rule of cross-validation
    (Hastie, Tibshirani and Friedman, The Elements of Statistical Learning, 2nd ed.,
    Springer 2009, Sec. 7.10), with the standard error from the flight-to-flight spread
    of the SSE differences. One Jacobian of the full series (the residual is affine in
    it); each order's folds from its blocks.

    Returns the restricted candidate and its start ``(vecs, jac)`` for
    :func:`_fit_candidate`.
    """
    cfg = prob.config
    start = cand.start(cfg)
    lo, hi = _bounds(cand, cfg, start)
    start = np.clip(start, lo, hi)
    vecs = prob.vectors(cand.variant(cfg, start))
    jac = _jacobian(prob, cand, start, vecs, list(range(len(cand.params))), lo, hi)
    A, b, c = _stats(vecs, jac)
    A, b, c = A.sum(1), b.sum(1), c.sum(1)  # per flight
    nf = c.size
    held = np.zeros((len(cand.orders), nf))  # per order and held-out flight
    for o, n in enumerate(cand.orders):
        for i in range(nf):
            m = np.arange(nf) != i
            d, _ = _qp(A[m].sum(0)[:n, :n], b[m].sum(0)[:n], (lo - start)[:n],
                       (hi - start)[:n])
            held[o, i] = c[i] + 2 * b[i, :n] @ d + d @ A[i, :n, :n] @ d
    n = cand.orders[_one_se_order(held)]
    return cand.restricted(n), (vecs, jac[:n])


def _one_se_order(held) -> int:
    """Index of the lowest order whose held-out SSE is within one standard error of the
    best order's; ``held``: (n_orders, n_flights) held-out SSE per order and flight, the
    standard error of a sum of differences from their flight-to-flight spread."""
    held = np.asarray(held, dtype=float)
    best = int(np.argmin(held.sum(1)))
    nf = held.shape[1]
    for o in range(best):
        diff = held[o] - held[best]
        se = float(np.std(diff, ddof=1)) * math.sqrt(nf) if nf > 1 else 0.0
        if diff.sum() <= se:
            return o
    return best


@dataclass(frozen=True)
class _Fit:
    """What a fitting algorithm hands to :func:`_score`: the estimate ``theta``, the
    weighted residual there ``vecs`` (list over flights of {axis: (n,)}) and its sum of
    squares ``fit_sq`` (n_flights, n_axes); the leave-one-flight-out estimates ``folds``
    (n_flights, k) with each left-out flight's sum of squares ``held`` (n_flights,
    n_axes) and residual ``held_vecs``; the Jacobian ``jac`` at the estimate and the
    fold ``spread`` when the algorithm has them (None: :func:`_score` computes them)."""

    theta: np.ndarray
    vecs: list
    fit_sq: np.ndarray
    folds: np.ndarray
    held: np.ndarray
    held_vecs: list
    jac: list | None
    spread: float | None


def _fit_candidate(prob: _Problem, cand: Candidate, base_sq, base_vecs,
                   pre=None) -> CandidateResult:
    """Fit ``cand`` and score it (module docstring). ``pre``: ``(vecs, jac)`` at the
    start values for an affine candidate without search (:func:`_choose_order`)."""
    cfg = prob.config
    start = cand.start(cfg)
    lo, hi = _bounds(cand, cfg, start)
    start = np.clip(start, lo, hi)
    k = len(cand.params)
    nf, na = base_sq.shape
    lin = [j for j in range(k) if j != cand.search]
    if cand.search is None:
        fit = _fit_gauss_newton(prob, cand, start, lo, hi, lin, base_vecs, nf, na, k, pre)
    else:
        fit = _fit_search(prob, cand, start, lo, hi, lin, nf, na, k)
    return _score(prob, cand, fit, base_sq, base_vecs, start, lo, hi)


def _fit_gauss_newton(prob, cand, start, lo, hi, lin, base_vecs, nf, na, k, pre) -> _Fit:
    """A candidate without a searched parameter: bounded Gauss-Newton steps from
    ``start`` (one for an affine residual, up to four otherwise), then each fold one
    step from the estimate on the normal equations without its flight, its held-out
    residual and how far it moves the prediction relative to the effect (the spread).
    ``pre``: ``(vecs, jac)`` at ``start`` (:func:`_choose_order`) or None."""
    cfg = prob.config
    theta = start.copy()
    vecs = pre[0] if pre else prob.vectors(cand.variant(cfg, theta))
    for it in range(1 if cand.affine else 4):
        jac = pre[1] if pre and it == 0 else _jacobian(prob, cand, theta, vecs, lin, lo, hi)
        A, b, c = _stats(vecs, jac)
        d, _ = _qp(A.sum((0, 1)), b.sum((0, 1)), lo - theta, hi - theta)
        theta = theta + d
        vecs = prob.vectors(cand.variant(cfg, theta))
        if np.all(np.abs(d) <= 1e-6 * (hi - lo)):
            break
    if not cand.affine:
        jac = _jacobian(prob, cand, theta, vecs, lin, lo, hi)
    A, b, c = _stats(vecs, jac)
    Atot = A.sum((0, 1))
    folds = np.zeros((nf, k))
    held = np.zeros((nf, na))
    spread = 0.0
    eff = np.concatenate([np.concatenate([bv[a] - v[a] for a in bv])
                          for bv, v in zip(base_vecs, vecs, strict=True)])
    eff_norm = float(np.sqrt(np.sum(eff * eff)))
    held_vecs = []
    for i in range(nf):
        Ai = A.sum(1)[np.arange(nf) != i].sum(0)
        bi = b.sum(1)[np.arange(nf) != i].sum(0)
        d, _ = _qp(Ai, bi, lo - theta, hi - theta)
        folds[i] = theta + d
        held[i] = c[i] + 2 * b[i] @ d + np.einsum("j,ajk,k->a", d, A[i], d)
        held_vecs.append({a: v + sum(d[j] * jac[j][i][a] for j in range(k))
                          for a, v in vecs[i].items()})
        dd = math.sqrt(max(float(d @ Atot @ d), 0.0))
        spread = max(spread, dd / eff_norm if eff_norm > 0 else math.inf)
    return _Fit(theta, vecs, c, folds, held, held_vecs, jac, spread)


def _fit_search(prob, cand, start, lo, hi, lin, nf, na, k) -> _Fit:
    """A candidate with a searched parameter: its grid (geometric for a log scale), the
    all-data estimate refined by :func:`scipy.optimize.minimize_scalar` between the grid
    neighbours of the best point, the linear parameters solved at the search value
    (:func:`_profile`); the folds from :func:`_search_folds`. No Jacobian and no spread
    (:func:`_score` takes both from the Jacobian at the estimate)."""
    cfg = prob.config
    s = cand.search
    p = cand.params[s]
    g = (np.geomspace(p.lower, p.upper, cand.grid_size) if p.scale == "log"
         else np.linspace(p.lower, p.upper, cand.grid_size))
    sse_tr, held_g, th_g, sse_all = _grid(prob, cand, g, lin, lo, hi, start, nf, na, k)
    # all data: refine the search value between the grid neighbours of the best point
    G = g.size
    gbest = int(np.argmin(sse_all))
    a_, b_ = g[max(gbest - 1, 0)], g[min(gbest + 1, G - 1)]

    def f(sv):
        th, vecs, st = _profile(prob, cand, sv, lin, lo, hi, start)
        if st is None:
            return float(_sq(vecs).sum())
        A, b, c, d, *_ = st
        return float(c.sum() + 2 * b.sum((0, 1)) @ d + d @ A.sum((0, 1)) @ d)

    if a_ < b_:
        tol = 1e-3 * max(g[gbest], (b_ - a_) * 0.01)
        opt = minimize_scalar(f, bounds=(a_, b_), method="bounded", options={"xatol": tol})
        sbest = float(opt.x) if opt.fun <= sse_all[gbest] else float(g[gbest])
    else:
        sbest = float(g[gbest])
    theta, vecs, st = _profile(prob, cand, sbest, lin, lo, hi, start)
    if st is not None:
        vecs = prob.vectors(cand.variant(cfg, theta))
    fit_sq = _sq(vecs)
    folds, held, held_vecs = _search_folds(prob, cand, g, sbest, sse_tr, th_g, lin, lo, hi,
                                           start, nf, na, k)
    return _Fit(theta, vecs, fit_sq, folds, held, held_vecs, None, None)


def _search_folds(prob, cand, g, sbest, sse_tr, th_g, lin, lo, hi, start, nf, na, k):
    """The leave-one-flight-out estimates of a searched candidate, from its coarse grid
    ``g`` (training SSE ``sse_tr`` (G, nf), fold parameters ``th_g`` (G, nf, k)) and its
    all-data search value ``sbest``: ``(folds (nf, k), held (nf, na), held_vecs)``."""
    cfg = prob.config
    s = cand.search
    p = cand.params[s]
    G = g.size
    # folds: each fold's search value from a parabola through its training SSE on a
    # fine local grid around the all-data estimate (or, when its optimum lies outside,
    # on the coarse grid), linear parameters from the nearest grid point; then the
    # held-out flight evaluated exactly there
    to_u = (np.log if p.scale == "log" else (lambda x: np.asarray(x, float)))
    from_u = (np.exp if p.scale == "log" else (lambda x: x))
    h = 0.05 if p.scale == "log" else 0.02 * (p.upper - p.lower)
    u0 = float(to_u(sbest))
    ul = np.clip(u0 + h * np.arange(-2, 3), to_u(p.lower), to_u(p.upper))
    ul = np.unique(ul)
    loc = _grid(prob, cand, from_u(ul), lin, lo, hi, start, nf, na, k) if ul.size >= 3 else None
    u = to_u(g)
    folds = np.zeros((nf, k))
    held = np.zeros((nf, na))
    held_vecs = []
    for i in range(nf):
        uo = None
        if loc is not None:
            y = loc[0][:, i]
            cc = np.polyfit(ul - u0, y, 2)
            if cc[0] > 0:
                cand_u = u0 - cc[1] / (2 * cc[0])
                if ul[0] <= cand_u <= ul[-1]:
                    uo = float(cand_u)
                    j = int(np.argmin(np.abs(ul - uo)))
                    folds[i] = loc[2][j, i]
        if uo is None:
            j = int(np.argmin(sse_tr[:, i]))
            jl, jr = max(j - 1, 0), min(j + 1, G - 1)
            folds[i] = th_g[j, i]
            uo = float(u[j])
            if jr - jl == 2:
                x3, y3 = u[jl : jr + 1], sse_tr[jl : jr + 1, i]
                cc = np.polyfit(x3 - x3[1], y3, 2)
                if cc[0] > 0:
                    uo = float(np.clip(x3[1] - cc[1] / (2 * cc[0]), x3[0], x3[2]))
        folds[i, s] = float(from_u(uo))
        held_vecs += prob.vectors(cand.variant(cfg, folds[i]), only=i)
        held[i] = _sq(held_vecs[-1:])[0]
    return folds, held, held_vecs


def _intervals(cand, Atot, s2, window, lo, hi):
    """95 % confidence half-widths and the parameter correlation matrix of the estimate
    from the Gauss-Newton information ``Atot`` (k, k), the residual variance ``s2`` and
    the differentiation ``window`` (neighbouring samples are not independent), with the
    notes on what the flights do not identify: ``(ci (k,), corr (k, k), notes)``."""
    k = len(cand.params)
    notes = []
    # a parameter the residual does not see at all (a zero Jacobian column: a joint
    # fit's unidentified damping) has no interval; the others have theirs
    ci, corr = np.full(k, math.inf), np.full((k, k), math.nan)
    seen = np.diag(Atot) > 1e-12 * max(float(np.max(np.diag(Atot))), 1e-300)
    try:
        cov = np.linalg.inv(Atot[np.ix_(seen, seen)]) * s2 * window
        ci[seen] = 1.96 * np.sqrt(np.maximum(np.diag(cov), 0.0))
        sd = np.sqrt(np.maximum(np.diag(cov), 1e-300))
        corr[np.ix_(seen, seen)] = cov / np.outer(sd, sd)
    except np.linalg.LinAlgError:
        pass
    for j, q in enumerate(cand.params):
        if not ci[j] < (hi[j] - lo[j]):
            notes.append(f"{q.name} is not identified on these flights (95% CI wider than "
                         "its range)")
    sub = corr[np.ix_(seen, seen)]
    if sub.shape[0] > 1 and np.all(np.isfinite(sub)):
        off = np.abs(sub - np.diag(np.diag(sub))).max()
        if off >= THRESHOLDS["max_param_corr"]:
            names = [q.name for q in cand.params]
            notes.append(f"parameters {' and '.join(names)} are correlated ({off:.3f}, VIF "
                         f"{1 / max(1 - off**2, 1e-12):.0f}): only their combination is "
                         "identified on these flights")
    return ci, corr, notes


def _score(prob, cand, fit: _Fit, base_sq, base_vecs, start, lo, hi) -> CandidateResult:
    """The scores of a fit (module docstring of the package) and its
    :class:`CandidateResult`."""
    cfg = prob.config
    k = len(cand.params)
    nf = base_sq.shape[0]
    theta, vecs, folds, held = fit.theta, fit.vecs, fit.folds, fit.held
    # confidence intervals from the Jacobian at the estimate (all parameters)
    J_all = fit.jac
    if J_all is None or len(J_all) != k:
        J_all = _jacobian(prob, cand, theta, vecs, list(range(k)), lo, hi)
    Aci, _, cci = _stats(vecs, J_all)
    Atot = Aci.sum((0, 1))
    spread = fit.spread
    if spread is None:
        # how far the fold estimates move the prediction (linearised at the estimate),
        # relative to the effect itself: robust to a poorly determined second parameter
        eff = np.concatenate([np.concatenate([bv[a] - v[a] for a in bv])
                              for bv, v in zip(base_vecs, vecs, strict=True)])
        eff_norm = float(np.sqrt(np.sum(eff * eff)))
        moves = [math.sqrt(max(float(d @ Atot @ d), 0.0)) for d in folds - theta]
        spread = (max(moves) / eff_norm if eff_norm > 0 else math.inf) if nf > 1 else 0.0
    n_total = sum(v.size for f_ in vecs for v in f_.values())
    sse_fit = float(fit.fit_sq.sum())
    s2 = sse_fit / max(n_total - k, 1)
    ci, corr, notes = _intervals(cand, Atot, s2, prob.window, lo, hi)
    # scores
    sse_base = float(base_sq.sum())
    held_base = base_sq.sum()
    held_fit = float(held.sum())
    red = 1 - math.sqrt(held_fit / held_base) if held_base > 0 else 0.0
    excess = held_base - n_total
    exc = (held_base - held_fit) / excess if excess > 0.02 * n_total else math.nan
    n_eff = n_total / prob.window
    dbic = n_eff * math.log(max(sse_fit, 1e-300) / sse_base) + k * math.log(n_eff)
    rng = hi - lo
    # at the edge: an identified parameter (95 % CI within its range) on a bound; one the
    # flights do not identify is not written as fitted (unidentified()), so no reason
    # to refuse the parameters it rides with
    seen = ci < rng
    at = seen & (((theta - lo < 0.01 * rng) & (lo > 0)) | (hi - theta < 0.01 * rng))
    edge = bool(np.any(at))
    if edge:
        notes.append(f"{', '.join(q.name for q, a in zip(cand.params, at, strict=True) if a)}"
                     " at the edge of the plausible range")
    plausible = not edge
    stable = spread <= THRESHOLDS["max_fold_spread"]
    axes = list(prob.axes)
    n_ax = np.array([[v.size for v in f_.values()] for f_ in vecs]).sum(0)
    rb = {a: float(np.sqrt(base_sq[:, j].sum() / n_ax[j])) for j, a in enumerate(axes)}
    ra = {a: float(np.sqrt(held[:, j].sum() / n_ax[j])) for j, a in enumerate(axes)}
    contrib = np.concatenate([np.concatenate([bv[a] - v[a] for a in bv])
                              for bv, v in zip(base_vecs, vecs, strict=True)])
    contrib = contrib.astype(np.float32)
    p_before = prob.base_structure_power()
    structure = None
    if p_before:
        structure = 1 - math.sqrt(prob.structure_power(fit.held_vecs) / p_before)
    empirical = bool(getattr(cand, "empirical", False))
    # what a right model would not leave: significant binned structure (in azimuth,
    # airspeed, thrust or time) on any axis of the held-out residual (at the noise floor
    # the structure removed judges instead: CandidateResult.failed)
    left = () if structure is not None else tuple(
        f.sentence() for f in prob.structure_left(fit.held_vecs))
    law, implausible = _effect_words(prob, cand, cand.variant(cfg, theta).config)
    return CandidateResult(
        cand.name, cand.doc, cand.params, theta, ci, folds, start, cand.report_values(theta),
        float(red), float(exc), float(dbic), bool(plausible), float(spread), bool(stable), corr,
        held_fit, n_eff, rb, ra, float(1 - math.sqrt(sse_fit / sse_base)), tuple(notes), contrib,
        structure, empirical, law, cand, left, implausible,
    )


def _effect_words(prob, cand, fitted: Config) -> tuple[str, tuple]:
    """An empirical law, or a physical effect's own words (the weak motor), of the
    candidate or of the parts of a joint one, in the ``fitted`` config; and what no such
    effect could be (:meth:`~gainsched.model.effects.Effect.implausible` over the
    flights' airspeeds, :meth:`~gainsched.model.effects.Effect.implausible_tension` over
    their tensions): ``(law, implausible)``."""
    kinds = [k for k in (getattr(c, "kind", None) for c in getattr(cand, "parts", (cand,)))
             if k is not None]
    effects = [e for e in Model(fitted).effects if e.kind in kinds]
    law = "; ".join(e.law() for e in effects
                    if EFFECTS[e.kind].empirical or EFFECTS[e.kind].law is not Effect.law)
    implausible = tuple(why for e in effects
                        for why in [e.implausible(prob.airspeed_range),
                                    e.implausible_tension(prob.tension_range)] if why)
    return law, implausible
