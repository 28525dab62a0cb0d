"""The entry point: :func:`diagnose`, from flight logs to the ranked candidates and the verdict.

The base comparison, the fit problem (:mod:`._problem`), the candidates to fit
(:mod:`._candidates`), the fits and their selection (:mod:`._fit`, :mod:`._select`),
the twins and the verdict (:mod:`._verdict`), gathered into a
:class:`~gainsched.analysis.diagnose.Diagnosis`.
"""

from __future__ import annotations

import dataclasses

from ...config import Config
from ..compare import (
    AT_NOISE_FLOOR,
    Comparison,
    compare,
)
from ._calibration import sensor_calibration
from ._candidates import NUISANCE, _logged, candidate_library, select_candidates
from ._fit import _fit_candidate
from ._lsq import _sq
from ._problem import _Problem
from ._results import THRESHOLDS, Diagnosis, unidentified
from ._select import _joint_fits, _select, _twins
from ._verdict import _verdict


def diagnose(config: Config, logs, *, candidates=None, comparison: Comparison | None = None,
             progress=None, joint: bool = False, forward: bool = True,
             channel_map=None, exclude=(), trust=(), sensors: bool = True,
             n_jobs: int = -1) -> Diagnosis:
    """Find which physical effect the model misses: fit candidates, score them held out.

    The whole of ``gainsched diagnose`` (docs/model-vs-measurement.md, the module
    docstring): each candidate (a missing effect, a config parameter, the measurement
    latency) is refitted to the residual of :func:`~gainsched.analysis.compare.compare`,
    every axis weighted by its noise floor; it is scored on held-out flights
    (leave-one-flight-out: the RMS reduction and the share of the residual above the
    noise floor it explains), by delta-BIC, plausibility and fold stability; the
    candidates are ranked, near-collinear twins are named with the flight that would
    separate them, and the first candidate clearing every threshold of
    :data:`THRESHOLDS` is the verdict (the sensors calibrated first: ``sensors``).

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
        ``progress(name)`` as each candidate's fit is done.
    joint : bool, default False
        Fit pairs of the best singles even when one passes (else only when none passes
        above the noise floor): a passing joint fit replaces the accepted single when its
        delta-BIC is lower by ``THRESHOLDS["nested_bic_gain"]``.
    forward : bool, default True
        Forward selection (:func:`_forward`): while the accepted fit (or the best single)
        leaves more than ``THRESHOLDS["forward_excess_gain"]`` of the residual above
        noise, add the next best effect that explains clearly more.
    channel_map : ChannelMap, str or path-like, optional
        For PX4 ULogs and ROS 2 bags among ``logs`` (:func:`compare`).
    exclude : sequence of str
        Candidates or effect kinds to leave out (:func:`select_candidates`): the library
        told that an effect is not there (when no other explains what it would have, the
        verdict says so and fits an empirical term).
    trust : iterable of str, optional
        Consistency checks of the log files to skip (:func:`compare`).
    sensors : bool, default True
        Calibrate the sensors first (:func:`_calibrated`); False: ``[sensors]`` as it is.
    n_jobs : int, default -1
        Threads the fits run in side by side (-1: one per core); nothing else depends
        on it.

    Returns
    -------
    Diagnosis
        The ranked candidates, the accepted one (or None), the twins, the verdict.

    Raises
    ------
    InputError
        Fewer than two flights, an unknown candidate, or a log :func:`compare` refuses.

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
    config, base, calibration = _calibrated(config, base) if sensors else (config, base, None)
    prob = _problem(config, base, n_jobs)
    library = candidate_library()
    names = select_candidates(candidates, exclude, library)
    names = _logged(names, library, base.measured, asked=candidates is not None)
    at_floor, base_vecs, base_sq = _base_residual(prob, base)
    results, accepted, twins, similarity = _fits(
        prob, library, names, base, at_floor, base_sq, base_vecs,
        asked=candidates is not None, joint=joint, forward=forward, progress=progress)
    verdict = _verdict(base, results, accepted, twins, at_floor)
    if calibration is not None and calibration.accepted:
        verdict = f"{calibration.sentence()}. {verdict}"
    return Diagnosis(config, base, results, accepted, twins, verdict, at_floor,
                     prob.flight_names, int(round(prob.n_evals)), similarity, calibration)


def _calibrated(config: Config, base: Comparison):
    """The sensor first, then the dynamics: ``(config, base, calibration)`` with the gyro's
    calibration fitted against the motion capture
    (:func:`~gainsched.analysis.diagnose._calibration.sensor_calibration`) and, when it is
    accepted, in the config and in the measurement (``base`` measured again with it)."""
    calibration = sensor_calibration(config, base.measured)
    if calibration is not None and calibration.accepted:
        config = calibration.applied(config)
        base = compare(config, base.segs)
    return config, base, calibration


#: the most a nuisance tether stretches at the flights' highest tension, m: a real
#: tether's stretch (0.3 mm for 1.5 m of a k = 2e5 N/m line at 60 N, 0.02 %); a larger
#: one is an effect in its own right (a rubber cord), and a fit of the compliance that
#: reaches it stands in for something else (a length or attachment error shifts the
#: stretch by centimetres), so it is left to the ordinary fits
NUISANCE_MAX_STRETCH = 2e-3


def _ranked(results):
    return sorted(results, key=lambda r: (-r.rms_reduction, r.delta_bic))


def _nuisance(prob: _Problem, library, names, base_sq, base_vecs, progress):
    """The nuisance fit (:data:`NUISANCE`) these flights need whatever else is missing:
    ``(fit, None)``, or ``(None, fits tried by name)`` when none is needed. Needed: a
    parameter that carries it identified (:func:`unidentified`), small (a stretch of at
    most :data:`NUISANCE_MAX_STRETCH` at the flights' highest tension), the held-out RMS
    of each residual axis it acts on (the stretch) lower by
    ``THRESHOLDS["min_rms_reduction"]`` with no significant structure left there, the
    held-out RMS over all axes lower, and no axis worse. Judged on its own axes: another
    effect's large residual elsewhere (a thrust error) would hide it in the scores over
    all axes. (A real tether stretches a few tenths of a millimetre at the highest
    tensions: on every flight, the stretch axis shows it.)"""
    fall = 1 - THRESHOLDS["min_rms_reduction"]
    tried = {}
    base_structure = None
    for name in NUISANCE:
        if name not in names:
            continue
        if progress is not None:
            progress(name)
        cand = library[name]
        r = tried[name] = _fit_candidate(prob, cand, base_sq, base_vecs)
        axes = cand.variant(prob.config, r.theta).axes or frozenset(r.axis_rms_before)
        carried = [p.name for p in r.params if p.name not in unidentified(r)]
        stretch = prob.tension_range[1] / r.values["stiffness"]
        if base_structure is None:
            base_structure = {f.axis for f in prob.structure_left(base_vecs)}
        # its axes fall, or (near their noise floor, where a fall hides in the noise) the
        # binned structure the model leaves there goes
        fell = all(r.axis_rms_after[a] <= fall * r.axis_rms_before[a]
                   for a in axes if a in r.axis_rms_before)
        structured = bool(base_structure & set(axes))  # and none left: checked below
        # identified: a parameter's CI within its range, or its own axes falling clearly
        # (a large residual elsewhere, which the CI takes for noise, widens it)
        if ((carried or fell) and stretch <= NUISANCE_MAX_STRETCH and r.rms_reduction > 0
                and not r.worse_axes() and (fell or structured)
                and not any(s.startswith(f"{a} residual") for s in r.structure_left
                            for a in axes)):
            return r, None
    return None, tried


def _fits(prob, library, names, base, at_floor, base_sq, base_vecs, *, asked, joint, forward,
          progress):
    """Every fit of a diagnosis and the choice among them: ``(results, accepted, twins,
    similarity)``. With a nuisance these flights need (:func:`_nuisance`; not when the
    candidates were ``asked`` for by name), the candidates are fitted beside it
    (:func:`_select_beside`); otherwise as they are (:func:`_select`)."""
    nuisance, tried = ((None, None) if asked else
                       _nuisance(prob, library, names, base_sq, base_vecs, progress))
    if nuisance is not None:
        return _select_beside(prob, library, names, base, nuisance, base_sq, base_vecs,
                              joint=joint, forward=forward, progress=progress)
    results, accepted = _select(prob, library, names, base, at_floor, base_sq, base_vecs,
                                asked=asked, joint=joint, forward=forward, progress=progress,
                                fitted=tried)
    return (results, accepted, *_twins(library, results, accepted))


def _select_beside(prob, library, names, base, nuisance, base_sq, base_vecs, *, joint,
                   forward, progress):
    """:func:`_select` with the ``nuisance`` in the model (held at its fit): every other
    candidate fitted beside it, so it never vetoes the effect it rides with; the one
    accepted there fitted again together with it on the model as it is
    (:func:`_with_nuisance`). Returns ``(results, accepted, twins, similarity)``, the
    fits beside the nuisance noting it."""
    cfg2 = nuisance.candidate.variant(prob.config, nuisance.theta).config
    base2 = compare(cfg2, base.segs, measured=base.measured, segs=base.segs)
    prob2 = _problem(cfg2, base2, prob.n_jobs)
    at2, vecs2, sq2 = _base_residual(prob2, base2)
    results, found = _select(prob2, library, [n for n in names if n != nuisance.name],
                             base2, at2, sq2, vecs2, asked=False, joint=joint,
                             forward=forward, progress=progress)
    held = (f"fitted with {nuisance.name} in the model ("
            + ", ".join(f"{k} = {v:.4g}" for k, v in nuisance.values.items()) + ")")
    results = [dataclasses.replace(r, notes=(*r.notes, held)) for r in results]
    found = next((r for r in results if found is not None and r.name == found.name), None)
    twins, similarity = _twins(library, results, found)
    accepted = _with_nuisance(prob, nuisance, found, base_sq, base_vecs, progress)
    prob.n_evals += prob2.n_evals
    return (_ranked([nuisance, *([accepted] if accepted not in (None, nuisance) else []),
                     *results]), accepted, twins, similarity)


def _with_nuisance(prob, nuisance, found, base_sq, base_vecs, progress):
    """The accepted fit of a diagnosis whose candidates were fitted with the ``nuisance``
    in the model: ``found`` (None: nothing more) fitted together with the nuisance on
    the model as it is, unless ``found`` alone explains as much (delta-BIC within
    ``THRESHOLDS["nested_bic_gain"]``): then ``found`` alone. None when the fit does not
    pass."""
    if found is None:
        return nuisance if nuisance.passes else None
    both, alone = _joint_fits(prob, [[found, nuisance], [found]], base_sq, base_vecs,
                              progress)
    pick = (both if both.delta_bic < alone.delta_bic - THRESHOLDS["nested_bic_gain"]
            else alone)
    return pick if pick.passes else None


def _problem(config: Config, base: Comparison, n_jobs: int) -> _Problem:
    """The fit problem of ``config`` on the flights of its comparison ``base``, its fits
    ``n_jobs`` at a time; InputError with fewer than two flights (no held-out scores)."""
    from ...errors import InputError

    prob = _Problem(config, base.measured, base.segs, base.noise, base.residuals, n_jobs)
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
