"""What a diagnosis returns: the acceptance thresholds, one candidate's fit, the diagnosis.

:data:`THRESHOLDS` (the acceptance rule: :meth:`CandidateResult.failed` says which a
fit misses), :class:`CandidateResult` (a candidate's parameters with their confidence
intervals and folds, its held-out scores, its JSON), :class:`Diagnosis` (the ranked
candidates, the accepted one, its twins, the verdict) and :func:`unidentified` (the
parameters of a fit that the flights did not identify: neither the verdict nor
:func:`~gainsched.analysis.diagnose.apply_candidate` writes them as fitted).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...config import Config
from ..compare import (
    AT_NOISE_FLOOR,
    Comparison,
)
from ._candidates import Candidate

#: Acceptance thresholds (held-out where it says so).
THRESHOLDS = {
    "min_rms_reduction": 0.05,  # held-out RMS of the normalised residual falls by >= 5%
    "min_excess_explained": 0.5,  # and >= half of the residual power above the noise floor
    "max_delta_bic": -10.0,
    "max_fold_spread": 0.5,  # fold fits move the prediction by <= 50% of the effect itself
    "twin_cos": 0.95,  # |cos| of two fitted contributions: VIF >= 10
    "twin_excess_gap": 0.1,  # ... unless the held-out excess explained differs by > 10 points
    "max_param_corr": 0.95,  # within a candidate
    # a candidate that fits more parameters of the same effect than another passing one
    # (drag versus drag_quadratic) is preferred only when its delta-BIC is lower by this
    "nested_bic_gain": 10.0,
    # below the noise floor (no excess to explain) a candidate must instead remove this
    # share of the held-out binned structure (analysis.structure) that compare found
    "min_structure_explained": 0.5,
    # no residual axis may be worse held out by more than this share and end above its
    # noise floor (AT_NOISE_FLOOR times it): a fit that trades one axis for another tells
    # a wrong story
    "max_axis_worse": 0.05,
    # forward selection adds a candidate only when the fit together explains this much
    # more of the residual power above the noise floor (and lowers delta-BIC by
    # nested_bic_gain)
    "forward_excess_gain": 0.1,
    # ... or this share of the residual power above the noise floor that the current fit
    # leaves (near the end of a selection, when little is left to gain in absolute terms)
    "forward_left_share": 0.25,
}


@dataclass(frozen=True)
class CandidateResult:
    """Fit and scores of one candidate (see the module docstring).

    ``theta``/``ci``: fitted parameters and their 95% confidence half-widths (fit
    parametrisation, :attr:`Candidate.params`); ``folds``: (n_flights, k) leave-one-out
    estimates; ``values``: parameters as written to the config; ``axis_rms``: per axis
    held-out RMS (normalised) before and after; ``corr``: parameter correlation matrix.
    """

    name: str
    doc: str
    params: tuple
    theta: np.ndarray
    ci: np.ndarray
    folds: np.ndarray
    start: np.ndarray
    values: dict
    rms_reduction: float
    excess_explained: float
    delta_bic: float
    plausible: bool
    fold_spread: float
    stable: bool
    corr: np.ndarray
    heldout_sse: float
    n_eff: float
    axis_rms_before: dict
    axis_rms_after: dict
    in_sample_reduction: float
    notes: tuple = ()
    contribution: np.ndarray | None = field(default=None, repr=False)
    structure_reduction: float | None = None
    empirical: bool = False
    law: str = ""
    candidate: Candidate | None = field(default=None, repr=False)
    structure_left: tuple = ()
    implausible: tuple = ()

    def __repr__(self) -> str:
        """One line: the candidate, its parameters and its scores."""
        vals = ", ".join(f"{k}={v:.4g}" for k, v in list(self.values.items())[:6])
        more = ", ..." if len(self.values) > 6 else ""
        return (f"CandidateResult({self.name!r}, {vals}{more}, held-out RMS "
                f"{-self.rms_reduction:+.0%}, excess {self.excess_explained:.0%}, "
                f"passes={self.passes})")

    @property
    def below_noise(self) -> bool:
        """Judged on the binned structure: every axis at its noise floor, but significant
        binned structure to remove (``structure_reduction`` is set only then)."""
        return self.structure_reduction is not None

    @property
    def passes(self) -> bool:
        return not self.failed()

    def worse_axes(self) -> list[str]:
        """The residual axes the fit makes worse held out: normalised RMS up by more than
        ``THRESHOLDS["max_axis_worse"]`` and above the noise floor after (``AT_NOISE_FLOOR``
        times it: within it, the axis is noise either way)."""
        tol = THRESHOLDS["max_axis_worse"]
        return [a for a, before in self.axis_rms_before.items()
                if self.axis_rms_after.get(a, 0.0) > max(before * (1 + tol), AT_NOISE_FLOOR)]

    def failed(self) -> list[str]:
        """Which thresholds the candidate misses, in words (empty: it passes)."""
        t = THRESHOLDS
        out = []
        if self.below_noise:
            # at the noise floor the in-sample delta-BIC (with its conservative n_eff)
            # cannot see a sector-locked effect: the held-out binned structure judges, and
            # the held-out residual must fall
            if not self.structure_reduction >= t["min_structure_explained"]:
                out.append(f"removes {self.structure_reduction:.0%} of the held-out binned "
                           f"structure (< {t['min_structure_explained']:.0%})")
            if not self.rms_reduction > 0:
                out.append(f"held-out RMS changes by {-self.rms_reduction:+.1%}")
        else:
            if not self.rms_reduction >= t["min_rms_reduction"]:
                out.append(f"held-out RMS reduction {self.rms_reduction:.1%} < "
                           f"{t['min_rms_reduction']:.0%}")
            # nan: no residual power above the noise floor over all axes to speak of (one
            # axis above it, the others at it): the held-out RMS, delta-BIC and the
            # structure left judge alone
            if (np.isfinite(self.excess_explained)
                    and not self.excess_explained >= t["min_excess_explained"]):
                out.append(f"explains {self.excess_explained:.0%} of the residual above noise "
                           f"(< {t['min_excess_explained']:.0%})")
        if not self.below_noise and not self.delta_bic <= t["max_delta_bic"]:
            out.append(f"delta-BIC {self.delta_bic:.1f} > {t['max_delta_bic']:g}")
        for a in self.worse_axes():
            out.append(f"makes the {a} axis worse held out (normalised RMS "
                       f"{self.axis_rms_before[a]:.3g} -> {self.axis_rms_after[a]:.3g})")
        if self.structure_left and not self.below_noise:
            out.append(f"leaves structure a right model would remove: {self.structure_left[0]}")
        if not self.plausible:
            out.append("estimate implausible (at the edge of its range)")
        out += [f"implausible: {why}" for why in self.implausible]
        if not self.stable:
            out.append(f"unstable across folds (spread {self.fold_spread:.2f})")
        return out

    def to_json(self) -> dict:
        ps = [p.name for p in self.params]
        return {
            "doc": self.doc,
            "params": {n: {"estimate": float(v), "ci95": float(c), "unit": p.unit,
                           "folds": self.folds[:, j].tolist(), "start": float(s),
                           "bounds": [p.lower, p.upper]}
                       for j, (n, v, c, p, s) in enumerate(
                           zip(ps, self.theta, self.ci, self.params, self.start, strict=True))},
            "values": self.values,
            "heldout_rms_reduction": self.rms_reduction,
            "heldout_excess_explained": _num(self.excess_explained),
            "delta_bic": self.delta_bic,
            "plausible": self.plausible,
            "fold_spread": _num(self.fold_spread),
            "stable": self.stable,
            "param_corr": self.corr.tolist(),
            "heldout_axis_rms_normalised": {"before": self.axis_rms_before,
                                            "after": self.axis_rms_after},
            "in_sample_rms_reduction": self.in_sample_reduction,
            "heldout_structure_reduction": _num(self.structure_reduction),
            "empirical": self.empirical,
            "law": self.law,
            "structure_left": list(self.structure_left),
            "implausible": list(self.implausible),
            "passes": self.passes,
            "failed": self.failed(),
            "notes": list(self.notes),
        }


def _num(x):
    return float(x) if x is not None and np.isfinite(x) else None


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Which effect is missing: the ranked candidates, the verdict and the twins.

    What :func:`diagnose` returns; ``d.to_json()`` is the report's JSON.

    Attributes
    ----------
    config : Config
        The model that was diagnosed.
    base : Comparison
        Its comparison with the logs: the residual the candidates were fitted to.
    results : list of CandidateResult
        Every fitted candidate (joint fits ``"a + b"`` included when they ran), ranked by
        held-out RMS reduction, then delta-BIC: the parameters with their 95 % CIs
        (``theta``, ``ci``; ``values`` as written to the config), the held-out scores
        (``rms_reduction``, ``excess_explained``), ``delta_bic``, ``passes`` and
        ``failed()`` (the thresholds missed, in words)
        (:class:`~gainsched.analysis.diagnose.CandidateResult`).
    accepted : CandidateResult or None
        The verdict's candidate: the best-ranked one clearing every threshold of
        :data:`THRESHOLDS` (a nested fit of the same effect preferred unless the larger
        lowers delta-BIC clearly); None when none does. :func:`apply_candidate` writes
        it into the config.
    twins : list of (str, float, str)
        Candidates that cannot be told apart from the accepted one on these flights:
        ``(name, |cos| of their fitted contributions to the residual, the flight that
        would separate them)``.
    verdict : str
        The conclusion in one paragraph (what ``gainsched diagnose`` prints).
    at_noise_floor : bool
        Every residual axis of ``base`` was within ``AT_NOISE_FLOOR`` (1.25) times its
        noise floor: candidates were then judged on the binned structure they remove.
    flights : list of str
        The flights (one per log file), the folds of the leave-one-flight-out scores.
    evaluations : int
        How many times the model was evaluated on all flights (the cost of the fits).
    similarity : dict of str to float
        ``|cos|`` of each other candidate's fitted contribution to the accepted one's
        (empty without an accepted candidate).
    calibration : SensorCalibration or None
        The gyro's scale and bias fitted against the motion capture's rates, before any
        dynamics (:func:`~gainsched.analysis.diagnose._calibration.sensor_calibration`);
        when it is accepted, ``config`` has it and ``base`` was measured with it. None
        without a gyro on two flights.
    """

    config: Config
    base: Comparison
    results: list  # ranked CandidateResult
    accepted: CandidateResult | None
    twins: list  # (name, |cos|, separating flight)
    verdict: str
    at_noise_floor: bool
    flights: list
    evaluations: int
    similarity: dict = field(default_factory=dict)  # |cos| of each fit to the accepted one
    calibration: object | None = None  # SensorCalibration

    @property
    def applied(self) -> list[str]:
        """What :func:`~gainsched.analysis.diagnose.apply_diagnosis` writes: the gyro's
        calibration (``"sensor_calibration"``) when accepted, the accepted candidate."""
        cal = ["sensor_calibration"] if self.calibration is not None and \
            self.calibration.accepted else []
        return cal + ([] if self.accepted is None else [self.accepted.name])

    def __repr__(self) -> str:
        """One line: the config, the flights, the candidates fitted and the verdict's start."""
        v = self.verdict if len(self.verdict) <= 100 else self.verdict[:97] + "..."
        return (f"Diagnosis({self.config.name!r}, {len(self.flights)} flights, "
                f"{len(self.results)} fits, accepted="
                f"{None if self.accepted is None else self.accepted.name!r}, verdict={v!r})")

    def to_json(self) -> dict:
        return {
            "config": self.config.source,
            "flights": self.flights,
            "verdict": self.verdict,
            "accepted": self.accepted.name if self.accepted else None,
            "twins": [{"candidate": n, "abs_cos": c, "separating_flight": s}
                      for n, c, s in self.twins],
            "at_noise_floor": self.at_noise_floor,
            "thresholds": THRESHOLDS,
            "ranking": [r.name for r in self.results],
            "candidates": {r.name: r.to_json() for r in self.results},
            "base_where_it_fails": self.base.where["sentence"],
            "model_evaluations": self.evaluations,
            "abs_cos_to_accepted": self.similarity,
            "sensor_calibration": (None if self.calibration is None
                                 else self.calibration.to_json()),
            "applied": self.applied,
        }


