"""The paper's flight experiments, flown in simulation: ``gainsched paper -o DIR``.

Paper Sec. V.B (the vehicle of configs/paper.toml): constant-speed horizontal circles at
5-9 m/s with motion-capture noise (RMS z error 0.013 m), tilted circles up to
40 deg, a speed-up with peak tangential acceleration 12.5 m/s^2 (eq. 20),
braking from 11.3 to 1.0 m/s in under 1.5 s with peak deceleration 17.5 m/s^2
(Fig. 4; decelerations up to 19.75 m/s^2 were flown), and the speed staircase
of Fig. 3 (tracked well up to about 9 m/s). Each experiment is a scenario in
``gainsched/sim/scenarios`` (one source of truth with ``gainsched simulate``), flown
with the committed tables through :func:`gainsched.sim.loop.simulate` on the design
config as the plant (no model error), motion capture at 200 Hz with 0.5 mm /
0.2 deg noise. The staircase is flown a second time on a plant with the model
error the paper blames for Fig. 3 (thrust falling with airspeed, momentum
theory, paper eq. 29: the ``thrust_momentum`` plant of
:data:`gainsched.sim.campaign.HIDDEN`).

Outputs in ``DIR``: one folder per experiment (``write_run``: log.csv, log.h5,
metrics.json, speed_roll.png, path3d.png), ``horizontal_out_of_plane.png``,
``report.md`` (the paper-versus-simulation table and the plots) and
``report.json`` (the same table and every experiment's metrics).

Run time (2026-12-04, a shared 2-core machine, wall): about 19 s for everything, the
thrust-loss staircase's ``thrust_momentum`` plant on the compiled plant too (22 s of
flight); ``--quick`` about 10 s.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .loop import (
    SCENARIO_DIR,
    Maneuver,
    Scenario,
    Scheduler,
    SimResult,
    load_scenario,
    metrics,
    simulate,
    write_run,
)

__all__ = [
    "Experiment",
    "Row",
    "PaperReport",
    "experiments",
    "run_paper",
    "write_report",
    "tangential_acceleration",
    "plateaus",
    "SCHEMA",
]

SCHEMA = "gainsched-paper-report/1"

# the paper's numbers (Sec. V.B, Figs. 3 and 4)
RMS_Z_M = 0.013  # RMS z error on horizontal circles, m
HORIZONTAL_SPEEDS = (5.0, 6.0, 7.0, 8.0, 9.0)  # m/s, where the paper says tracking is good
TILTS_DEG = (20.0, 40.0)  # "tilt angles up to 40 degrees"
SPEEDUP_PEAK = 12.5  # m/s^2
BRAKE_V0, BRAKE_V1 = 11.3, 1.0  # m/s
BRAKE_TIME = 1.5  # s, "in under 1.5 s"
BRAKE_PEAK = 17.5  # m/s^2 (Fig. 4)
BRAKE_PEAK_MAX = 19.75  # m/s^2, the hardest deceleration flown
GOOD_UP_TO = 9.0  # m/s, Fig. 3: "tracked well up to a velocity of about 9 m/s"
TOP_SPEED = 15.0  # m/s (> 13 g centripetal)
MODEL_ERROR = "thrust_momentum"  # Fig. 3's explanation, as a plant (gainsched.sim.campaign.HIDDEN)

SPEED_TOL = 0.05  # m/s: "reached" a target speed
ACCEL_TOL = 0.10  # relative: a peak acceleration "agrees"
TRACK_TOL = 0.1  # m/s: mean speed error on a plateau that counts as tracked well
SMOOTH_S = 0.005  # s: moving average on the differentiated speed


@dataclass(frozen=True)
class Experiment:
    """One flight: folder name, kind (``horizontal``, ``tilted``, ``speedup``, ``braking``,
    ``staircase``), the scenario, and the hidden effect of the plant (a name in
    :data:`gainsched.sim.campaign.HIDDEN`; None: the plant is the given config)."""

    name: str
    kind: str
    scenario: Scenario
    plant_effect: str | None = None


@dataclass(frozen=True)
class Row:
    """A line of the paper-versus-simulation table.

    ``paper`` is the paper's statement as text, ``paper_value`` its number (None if
    the paper gives a plot only); ``simulated`` the simulated number (SI units of
    ``unit``) and ``simulated_text`` how the report prints it; ``agrees`` whether the
    simulation meets the paper's statement (None: nothing to compare).
    """

    figure: str
    quantity: str
    unit: str
    paper: str
    paper_value: float | None
    simulated: float | None
    simulated_text: str
    agrees: bool | None
    note: str = ""


@dataclass(frozen=True)
class PaperReport:
    """Rows of the table, per-experiment results (metrics plus analyses) and the run facts."""

    rows: tuple[Row, ...]
    results: dict
    meta: dict

    def to_json(self) -> dict:
        return {
            "schema": SCHEMA,
            **self.meta,
            "rows": [dataclasses.asdict(r) for r in self.rows],
            "experiments": self.results,
        }


# --------------------------------------------------------------------------- experiments


def _load(scenario_dir: Path, name: str) -> Scenario:
    path = Path(scenario_dir) / f"{name}.toml"
    if not path.is_file():
        raise InputError(path, "", "scenario file missing (the paper experiments need it)")
    return load_scenario(path)


def _compact(scn: Scenario, n_maneuvers: int, lead: float, tail: float) -> Scenario:
    """The first ``n_maneuvers`` manoeuvres back to back with ``lead`` s before each and
    ``tail`` s after the last (same speeds and eq. 20 parameters)."""
    mans, t, v = [], lead, scn.speed
    for m in scn.maneuvers[:n_maneuvers]:
        mans.append(Maneuver(t, m.speed, m.a))
        t += abs(m.speed - v) / m.a + lead
        v = m.speed
    return dataclasses.replace(scn, maneuvers=tuple(mans), duration=t - lead + tail)


def experiments(scenario_dir=None, *, quick: bool = False) -> list[Experiment]:
    """The paper's experiments from the scenario files; ``quick``: a short smoke version
    (two speeds, one tilt, 0.3 s circles, manoeuvres with 0.1 s margins, one stair)."""
    d = Path(scenario_dir) if scenario_dir is not None else SCENARIO_DIR
    horizontal, tilted = _load(d, "horizontal"), _load(d, "tilted40")
    speedup, braking, stairs = _load(d, "speedup"), _load(d, "braking"), _load(d, "staircase")
    out = []
    speeds = (HORIZONTAL_SPEEDS[0], HORIZONTAL_SPEEDS[-1]) if quick else HORIZONTAL_SPEEDS
    for i, v in enumerate(speeds):
        # steady flight: start on the nominal (the file's initial error is for `simulate`)
        scn = dataclasses.replace(
            horizontal, name=f"horizontal-{v:g}", speed=v, initial_error=(),
            duration=0.3 if quick else horizontal.duration,
            sensing=dataclasses.replace(horizontal.sensing, seed=horizontal.sensing.seed + i),
        )
        out.append(Experiment(scn.name, "horizontal", scn))
    for a in TILTS_DEG[-1:] if quick else TILTS_DEG:
        scn = dataclasses.replace(tilted, name=f"tilted-{a:g}", tilt=float(np.deg2rad(a)),
                                  duration=0.3 if quick else tilted.duration)
        out.append(Experiment(scn.name, "tilted", scn))
    if quick:
        speedup = _compact(speedup, 1, 0.1, 0.1)
        braking = _compact(braking, 1, 0.1, 0.1)
        stairs = _compact(stairs, 1, 0.1, 0.1)
    out.append(Experiment("speedup", "speedup", speedup))
    out.append(Experiment("braking", "braking", braking))
    if not quick:  # the hardest deceleration the paper flew
        (m,) = braking.maneuvers
        hard = dataclasses.replace(braking, name="braking-hard",
                                   maneuvers=(Maneuver(m.t_start, m.speed, BRAKE_PEAK_MAX / 2),))
        out.append(Experiment("braking-hard", "braking", hard))
    out.append(Experiment("staircase", "staircase", stairs))
    out.append(Experiment("staircase-thrust-loss", "staircase",
                          dataclasses.replace(stairs, name="staircase-thrust-loss"),
                          plant_effect=MODEL_ERROR))
    return out


# --------------------------------------------------------------------------- analyses


def tangential_acceleration(res: SimResult) -> tuple[np.ndarray, np.ndarray]:
    """Simulated and desired tangential acceleration ``d(r xi')/dt`` (N,), m/s^2.

    From the true state (central differences, then a ``SMOOTH_S`` moving average
    against the control-rate ripple) and from the reference path.
    """
    v, v_d = res.z[:, 3] * res.r, res.z_d[:, 3] * res.r
    a, a_d = np.gradient(v, res.t), np.gradient(v_d, res.t)
    n = max(1, int(round(SMOOTH_S / (res.t[1] - res.t[0]))))
    if n > 1 and a.size > n:
        a = np.convolve(a, np.ones(n) / n, mode="same")
    return a, a_d


def plateaus(scn: Scenario) -> list[tuple[float, float, float]]:
    """Constant-speed segments of a scenario: ``(t_start, t_end, speed)`` in s, s, m/s."""
    out, t0, v = [], 0.0, scn.speed
    for m in scn.maneuvers:
        out.append((t0, m.t_start, v))
        t0, v = m.t_start + abs(m.speed - v) / m.a, m.speed
    out.append((t0, scn.duration, v))
    return [p for p in out if p[1] > p[0]]


def _speed(res):
    return res.z[:, 3] * res.r, res.z_d[:, 3] * res.r


def _analyse(exp: Experiment, res: SimResult) -> dict:
    """Metrics of :func:`gainsched.sim.loop.metrics` plus what the paper reports for the kind."""
    out = metrics(res)
    out["kind"] = exp.kind
    out["plant_effect"] = exp.plant_effect
    out["tilt_deg"] = float(np.rad2deg(exp.scenario.tilt))
    out["speed_mps"] = exp.scenario.speed
    v, v_d = _speed(res)
    out["max_speed_desired_mps"] = float(np.abs(v_d).max())
    a, a_d = tangential_acceleration(res)
    if exp.kind in ("speedup", "braking"):
        (m,) = exp.scenario.maneuvers[:1]
        t_end = m.t_start + abs(m.speed - exp.scenario.speed) / m.a
        win = (res.t >= m.t_start - 0.05) & (res.t <= t_end + 0.3)
        sign = 1.0 if m.speed > exp.scenario.speed else -1.0
        out["peak_accel_mps2"] = float(np.max(sign * a[win])) if win.any() else float("nan")
        out["peak_accel_desired_mps2"] = float(np.max(sign * a_d[win])) if win.any() else 0.0
        out["maneuver_time_desired_s"] = t_end - m.t_start
        out["maneuver_time_s"] = _settling_time(res.t, v, m.t_start, m.speed)
        roll, roll_d = np.rad2deg(res.z[win, 4]), np.rad2deg(res.z_d[win, 4])
        out["roll_range_deg"] = [float(roll.min()), float(roll.max())] if win.any() else None
        out["roll_range_desired_deg"] = (
            [float(roll_d.min()), float(roll_d.max())] if win.any() else None
        )
        out["max_roll_error_deg"] = float(np.abs(roll - roll_d).max()) if win.any() else None
    if exp.kind == "staircase":
        rows = []
        steps = plateaus(exp.scenario)
        top = max(range(len(steps)), key=lambda i: steps[i][2])
        for i, (t0, t1, vp) in enumerate(steps):
            sel = (res.t >= 0.5 * (t0 + t1)) & (res.t <= t1)  # second half: settled
            if sel.sum() < 2:
                continue
            rows.append({"speed_mps": vp, "t_start_s": t0, "t_end_s": t1, "rising": i <= top,
                         "mean_speed_error_mps": float(np.mean(v[sel] - v_d[sel])),
                         "rms_out_of_plane_m": _rms_z(res, sel)})
        out["plateaus"] = rows
    return out


def _settling_time(t, v, t_start, target) -> float | None:
    """Time (s) after ``t_start`` from which the speed stays within ``SPEED_TOL`` of
    ``target``; None if it is outside at the end of the flight."""
    outside = np.flatnonzero(np.abs(v - target) > SPEED_TOL)
    if outside.size and outside[-1] == t.size - 1:
        return None
    t_in = t[outside[-1] + 1] if outside.size else t[0]
    return float(max(t_in - t_start, 0.0))


def _rms_z(res, sel) -> float:
    from ..rotations import R_IC_from_tilt

    p_C = res.p_I[sel] @ R_IC_from_tilt(res.scenario.tilt, res.scenario.gamma)
    return float(np.sqrt(np.mean(p_C[:, 2] ** 2)))


# --------------------------------------------------------------------------- the table


def _fmt(x, unit="", digits=3) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "n/a"
    return f"{x:.{digits}g} {unit}".strip()


def _effect_doc(name: str) -> str:
    from .campaign import HIDDEN

    return HIDDEN[name].doc


def _rows(exps: list[Experiment], results: dict) -> list[Row]:
    """The report's table rows: one block per kind of experiment, in the paper's order."""
    by_kind: dict[str, list] = {}
    for e in exps:
        by_kind.setdefault(e.kind, []).append(results[e.name])
    rows = []
    if by_kind.get("horizontal"):
        rows.append(_row_horizontal(by_kind["horizontal"]))
    if by_kind.get("tilted"):
        rows.append(_row_tilted(by_kind["tilted"]))
    for r in by_kind.get("speedup", []):
        rows.append(Row(
            "Sec. V.B, eq. 20", "speed-up peak tangential acceleration", "m/s^2",
            f"{SPEEDUP_PEAK} m/s^2", SPEEDUP_PEAK, r["peak_accel_mps2"],
            f"{r['peak_accel_mps2']:.3g} m/s^2 (desired {r['peak_accel_desired_mps2']:.3g})",
            abs(r["peak_accel_mps2"] / SPEEDUP_PEAK - 1) <= ACCEL_TOL,
        ))
    for r in by_kind.get("braking", []):
        rows += _rows_braking(r)
    for r in by_kind.get("staircase", []):
        rows += _rows_staircase(r)
    return rows


def _row_horizontal(hor: list[dict]) -> Row:
    """Sec. V.B: the RMS out-of-plane error of the horizontal circles (the worst)."""
    worst = max(hor, key=lambda r: r["rms_out_of_plane_m"])
    each = ", ".join(f"{r['speed_mps']:g}: {1000 * r['rms_out_of_plane_m']:.2f}" for r in hor)
    return Row(
        "Sec. V.B", "RMS z error, horizontal circles 5-9 m/s (mocap 0.5 mm / 0.2 deg)",
        "m", f"{RMS_Z_M} m", RMS_Z_M, worst["rms_out_of_plane_m"],
        f"{worst['rms_out_of_plane_m']:.2g} m (worst; per speed m/s: mm {each})",
        worst["rms_out_of_plane_m"] <= RMS_Z_M,
        "no model error in the simulated plant",
    )


def _row_tilted(tilted: list[dict]) -> Row:
    """Sec. V.B: the tilted circles, flown up to 40 deg without slack."""
    top = max(tilted, key=lambda r: r["tilt_deg"])
    ok = all(r["slack_events"] == 0 and r["max_out_of_plane_m"] < 0.05 for r in tilted)
    return Row(
        "Sec. V.B", f"tilted circles at {top['speed_mps']:g} m/s", "deg",
        "flown up to 40 deg", 40.0, top["tilt_deg"],
        "; ".join(f"{r['tilt_deg']:g} deg: RMS z {r['rms_out_of_plane_m']:.2g} m, "
                  f"saturated {100 * r['saturation_fraction']:.1f}%, "
                  f"slack {r['slack_events']}" for r in tilted),
        ok and top["tilt_deg"] >= 40.0,
    )


def _rows_braking(r: dict) -> list[Row]:
    """Fig. 4 (or Sec. V.B for the hard brake): time to the lower speed, the peak
    deceleration and the roll."""
    hard = r["peak_accel_desired_mps2"] > 0.5 * (BRAKE_PEAK + BRAKE_PEAK_MAX)
    peak = BRAKE_PEAK_MAX if hard else BRAKE_PEAK
    fig = "Sec. V.B" if hard else "Fig. 4"
    t = r["maneuver_time_s"]
    rows = [Row(
        fig, f"braking {r['speed_mps']:g} -> {BRAKE_V1:g} m/s (peak {peak:g} m/s^2): time to "
        f"reach "
        f"{BRAKE_V1:g} +- {SPEED_TOL:g} m/s and stay", "s", f"< {BRAKE_TIME} s", BRAKE_TIME, t,
        f"{_fmt(t, 's')} (desired {r['maneuver_time_desired_s']:.3g} s)",
        None if t is None else t < BRAKE_TIME,
    ), Row(
        fig, "braking peak tangential deceleration", "m/s^2", f"{peak} m/s^2", peak,
        r["peak_accel_mps2"],
        f"{r['peak_accel_mps2']:.3g} m/s^2 (desired {r['peak_accel_desired_mps2']:.3g})",
        abs(r["peak_accel_mps2"] / peak - 1) <= ACCEL_TOL,
    )]
    if not hard and r["roll_range_deg"] is not None:
        lo, hi = r["roll_range_deg"]
        dlo, dhi = r["roll_range_desired_deg"]
        rows.append(Row(
            "Fig. 4", "roll during braking", "deg", "plot only (Fig. 4, bottom)", None,
            lo if abs(lo) > abs(hi) else hi,
            f"{lo:.1f} .. {hi:.1f} deg (nominal {dlo:.1f} .. {dhi:.1f}; "
            f"max error {r['max_roll_error_deg']:.2g} deg)", None,
        ))
    return rows


def _rows_staircase(r: dict) -> list[Row]:
    """Fig. 3: the mean speed error on the rising plateaus below and above
    :data:`GOOD_UP_TO`, and (design plant, full mode) the top steady speed."""
    rows = []
    rising = [p for p in r["plateaus"] if p["rising"]]  # Fig. 3: speeds going up
    low = [p for p in rising if p["speed_mps"] <= GOOD_UP_TO]
    high = [p for p in rising if p["speed_mps"] > GOOD_UP_TO]
    worst = {k: max(sel, key=lambda p: abs(p["mean_speed_error_mps"])) if sel else None
             for k, sel in (("low", low), ("high", high))}
    err = {k: None if w is None else abs(w["mean_speed_error_mps"]) for k, w in worst.items()}
    effect = r["plant_effect"]
    plant = "design plant" if effect is None else f"plant with {_effect_doc(effect)}"
    if effect is None:
        claims = (("low", "tracked well", err["low"] is not None and err["low"] <= TRACK_TOL),
                  ("high", "tracking degrades (model error)", None))
    else:
        degrades = (err["high"] is not None and err["low"] is not None
                    and err["high"] > TRACK_TOL and err["high"] > 2 * err["low"])
        claims = (("low", "tracked well", err["low"] is not None and err["low"] <= TRACK_TOL),
                  ("high", "tracking degrades (model error)", degrades))
    for k, paper, agrees in claims:
        w = worst[k]
        if w is None:
            continue
        sel = low if k == "low" else high
        label = f"<= {GOOD_UP_TO:g}" if k == "low" else f"> {GOOD_UP_TO:g}"
        rows.append(Row(
            "Fig. 3", f"speed staircase, {plant}: mean speed error on rising plateaus "
            f"{label} m/s", "m/s", paper, None, w["mean_speed_error_mps"],
            f"worst {w['mean_speed_error_mps']:+.3f} m/s at {w['speed_mps']:g} m/s "
            f"(plateaus {', '.join(format(p['speed_mps'], 'g') for p in sel)} m/s)",
            agrees,
            "the design plant has no thrust loss at airspeed"
            if effect is None and k == "high" else "",
        ))
    if effect is not None or r["max_speed_desired_mps"] < TOP_SPEED - SPEED_TOL:
        return rows  # (quick mode: not flown)
    rows.append(Row(
        "Sec. V.B", "top steady speed, centripetal load", "m/s", f"{TOP_SPEED:g} m/s (> 13 g)",
        TOP_SPEED, r["max_speed_mps"],
        f"{r['max_speed_mps']:.3g} m/s, {r['max_g_load']:.1f} g, "
        f"max tension {r['max_tension_N']:.0f} N, slack {r['slack_events']}",
        r["max_speed_mps"] >= TOP_SPEED - SPEED_TOL and r["slack_events"] == 0,
    ))
    return rows


# --------------------------------------------------------------------------- running


def run_paper(design, scheduler, out_dir, *, quick: bool = False, plant=None,
              scenario_dir=None, progress=None, meta=None, table=None) -> PaperReport:
    """Fly every experiment, write its folder, the plots, report.md and report.json.

    Parameters
    ----------
    design : Config
        The config the tables were built from (the paper config).
    scheduler : Scheduler or callable
        Gain lookup of the committed table (:func:`gainsched.sim.loop.runtime_scheduler`).
        When it is a :class:`~gainsched.sim.loop.Scheduler` (the C runtime or its Python
        reference: the table's feed-forward and controller) the flights are the firmware's
        whole control step (``simulate(controller="firmware")``: the C controller or its
        Python reference), else they fly the design model's nominal.
    out_dir : path
    quick : bool
        Short smoke version (see :func:`experiments`).
    plant : Config, optional
        The truth (default: ``design``).
    progress : callable(int), optional
        Called with 1 after each experiment.
    meta : dict, optional
        Extra facts for the report header (table path, hashes).
    table : Table, optional
        The table flown: its flight envelope (:mod:`gainsched.schedule.envelope`) goes
        into the report as envelope.png and the circle counts, and its worst stability
        margins (``margins`` in report.json, :func:`gainsched.worst_margins`).
    """
    out_dir = Path(out_dir)
    exps = experiments(scenario_dir, quick=quick)
    results, runs = {}, {}
    for exp in exps:
        truth = plant
        if exp.plant_effect is not None:
            from .campaign import plant_config

            truth = plant_config(plant or design, exp.plant_effect)
        # the firmware's nominal (lookup + closed form) when the scheduler offers it: the
        # flights a firmware would fly from the generated files
        mode = "firmware" if isinstance(scheduler, Scheduler) else "path"
        res = simulate(design, scheduler, exp.scenario, truth, controller=mode)
        write_run(res, out_dir / exp.name)
        results[exp.name] = _analyse(exp, res)
        runs[exp.name] = res
        if progress is not None:
            progress(1)
    _plot_out_of_plane([runs[e.name] for e in exps if e.kind == "horizontal"],
                       out_dir / "horizontal_out_of_plane.png")
    info = {
        "config": design.name,
        "config_sha256": design.sha256,
        "plant": (plant or design).name,
        "quick": bool(quick),
        "experiments_run": [e.name for e in exps],
        "nominal": (f"the firmware's control step: its estimator, the table lookup plus "
                    f"the drag-only closed form "
                    f"({scheduler.source})"
                    if isinstance(scheduler, Scheduler)
                    else "design model along the reference"),
        **(meta or {}),
    }
    if table is not None:
        from ..publish import write_atomic
        from ..schedule.envelope import envelope_from_table, envelope_png

        env = envelope_from_table(table)
        write_atomic(out_dir / "envelope.png", envelope_png(env))
        info["envelope"] = env.counts()
        if table.loop_margins is not None:  # the table's worst (docs/margins.md)
            from ..schedule.margin_report import worst_margins

            info["margins"] = worst_margins(table.loop_margins, table.speed, table.tilt)
    report = PaperReport(tuple(_rows(exps, results)), results, info)
    write_report(report, out_dir, exps)
    return report


def _plot_out_of_plane(runs: list[SimResult], path: Path) -> None:
    """Out-of-plane COG error (mm) against time for the horizontal circles."""
    if not runs:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..rotations import R_IC_from_tilt

    fig, ax = plt.subplots(figsize=(8, 4))
    for res in runs:
        z = (res.p_I @ R_IC_from_tilt(res.scenario.tilt, res.scenario.gamma))[:, 2]
        ax.plot(res.t, 1000 * z, lw=0.8, label=f"{res.scenario.speed:g} m/s")
    ax.axhline(1000 * RMS_Z_M, color="r", ls="--", lw=0.8, label="paper RMS (+-)")
    ax.axhline(-1000 * RMS_Z_M, color="r", ls="--", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("out-of-plane error (mm)")
    ax.set_title("horizontal circles with motion-capture noise")
    ax.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _md_table(head, rows) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    return out


def write_report(report: PaperReport, out_dir, exps: list[Experiment]) -> None:
    """report.md (table, per-experiment tables, plots) and report.json in ``out_dir``."""
    from ..publish import write_atomic

    out_dir = Path(out_dir)
    lines = (_md_head(report) + _md_experiments(report.results, exps)
             + _md_along(report.results, exps) + _md_envelope(report.meta))
    lines += ["", "Every experiment folder holds log.csv / log.h5 (flight-log format), "
              "metrics.json, speed_roll.png and path3d.png.", ""]
    write_atomic(out_dir / "report.md", "\n".join(lines).encode())
    text = json.dumps(_jsonable(report.to_json()), indent=2, sort_keys=True) + "\n"
    write_atomic(out_dir / "report.json", text.encode())


def _md_head(report: PaperReport) -> list[str]:
    """The report's title, what was flown and the paper-versus-simulation table."""
    m = report.meta
    yes = {True: "yes", False: "**no**", None: "-"}
    lines = [
        "# The paper's experiments in simulation",
        "",
        f"Config `{m['config']}` (sha256 {m['config_sha256'][:12]}), plant `{m['plant']}`"
        + (f", tables `{m['table']}`" if "table" in m else "")
        + (" — **quick mode** (short smoke flights; numbers not meaningful)" if m["quick"]
           else "") + ".",
        "",
        f"Nominal flown: {m.get('nominal', 'design model along the reference')} "
        "(docs/runtime.md, \"Manoeuvres: the feed-forward\").",
        "",
        "The plant is the design model (no model error); motion capture at 200 Hz with "
        "0.5 mm / 0.2 deg noise, fused with a model prediction at 1 kHz. Paper values that "
        "come from model error on the real vehicle (the 0.013 m RMS, the speed loss above "
        "9 m/s in Fig. 3) are bounds here, not targets.",
        "",
        "## Paper versus simulation",
        "",
    ]
    lines += _md_table(
        ["paper figure", "quantity", "paper value", "simulated value", "agrees", "note"],
        [(r.figure, r.quantity, r.paper, r.simulated_text, yes[r.agrees], r.note)
         for r in report.rows],
    )
    return lines


def _md_experiments(res: dict, exps: list[Experiment]) -> list[str]:
    """One section per kind of experiment: its table or its figures."""
    lines = []
    kinds = {}
    for e in exps:
        kinds.setdefault(e.kind, []).append(e.name)
    if "horizontal" in kinds:
        lines += ["", "## Horizontal circles (Sec. V.B)", ""]
        lines += _md_table(
            ["speed (m/s)", "RMS z (mm)", "max z (mm)", "RMS speed error (m/s)",
             "max tension (N)", "roll max (deg)"],
            [(f"{res[n]['speed_mps']:g}", f"{1000 * res[n]['rms_out_of_plane_m']:.3f}",
              f"{1000 * res[n]['max_out_of_plane_m']:.3f}",
              f"{res[n]['rms_speed_error_mps']:.4f}", f"{res[n]['max_tension_N']:.1f}",
              f"{res[n]['max_roll_deg']:.1f}") for n in kinds["horizontal"]],
        )
        lines += ["", "![out-of-plane error](horizontal_out_of_plane.png)"]
    if "tilted" in kinds:
        lines += ["", "## Tilted circles (Sec. V.B)", ""]
        lines += _md_table(
            ["tilt (deg)", "speed (m/s)", "RMS out-of-plane (mm)", "saturated (%)", "slack"],
            [(f"{res[n]['tilt_deg']:g}", f"{res[n]['speed_mps']:g}",
              f"{1000 * res[n]['rms_out_of_plane_m']:.3f}",
              f"{100 * res[n]['saturation_fraction']:.1f}", res[n]["slack_events"])
             for n in kinds["tilted"]],
        )
        lines += [""] + [f"![{n}]({n}/path3d.png)" for n in kinds["tilted"][-1:]]
    for kind, title in (("speedup", "Speed-up (eq. 20)"), ("braking", "Braking (Fig. 4)")):
        for n in kinds.get(kind, []):
            r = res[n]
            lines += ["", f"## {title}: `{n}`", "",
                      f"Peak tangential {'acceleration' if kind == 'speedup' else 'deceleration'}"
                      f" {r['peak_accel_mps2']:.3g} m/s^2 (desired "
                      f"{r['peak_accel_desired_mps2']:.3g}); manoeuvre done in "
                      f"{_fmt(r['maneuver_time_s'], 's')} (desired "
                      f"{r['maneuver_time_desired_s']:.3g} s); roll "
                      f"{r['roll_range_deg'][0]:.1f} .. {r['roll_range_deg'][1]:.1f} deg; "
                      f"saturated {100 * r['saturation_fraction']:.1f}%, slack "
                      f"{r['slack_events']}.", "", f"![{n}]({n}/speed_roll.png)"]
    for n in kinds.get("staircase", []):
        eff = res[n]["plant_effect"]
        plant = "design plant" if eff is None else f"plant with {_effect_doc(eff)}"
        lines += ["", f"## Speed staircase (Fig. 3): `{n}`, {plant}", ""]
        lines += _md_table(
            ["plateau (m/s)", "from (s)", "to (s)", "rising", "mean speed error (m/s)",
             "RMS z (mm)"],
            [(f"{p['speed_mps']:g}", f"{p['t_start_s']:.2f}", f"{p['t_end_s']:.2f}",
              "yes" if p["rising"] else "no", f"{p['mean_speed_error_mps']:+.4f}",
              f"{1000 * p['rms_out_of_plane_m']:.3f}") for p in res[n]["plateaus"]],
        )
        lines += ["", f"![{n}]({n}/speed_roll.png)"]
    return lines


def _md_along(res: dict, exps: list[Experiment]) -> list[str]:
    """The along-track table of every flight (held gains, time below the margin)."""
    lines = ["", "## Along the circle (every flight)", "",
              "Azimuth error between continuous azimuths (a lap behind is -2 pi); along-track "
              "error = azimuth error x COG radius. Held: the lookup had no usable gains and "
              "the last good ones were flown. Below margin: the nominal tension under the "
              "config's `min_tension`.", ""]
    lines += _md_table(
        ["flight", "RMS along-track (mm)", "max along-track (mm)", "final azimuth error (mrad)",
         "lap slips", "held gains (s)", "below tension margin (s)"],
        [(n, f"{1000 * r['rms_along_track_m']:.2f}", f"{1000 * r['max_along_track_m']:.2f}",
          f"{1000 * r['final_azimuth_error_rad']:+.2f}", r["lap_slips"],
          f"{r['held_gains_s']:.2f}", f"{r['below_tension_margin_s']:.2f}")
         for n, r in ((e.name, res[e.name]) for e in exps)],
    )
    return lines


def _md_envelope(m: dict) -> list[str]:
    """The table's flight envelope, when the report has one."""
    lines = []
    if "envelope" in m:
        counts = ", ".join(f"{n} {c}" for c, n in m["envelope"].items())
        lines += ["", "## Flight envelope of the table", "",
                  f"Circles of the grid (tilt x speed): {counts}. Tilts up to 40 deg are flown "
                  "up to 15 m/s wherever the tether stays taut; where the zero-offset nominal "
                  "runs a motor out of range the table's nominal has pitch and yaw offsets "
                  "(docs/conventions.md, \"Attitude offsets\").", "",
                  "![flight envelope](envelope.png)"]
    if m.get("margins"):
        from ..schedule.margin_report import worst_lines

        lines += ["", "```", *worst_lines(m["margins"], "The table's stability margins"),
                  "```"]
    return lines


def _jsonable(x):
    """NaN and infinities as null (strict JSON)."""
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None
    if isinstance(x, np.floating | np.integer | np.bool_):
        return _jsonable(x.item())
    return x
