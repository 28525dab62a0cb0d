"""Writing a fitted candidate into the config text (``gainsched diagnose --apply``).

:func:`apply_candidate`: the config's own text with the candidate's values (through
:meth:`~gainsched.analysis.diagnose._candidates.Candidate.apply_text`), each with its
unit, 95 % CI and leave-one-flight-out range as a comment; a parameter the flights did
not identify (:func:`~gainsched.analysis.diagnose._results.unidentified`) keeps its value.
"""

from __future__ import annotations

from ...config import Config, config_from_text
from ...configedit import set_value
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
    from ...configedit import get_value

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
