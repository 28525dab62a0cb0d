"""A table's closed loops under a diagnosis's uncertainty (``gainsched check TABLE
--uncertain REPORT``; docs/margins.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ._plan import read_report
from ._report import SILENT, Reporter, teller

__all__ = ["UncertainCheck", "check_uncertain"]


@dataclass(frozen=True, eq=False)
class UncertainCheck:
    """What :func:`check_uncertain` found.

    Attributes
    ----------
    table : Path
        The table checked.
    result : Uncertainty
        The plants, their multipliers per circle, the worst plant's margins and, where a
        loop is unstable, the parameter that makes it so
        (:class:`~gainsched.sim.uncertain.Uncertainty`; ``to_json()`` has every number).
    ok : bool
        Every plant's loop stable on every circle (the command exits 1 when not).
    said : tuple of str
        :meth:`lines`.
    """

    table: Path
    result: object
    ok: bool
    said: tuple

    def lines(self) -> list[str]:
        """What ``gainsched check --uncertain`` prints: the box, the worst multiplier and
        where, the worst plant's margins, and PASS or FAIL naming the parameter."""
        return list(self.said)


def check_uncertain(table, report, *, samples: int | None = None, seed: int = 0,
                    reporter: Reporter = SILENT) -> UncertainCheck:
    """Close a table's gains on plants drawn over a diagnosis's 95 % box: what
    ``gainsched check TABLE --uncertain REPORT`` does (:mod:`gainsched.sim.uncertain`).

    Parameters
    ----------
    table : path-like
        The gain table (HDF5).
    report : path-like or dict
        The diagnose report (``diagnose.json`` or its folder), or its data.
    samples : int, optional
        Random plants inside the box besides its corners and the estimate (default
        :data:`~gainsched.sim.uncertain.SAMPLES`).
    seed : int
        Seed of the samples.
    reporter : Reporter, optional
        Shows the plants' progress and the lines as they come; default: nothing.

    Returns
    -------
    UncertainCheck

    Raises
    ------
    InputError
        An unreadable table or report, a report without a fit, a negative ``samples``,
        before any work.

    Examples
    --------
    >>> try:
    ...     gs.studies.check_uncertain("tables/paper.h5", {"candidates": {}})
    ... except gs.InputError as e:
    ...     print(str(e).split(": give")[0])
    report: candidates: no fitted candidate in the report
    """
    from ..schedule.tables import load_table
    from ..sim.uncertain import SAMPLES, plant_count, uncertain_loops

    samples = SAMPLES if samples is None else samples
    if samples < 0:
        raise InputError("command line", "--samples", f"{samples}: must be >= 0")
    t = load_table(table)
    data, source = (report, "report") if isinstance(report, dict) else read_report(report)
    total = plant_count(data, samples, str(source))  # its checks first, before any work
    said, say = teller(reporter)
    with reporter.bar(f"check {t.name} --uncertain", total, "plant") as bar:
        u = uncertain_loops(t, data, samples=samples, seed=seed, source=str(source),
                            progress=bar.update)
    say(u.lines(str(table)))
    return UncertainCheck(Path(table), u, u.stable, tuple(said))