def unidentified(result: CandidateResult) -> dict[str, str]:
    """Parameters of a fit that must not be written as fitted, with the reason: a 95 %
    CI wider than the estimate itself or than the parameter's fit range (it could be
    anything on these flights), or an estimate on a bound of that range."""
    out = {}
    for j, p in enumerate(result.params):
        v, c = float(result.theta[j]), float(result.ci[j])
        rng = p.upper - p.lower  # 0: bounds relative to the config's value (mass)
        on_bound = rng > 0 and min(v - p.lower, p.upper - v) <= 1e-9 * rng  # clipped there
        bound = f"estimate {v:.3g} {p.unit} on a bound of [{p.lower:g}, {p.upper:g}]"
        if result.empirical:
            # a series: its order was chosen held-out (one-SE rule), not its terms one by
            # one, and a small harmonic's wide CI is no reason to drop it from the law
            if on_bound:
                out[p.name] = bound
        elif not np.isfinite(c) or (rng > 0 and c >= rng):
            out[p.name] = f"95% CI +-{c:.2g} {p.unit} wider than its range"
        elif c >= abs(v):
            out[p.name] = f"95% CI +-{c:.2g} {p.unit} wider than the estimate {v:.3g}"
        elif on_bound:
            out[p.name] = bound
    return out
