"""Writing a fitted candidate into the config text (``gainsched diagnose --apply``).

:func:`apply_candidate`: the config's own text with the candidate's values (through
:meth:`~gainsched.analysis.diagnose._candidates.Candidate.apply_text`), each with its
unit, 95 % CI and leave-one-flight-out range as a comment; a parameter the flights did
not identify (:func:`~gainsched.analysis.diagnose._results.unidentified`) keeps its value.
:func:`apply_diagnosis`: all a diagnosis accepted, the gyro's calibration (``[sensors]``)
and the accepted candidate.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...config import Config, config_from_text, get_value, set_value
from ._candidates import candidate_library
from ._results import CandidateResult, unidentified


def apply_candidate(config: Config, result: CandidateResult, *, name: str | None = None) -> str:
    """Write a fitted candidate into the config: the new config text, CIs as comments.

    ``config``'s own text (its comments and layout kept) with the candidate's fitted
    values: an effect section added or updated, or a config key changed. Each value
    carries its unit, 95 % CI and leave-one-flight-out range as a comment, and the
    section a comment with the held-out scores. A parameter the flights did not identify (a CI wider
    than the estimate or than its range, or an estimate on a bound) keeps its value
    before the fit, with the reason as a comment. The text is validated with
    :func:`~gainsched.config.config_from_text` before it is returned.

    Parameters
    ----------
    config : Config
        The config the candidate was fitted to (``Diagnosis.config``).
    result : CandidateResult
        A fitted candidate: ``Diagnosis.accepted`` or any of ``Diagnosis.results``.
    name : str, optional
        A new ``name`` for the config; default: the config's own, so that the tables
        rebuilt from it keep their header and C symbol names (``<name>_gains.h``,
        ``<name>_...``) and firmware built on them keeps compiling through the loop
        compare -> diagnose -> apply -> build (replaced only when the text has a
        ``name`` key).

    Returns
    -------
    str
        The new config text (TOML), ready to write to a file or to load with
        :func:`~gainsched.config.config_from_text`.

    Raises
    ------
    InputError
        The edited text is not a valid config.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = ["examples/flights/v3.csv", "examples/flights/v9.csv",
    ...         "examples/flights/v15.csv"]
    >>> d = gs.diagnose(cfg, logs, candidates=["thrust_momentum"])
    >>> text = gs.apply_candidate(cfg, d.accepted, name="paper_momentum")
    >>> print(text[text.index("[effects.thrust_momentum]"):])
    [effects.thrust_momentum]              # gainsched diagnose: thrust_momentum, held-out RMS ...
    disk_area = 0.0060...       # m^2, 95% CI [...], folds ...
    rho_air = 1.225                        # kept
    ...
    >>> improved = gs.config_from_text(text, "paper_momentum.toml")
    >>> improved.name, [e.name for e in improved.effects]
    ('paper_momentum', ['drag', 'thrust_momentum'])

    The residual falls on the same flights (normalised RMS, 1 = measurement noise):

    >>> before, after = d.base.normalized_rms(), gs.compare(improved, logs).normalized_rms()
    >>> f"{before:.1f} -> {after:.1f}"
    '5.3 -> 2.0'
    """
    cand = result.candidate or candidate_library()[result.name]
    why = unidentified(result)
    comments = []
    theta = result.theta.copy()
    for j, p in enumerate(result.params):
        if p.name in why:
            theta[j] = result.start[j]
            comments.append(f"not identified on these flights ({why[p.name]}), so not "
                            "written as fitted: the value before the fit")
            continue
        lo, hi = result.theta[j] - result.ci[j], result.theta[j] + result.ci[j]
        f = result.folds[:, j]
        comments.append(
            f"{p.unit}, 95% CI [{lo:.4g}, {hi:.4g}], folds {f.min():.4g}..{f.max():.4g}"
        )
    header = (f"gainsched diagnose: {result.name}, held-out RMS -{result.rms_reduction:.0%}, "
              f"delta-BIC {result.delta_bic:.0f}")
    if why:
        header += f"; not identified, not written: {', '.join(why)}"
    text = cand.apply_text(config.text, config, theta, comments, header,
                           keep=frozenset(why))
    if name is not None and get_value(text, "", "name") is not None:
        text = set_value(text, "", "name", name)
    cfg = config_from_text(text, "<diagnose --apply>")  # raises if the edit is invalid
    del cfg
    return text


def apply_diagnosis(diagnosis, *, name: str | None = None) -> str | None:
    """Write what a diagnosis accepted into its config: the gyro's calibration
    (``[sensors]``, when accepted: :attr:`Diagnosis.calibration`) and the accepted
    candidate (:func:`apply_candidate`); None when it accepted nothing.

    Parameters
    ----------
    diagnosis : Diagnosis
        What :func:`~gainsched.analysis.diagnose.diagnose` returned.
    name : str, optional
        As for :func:`apply_candidate`.

    Returns
    -------
    str or None
        The new config text (validated), or None.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = ["examples/flights/v3.csv", "examples/flights/v9.csv",
    ...         "examples/flights/v15.csv"]
    >>> d = gs.diagnose(cfg, logs, candidates=["thrust_momentum"])
    >>> d.applied, d.calibration.accepted   # the example gyro needs no calibration
    (['thrust_momentum'], False)
    >>> text = gs.apply_diagnosis(d)
    >>> "[effects.thrust_momentum]" in text, "[sensors]" in text
    (True, False)
    """
    d = diagnosis
    if not d.applied:
        return None
    cfg = d.config
    cal = d.calibration
    if cal is not None and cal.accepted:
        text = _with_calibration(cfg.text, cal)
        cfg = dataclasses.replace(cfg, text=text)
    if d.accepted is not None:
        return apply_candidate(cfg, d.accepted, name=name)
    if name is not None and get_value(cfg.text, "", "name") is not None:
        cfg = dataclasses.replace(cfg, text=set_value(cfg.text, "", "name", name))
    config_from_text(cfg.text, "<diagnose --apply>")  # raises if the edit is invalid
    return cfg.text


def _with_calibration(text: str, cal) -> str:
    """``text`` with the calibration ``cal`` in ``[sensors]``: the gyro's scale and bias,
    the marker frame's rotation when it turned, the accelerometer's scale and bias when
    one is off; the 95 % intervals and the held-out fall as comments."""
    s = cal.sensors()
    ci = lambda v, c: ", ".join(f"{x:.4g} +- {e:.1g}" for x, e in zip(v, c, strict=True))  # noqa: E731
    header = (f"gainsched diagnose: sensors against the motion capture, held-out residual "
              f"above noise -{cal.fall:.0%}")
    g, off = cal.gyro, cal.off
    text = set_value(text, "sensors", "gyro_scale", list(s.gyro_scale),
                     f"fitted {ci(g.scale, g.scale_ci)} (95%); {header}")
    text = set_value(text, "sensors", "gyro_bias", list(s.gyro_bias),
                     f"rad/s, fitted {ci(g.bias, g.bias_ci)} (95%)")
    if cal.rotated:
        text = set_value(text, "sensors", "marker_rotation_deg",
                         [round(float(np.rad2deg(a)), 4) for a in s.marker_rotation],
                         "deg, roll pitch yaw of the body in the markers' frame, fitted "
                         f"{ci(cal.marker_deg(), np.rad2deg(cal.rotation_ci))} (95%)")
    a = cal.accel
    if a is not None and any(v for k, v in off.items() if k.startswith("accel")):
        text = set_value(text, "sensors", "accel_scale", list(s.accel_scale),
                         f"fitted {ci(a.scale, a.scale_ci)} (95%)")
        text = set_value(text, "sensors", "accel_bias", list(s.accel_bias),
                         f"m/s^2, fitted {ci(a.bias, a.bias_ci)} (95%)")
    return text
