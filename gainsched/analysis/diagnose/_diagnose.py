"""The entry point: :func:`diagnose`, from flight logs to the ranked candidates and the verdict.

The base comparison, the fit problem (:mod:`._problem`), the candidates to fit
(:mod:`._candidates`), the fits and their selection (:mod:`._fit`, :mod:`._select`),
the twins and the verdict (:mod:`._verdict`), gathered into a
:class:`~gainsched.analysis.diagnose.Diagnosis`.
"""

from __future__ import annotations

from ...config import Config
from ..compare import (
    AT_NOISE_FLOOR,
    Comparison,
    compare,
)
from ._candidates import _logged, candidate_library, select_candidates
from ._lsq import _sq
from ._problem import _Problem
from ._results import Diagnosis
from ._select import _select, _twins
from ._verdict import _verdict


def diagnose(config: Config, logs, *, candidates=None, comparison: Comparison | None = None,
             progress=None, joint: bool = False, forward: bool = True,
             channel_map=None, exclude=(), trust=()) -> Diagnosis:
    """Find which physical effect the model misses: fit candidates, score them held out.

    The whole of ``gainsched diagnose`` (docs/model-vs-measurement.md, the module
    docstring): each candidate (a missing effect, a config parameter, the measurement
    latency) is refitted to the residual of :func:`~gainsched.analysis.compare.compare`,
    every axis weighted by its noise floor; it is scored on held-out flights
    (leave-one-flight-out: the RMS reduction and the share of the residual above the
    noise floor it explains), by delta-BIC, plausibility and fold stability; the
    candidates are ranked, near-collinear twins are named with the flight that would
    separate them, and the first candidate clearing every threshold of
    :data:`THRESHOLDS` is the verdict.

    Parameters
    ----------
    config : Config
        The model to improve.
    logs : iterable of str, path-like or FlightLog
        Flight log files or segments, from at least two flights (log files) for held-out
        scores. Not read when ``comparison`` is given.
    candidates : list of str, optional
        Names of the candidates to fit
        (:func:`~gainsched.analysis.diagnose.candidate_library`: ``"drag_quadratic"``,
        ``"thrust_momentum"``, ``"motor_lag"``, ``"latency"``, ``"mass"``, ...). Default:
        all of them. Empirical candidates (a law with no physics behind it, such as
        ``"thrust_azimuth"``) are fitted only when no physical one is accepted.
    comparison : Comparison, optional
        ``compare(config, logs)`` if already computed: it is reused, not recomputed.
    progress : callable, optional
        ``progress(name)`` before each candidate is fitted.
    joint : bool, default False
        Fit pairs of the best single candidates even when one passes (without
        ``joint`` they run only when none passes and the residual is above the noise
        floor): a passing joint fit then replaces the accepted single when its delta-BIC
        is lower by ``THRESHOLDS["nested_bic_gain"]``.
    forward : bool, default True
        Forward selection (:func:`_forward`): when the accepted fit, or the best single if
        none passes, leaves more than ``THRESHOLDS["forward_excess_gain"]`` of the
        residual above noise, add the next best effects while each explains clearly
        more; False: the single and joint fits only.
    channel_map : ChannelMap, str or path-like, optional
        For PX4 ULogs and ROS 2 bags among ``logs`` (:func:`compare`).
    exclude : sequence of str
        Candidates or effect kinds to leave out (:func:`select_candidates`): the library
        told that an effect is not there. When no other effect explains what it would
        have, the verdict says that no library effect explains it and fits an empirical
        term.
    trust : iterable of str, optional
        Consistency checks of the log files to skip (:func:`compare`).

    Returns
    -------
    Diagnosis
        The ranked candidates, the accepted one (or None), the twins, the verdict.

    Raises
    ------
    InputError
        Fewer than two flights, an unknown candidate name, or a log :func:`compare`
        refuses.

    Examples
    --------
    Two candidates on the seven example flights (held out: each flight predicted by the
    fit to the six others; the accepted one leaves a residual above noise, so forward
    selection tries the other with it, which does not explain clearly more):

    >>> import glob
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = sorted(glob.glob("examples/flights/*.csv"))
    >>> d = gs.diagnose(cfg, logs, candidates=["drag_quadratic", "thrust_momentum"])
    >>> for r in d.results:
    ...     print(f"{r.name:32s} held-out RMS -{r.rms_reduction:.0%}, passes: {r.passes}")
    thrust_momentum                  held-out RMS -31%, passes: True
    thrust_momentum + drag_quadratic held-out RMS -30%, passes: True
    drag_quadratic                   held-out RMS -2%, passes: False
    >>> d.accepted.name, f"{d.accepted.values['disk_area']:.4f} m^2"
    ('thrust_momentum', '0.0061 m^2')
    >>> d.verdict
    'missing effect: thrust_momentum (thrust change with airspeed by momentum theory ...'
    """
    base = comparison or compare(config, logs, channel_map=channel_map, trust=trust)
    prob = _problem(config, base)
    library = candidate_library()
    names = select_candidates(candidates, exclude, library)
    names = _logged(names, library, base.measured, asked=candidates is not None)
    at_floor, base_vecs, base_sq = _base_residual(prob, base)
    results, accepted = _select(prob, library, names, base, at_floor, base_sq, base_vecs,
                                asked=candidates is not None, joint=joint, forward=forward,
                                progress=progress)
    twins, similarity = _twins(library, results, accepted)
    verdict = _verdict(base, results, accepted, twins, at_floor)
    return Diagnosis(config, base, results, accepted, twins, verdict, at_floor,
                     prob.flight_names, int(round(prob.n_evals)), similarity)


def _problem(config: Config, base: Comparison) -> _Problem:
    """The fit problem of ``config`` on the flights of its comparison ``base``; InputError
    with fewer than two flights (no held-out scores)."""
    from ...errors import InputError

    prob = _Problem(config, base.measured, base.segs, base.noise, base.residuals)
    if len(prob.flights) < 2:
        raise InputError("command line", "LOG", "diagnose needs at least two flights (log "
                         "files) for held-out scores")
    return prob


def _base_residual(prob: _Problem, base: Comparison):
    """Whether every axis of ``base`` is within ``AT_NOISE_FLOOR`` times its noise floor
    (then the fits are also scored on the binned structure ``base`` found) and the base
    model's weighted residual with its sums of squares: ``(at_floor, base_vecs,
    base_sq)``."""
    at_floor = all(s.rms_over_noise < AT_NOISE_FLOOR for s in base.stats.values())
    if at_floor:
        prob.track_structure(base)
    base_vecs = prob.base_vectors()
    return at_floor, base_vecs, _sq(base_vecs)
