"""Gain-compiler benchmarks on the paper config (``python -m bench``).

Every figure is measured in this run next to its baseline or peer, as a ratio:

(a) Riccati kernel, in point-steps per second (one point-step = one step of the
    backward recursion at one operating point), on the same A_k, B_k (64
    circles of the paper grid over their first N common steps):
    - ours: the compiled kernel (1 and 2 threads) and the batched numpy fallback;
    - baseline: a per-point Python loop doing the same recursion with numpy;
    - peers: Drake's discrete ``FiniteHorizonLinearQuadraticRegulator`` (extra
      ``[peers]``; skipped with a message when absent), per step, on one circle's
      time-varying A_k, B_k (and, for context, the time-invariant tilt-0 problem);
      ``scipy.linalg.solve_discrete_are`` and
      python-control ``dlqr`` per point on the tilt-0 problems against our
      periodic recursion on the same problems (gains compared).
(b) Linearisation + discretisation, in blocks (one step's A_d, B_d) per second:
    ours (exact at M azimuths + trigonometric interpolation) against complex-step
    Jacobians at every step, and our batched Taylor ``expm`` against scipy's
    batched ``expm`` on the same blocks.
(c) Full builds: configs/paper.toml (n_jobs 1 and 2; peak memory of a build in a
    fresh process) and a 4x finer grid; the growth exponents of the build time in
    grid points (1x .. 4x speeds; 1x .. 8x tilts) and in steps per period (control
    rate 1 .. 16 kHz), fitted as plain log-log slopes (in steps also as
    t = a + b x^p, a: the work that does not grow with the steps).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from bench import best_of, interleaved, quick
from gainsched.config import config_from_text, load_config
from gainsched.model.reduced import Model
from gainsched.schedule.grid import build_grid, discrete_system, solve_circle, steps_per_period
from gainsched.schedule.linearize import discretize, expm_batched, jacobians, lqr_system
from gainsched.schedule.lqr import dlqr, native_available, periodic_lqr, sweep
from gainsched.schedule.nominal import circle_nominal
from gainsched.schedule.path import period

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "configs" / "paper.toml"
SPEED = 9.0  # m/s: all tilts feasible


def loop_sweep(Ad, Bd, Q, R):
    """The same backward recursion, one point at a time with numpy (the baseline)."""
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


def weights(cfg, n):
    Q = np.zeros((n, n))
    Q[:11, :11] = cfg.control.Q
    return Q, np.asarray(cfg.control.R, dtype=float)


def _rel(X, Y):
    return float(np.abs(X - Y).max() / np.abs(Y).max())


# ------------------------------------------------------------------ (a) Riccati


def circles_64(cfg):
    """A_d, B_d of 64 circles (the feasible tilted circles of the grid, repeated)."""
    model = Model(cfg)
    tilts = cfg.grid.tilts[1:]
    As, Bs = [], []
    for v in cfg.grid.speeds:
        sol = solve_circle(cfg, float(v), tilts)
        ok = tilts[np.isfinite(sol.spectral_radius)]
        if ok.size:
            N = steps_per_period(v, model.r, cfg.control.dt)
            Ad, Bd, _, _ = discrete_system(model, float(v), ok, N, period(v, model.r) / N)
            As.extend(Ad)
            Bs.extend(Bd)
    N = min(a.shape[0] for a in As)
    idx = [i % len(As) for i in range(64)]
    return (np.ascontiguousarray(np.stack([As[i][:N] for i in idx])),
            np.ascontiguousarray(np.stack([Bs[i][:N] for i in idx])), len(As))


def bench_riccati(cfg, Ad, Bd, distinct):
    b, N, n, _ = Bd.shape
    Q, R = weights(cfg, n)
    P0 = np.broadcast_to(Q, (b, n, n))
    pts = b * N
    out = {"points": b, "steps": N, "distinct_circles": distinct}
    t_np, sw_np = best_of(lambda: sweep(Ad, Bd, Q, R, P0, use_native=False), 2)
    n_loop = 8  # the baseline on 8 points (it is per point: its rate does not depend on b)
    t_loop, P_loop = best_of(lambda: loop_sweep(Ad[:n_loop], Bd[:n_loop], Q, R), 2)
    rate_loop = n_loop * N / t_loop
    out["numpy_batched_point_steps_per_s"] = pts / t_np
    out["per_point_loop_point_steps_per_s"] = rate_loop
    agree = _rel(sw_np.P0[:n_loop], P_loop)
    print(f"  riccati, {b} circles x {N} steps (one point-step = one recursion step at one point)")
    print(f"    per-point Python loop       {rate_loop:12,.0f} point-steps/s "
          f"({1e6 / rate_loop:.2f} us)  baseline")
    print(f"    batched numpy (fallback)    {pts / t_np:12,.0f} point-steps/s "
          f"({1e6 * t_np / pts:.2f} us)  {pts / t_np / rate_loop:5.1f}x")
    if native_available():
        for threads in (1, 2):
            t_c, sw_c = best_of(lambda th=threads: sweep(Ad, Bd, Q, R, P0, threads=th), 3)
            rate = pts / t_c
            err = _rel(sw_c.P0, sw_np.P0)
            print(f"    compiled kernel, {threads} thread{'s' if threads > 1 else ' '}  "
                  f"{rate:12,.0f} point-steps/s ({1e6 / rate:.2f} us)  "
                  f"{rate / rate_loop:5.1f}x  (P agrees with numpy to {err:.0e})")
            out[f"compiled_{threads}t_point_steps_per_s"] = rate
            out[f"compiled_{threads}t_us_per_point_step"] = 1e6 / rate
            out[f"compiled_{threads}t_ratio_vs_loop"] = rate / rate_loop
            out["compiled_vs_numpy_rel"] = err
        # a strided layout (steps innermost), read without a copy
        inner = [np.moveaxis(np.moveaxis(X, 1, -1).copy(), -1, 1) for X in (Ad, Bd)]
        t_i, sw_i = best_of(lambda: sweep(*inner, Q, R, P0, threads=2), 3)
        assert np.array_equal(sw_i.P0, sw_c.P0)
        print(f"    same, steps innermost (strided, no copy), 2 threads: "
              f"{1e6 * t_i / pts:.2f} us per point-step (same bits)")
        out["compiled_2t_steps_inner_us"] = 1e6 * t_i / pts
    else:
        print("    compiled kernel: no C compiler, skipped")
    out["loop_vs_batched_rel"] = agree
    return out


def _tilt0_problems(cfg):
    model = Model(cfg)
    probs = []
    for v in cfg.grid.speeds:
        N = steps_per_period(v, model.r, cfg.control.dt)
        dt = period(v, model.r) / N
        nom = circle_nominal(model, float(v), 0.0, 1)
        if nom.reasons.any():
            continue
        A, B = jacobians(model, nom.z[0], nom.u[0], 0.0)
        Ad, Bd = discretize(*lqr_system(A, B), dt)
        probs.append((float(v), Ad, Bd, N))
    return probs


def bench_peers(cfg, probs):
    """DARE and python-control dlqr per point on the tilt-0 ``probs`` (see _tilt0_problems)."""
    Q, R = weights(cfg, probs[0][1].shape[-1])
    out = {}
    t_dare, Ks = best_of(lambda: [dlqr(Ad, Bd, Q, R)[0] for _, Ad, Bd, _ in probs], 3)
    out["dare_s_per_point"] = t_dare / len(probs)
    # ours on the same problems: the periodic recursion over one period of steps
    steps = sum(N for *_, N in probs)

    def ours():
        return [periodic_lqr(np.broadcast_to(Ad, (N,) + Ad.shape)[None],
                             np.broadcast_to(Bd, (N,) + Bd.shape)[None], Q, R,
                             steps=[0]).K[0, 0] for _, Ad, Bd, N in probs]

    t_ours, K_ours = best_of(ours, 1)
    err = max(_rel(a, b) for a, b in zip(K_ours, Ks, strict=True))
    out["ours_periodic_s_per_point"] = t_ours / len(probs)
    out["ours_vs_dare_gain_rel"] = err
    print(f"  tilt-0 problems ({len(probs)} speeds): scipy DARE {1e3 * t_dare / len(probs):.2f} "
          f"ms/point; our periodic recursion over the period ({steps // len(probs)} steps on "
          f"average) {1e3 * t_ours / len(probs):.2f} ms/point, gains agree to {err:.0e}; "
          "the build uses the DARE at tilt 0")
    try:
        import control
    except ImportError:
        print("  python-control not installed (extra [peers]): dlqr peer skipped")
    else:
        t_ctl, Kc = best_of(lambda: [control.dlqr(Ad, Bd, Q, R)[0] for _, Ad, Bd, _ in probs], 3)
        err_c = max(_rel(a, b) for a, b in zip(Kc, Ks, strict=True))
        out["python_control_dlqr_s_per_point"] = t_ctl / len(probs)
        print(f"  python-control dlqr {1e3 * t_ctl / len(probs):.2f} ms/point "
              f"({t_ctl / t_dare:.2f}x scipy's time), gains agree to {err_c:.0e}")
    return out


def _drake(Ad, Bd, Q, R, batched_us, tilt0):
    """Drake's discrete finite-horizon LQR per step against our kernel.

    Headline: one circle's time-varying A_k, B_k (the same matrices as the kernel
    benchmark), through a ``TrajectoryLinearSystem`` with zero-order-hold trajectories;
    for context also the time-invariant tilt-0 problem ``tilt0`` (a ``LinearSystem``,
    cheaper per step for Drake).
    """
    try:
        from pydrake.systems.controllers import (
            FiniteHorizonLinearQuadraticRegulator,
            FiniteHorizonLinearQuadraticRegulatorOptions,
        )
        from pydrake.systems.primitives import LinearSystem, TrajectoryLinearSystem
        from pydrake.trajectories import PiecewisePolynomial
    except ImportError:
        print("  drake not installed (extra [peers]): Drake peer skipped")
        return {}
    N, n, m = Bd.shape
    opts = FiniteHorizonLinearQuadraticRegulatorOptions()
    opts.Qf = Q

    def solve(sysd, steps):
        ctx = sysd.CreateDefaultContext()
        sysd.get_input_port().FixValue(ctx, np.zeros(m))
        return FiniteHorizonLinearQuadraticRegulator(sysd, ctx, 0.0, float(steps), Q, R, opts)

    t = [float(k) for k in range(N + 1)]
    zoh = lambda X: PiecewisePolynomial.ZeroOrderHold(t, list(np.concatenate([X, X[-1:]])))  # noqa: E731
    tv = TrajectoryLinearSystem(zoh(Ad), zoh(Bd), zoh(np.broadcast_to(np.eye(n), (N, n, n))),
                                zoh(np.zeros((N, n, m))), time_period=1.0)
    t_d, res = best_of(lambda: solve(tv, N), 1)
    steps = [0, 1, N // 2, N - 1]
    t_o, sw = best_of(lambda: sweep(Ad[None], Bd[None], Q, R, Q[None], steps=steps), 3)
    err = max(_rel(sw.K[0, i], np.asarray(res.K.value(float(k)))) for i, k in enumerate(steps))
    us_d, us_o = 1e6 * t_d / N, 1e6 * t_o / N
    print(f"  Drake FiniteHorizonLQR, discrete, on one circle's time-varying A_k, B_k ({N} "
          f"steps): {us_d:.1f} us/step; ours {us_o:.2f} us/step on this one point "
          f"({us_d / us_o:.0f}x), {batched_us:.2f} us per point-step batched "
          f"({us_d / batched_us:.0f}x); gains agree to {err:.0e}")
    out = {"drake_us_per_step": us_d, "ours_single_point_us_per_step": us_o,
           "ratio_vs_drake_single_point": us_d / us_o,
           "ratio_vs_drake_batched": us_d / batched_us, "drake_gain_rel": err}
    speed, A0, B0, N0 = tilt0
    lti = LinearSystem(A0, B0, np.eye(n), np.zeros((n, m)), time_period=1.0)
    t_l, res_l = best_of(lambda: solve(lti, N0), 1)
    K0 = sweep(np.broadcast_to(A0, (1, N0, n, n)), np.broadcast_to(B0, (1, N0, n, m)), Q, R,
               Q[None], steps=[0]).K[0, 0]
    err_l = _rel(K0, np.asarray(res_l.K.value(0.0)))
    print(f"    (time-invariant tilt-0 problem at {speed:g} m/s, LinearSystem: Drake "
          f"{1e6 * t_l / N0:.1f} us/step, gains agree to {err_l:.0e})")
    out.update(drake_lti_us_per_step=1e6 * t_l / N0, drake_lti_gain_rel=err_l)
    return out


# ------------------------------------------------------------------ (b) linearisation


def bench_linearization(cfg):
    model = Model(cfg)
    tilts = cfg.grid.tilts[1:]
    N = steps_per_period(SPEED, model.r, cfg.control.dt)
    dt = period(SPEED, model.r) / N
    blocks = tilts.size * N

    def direct():
        zs = [circle_nominal(model, SPEED, a, N) for a in tilts]
        A, B = jacobians(model, np.stack([z.z for z in zs]), np.stack([z.u for z in zs]),
                         tilts[:, None])
        return discretize(*lqr_system(A, B), dt)

    t_dir, (Ad_ref, _) = best_of(direct, 1)
    t_int, (Ad, _, M, _) = best_of(lambda: discrete_system(model, SPEED, tilts, N, dt), 3)
    err = _rel(Ad - np.eye(Ad.shape[-1]), Ad_ref - np.eye(Ad.shape[-1]))
    print(
        f"  linearise + discretise, {tilts.size} tilts x {N} steps: every step "
        f"{blocks / t_dir:,.0f} blocks/s; exact at {M} azimuths + interpolation "
        f"{blocks / t_int:,.0f} blocks/s -> {t_dir / t_int:.0f}x (agree to {err:.0e})"
    )
    # discretisation alone: batched Taylor vs scipy's expm on the same blocks
    from scipy.linalg import expm

    A, B = jacobians(model, circle_nominal(model, SPEED, tilts[-1], 256).z,
                     circle_nominal(model, SPEED, tilts[-1], 256).u, tilts[-1])
    Ax, Bx = lqr_system(A, B)
    n, m = Bx.shape[-2:]
    Mb = np.zeros(Ax.shape[:-2] + (n + m, n + m))
    Mb[..., :n, :n], Mb[..., :n, n:] = Ax * dt, Bx * dt
    t_ours, E = best_of(lambda: expm_batched(Mb), 5)
    t_sp, E_ref = best_of(lambda: expm(Mb), 2)
    e_err = _rel(E, E_ref)
    print(f"  discretisation ({Mb.shape[-1]}x{Mb.shape[-1]} blocks): batched Taylor "
          f"{len(Mb) / t_ours:,.0f} blocks/s ({1e6 * t_ours / len(Mb):.1f} us), scipy expm "
          f"{len(Mb) / t_sp:,.0f} blocks/s ({1e6 * t_sp / len(Mb):.1f} us) -> "
          f"{t_sp / t_ours:.1f}x (agree to {e_err:.0e})")
    return {"blocks": blocks, "interp_samples": M, "direct_blocks_per_s": blocks / t_dir,
            "interp_blocks_per_s": blocks / t_int, "interp_ratio": t_dir / t_int,
            "interp_rel": err, "taylor_us_per_block": 1e6 * t_ours / len(Mb),
            "scipy_expm_us_per_block": 1e6 * t_sp / len(Mb), "expm_ratio": t_sp / t_ours,
            "expm_rel": e_err}


# ------------------------------------------------------------------ (c) builds


def _variant(text, speeds=None, tilts=None, rate=None):
    if speeds is not None:
        text = re.sub(r"^speeds = .*$", f"speeds = {json.dumps(speeds)}", text, flags=re.M)
    if tilts is not None:
        text = re.sub(r"^tilts_deg = .*$", f"tilts_deg = {json.dumps(tilts)}", text, flags=re.M)
    if rate is not None:
        text = re.sub(r"^rate_hz = [0-9.]+", f"rate_hz = {rate}", text, flags=re.M)
    return text


def _peak_rss_mib(text, n_jobs=1):
    """Wall time and peak resident memory of a build in a fresh process."""
    code = (  # VmHWM: this process's peak resident set (ru_maxrss may carry the parent's)
        "import re, sys, time\n"
        "def hwm():\n"
        "    s = open('/proc/self/status').read()\n"
        "    return int(re.search(r'VmHWM:\\s+(\\d+)', s).group(1)) / 1024\n"
        "from gainsched.config import config_from_text\n"
        "from gainsched.schedule.grid import build_grid\n"
        "cfg = config_from_text(sys.stdin.read(), 'bench.toml')\n"
        "base = hwm()\n"
        f"t0 = time.perf_counter(); build_grid(cfg, n_jobs={n_jobs})\n"
        "print(time.perf_counter() - t0, base, hwm())\n"
    )
    res = subprocess.run([sys.executable, "-c", code], input=text, capture_output=True,
                         text=True, check=True)
    t, base, peak = map(float, res.stdout.split())
    return t, base, peak


def _refine(x):
    """Grid values with the midpoints added (2x - 1 values)."""
    x = np.asarray(x, dtype=float)
    return [round(float(v), 3) for v in np.sort(np.concatenate([x, 0.5 * (x[1:] + x[:-1])]))]


def _refinements(x, times):
    """``x`` (as floats) and its ``times`` successive refinements (see _refine)."""
    out = [[float(v) for v in x]]
    for _ in range(times):
        out.append(_refine(out[-1]))
    return out


def _exponent(x, y):
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def _fixed_plus_power(x, y):
    """Least-squares fit of ``y = a + b x^p`` (relative residuals); returns a, b, p."""
    from scipy.optimize import least_squares

    x, y = np.asarray(x, float), np.asarray(y, float)
    p0 = _exponent(x, y)
    b0 = y[-1] / x[-1] ** p0
    res = least_squares(lambda q: (q[0] + q[1] * (x / x[0]) ** q[2]) / y - 1.0,
                        [0.0, b0 * x[0] ** p0, p0],
                        bounds=([0.0, 0.0, 0.1], [y.min(), np.inf, 3.0]))
    a, b, p = res.x
    return float(a), float(b / x[0] ** p), float(p)


def _growth(what, variants, size, unit, first):
    """Build each (name, config text) of ``variants`` (best of 2, :func:`best_of`) but the
    first, the paper build already timed: ``first`` its (time s, grid); their sizes and
    times."""
    xs, ts = [], []
    for i, (name, vt) in enumerate(variants):
        c = config_from_text(vt, "bench.toml")
        t, g = first if i == 0 else best_of(lambda c=c: build_grid(c, n_jobs=1), 2)
        xs.append(size(g))
        ts.append(t)
        print(f"    {what} {name}: {xs[-1]} {unit}, {t:.2f} s")
    return xs, ts


def bench_build(cfg):
    out = {}
    text = PAPER.read_text()
    # the paper build on one job is every sweep's first point and the bound's baseline:
    # always the best of 2 (a slow spell on one call of it moved the fit of the growth
    # in steps from exponent 1.00 to 1.57)
    t1, g = best_of(lambda: build_grid(cfg, n_jobs=1), 2, long_s=np.inf)
    t2_cold, _ = best_of(lambda: build_grid(cfg, n_jobs=2), 1)
    t2, _ = best_of(lambda: build_grid(cfg, n_jobs=2), 2)
    print(
        f"  build paper ({g.reasons.size} grid points, {g.spectral_radius.size} circles): n_jobs=1 "
        f"{t1:.2f} s; n_jobs=2 {t2_cold:.2f} s cold (worker start-up), {t2:.2f} s warm"
    )
    _, base, peak = _peak_rss_mib(text)
    print(
        f"  peak memory of the paper build: {peak:.0f} MiB resident "
        f"({peak - base:.0f} MiB above the interpreter with its imports, {base:.0f} MiB)"
    )
    out.update(n_jobs_1_s=t1, n_jobs_2_cold_s=t2_cold, n_jobs_2_warm_s=t2,
               grid_points=int(g.reasons.size), circles=int(g.spectral_radius.size),
               peak_rss_mib=peak, peak_rss_above_imports_mib=peak - base)

    # the closed-loop bound (issue 20: within 1.2x): the scaled LQR, plus the LQR without
    # the bound for the price line, at every circle
    bounded = cfg.with_values({"control.max_time_constant_s": 1.5})
    t_b, g_b = best_of(lambda: build_grid(bounded, n_jobs=1), 2, long_s=np.inf)
    print(f"  build with max_time_constant_s = 1.5: {t_b:.2f} s, x{t_b / t1:.2f} the paper "
          f"build (slowest mode {np.nanmax(g_b.mode_tau):.2f} s, was "
          f"{np.nanmax(g.mode_tau):.1f} s)")
    out.update(bounded_s=t_b, bounded_ratio=t_b / t1)

    # the stability margins of every circle (issue 56: within 1.5x of the build without),
    # on 2 warm workers, the builds with and without in interleaved rounds
    bare = cfg.with_values({"control.margins": False})
    got = interleaved({"on": lambda: build_grid(cfg, n_jobs=2),
                       "off": lambda: build_grid(bare, n_jobs=2)}, 2 if quick() else 3)
    t_on, t_bare = got["on"][0], got["off"][0]
    print(f"  build without margins ([control] margins = false): {t_bare:.2f} s on 2 jobs "
          f"(warm), with them {t_on:.2f} s: x{t_on / t_bare:.2f} (goal 1.5x; interleaved, "
          "best of each)")
    out.update(no_margins_2_warm_s=t_bare, margins_2_warm_s=t_on, margins_ratio=t_on / t_bare)
    if quick():
        print("  growth sweeps and the 4x finer grid: not in the quick mode (make bench)")
        return out
    out.update(_growth_sweeps(cfg, text, (t1, g), peak))
    return out


def _growth_sweeps(cfg, text, paper, peak):
    """The build's growth in grid points and in steps per period, and the 4x finer grid;
    ``paper``: the paper build's (time s, grid) on one job, the sweeps' first point,
    ``peak`` its peak memory, MiB."""
    # growth in grid points, two ways. Speeds refined: one job per speed, each with the
    # same cost profile, so this is the growth of the work per grid point. Tilts
    # refined at fixed speeds: the tilts of a speed are solved as batches, which
    # amortise the per-speed work (set-up, the tilt-0 DARE, numpy call overheads), so
    # this grows slower than linearly.
    # Growth in steps: the control rate raised at fixed grid. A build has work that does
    # not grow with the steps (the linearisation at M azimuths, set by the
    # interpolation check; the set-up), so the time is fitted as t = a + b steps^p: p is
    # the growth exponent of the work that grows with the steps; the plain log-log
    # slope, pulled below 1 by a, is printed too.
    def circles(g):
        return g.spectral_radius.size

    speeds = _refinements(cfg.grid.speeds, 2)
    pts, times = _growth(
        "grid", [(f"{2**i}x speeds", _variant(text, speeds=v)) for i, v in enumerate(speeds)],
        circles, "circles", paper)
    e_pts = _exponent(pts, times)
    tilts = _refinements(np.rad2deg(cfg.grid.tilts), 3)
    pts_t, times_t = _growth(
        "grid", [(f"{2**i}x tilts", _variant(text, tilts=a)) for i, a in enumerate(tilts)],
        circles, "circles", paper)
    e_tilts = _exponent(pts_t, times_t)
    print(f"  growth exponent in grid points {e_pts:.2f} (speeds refined: one job each); "
          f"{e_tilts:.2f} with tilts refined (batched in a job, sublinear)")
    # 4x finer grid: the spacing of speeds and of tilts halved (midpoints added), built
    # once in a fresh process (its time and peak memory)
    fine = _variant(text, speeds=speeds[1], tilts=tilts[1])
    t_fine, _, peak4 = _peak_rss_mib(fine)
    n_fine = len(speeds[1]) * len(tilts[1])
    print(
        f"  4x finer grid (speeds and tilts refined, {n_fine} circles): "
        f"{t_fine:.2f} s, peak memory {peak4:.0f} MiB (paper: {peak:.0f} MiB)"
    )
    rates = (1000.0, 2000.0, 4000.0, 8000.0, 16000.0)
    steps, t_steps = _growth(
        "control rate", [(f"{r:g} Hz", _variant(text, rate=r)) for r in rates],
        lambda g: int(g.steps.sum()), "steps per sweep of all speeds", paper)
    a, b, e_steps = _fixed_plus_power(steps, t_steps)
    e_steps_loglog = _exponent(steps, t_steps)
    print(f"  growth exponent in steps per period {e_steps:.2f} (t = a + b steps^p over 1-16 "
          f"kHz, a = {a:.2f} s); plain log-log slope {e_steps_loglog:.2f}")
    return dict(fine_grid_s=t_fine, fine_grid_circles=n_fine,
                fine_peak_rss_mib=peak4, growth_exponent_points=e_pts,
                growth_exponent_points_tilts=e_tilts, growth_exponent_steps=e_steps,
                growth_exponent_steps_loglog=e_steps_loglog, step_fit=[a, b, e_steps],
                scaling={"circles": pts, "circle_times_s": times, "circles_tilts": pts_t,
                         "circle_times_tilts_s": times_t, "steps": steps,
                         "step_times_s": t_steps})


def bench_effect_builds(cfg):
    """Issue 39: builds whose effects leave the closed form against the drag-only build of
    the same grid, in a process pinned like the command (bench/_effects.py, one worker:
    the builds run in it, no worker hand-off in the figures)."""
    res = subprocess.run([sys.executable, "-m", "bench._effects"], check=True,
                         capture_output=True, text=True, cwd=ROOT)
    *lines, last = res.stdout.splitlines()
    print("\n".join(lines))
    return json.loads(last)


def build_stages():
    """Issue 39: the paper build's time split by stage (bench/_stages.py: a process pinned
    like the command, one worker, cProfile's cumulative times)."""
    res = subprocess.run([sys.executable, "-m", "bench._stages", str(PAPER)], check=True,
                         capture_output=True, text=True, cwd=PAPER.parents[1])
    st = json.loads(res.stdout)
    print(f"  paper build by stage (one worker, profiled: {st['total_s']:.2f} s): nominal "
          f"{st['nominal_s']:.2f} s (of it attitude offsets {st['offsets_s']:.2f} s), "
          f"linearisation {st['linearisation_s']:.2f} s, Riccati "
          f"{st['riccati_s'] + st['riccati_tilt0_s']:.2f} s, outputs {st['outputs_s']:.2f} s")
    return st


