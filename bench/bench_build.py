"""Gain-compiler benchmarks on the paper config (``python -m bench``).

(a) Full build of configs/paper.toml with ``build_grid`` at n_jobs = 1 and 2
    (the n_jobs = 2 run once cold, with joblib worker start-up, and once warm).
(b) Riccati throughput, in point-steps per second (one point-step = one step of
    the backward recursion at one operating point), of the batched
    ``gainsched.lqr.riccati_sweep`` against a per-point Python loop doing the
    same recursion with numpy, on the same Ad/Bd in the same run:
    - the 5 tilts of one speed over a whole period (what a build job batches);
    - 64 circles (the feasible circles of the paper grid, the first ones
      repeated to make 64), over the first N steps common to all of them.

Only ratios against the baseline measured in the same run are meaningful.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gainsched.config import load_config
from gainsched.grid import build_grid, solve_circle
from gainsched.lqr import riccati_sweep

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "configs" / "paper.toml"
SPEED = 9.0  # m/s: all 5 tilts feasible


def best_of(fn, repeat):
    """Minimum wall time of ``repeat`` calls and the last result."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def loop_sweep(Ad, Bd, Q, R):
    """The same backward recursion as riccati_sweep, one point at a time (the baseline)."""
    P_out = np.empty(Ad.shape[:1] + Q.shape)
    for i in range(Ad.shape[0]):
        P = Q.copy()
        for k in range(Ad.shape[1] - 1, -1, -1):
            A, B = Ad[i, k], Bd[i, k]
            BtP = B.T @ P
            K = np.linalg.solve(R + BtP @ B, BtP @ A)
            P = Q + A.T @ P @ (A - B @ K)
            P = 0.5 * (P + P.T)
        P_out[i] = P
    return P_out


def riccati_case(label, Ad, Bd, Q, R, repeat=3):
    b, N = Ad.shape[:2]
    P_end = np.broadcast_to(Q, (b,) + Q.shape).copy()
    t_batch, (P_batch, _, _) = best_of(lambda: riccati_sweep(Ad, Bd, Q, R, P_end), repeat)
    t_loop, P_loop = best_of(lambda: loop_sweep(Ad, Bd, Q, R), repeat)
    err = float(np.abs(P_batch - P_loop).max() / np.abs(P_loop).max())
    pts = b * N
    res = {
        "points": int(b),
        "steps": int(N),
        "batched_s": t_batch,
        "loop_s": t_loop,
        "batched_point_steps_per_s": pts / t_batch,
        "loop_point_steps_per_s": pts / t_loop,
        "ratio": t_loop / t_batch,
        "max_rel_diff": err,
    }
    print(
        f"  riccati {label}: {b} points x {N} steps: batched {pts / t_batch:,.0f} point-steps/s, "
        f"per-point loop {pts / t_loop:,.0f} point-steps/s -> {t_loop / t_batch:.1f}x "
        f"(results agree to {err:.1e})"
    )
    return res


def bench_build(cfg):
    out = {}
    t1, g = best_of(lambda: build_grid(cfg, n_jobs=1), 1)
    print(f"  build paper, n_jobs=1: {t1:.2f} s ({g.reasons.size} grid points)")
    t2_cold, _ = best_of(lambda: build_grid(cfg, n_jobs=2), 1)
    t2_warm, _ = best_of(lambda: build_grid(cfg, n_jobs=2), 1)
    print(f"  build paper, n_jobs=2: {t2_cold:.2f} s cold (worker start-up), {t2_warm:.2f} s warm")
    print(f"  parallel speed-up (warm, 2 workers): {t1 / t2_warm:.2f}x")
    out.update(
        n_jobs_1_s=t1,
        n_jobs_2_cold_s=t2_cold,
        n_jobs_2_warm_s=t2_warm,
        speedup_2_workers=t1 / t2_warm,
        grid_points=int(g.reasons.size),
        circles=int(g.rho.size),
        feasible_circles=int(np.isfinite(g.rho).sum()),
    )
    return out


def weights(cfg, n):
    Q = np.zeros((n, n))
    Q[:11, :11] = cfg.control.Q
    return Q, np.asarray(cfg.control.R, dtype=float)


def bench_riccati(cfg):
    out = {}
    tilts = cfg.grid.tilts
    _, (Ad, Bd, _) = solve_circle(cfg, SPEED, tilts, keep_steps=True)
    assert Ad.shape[0] == tilts.size, "all tilts must be feasible at the benchmark speed"
    Q, R = weights(cfg, Ad.shape[-1])
    out["tilts_of_one_speed"] = riccati_case(f"{tilts.size} tilts at {SPEED:g} m/s", Ad, Bd, Q, R)

    # 64 circles: every feasible circle of the grid, first N_min steps, repeated to 64
    circles_A, circles_B = [], []
    for v in cfg.grid.speeds:
        _, steps = solve_circle(cfg, float(v), tilts, keep_steps=True)
        if steps is not None:
            circles_A.extend(steps[0])
            circles_B.extend(steps[1])
    n_feasible = len(circles_A)
    N = min(a.shape[0] for a in circles_A)
    idx = [i % n_feasible for i in range(64)]
    Ad64 = np.stack([circles_A[i][:N] for i in idx])
    Bd64 = np.stack([circles_B[i][:N] for i in idx])
    res = riccati_case(f"64 circles ({n_feasible} feasible, repeated)", Ad64, Bd64, Q, R)
    res["distinct_circles"] = n_feasible
    out["points_64"] = res
    return out


def main():
    cfg = load_config(PAPER)
    results = {"build": bench_build(cfg), "riccati": bench_riccati(cfg)}
    r5 = results["riccati"]["tilts_of_one_speed"]["ratio"]
    r64 = results["riccati"]["points_64"]["ratio"]
    print(
        f"  batched Riccati vs per-point loop: {r5:.1f}x over 5 points, {r64:.1f}x over 64 "
        f"points (target >= 10x: {'met' if r64 >= 10 else 'not met'} at 64, "
        f"{'met' if r5 >= 10 else 'not met'} at 5)"
    )
    return results


if __name__ == "__main__":
    main()
