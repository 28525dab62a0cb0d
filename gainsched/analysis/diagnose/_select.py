"""Choosing among the fits: parsimony, joint fits, forward selection and the twins.

:func:`_select` runs the fits of a diagnosis in their order (the physical singles; the
joint fits of the best of them, :func:`_fit_joint`, when none passes; the empirical
laws when no physical effect explains what is there; forward selection,
:func:`_forward`, while the fit leaves something) and returns the accepted one:
among nested fits of the same effect the smaller unless the larger lowers delta-BIC
clearly (:func:`_parsimonious`, :func:`_nested`), a physical effect before an empirical
law that fits as well (:func:`_physical_first`). :func:`_twins` names the candidates
whose fitted contributions are nearly collinear with the accepted one's and that
explain nearly as much: not to be told apart on these flights.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np

from ._candidates import NUISANCE, JointCandidate, separating_flight
from ._fit import _bounds, _choose_order, _fit_candidate
from ._results import THRESHOLDS, CandidateResult

#: single candidates whose best are combined into joint fits when none passes
JOINT_TOP = 4
#: candidates never fitted in the pairs of :func:`_fit_joint` (their single fit switches
#: the link model); forward selection (:func:`_forward`) adds them
_NOT_JOINT = frozenset({"tether_elasticity"})
#: the most candidates forward selection fits together
FORWARD_PARTS = 4


def _fit_joint(prob, library, results, base_sq, base_vecs, progress):
    """When no single candidate passes: the :data:`JOINT_TOP` best singles (held-out RMS
    reduction, distinct effects) fitted in pairs, and the best pair with each of the
    others as a triple. Appends to ``results`` (re-ranked) and returns the accepted one:
    the best passing pair, or a triple whose delta-BIC is lower by
    ``THRESHOLDS["nested_bic_gain"]`` (parsimony)."""
    top: list[CandidateResult] = []
    for r in results:  # ranked already
        if (r.rms_reduction > 0 and r.name in library and r.name not in _NOT_JOINT
                and not r.empirical
                and not any(_same_effect(library, r.name, t.name) or _nested(library, r, t)
                            or _nested(library, t, r) for t in top)):
            top.append(r)
        if len(top) == JOINT_TOP:
            break
    if len(top) < 2:
        return None

    def joint(fits):  # each a list of parts, fitted side by side
        return _joint_fits(prob, fits, base_sq, base_vecs, progress)

    pairs = joint(itertools.combinations(top, 2))
    pairs.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
    best = pairs[0]
    names = set(best.name.split(" + "))
    triples = joint([[*(t for t in top if t.name in names), r] for r in top
                     if r.name not in names])
    results.extend(pairs + triples)
    results.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
    ok_pairs = [r for r in pairs if r.passes]
    ok_triples = sorted((r for r in triples if r.passes), key=lambda r: r.delta_bic)
    pick = ok_pairs[0] if ok_pairs else None
    if ok_triples and (pick is None or ok_triples[0].delta_bic
                       < pick.delta_bic - THRESHOLDS["nested_bic_gain"]):
        pick = ok_triples[0]
    return pick


def _joint_fits(prob, fits, base_sq, base_vecs, progress) -> list[CandidateResult]:
    """For each list of fits ``parts`` of ``fits`` (CandidateResult, single or joint),
    their candidates fitted together (:class:`JointCandidate`), started at their fits;
    the joint fits side by side (:meth:`~._problem._Problem.map`)."""
    cands = [_joint_candidate(prob, parts) for parts in fits]
    return prob.map([(c.name, functools.partial(_fit_candidate, cand=c, base_sq=base_sq,
                                                base_vecs=base_vecs)) for c in cands],
                    progress)


def _fit_single(prob, cand, base_sq, base_vecs) -> CandidateResult:
    """The fit of a library candidate (a series' order chosen first,
    :func:`~._fit._choose_order`)."""
    pre = None
    if getattr(cand, "orders", ()):
        cand, pre = _choose_order(prob, cand)
    return _fit_candidate(prob, cand, base_sq, base_vecs, pre)


def _joint_candidate(prob, parts) -> JointCandidate:
    """The candidates of the fits ``parts`` as one, started at their fits."""
    cfg = prob.config
    cands, starts, bounds = [], [], []
    for r in parts:
        subs = r.candidate.parts if isinstance(r.candidate, JointCandidate) else (r.candidate,)
        thetas = (np.split(np.asarray(r.theta, dtype=float), r.candidate._cut)
                  if isinstance(r.candidate, JointCandidate) else (r.theta,))
        for c, th in zip(subs, thetas, strict=True):
            b = _bounds(c, cfg, c.start(cfg))
            cands.append(c)
            bounds.append(b)
            starts.append(np.clip(th, b[0], b[1]))
    return JointCandidate(cands, starts, bounds)


def _forward(prob, library, results, start, base_sq, base_vecs, progress):
    """Forward selection from the fit ``start`` (the accepted one, or the best single
    when none passes): add a single of another effect (held-out RMS reduction > 0; the
    tether's elasticity and empirical terms included; those whose fitted contribution
    projects most on what the current fit leaves tried first), all fitted
    together, while the fit leaves something (more than ``forward_excess_gain`` of the
    residual above noise, or binned structure) and the addition lowers delta-BIC by
    ``THRESHOLDS["nested_bic_gain"]`` and explains ``THRESHOLDS["forward_excess_gain"]``
    more of the residual above noise or removes the structure left; at most
    :data:`FORWARD_PARTS` parts (and the nuisance fit, :data:`NUISANCE`, beside them: the
    tether's own stretch is no effect of the story), the best :data:`JOINT_TOP` tried at
    each step, a passing addition preferred. Appends its fits to ``results`` and returns
    the last passing fit (None when ``start`` did not pass and no extension does)."""
    current = start
    accepted = start if start.passes else None
    gain = THRESHOLDS["forward_excess_gain"]

    def better(t):  # explains clearly more (of the whole, or of what is left), or
        # removes the structure the current one left
        left = 1.0 - current.excess_explained
        return (t.excess_explained >= current.excess_explained + gain
                or t.excess_explained >= current.excess_explained
                + THRESHOLDS["forward_left_share"] * left
                or (bool(current.structure_left) and not t.structure_left))

    base = np.concatenate([np.concatenate(list(bv.values())) for bv in base_vecs])

    def leftover_explained(r, left):
        # the share of what the current fit leaves that the single's own fitted
        # contribution could take (its projection on it): matching pursuit's choice
        c = r.contribution.astype(float)
        cc = float(c @ c)
        return float(c @ left) ** 2 / cc if cc > 0 else 0.0

    def effects(fit):  # its parts but the nuisance fit beside them, and all its parts
        names = fit.name.split(" + ")
        return [n for n in names if n not in NUISANCE], names

    # room for another effect, or for the nuisance fit beside FORWARD_PARTS of them
    while (len(effects(current)[0]) < FORWARD_PARTS
           or len(effects(current)[0]) == len(effects(current)[1])) and (
            current.excess_explained < 1 - gain or current.structure_left):
        story, names = effects(current)
        full = len(story) >= FORWARD_PARTS
        left = base - current.contribution.astype(float)
        # the nuisance fit is tried whatever its own score where the fit leaves structure
        # on its axes: alone it may explain little beside a large residual elsewhere
        eligible = [r for r in results
                    if not (" + " in r.name or r.name in names
                            or (r.rms_reduction <= 0 and r.name not in NUISANCE)
                            or (full and r.name not in NUISANCE)
                            or r.candidate is None or r.contribution is None
                            or any(_same_effect(library, r.name, n) for n in names)
                            or any(_nested(library, r, t) or _nested(library, t, r)
                                   for t in results if t.name in names))]
        pool = sorted(_physical_first(eligible, library),
                      key=lambda r: -leftover_explained(r, left))[:JOINT_TOP]
        pool += [r for r in eligible if r.name in NUISANCE and r not in pool
                 and _leaves_structure_on(current, _axes_of(prob, r))]
        fitted = {frozenset(r.name.split(" + ")): r for r in results}
        new = [r for r in pool if frozenset([*names, r.name]) not in fitted]
        made = iter(_joint_fits(prob, [[current, r] for r in new], base_sq, base_vecs,
                                progress))
        tries = [fitted.get(frozenset([*names, r.name])) or next(made) for r in pool]
        known = {id(r) for r in results}
        results.extend(t for t in tries if id(t) not in known)
        ok = [t for t in tries if better(t)
              and t.delta_bic < current.delta_bic - THRESHOLDS["nested_bic_gain"]]
        if not ok:
            break
        # a passing extension first; one that does not pass yet may still lead to one
        current = min([t for t in ok if t.passes] or ok, key=lambda t: t.delta_bic)
        if current.passes:
            accepted = current
    results.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
    return accepted


def _axes_of(prob, r: CandidateResult) -> frozenset:
    """The residual axes fit ``r``'s candidate acts on (all of them when it does not say)."""
    return r.candidate.variant(prob.config, r.theta).axes or frozenset(r.axis_rms_before)


def _leaves_structure_on(r: CandidateResult, axes) -> bool:
    """Whether fit ``r`` leaves significant binned structure on one of ``axes``."""
    return any(s.split(" ", 1)[0] in axes for s in r.structure_left)


def _same_effect(library, a: str, b: str) -> bool:
    """Whether candidates ``a`` and ``b`` fit the same effect of the library (joint fits:
    whether they share one)."""
    if " + " in a or " + " in b:
        return any(_same_effect(library, x, y) for x in a.split(" + ") for y in b.split(" + "))
    ka, kb = getattr(library[a], "kind", None), getattr(library[b], "kind", None)
    return ka is not None and ka == kb


def _nested(library, small: CandidateResult, big: CandidateResult) -> bool:
    """Whether every model of candidate ``small`` is one of ``big``'s: a subset of the
    same effect's parameters (drag_quadratic in drag), or a candidate ``big``'s refit
    declares it contains (thrust_scale in motor_efficiency, :class:`Refit` ``contains``)."""
    if ({p.name for p in small.params} < {p.name for p in big.params}
            and _same_effect(library, small.name, big.name)):
        return True
    refit = getattr(library.get(big.name), "refit", None)
    return refit is not None and small.name in refit.contains


def _physical_first(singles: list[CandidateResult], library) -> list[CandidateResult]:
    """``singles`` without the empirical candidates that contain a physical one of them
    (:func:`_nested`: ``thrust_motor`` holds every ``motor_efficiency``) which fits about as
    well (delta-BIC within ``THRESHOLDS["nested_bic_gain"]``): forward selection then
    builds on the effect with a physical story, as the parsimony of nested fits does for
    the single candidates (:func:`_parsimonious`)."""
    gain = THRESHOLDS["nested_bic_gain"]
    return [r for r in singles
            if not (r.empirical and any(not q.empirical and _nested(library, q, r)
                                        and r.delta_bic > q.delta_bic - gain
                                        for q in singles))]


def _parsimonious(passing: list[CandidateResult], library) -> CandidateResult | None:
    """The best-ranked passing candidate, or a passing one nested in it
    (:func:`_nested`) unless the larger fit lowers delta-BIC by
    ``THRESHOLDS["nested_bic_gain"]`` more: the parsimony between nested models that the
    held-out ranking alone does not give."""
    if not passing:
        return None
    best = passing[0]
    for r in passing[1:]:
        if (_nested(library, r, best)
                and best.delta_bic > r.delta_bic - THRESHOLDS["nested_bic_gain"]):
            best = r
    return best


def _select(prob, library, names, base, at_floor, base_sq, base_vecs, *, asked, joint,
            forward, progress, fitted=None):
    """The fits of a diagnosis, in their order, and the accepted one: ``(results,
    accepted)``, ``results`` ranked by held-out RMS reduction, then delta-BIC.

    The physical candidates of ``names`` first (a series' order chosen before its fit,
    :func:`~._fit._choose_order`), the best passing one accepted (:func:`_parsimonious`);
    joint fits of the best singles (:func:`_fit_joint`) when none passes above the noise
    floor, or always with ``joint``; the empirical candidates when no physical one is
    accepted and something is there to explain (an excess over the noise floor or binned
    structure of ``base``), or when the candidates were ``asked`` for by name; forward
    selection (:func:`_forward`, with ``forward``) while the fit leaves more than
    ``THRESHOLDS["forward_excess_gain"]`` of the residual above noise. ``progress(name)``
    as each fit is done, when given. ``fitted``: fits already made on ``prob``, by name (not
    made again)."""
    fitted = dict(fitted or {})

    def fit(names_):
        made = iter(prob.map([(n, functools.partial(_fit_single, cand=library[n],
                                                    base_sq=base_sq, base_vecs=base_vecs))
                              for n in names_ if n not in fitted], progress))
        results.extend(fitted.pop(n) if n in fitted else next(made) for n in names_)
        results.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
        return _parsimonious([r for r in results if r.passes], library)

    results: list[CandidateResult] = []
    empirical = [n for n in names if getattr(library[n], "empirical", False)]
    accepted = fit([n for n in names if n not in empirical])
    if (accepted is None and not at_floor) or joint:
        both = _fit_joint(prob, library, results, base_sq, base_vecs, progress)
        if both is not None and (accepted is None or both.delta_bic < accepted.delta_bic
                                 - THRESHOLDS["nested_bic_gain"]):
            accepted = both
    # beyond the library: empirical laws only when no physical effect explains what is
    # there (an excess over the noise floor or binned structure), or when asked for
    if accepted is None and empirical and (asked or base.structure or not at_floor):
        accepted = fit(empirical)
    # several effects of similar size: add the next best while it explains clearly more
    if forward and not at_floor and (accepted is None or accepted.excess_explained
                                     < 1 - THRESHOLDS["forward_excess_gain"]):
        if empirical and not any(r.empirical for r in results):
            fit(empirical)  # what no effect of the library named may be the rest
        start = accepted or next((r for r in _physical_first(
            [r for r in results if " + " not in r.name], library) if r.rms_reduction > 0), None)
        if start is not None:
            accepted = _forward(prob, library, results, start, base_sq, base_vecs, progress)
    return results, accepted


def _more_of_the_same(name: str, accepted: str) -> bool:
    """Fit ``name`` shares a part with fit ``accepted`` (``"tether_length + latency"`` of
    ``"tether_length"``) or has more parts: the same story with more in it (parsimony
    weighs it), not another story that explains as much."""
    parts, mine = set(name.split(" + ")), set(accepted.split(" + "))
    return bool(parts & mine) or len(parts) > len(mine)


def _story(name: str) -> str:
    """A fit's name without the nuisance parts (:data:`NUISANCE`): the story it tells."""
    return " + ".join(p for p in name.split(" + ") if p not in NUISANCE) or name


def _twins(library, results, accepted):
    """The candidates that cannot be told apart from ``accepted`` on these flights and
    the similarity of every fit to it: ``(twins, similarity)``, ``twins`` a list of
    ``(name, |cos| of the fitted contributions, the flight that would separate them)``,
    ``similarity`` ``{name: |cos|}`` (both empty without an accepted physical fit). A
    twin's contribution to the residual is nearly collinear with the accepted one's
    (``THRESHOLDS["twin_cos"]``) and its held-out fit explains nearly as much
    (``THRESHOLDS["twin_excess_gap"]``); another fit of the same effect, or one nested
    in the other, is none."""
    twins = []
    similarity = {}
    if accepted is not None and not accepted.empirical:
        ca = accepted.contribution.astype(float)
        na_ = float(np.sqrt(np.sum(ca * ca)))
        for r in results:
            if r is accepted or r.contribution is None:
                continue
            cb = r.contribution.astype(float)
            nb = float(np.sqrt(np.sum(cb * cb)))
            if na_ == 0 or nb == 0:
                continue
            cos = abs(float(np.sum(ca * cb)) / (na_ * nb))
            similarity[r.name] = cos
            if (_same_effect(library, r.name, accepted.name) or _nested(library, r, accepted)
                    or _nested(library, accepted, r)
                    or _more_of_the_same(_story(r.name), _story(accepted.name))):
                continue  # another fit of the same effect (drag_linear of drag), one
                # containing the other (thrust_scale in motor_efficiency), or a joint fit
                # with a part of the accepted one or more parts than it: no twin
            # told apart anyway when the held-out fits differ clearly: the twin leaves more
            # than a tenth of the residual above noise that the accepted one explains
            clear = accepted.excess_explained - r.excess_explained > THRESHOLDS["twin_excess_gap"]
            if cos >= THRESHOLDS["twin_cos"] and not clear:
                twins.append((r.name, cos, separating_flight(_story(accepted.name),
                                                             _story(r.name))))
    return twins, similarity
