"""Which physical effect is missing: fit candidates to the residual, score them on held-out flights.

For each candidate of :data:`CANDIDATES` (the effects library plus config
parameters and measurement latency) the model is refitted on the flight logs:
the parameters minimise the residual of :mod:`gainsched.analysis.compare`, every axis
weighted by its noise floor (so 1 per axis and sample is pure noise). Where
the residual is affine in a parameter (drag, rotor drag, thrust scale, thrust
polynomial, tether length, tether compliance) one linear least-squares step is
exact; mass and attachment offset take a few Gauss-Newton steps; motor time
constant, latency, momentum-theory disk area and the tether damping time are
found by a bounded 1-D search (grid, then :func:`scipy.optimize.minimize_scalar`).

Scores, all on **held-out flights** (leave-one-flight-out: refit without the
flight, predict it):

- ``rms_reduction``: ``1 - sqrt(SSE_fit / SSE_model)`` of the normalised residual;
- ``excess_explained``: the share of the residual power above the noise floor
  that the candidate removes, ``(SSE_model - SSE_fit) / (SSE_model - SSE_noise)``;
- ``delta_bic`` (in-sample, ``n_eff = samples x axes / window``: neighbouring
  samples share the differentiation window);
- plausibility (the estimate inside the parameter's plausible range, not
  pinned to its edge) and fold stability (how far the fold fits move the
  prediction, linearised at the estimate, relative to the effect itself).

A candidate is accepted when it clears every threshold of :data:`THRESHOLDS`, leaves
no significant binned structure (:mod:`gainsched.analysis.structure`: azimuth, airspeed,
thrust or flight time, every axis) in its held-out residual (a right model leaves noise;
a wrong one that correlates with the truth leaves what it cannot follow) and is
physically possible (:meth:`~gainsched.model.effects.Effect.implausible`); the first such
in the ranking (by held-out RMS reduction) is the verdict. When none is, forward
selection adds effects while they explain clearly more or remove the structure left
(:func:`_forward`).
**Identifiability gate**: two candidates whose fitted contributions to the
residual are nearly collinear (``|cos| >= 0.95``, i.e. VIF >= 10) and whose
held-out fits explain nearly as much (within 10 points of the residual power
above noise) cannot be told apart on these flights; the report says so and names the flight
that would separate them. Multi-parameter candidates report their parameter correlation.
**Beyond the library**: when no physical candidate passes while something is there
to explain (a residual above the noise floor, or significant binned structure of
:mod:`gainsched.analysis.structure` below it), the empirical candidates (effects
marked ``empirical``, e.g. the azimuth thrust series, or the tether stretch in tension,
whose law :mod:`._problem` takes off the stretch axis) are fitted too; a series'
order is chosen by leave-one-flight-out SSE with the one-standard-error rule
(:func:`_choose_order`). At the noise floor with significant structure, candidates
are judged by the share of that binned structure they remove on held-out flights
(``min_structure_explained``) instead of the RMS, excess and delta-BIC scores.
When nothing clears the thresholds the report says that no candidate explains
the residual and where the residual concentrates
(:func:`gainsched.analysis.compare.where_it_fails`).

The package's modules, one concept each (private: this namespace is the API),
top to bottom of their imports (a module imports only from those below it):

- ``_diagnose``: the entry point, :func:`diagnose`;
- ``_select``: choosing among the fits (parsimony, joint fits, forward selection,
  twins); ``_verdict``: the conclusion in words; ``_apply``: the config writer,
  :func:`apply_candidate`;
- ``_fit``: fitting one candidate (Gauss-Newton or 1-D search) and its held-out scores;
- ``_problem``: the logs, the noise weights and the weighted residual of a model variant;
- ``_results``: :data:`THRESHOLDS`, :class:`CandidateResult`, :class:`Diagnosis`;
- ``_candidates``: the candidate library; ``_lsq``: the bounded least-squares solver;
- ``_calibration``: the gyro's scale and bias against the motion capture, fitted before
  the candidates (:func:`sensor_calibration`).
"""

from ._apply import apply_candidate, apply_diagnosis
from ._calibration import SensorCalibration, sensor_calibration
from ._candidates import (
    CANDIDATES,
    Candidate,
    FitParam,
    candidate_library,
    select_candidates,
    separating_flight,
    single_parameter_set_candidates,
)
from ._diagnose import diagnose
from ._results import THRESHOLDS, CandidateResult, Diagnosis

__all__ = [
    "FitParam",
    "Candidate",
    "CANDIDATES",
    "candidate_library",
    "THRESHOLDS",
    "CandidateResult",
    "Diagnosis",
    "diagnose",
    "apply_candidate",
    "apply_diagnosis",
    "SensorCalibration",
    "sensor_calibration",
    "separating_flight",
    "single_parameter_set_candidates",
    "select_candidates",
]
