"""The model loop in one call: compare, diagnose and apply in rounds until no effect is
missing (docs/model-vs-measurement.md, "The loop in one command").

:func:`improve` is what ``gainsched compare``, ``diagnose --apply`` and a compare of the
new config do, repeated: each round diagnoses the current config on the flights, writes
the accepted effect into it (:func:`~gainsched.analysis.diagnose.apply_candidate`, the
config's ``name`` kept, so tables rebuilt from it keep their C symbols) and compares
again. It stops when nothing is accepted, when an accepted fit no longer lowers the
residual, or after ``rounds`` rounds. ``gainsched improve`` and :func:`gainsched.improve`
(:func:`gainsched.studies.improve`) add the rebuild of the tables, the standard flights
flown on the improved model with the old and the new table
(:func:`gainsched.sim.oldnew.fly_old_new`) and the report (:func:`write_improve`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from ..config import Config, config_from_text
from .compare import Comparison, compare, load_segments
from .diagnose import Diagnosis, apply_diagnosis, diagnose

__all__ = ["Round", "Improvement", "improve", "write_improve"]


@dataclass(frozen=True)
class Round:
    """One round of :func:`improve`: the config it started from, its comparison and the
    diagnosis (None for the final comparison of the last config)."""

    config: Config
    comparison: Comparison
    diagnosis: Diagnosis | None = None

    @property
    def rms(self) -> float:
        """Normalised RMS of the residual (1: the measurement noise)."""
        return self.comparison.normalized_rms()


@dataclass(frozen=True, eq=False)
class Improvement:
    """What :func:`improve` found.

    Attributes
    ----------
    rounds : list of Round
        Round 0 is the config given; each later one the config with one more accepted
        fit; the last round's diagnosis (or none) is the one that stopped the loop.
    config : Config
        Property: the improved config (the last round's).
    applied : list of str
        Property: the candidates written into the config, in order.
    """

    rounds: list = field(default_factory=list)

    @property
    def config(self) -> Config:
        """The improved config (the last round's)."""
        return self.rounds[-1].config

    @property
    def applied(self) -> list[str]:
        """The candidates written into the config, in order."""
        return [" + ".join(r.diagnosis.applied) for r in self.rounds
                if r.diagnosis is not None and r.diagnosis.applied]

    def to_json(self) -> dict:
        return {
            "config": self.config.name,
            "applied": self.applied,
            "rounds": [{"round": k, "normalized_rms": r.rms,
                        "verdict": None if r.diagnosis is None else r.diagnosis.verdict,
                        "accepted": (None if r.diagnosis is None or r.diagnosis.accepted is None
                                     else r.diagnosis.accepted.name)}
                       for k, r in enumerate(self.rounds)],
        }

    def __repr__(self) -> str:
        return (f"Improvement({self.config.name!r}, {len(self.rounds)} rounds, applied "
                f"{self.applied}, normalised RMS {self.rounds[0].rms:.3g} -> "
                f"{self.rounds[-1].rms:.3g})")


def improve(config: Config, logs, *, rounds: int = 3, exclude=(), channel_map=None,
            trust=(), sensors: bool = True, progress=None) -> Improvement:
    """Diagnose and apply in rounds until no effect is missing.

    Parameters
    ----------
    config : Config
        The model to improve.
    logs : list of path or FlightLog
        Two or more flights (held-out scores need them).
    rounds : int
        The most diagnose rounds (1..10).
    exclude, channel_map, trust, sensors
        As :func:`~gainsched.analysis.diagnose.diagnose` and
        :func:`~gainsched.analysis.compare.compare` take them (``sensors``: calibrate
        the sensors against the motion capture first, default True).
    progress : callable, optional
        ``progress(name)`` before each candidate fit (diagnose's).

    Returns
    -------
    Improvement
        Round 0 is ``config`` itself; each later round the config with one more
        accepted fit; the last round's diagnosis is the one that stopped the loop.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = ["examples/flights/v3.csv", "examples/flights/v9.csv",
    ...         "examples/flights/v15.csv"]
    >>> from gainsched.analysis.improve import improve
    >>> imp = improve(cfg, logs, rounds=1)
    >>> imp.applied, imp.config.name
    (['thrust_momentum + motor_lag'], 'paper')
    >>> imp.rounds[-1].rms < 0.5 * imp.rounds[0].rms
    True
    """
    measured, segs, _ = load_segments(config, logs, channel_map=channel_map, trust=trust)
    cfg = config
    cmp = compare(cfg, logs, measured=measured, segs=segs)
    out: list[Round] = []
    for _ in range(rounds):
        d = diagnose(cfg, segs, comparison=cmp, exclude=exclude, progress=progress,
                     sensors=sensors)
        out.append(Round(cfg, cmp, d))
        text = apply_diagnosis(d)
        if text is None:
            return Improvement(out)
        new = config_from_text(text, cfg.source)
        new_measured = load_segments(new, segs)[0]
        after = compare(new, segs, measured=new_measured, segs=segs)
        if after.normalized_rms() >= cmp.normalized_rms():  # a fit that does not help
            return Improvement(out)
        cfg, cmp = new, after
    out.append(Round(cfg, cmp, None))
    return Improvement(out)


def write_improve(imp: Improvement, out_dir, flights=None, *,
                  not_flown: str | None = None, uncertain=None) -> list[Path]:
    """The report of an improvement: the error round by round, the flights old and new.

    The flights, when the rebuilt tables were flown: the tracking of the standard flights
    with the old and with the new table.

    Parameters
    ----------
    imp : Improvement
        What :func:`improve` returned.
    out_dir : str or path-like
        An existing folder; files of the same names in it are replaced.
    flights : OldNewFlights, optional
        The standard flights flown with the old and the new table
        (:func:`gainsched.sim.oldnew.fly_old_new`); None: not flown.
    not_flown : str, optional
        Why the flights were not flown (``--no-build``, a table that cannot be built),
        said in the report when ``flights`` is None.
    uncertain : Uncertainty, optional
        The rebuilt table's loops over the last applied fit's 95 % box
        (:func:`gainsched.sim.uncertain.uncertain_loops`); None: not checked.

    Returns
    -------
    list of Path
        ``improve.json`` (the rounds: normalised RMS, accepted candidate, verdict; and
        ``flights``: the flights' metrics old, new and their ratio, per flight and over
        all flights, or None with ``flights_not_flown``; ``uncertain``: the check's
        numbers, or None), ``improve.md`` (the same as
        tables) and ``improve.png`` (the normalised RMS per round, each round's added
        effect written beside it; beside it, when flown, the RMS tracking errors of the
        flights, old table against new).

    Examples
    --------
    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = ["examples/flights/v3.csv", "examples/flights/v9.csv"]
    >>> imp = gs.improve(cfg, logs, rounds=1).improvement
    >>> [p.name for p in gs.write_improve(imp, tempfile.mkdtemp())]
    ['improve.json', 'improve.md', 'improve.png']
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    data = imp.to_json()
    data["flights"] = None if flights is None else flights.to_json()
    if flights is None:
        data["flights_not_flown"] = not_flown or "not asked for"
    data["uncertain"] = None if uncertain is None else uncertain.to_json()
    paths = [out_dir / "improve.json", out_dir / "improve.md", out_dir / "improve.png"]
    paths[0].write_text(json.dumps(data, indent=2) + "\n")
    lines = [f"# Model improvement of `{imp.config.name}`", "",
             "| round | normalised RMS | accepted | verdict |", "| --- | --- | --- | --- |"]
    for r in data["rounds"]:
        verdict = (r["verdict"] or "").replace("|", "/")
        lines.append(f"| {r['round']} | {r['normalized_rms']:.3g} | {r['accepted'] or '-'} | "
                     f"{verdict[:300]} |")
    lines += ["", f"Applied: {', '.join(imp.applied) or 'nothing'}. The normalised RMS is 1 at "
              "the measurement noise (docs/model-vs-measurement.md).", ""]
    lines += _flight_lines(flights, data.get("flights_not_flown"))
    if uncertain is not None:
        lines += ["## The new table under the fit's uncertainty", "",
                  "As `gainsched check TABLE --uncertain REPORT` (docs/margins.md):", "",
                  "```", *uncertain.lines("the rebuilt table"), "```", ""]
    paths[1].write_text("\n".join(lines))
    if flights is not None and flights.flights:
        fig, (ax, ax_f) = plt.subplots(1, 2, figsize=(12, 4),
                                       gridspec_kw={"width_ratios": [1, 1.4]})
        flights.plot(ax_f)
    else:
        fig, ax = plt.subplots(figsize=(6, 3.5))
    rms = [r["normalized_rms"] for r in data["rounds"]]
    ax.plot(range(len(rms)), rms, "o-")
    for k, r in enumerate(data["rounds"]):
        if r["accepted"]:
            ax.annotate(f"+ {r['accepted']}", (k, rms[k]), fontsize=7,
                        textcoords="offset points", xytext=(4, 4))
    ax.axhline(1.0, color="0.6", lw=0.8, ls="--", label="measurement noise")
    ax.set_xlabel("round")
    ax.set_ylabel("normalised RMS of the residual")
    ax.set_xticks(range(len(rms)))
    ax.set_title(f"{imp.config.name}: the residual round by round")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(paths[2], dpi=100)
    plt.close(fig)
    return paths


def _flight_lines(flights, not_flown) -> list[str]:
    """The report's section on the standard flights (Markdown lines)."""
    lines = ["## The standard flights, old table against new", ""]
    if flights is None:
        return lines + [f"Not flown: {not_flown}.", ""]
    meta = flights.meta or {}
    plant = (f"the improved model `{flights.plant}` (the best available stand-in for the "
             "vehicle)" if flights.plant_is_new else f"`{flights.plant}`")
    lines += [f"Plant: {plant}; "
              f"old: the original config's nominal and table ({meta.get('old_table', '?')}); "
              f"new: the improved config's nominal and the rebuilt table "
              f"({meta.get('new_table', '?')}). Flights of {flights.duration:g} s with "
              "motion-capture noise (the standard flights of `gainsched campaign`, the same "
              "noise for both tables); the metrics are `gainsched simulate`'s "
              "(metrics.json); **all**: the RMS over the flights of each RMS error and of the "
              "final azimuth error, the largest saturation, the slack events in all.", ""]
    if flights.flights:
        lines += flights.markdown_lines() + [""]
    else:
        lines += ["No flight flown.", ""]
    if flights.skipped:
        lines += ["Not flown: " + "; ".join(f"{n} ({why})" for n, why in flights.skipped)
                  + ".", ""]
    return lines
