"""The next flight: from a diagnose report, the flights that would tell its look-alike
candidates apart or shrink its widest interval the most (``gainsched plan``).

A diagnosis ends with a fitted effect whose parameters carry 95 % intervals, and often
with look-alikes: candidates that explain the same flights almost as well (its
``twins``, and the runners-up whose held-out fall is close). Which flight settles it is
an experiment-design question; here it is answered by flying it, in simulation, before
the vehicle does:

1. **the menu**: flights the table can fly (its speeds and tilts): level circles at the
   slowest and the fastest speed, the fastest at the largest tilt, the middle speed at
   the largest tilt and at half of it, a speed-up and a braking over the whole range,
   and a multisine on the along-track speed (four tones, 0.2-1.6 Hz, Schroeder phases)
   about the middle speed, level and tilted, its amplitude the most the envelope and
   the tension margin allow (halved until the nominal is feasible on the design model);
2. **each flown** by the table on the plant the report believes in (the config with the
   fitted effect at its estimate: :func:`truth_config`), with the campaign's motion-capture
   and IMU noise, twice (two noise draws: diagnose's held-out scores need two flights);
3. **diagnosed** with the focus and its look-alikes only: the focus's 95 % interval on
   that flight pair, combined with the report's as independent information
   (``1 / ci^2`` adds), is the interval expected after flying it; the look-alikes'
   held-out fall against the focus's is how well the flight tells them apart (the
   separation: the focus's fall minus the look-alike's, in points of the held-out RMS).

The flights are ranked by the separation when there are look-alikes (telling them apart
is the open question), else by how much they shrink the widest relative interval. Each
is written as a scenario (``gainsched simulate`` flies it; its speed profile is the
reference the generated controller flies) and as the reference itself, ``t, xi_ref,
xi_dot_ref`` at the control rate.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .campaign import default_flights
from .loop import Maneuver, Scenario, Sine, log_from_result, profile_path, simulate

__all__ = ["TONES_HZ", "PlannedFlight", "Plan", "report_focus", "truth_config", "menu", "named",
           "plan_flights"]

#: the multisine's tones, Hz: within the closed loop's bandwidth, apart from the circle's
#: own frequencies by their spread
TONES_HZ = (0.2, 0.45, 0.9, 1.6)
#: a manoeuvre's eq. 20 parameter, m/s^2 (peak tangential acceleration 2 a)
MANOEUVRE_A = 4.0
#: the look-alikes planned for: the report's twins, and the candidates whose held-out
#: fall is at least this share of the focus's
LOOK_ALIKE_SHARE = 0.8


@dataclass(frozen=True)
class PlannedFlight:
    """A flight of the menu, flown and diagnosed.

    Attributes
    ----------
    name : str
        What it is (``"circle 15 m/s level"``, ``"multisine 9 +- 2.1 m/s 40 deg"``).
    scenario : Scenario
        The flight (speeds, tilt, manoeuvres, excitation, sensing).
    ci : dict
        Per parameter of the focus: ``(now, alone, expected)``, the report's 95 % half
        width, this flight's alone and the two combined, in the parameter's unit (NaN
        when this flight could not fit it).
    separation : dict
        Per look-alike: the focus's held-out RMS fall minus the look-alike's on this
        flight (0.3: 30 points of the held-out RMS), NaN when not fitted.
    """

    name: str
    scenario: Scenario
    ci: dict
    separation: dict

    def shrink(self, param: str) -> float:
        """Expected over current 95 % half width of ``param`` (1: no gain)."""
        now, _, exp = self.ci[param]
        return exp / now if now > 0 and math.isfinite(exp) else 1.0


@dataclass(frozen=True, eq=False)
class Plan:
    """What :func:`plan_flights` found.

    Attributes
    ----------
    focus : str
        The candidate planned for (the report's accepted one, else its best).
    params : dict
        Its parameters in the report: name -> ``(estimate, ci95, unit)``.
    look_alikes : tuple of str
        The candidates it must be told apart from.
    flights : tuple of PlannedFlight
        Best first.
    skipped : tuple of (str, str)
        Menu flights not flown, and why.
    widest : str
        The focus's parameter with the widest 95 % interval relative to its estimate.
    """

    focus: str
    params: dict
    look_alikes: tuple
    flights: tuple
    skipped: tuple
    widest: str

    def rows(self) -> list[list[str]]:
        """The table: flight, then per parameter the interval now -> expected, then per
        look-alike the separation."""
        out = []
        for f in self.flights:
            row = [f.name]
            for p, (_, _, unit) in self.params.items():
                now, _, exp = f.ci[p]
                row.append(f"{now:.3g} -> {exp:.3g} {unit}".strip() if math.isfinite(exp)
                           else f"{now:.3g} -> ? {unit}")
            row += [f"{100 * f.separation[a]:+.0f} pts" if math.isfinite(f.separation[a])
                    else "?" for a in self.look_alikes]
            out.append(row)
        return out

    def head(self) -> list[str]:
        return (["flight"] + [f"{p} 95% CI" for p in self.params]
                + [f"vs {a}" for a in self.look_alikes])

    def lines(self) -> list[str]:
        """What ``gainsched plan`` prints: the focus, then the flights best first."""
        est = ", ".join(f"{p} = {v:.4g} +- {c:.2g} {u}".rstrip()
                        for p, (v, c, u) in self.params.items())
        out = [f"plan for {self.focus} ({est})"
               + (f", to tell apart from {', '.join(self.look_alikes)}" if self.look_alikes
                  else "") + ": the flights best first"]
        rows = [self.head(), *self.rows()]
        widths = [max(len(r[j]) for r in rows) for j in range(len(rows[0]))]
        out += ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
                for r in rows]
        out += [f"  not planned: {n} ({why})" for n, why in self.skipped]
        return out

    def markdown(self) -> str:
        head = self.head()
        rows = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
        rows += ["| " + " | ".join(r) + " |" for r in self.rows()]
        note = ("Each flight flown in simulation on the plant the report believes in (the "
                "config with the fitted effect), twice with the campaign's sensor noise, and "
                "diagnosed with the focus and its look-alikes only. CI: the report's 95 % "
                "half width -> the one expected after flying it (the two combined). vs: the "
                "focus's held-out RMS fall minus the look-alike's on the flight (higher: "
                "told apart better).")
        skipped = "".join(f"\n- not planned: {n} ({why})" for n, why in self.skipped)
        return (f"# The next flight: {self.focus}\n\n" + "\n".join(self.lines()[:1]) + "\n\n"
                + note + "\n\n" + "\n".join(rows) + "\n" + skipped + "\n")

    def to_json(self) -> dict:
        nan = lambda x: None if not math.isfinite(x) else x  # noqa: E731
        return {"focus": self.focus, "look_alikes": list(self.look_alikes),
                "widest": self.widest,
                "params": {p: {"estimate": v, "ci95": c, "unit": u}
                           for p, (v, c, u) in self.params.items()},
                "flights": [{"name": f.name, "file": f"{i:02d}.toml",
                             "ci95": {p: {"now": nan(a), "alone": nan(b), "expected": nan(c)}
                                      for p, (a, b, c) in f.ci.items()},
                             "separation": {k: nan(v) for k, v in f.separation.items()}}
                            for i, f in enumerate(self.flights, 1)],
                "not_planned": [{"name": n, "reason": w} for n, w in self.skipped]}


def report_focus(report: dict, source) -> tuple[str, dict, tuple]:
    """The candidate to plan for, its parameters ``{name: (estimate, ci95, unit)}`` and
    its look-alikes, from a diagnose report's JSON."""
    cands = report.get("candidates")
    if not isinstance(cands, dict) or not cands:
        raise InputError(source, "candidates", "no fitted candidate in the report: give a "
                         "diagnosis with at least one fit (gainsched diagnose --report DIR "
                         "writes diagnose.json)")
    focus = report.get("accepted") or next(iter(report.get("ranking") or cands))
    if focus not in cands:
        raise InputError(source, "accepted", f"{focus!r} is not among the report's candidates")
    try:
        params = {p: (float(v["estimate"]), float(v["ci95"]), str(v.get("unit", "")))
                  for p, v in cands[focus]["params"].items()}
        fall = float(cands[focus]["heldout_rms_reduction"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(source, f"candidates.{focus}", f"not a diagnose report's fit "
                         f"({type(exc).__name__}: {exc})") from None
    alike = [t["candidate"] for t in report.get("twins") or [] if isinstance(t, dict)
             and t.get("candidate") in cands and t.get("candidate") != focus]
    for name in report.get("ranking") or []:
        r = cands.get(name, {})
        if (name != focus and name not in alike and not r.get("empirical")
                and isinstance(r.get("heldout_rms_reduction"), (int, float))
                and r["heldout_rms_reduction"] >= LOOK_ALIKE_SHARE * fall > 0):
            alike.append(name)
    return focus, params, tuple(alike[:3])


def truth_config(config, focus: str, estimates, keep=frozenset()):
    """The config with the candidate ``focus`` (a library name, or parts joined by
    ``" + "``) at ``estimates`` (its parameters in order): the plant the report believes
    in. ``keep``: parameters the fit did not identify, whose ``estimates`` are the
    config's own values (:func:`focus_values`), left as the config has them."""
    from ..analysis.diagnose import candidate_library
    from ..config import config_from_text

    lib = candidate_library()
    parts = focus.split(" + ")
    missing = [p for p in parts if p not in lib]
    if missing:
        raise InputError("report", f"candidates.{focus}", f"{', '.join(missing)} is no "
                         "candidate of the library (an empirical term or a sensor "
                         "calibration is not planned for)")
    cfg, theta, k = config, np.asarray(estimates, float), 0
    for part in parts:
        cand = lib[part]
        n = len(cand.params)
        text = cand.apply_text(cfg.text, cfg, theta[k:k + n], [""] * n, "gainsched plan",
                               keep=frozenset(keep))
        cfg = config_from_text(text, f"<{config.name} with {part}>")
        k += n
    return cfg


def focus_values(config, focus: str) -> np.ndarray:
    """The values the config has of the candidate ``focus``'s parameters (in the fit's
    parametrisation, as :func:`truth_config` takes them)."""
    from ..analysis.diagnose import candidate_library

    lib = candidate_library()
    return np.concatenate([np.asarray(lib[part].start(config), float)
                           for part in focus.split(" + ")])


def menu(table, duration: float, seed: int = 1) -> list[Scenario]:
    """The flights the plan tries (module docstring), within ``table``'s speeds and tilts."""
    sens = default_flights(duration, seed)[0].sensing
    lo, hi = float(np.min(table.speed)), float(np.max(table.speed))
    tilt = float(np.max(np.abs(table.tilt)))
    mid = 0.5 * (lo + hi)
    amp = min(0.3 * mid, mid - lo, hi - mid)
    K = len(TONES_HZ)
    tones = tuple(Sine(amp / K, f, -math.pi * k * (k - 1) / K) for k, f in enumerate(TONES_HZ))

    def scn(v, a, man=(), exc=()):
        return named(Scenario("", a, v, duration, man, sensing=sens, excitation=exc))

    return [scn(lo, 0.0), scn(hi, 0.0), scn(hi, tilt), scn(mid, tilt), scn(mid, 0.5 * tilt),
            scn(lo, 0.0, (Maneuver(1.0, hi, MANOEUVRE_A),)),
            scn(hi, 0.0, (Maneuver(1.0, lo, MANOEUVRE_A),)),
            scn(mid, 0.0, exc=tones), scn(mid, tilt, exc=tones)]


def named(scn: Scenario) -> Scenario:
    """``scn`` named after what it flies: ``circle 15 m/s level``, ``speed-up 1.3->15 m/s
    level``, ``multisine 8.15 +- 2.4 m/s 40 deg``."""
    tilt = "level" if scn.tilt == 0 else f"{math.degrees(scn.tilt):.0f} deg"
    if scn.excitation:
        amp = sum(s.amplitude for s in scn.excitation)
        what = f"multisine {scn.speed:g} +- {amp:.2g} m/s"
    elif scn.maneuvers:
        end = scn.maneuvers[-1].speed
        what = f"{'speed-up' if end > scn.speed else 'braking'} {scn.speed:g}->{end:g} m/s"
    else:
        what = f"circle {scn.speed:g} m/s"
    return dataclasses.replace(scn, name=f"{what} {tilt}")


def _feasible(model, scn: Scenario) -> Scenario | str:
    """``scn``, its excitation halved (at most twice) until the nominal of ``model`` (the
    truth's) along it keeps the tension margin and the motors' range; else why it cannot
    be flown."""
    from ..schedule.nominal import nominal_from_path
    from ..schedule.trim import TrimError

    dt = model.config.control.dt
    t = np.arange(int(round(scn.duration / dt)) + 1) * dt
    for _ in range(3):
        try:
            nom = nominal_from_path(model, profile_path(scn, model.r, t), scn.tilt)
        except TrimError:
            return "no nominal along it on the fitted model"
        if nom.feasible.all():
            return scn
        if not scn.excitation:
            break
        scn = named(dataclasses.replace(scn, excitation=tuple(
            dataclasses.replace(s, amplitude=0.5 * s.amplitude) for s in scn.excitation)))
    return "beyond the vehicle on the fitted model (tension margin or motor range)"


def plan_flights(config, report: dict, table, *, duration: float = 10.0, source="report",
                 progress=None) -> Plan:
    """The flights that would settle a diagnosis, best first (module docstring).

    Parameters
    ----------
    config : Config
        The config the report diagnosed (its table flies the flights).
    report : dict
        The diagnose report's JSON (``diagnose.json``).
    table : Table
        ``config``'s gain table.
    duration : float
        Seconds per flight.
    source : str
        The report's file, for errors.
    progress : callable, optional
        ``progress(1)`` per menu flight done.

    Returns
    -------
    Plan

    Raises
    ------
    InputError
        The report holds no fit, or its focus is no library candidate.
    """
    from ..analysis.diagnose import diagnose
    from ..model.reduced import Model
    from .loop import table_scheduler

    focus, params, alike = report_focus(report, source)
    truth = truth_config(config, focus, [v for v, _, _ in params.values()])
    model = Model(truth)  # its nominals: one model for the whole menu
    sched = table_scheduler(table)
    step = progress or (lambda n: None)
    names = [*focus.split(" + "), *alike]
    joint = " + " in focus
    flights, skipped = [], []
    for k, scn0 in enumerate(menu(table, duration)):
        scn = _feasible(model, scn0)
        if isinstance(scn, str):
            skipped.append((scn0.name, scn))
            step(1)
            continue
        logs = [log_from_result(simulate(config, sched, dataclasses.replace(  # two flights
            scn, name=f"{scn.name} #{j}", sensing=dataclasses.replace(scn.sensing,
                                                                    seed=10 * k + j)), truth),
            seed=10 * k + j) for j in (1, 2)]
        try:
            d = diagnose(config, logs, candidates=names, joint=joint, sensors=False)
        except InputError as e:
            skipped.append((scn.name, e.message))
            step(1)
            continue
        res = {frozenset(r.name.split(" + ")): r for r in d.results}  # parts in any order
        fit = res.get(frozenset(focus.split(" + ")))
        by_name = {} if fit is None else {q.name: float(c) for q, c in zip(fit.params, fit.ci,
                                                                          strict=True)}
        ci = {}
        for p, (_, now, _) in params.items():
            alone = by_name.get(p, math.nan)
            exp = (1.0 / math.sqrt(1.0 / now**2 + 1.0 / alone**2)
                   if now > 0 and alone > 0 and math.isfinite(alone) else now)
            ci[p] = (now, alone, exp)
        sep = {}
        for a in alike:
            other = res.get(frozenset(a.split(" + ")))
            sep[a] = (fit.rms_reduction - other.rms_reduction if fit is not None and
                      other is not None else math.nan)
        flights.append(PlannedFlight(scn.name, scn, ci, sep))
        step(1)
    widest = max(params, key=lambda p: params[p][1] / max(abs(params[p][0]), 1e-300))
    if alike:
        key = lambda f: -min((v for v in f.separation.values() if math.isfinite(v)),  # noqa: E731
                             default=-math.inf)
    else:
        key = lambda f: f.shrink(widest)  # noqa: E731
    return Plan(focus, params, alike, tuple(sorted(flights, key=key)), tuple(skipped), widest)
