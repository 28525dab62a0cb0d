"""Closed-loop simulation speed (issue 5): real-time factor of ``gainsched.sim.loop.simulate``.

    python -m bench sim      (or: python -m bench.bench_sim)

Flight: paper config (configs/paper.toml), rigid link, horizontal circle at 9 m/s
from an initial error of (0.01, 0.02) rad in (delta, xi), 1 kHz control, gains from
tables/paper.h5. Real-time factor (RTF) = simulated seconds / wall seconds, best of
several runs (the nominal trajectory and the table set-up are inside the timed call,
as a user sees them).

(a) fast path: the compiled plant (gainsched/native/plant.c) and the Python reference
    interpolator (``table_scheduler``: gains of the reference path looked up in
    blocks of 1000 steps), 10 s of flight, ideal sensing; also with one lookup per
    step, through the reference's single-query path and through the compiled C
    runtime (``c_runtime_scheduler``, when a compiler is present);
(b) baseline, same run: the numpy model (``GAINSCHED_NATIVE=0``) and the vectorised
    reference lookup called per step (the per-step path before issue 5), over 1 s of
    flight (the baseline runs at well under 1x real time; RTF does not depend on the
    duration beyond the fixed set-up, which favours the baseline slightly);
(c) fast path with motion-capture sensing (200 Hz, 0.5 mm / 0.2 deg noise, 5 ms
    latency, gyro noise): the estimator's prediction model is compiled too.

The ratio (a)/(b) is the figure of merit (target: fast path >= 10x real time).
Only ratios against the baseline measured in the same run are meaningful.
"""

from __future__ import annotations

import os
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from gainsched import native
from gainsched.config import load_config
from gainsched.firmware.runtime import Interpolator
from gainsched.schedule.tables import load_table
from gainsched.sim.loop import Scenario, Sensing, c_runtime_scheduler, simulate, table_scheduler

ROOT = Path(__file__).resolve().parents[1]
SPEED = 9.0  # m/s
DURATION = 10.0  # s, fast path
BASELINE_DURATION = 1.0  # s, numpy baseline
INITIAL_ERROR = (0.01, 0.02)  # delta, xi (rad), as the shipped horizontal scenario
MOCAP = Sensing(False, 200.0, 0.0005, np.deg2rad(0.2), 0.01, 0.005, 1)


@contextmanager
def numpy_plant():
    """``GAINSCHED_NATIVE=0`` for the duration (the compiled plant is not used)."""
    old = os.environ.get("GAINSCHED_NATIVE")
    os.environ["GAINSCHED_NATIVE"] = "0"
    try:
        yield
    finally:
        if old is None:
            del os.environ["GAINSCHED_NATIVE"]
        else:
            os.environ["GAINSCHED_NATIVE"] = old


def vectorised_scheduler(table):
    """The per-step lookup before issue 5: the vectorised reference on one query."""
    interp = Interpolator(table)

    def lookup(xi, xi_dot, alpha):
        r = interp(xi, xi_dot, alpha)
        return r.K, int(r.status)

    return lookup


def rtf(cfg, sched, scn, repeat):
    """Best real-time factor over ``repeat`` runs, and the last result."""
    best, res = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = simulate(cfg, sched, scn)
        best = min(best, time.perf_counter() - t0)
    return scn.duration / best, res


def main():
    cfg = load_config(ROOT / "configs" / "paper.toml")
    table = load_table(ROOT / "tables" / "paper.h5")
    sched = table_scheduler(table)
    ideal = Scenario("bench", 0.0, SPEED, DURATION, initial_error=INITIAL_ERROR)
    out = {"speed_mps": SPEED, "rate_hz": cfg.control.rate_hz, "native": native.available("plant")}
    # wall-clock figures: other processes on the machine slow them down, record the load
    out["load_average_1min_before"] = os.getloadavg()[0]
    simulate(cfg, sched, Scenario("warm", 0.0, SPEED, 0.05))  # compile/load the kernel

    fast, res_fast = rtf(cfg, sched, ideal, 3)
    out["fast_rtf"] = fast
    print(f"  fast path ({DURATION:g} s, compiled plant, Python reference lookup in blocks): "
          f"{fast:.1f}x real time")

    def per_step(xi, xi_dot, alpha):  # no ``batch``: one single-query lookup per step
        return sched(xi, xi_dot, alpha)

    fast_q, _ = rtf(cfg, per_step, ideal, 3)
    out["fast_per_step_lookup_rtf"] = fast_q
    print(f"  fast path, Python reference single-query lookup every step: {fast_q:.1f}x real time")

    if native.available("plant"):
        try:
            c_sched = c_runtime_scheduler(table)
        except RuntimeError as exc:  # no compiler for the runtime
            print(f"  C runtime scheduler unavailable: {exc}")
        else:
            fast_c, res_c = rtf(cfg, c_sched, ideal, 3)
            dev = float(np.abs(res_c.p_I - res_fast.p_I).max())
            out.update(fast_c_runtime_rtf=fast_c, c_runtime_vs_python_max_dev_m=dev)
            print(f"  fast path, C runtime lookup every step: {fast_c:.1f}x real time "
                  f"(COG path within {dev:.1e} m of the Python-lookup flight)")

    short = Scenario("bench", 0.0, SPEED, BASELINE_DURATION, initial_error=INITIAL_ERROR)
    with numpy_plant():
        base, res_base = rtf(cfg, vectorised_scheduler(table), short, 1)
    n = res_base.t.size
    dev = float(np.abs(res_base.p_I - res_fast.p_I[:n]).max())
    out.update(baseline_rtf=base, ratio=fast / base, baseline_vs_fast_max_dev_m=dev,
               baseline_duration_s=BASELINE_DURATION)
    print(f"  numpy baseline ({BASELINE_DURATION:g} s, numpy model, vectorised lookup per "
          f"step): {base:.2f}x real time; same flight to {dev:.1e} m")

    mocap = Scenario("bench-mocap", 0.0, SPEED, DURATION, sensing=MOCAP,
                     initial_error=INITIAL_ERROR)
    fast_mocap, _ = rtf(cfg, sched, mocap, 2)
    out["fast_mocap_rtf"] = fast_mocap
    print(f"  fast path with motion-capture sensing (200 Hz, noise, 5 ms latency): "
          f"{fast_mocap:.1f}x real time")
    print(f"sim: fast {fast:.1f}x real time, numpy baseline {base:.2f}x -> {fast / base:.0f}x "
          f"(target >= 10x real time: {'met' if fast >= 10 else 'not met'}); "
          f"motion capture {fast_mocap:.1f}x")
    out["load_average_1min_after"] = os.getloadavg()[0]
    print(f"  (1-min load average {out['load_average_1min_before']:.1f} before, "
          f"{out['load_average_1min_after']:.1f} after, {os.cpu_count()} CPUs)")
    return out


if __name__ == "__main__":
    main()