def plot(results, out_dir):
    """Scaling curves (PNG) next to bench/results.json."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bd = results["build"]
    sc = bd["scaling"]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
    for key, lab in (("", "speeds refined"), ("_tilts", "tilts refined")):
        x = np.asarray(sc["circles" + key], dtype=float)
        y = np.asarray(sc[f"circle_times{key}_s"])
        ax[0].loglog(x, y, "o-", label=f"{lab}, slope {_exponent(x, y):.2f}")
    xs = np.asarray(sc["steps"], dtype=float)
    ys = np.asarray(sc["step_times_s"])
    fa, fb, fp = bd["step_fit"]
    ax[1].loglog(xs, ys, "o", label=f"build, log-log slope {_exponent(xs, ys):.2f}")
    ax[1].loglog(xs, fa + fb * xs**fp, "C1-", label=f"a + b x^p, p = {fp:.2f}, a = {fa:.2f} s")
    for a, x, y, lab in ((ax[0], sc["circles"], sc["circle_times_s"], "circles"),
                         (ax[1], xs, ys, "steps per sweep of all speeds")):
        x = np.asarray(x, dtype=float)
        a.loglog(x, x / x[0] * y[0], "k:", label="slope 1")
        a.set_xlabel(lab)
        a.set_ylabel("build time (s)")
        a.legend(fontsize=8)
        a.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path = Path(out_dir) / "build_scaling.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main():
    cfg = load_config(PAPER)
    probs = _tilt0_problems(cfg)
    Ad, Bd, distinct = circles_64(cfg)
    results = {"riccati": bench_riccati(cfg, Ad, Bd, distinct), "peers": bench_peers(cfg, probs)}
    r = results["riccati"]
    best_us = (
        min(v for k, v in r.items() if k.endswith("us_per_point_step"))
        if any(k.endswith("us_per_point_step") for k in r)
        else 1e6 / r["numpy_batched_point_steps_per_s"]
    )
    Q, R = weights(cfg, probs[0][1].shape[-1])
    results["peers"].update(_drake(Ad[0], Bd[0], Q, R, best_us, probs[len(probs) // 2]))
    results.update(
        {
            "linearization": bench_linearization(cfg),
            "build": bench_build(cfg),
            "effect_builds": bench_effect_builds(cfg),
            "build_stages": build_stages(),
        }
    )
    if "compiled_2t_ratio_vs_loop" in r:
        print(f"  Riccati kernel vs per-point loop: {r['compiled_1t_ratio_vs_loop']:.1f}x on 1 "
              f"thread, {r['compiled_2t_ratio_vs_loop']:.1f}x on 2 "
              f"({r['compiled_2t_us_per_point_step']:.2f} us per point-step)")
    if "scaling" in results["build"]:  # not in the quick mode
        results["plot"] = str(plot(results, Path(__file__).parent))
    return results


if __name__ == "__main__":
    main()
