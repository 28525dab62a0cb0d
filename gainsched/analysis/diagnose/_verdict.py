"""The verdict: a diagnosis's conclusion in one paragraph (what ``gainsched diagnose`` prints).

Below the noise floor: the significant binned structure or the correlation in time
the residual still has, or "no effect needed". Above it: the accepted candidate with
its values and held-out scores, its twins and the flight that would separate them, an
empirical law marked as a fit (and whether a table can hold it,
:func:`~gainsched.model.symmetry.table_refusal`); or, when none is accepted, where the
residual concentrates (:func:`~gainsched.analysis.compare.where_it_fails`).
"""

from __future__ import annotations

from ...model.effects import EFFECTS
from ...model.symmetry import table_refusal
from ..compare import (
    AT_NOISE_FLOOR,
)
from ._candidates import NUISANCE
from ._results import THRESHOLDS, CandidateResult, unidentified


def _fmt_values(r: CandidateResult) -> str:
    parts = []
    for p, v, c in zip(r.params, r.theta, r.ci, strict=True):
        parts.append(f"{p.name} = {v:.4g} +- {c:.2g} {p.unit}")
    return ", ".join(parts)


def _table_refusal(result: CandidateResult) -> str:
    """Why no table can hold the effect ``result`` fitted, at its values (the build's
    check, :func:`~gainsched.model.symmetry.table_refusal`); "" when one can or when the
    candidate holds no effect (of a joint fit: the first of its parts' refusals)."""
    for part in getattr(result.candidate, "parts", (result.candidate,)):
        kind = getattr(part, "kind", None)
        if kind not in EFFECTS:
            continue
        cls = EFFECTS[kind]
        names = {p.name for p in cls.params}
        why = table_refusal(cls(**{k: v for k, v in result.values.items() if k in names}))
        if why:
            return why
    return ""


def _verdict(base, results, accepted, twins, at_floor) -> str:
    """The conclusion of a diagnosis in one paragraph: of the ``accepted`` fit (None:
    none passes) among the ranked ``results``, on the ``base`` comparison (``at_floor``:
    every axis at its noise floor), with its ``twins``."""
    if accepted is None:
        return _no_effect_verdict(base, results, at_floor)
    return _effect_verdict(base, accepted, twins)


def _no_effect_verdict(base, results, at_floor) -> str:
    """The verdict when no candidate passes: the structure or the correlation in time
    left below the noise floor, no effect needed, or where the residual concentrates and
    why the best candidate fails."""
    if at_floor and base.structure:
        # the overall RMS hides it; averaging over revolutions (or airspeed, thrust bins)
        # shows a systematic residual: name it instead of "no effect needed"
        f = base.structure[0]
        more = (f" ({len(base.structure) - 1} more in the structure table)"
                if len(base.structure) > 1 else "")
        best = results[0] if results else None
        tail = (f" No candidate explains it (the best, {best.name}, fails: "
                f"{'; '.join(best.failed())})." if best is not None else "")
        return (f"significant structure below the noise floor: {f.sentence()}{more}; every "
                f"axis is within {AT_NOISE_FLOOR:g}x its noise floor overall, but averaged over "
                f"the revolutions it is systematic.{tail}")
    grey = [f"{a} (Q {st.whiteness_q:.1f} > {st.whiteness_limit:.1f})"
            for a, st in base.stats.items() if not st.white]
    if at_floor and grey:
        # "no effect needed" needs a white residual too: a correlation in time that no
        # bin shows is still something the model does not explain
        best = results[0] if results else None
        tail = (f" No candidate explains it (the best, {best.name}, fails: "
                f"{'; '.join(best.failed())})." if best is not None else "")
        return (f"residual correlated in time: {', '.join(grey)} not white at the 99% "
                f"level (see the autocorrelation plot), although every axis is within "
                f"{AT_NOISE_FLOOR:g}x its noise floor with no significant structure in "
                f"azimuth, airspeed, thrust or time bins.{tail}")
    if at_floor:
        return (f"no effect needed: every residual axis is within {AT_NOISE_FLOOR:g}x its "
                "noise floor, and white, with no significant structure in azimuth, "
                "airspeed, thrust or time bins")
    best = results[0] if results else None
    tail = ""
    if best is not None and best.passes:
        # a passing fit left out by the parsimony of the selection (_select: a larger fit
        # must lower delta-BIC by nested_bic_gain below the fit it extends)
        tail = (f" The best candidate, {best.name}, removes {best.rms_reduction:.0%} of the "
                f"held-out RMS and passes every threshold, but its delta-BIC "
                f"({best.delta_bic:.0f}) is not {THRESHOLDS['nested_bic_gain']:g} below the "
                "fit it extends: more parameters than these flights ask for.")
    elif best is not None:
        tail = (f" The best candidate, {best.name}, removes {best.rms_reduction:.0%} of the "
                f"held-out RMS but fails: {'; '.join(best.failed())}.")
    if base.structure:
        tail += f" Averaged over the revolutions: {base.structure[0].sentence()}."
    return (f"no library effect explains it: {base.where['sentence']}.{tail}")


def _effect_verdict(base, accepted, twins) -> str:
    """The verdict of an accepted fit: the effect (or empirical law) with its values and
    held-out scores, what is not identified, and its twins with the flight that would
    separate them."""
    if accepted.below_noise:
        score = (f"held-out binned structure -{accepted.structure_reduction:.0%}, held-out "
                 f"RMS -{accepted.rms_reduction:.1%}")
    else:
        score = (f"held-out RMS -{accepted.rms_reduction:.0%}, explains "
                 f"{accepted.excess_explained:.0%} of the residual above noise")
    parts = getattr(accepted.candidate, "parts", ())
    story = [q for q in parts if q.name not in NUISANCE]
    beside = [q.name for q in parts if q.name in NUISANCE]
    if accepted.empirical or (beside and story
                              and all(getattr(q, "empirical", False) for q in story)):
        # an empirical law, alone or with the nuisance fit these flights need beside it
        what = (base.structure[0].sentence() if base.structure
                else base.where["sentence"])
        refusal = _table_refusal(accepted)
        where = (f"; no table can hold it: it {refusal}" if refusal
                 else " (and, by the table's symmetries, their mirror images)")
        name = " + ".join(q.name for q in story) if beside else accepted.name
        with_ = f", fitted together with {' and '.join(beside)}" if beside else ""
        return (f"no physical effect of the library explains the residual ({what}); "
                f"empirical correction: {name}{with_}, {accepted.law}; "
                f"{score}, delta-BIC {accepted.delta_bic:.0f}. It is a fit, not a model: "
                f"it holds on the circles flown{where}")
    what = "missing effects, fitted together" if parts else "missing effect"
    law = f" ({accepted.law})" if accepted.law else ""
    s = (f"{what}: {accepted.name} ({accepted.doc}), {_fmt_values(accepted)}{law}; "
         f"{score}, delta-BIC {accepted.delta_bic:.0f}")
    fits = [q.name for q in parts if getattr(q, "empirical", False)]
    if fits:
        s += (f". {' and '.join(fits)} is an empirical correction: a fit, not a model, that "
              "holds on the circles flown (and, by the table's symmetries, their mirror "
              "images)")
    why = unidentified(accepted)
    if why:
        s += ". Not identified, so --apply keeps the config's value: " + "; ".join(
            f"{n} ({w})" for n, w in why.items())
    for name, cos, sep in twins:
        s += (f". It cannot be told apart from {name} on these flights (|cos| {cos:.3f}); "
              f"to separate them: {sep}")
    return s
