"""Periodic LQR (issue 3, paper Sec. IV).

- the doubling-based periodic terminal cost is the limit of plain repeated sweeps;
- the period triple composes the per-step Riccati maps exactly;
- "single-period" is one plain sweep from P_N = Q;
- the returned gains and cost-to-go satisfy the Riccati recursion;
- at tilt 0 the gains equal scipy's DARE gains and do not depend on xi;
- the closed-loop monodromy has spectral radius < 1 at every feasible circle.
"""

from __future__ import annotations

import ctypes
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from gainsched import native
from gainsched.schedule import lqr
from gainsched.schedule.grid import solve_circle
from gainsched.schedule.lqr import (
    dlqr,
    monodromy,
    native_available,
    period_triple,
    periodic_cost,
    periodic_lqr,
    riccati_sweep,
    spectral_radius,
    sweep,
)


def _spd(rng, n, lo=0.5):
    X = rng.normal(size=(n, n))
    return X @ X.T / n + lo * np.eye(n)


@pytest.fixture(scope="module")
def small_problem():
    """A random periodic problem (N = 6 steps, n = 4, m = 2, batch of 3) that converges fast."""
    rng = np.random.default_rng(123)
    b, N, n, m = 3, 6, 4, 2
    Ad = rng.normal(size=(b, N, n, n)) * (0.9 / np.sqrt(n))
    Bd = rng.normal(size=(b, N, n, m))
    Q = _spd(rng, n)
    R = _spd(rng, m)
    return Ad, Bd, Q, R


def _rel(X, Y):
    return np.abs(X - Y).max() / np.abs(Y).max()


def test_periodic_cost_is_limit_of_plain_sweeps(small_problem):
    Ad, Bd, Q, R = small_problem
    P = np.broadcast_to(Q, Ad.shape[:-3] + Q.shape).copy()
    for _ in range(500):
        P_prev = P
        P, _, _ = riccati_sweep(Ad, Bd, Q, R, P)
    assert _rel(P, P_prev) < 1e-14, "the plain sweeps themselves did not converge"
    P_doubling, doublings = periodic_cost(Ad, Bd, Q, R)
    assert doublings < 20
    assert _rel(P_doubling, P) <= 1e-10
    sol = periodic_lqr(Ad, Bd, Q, R)  # the default terminal cost is the periodic one
    assert _rel(sol.S0, P) <= 1e-10
    assert sol.sweeps == 2**doublings + 1


def test_period_triple_equals_one_sweep(small_problem):
    """f(P) = H + A^T P (I + G P)^-1 A with the period's triple equals one backward sweep."""
    Ad, Bd, Q, R = small_problem
    rng = np.random.default_rng(5)
    P_end = np.stack([_spd(rng, Q.shape[0], lo=0.1) * 10.0 for _ in range(Ad.shape[0])])
    A, G, H = period_triple(Ad, Bd, Q, R)
    n = Q.shape[0]
    At = np.swapaxes(A, -1, -2)
    P_triple = H + At @ P_end @ np.linalg.solve(np.eye(n) + G @ P_end, A)
    P_sweep, _, _ = riccati_sweep(Ad, Bd, Q, R, P_end)
    assert _rel(P_triple, P_sweep) <= 1e-12


@pytest.mark.parametrize("N", [1, 5, 7, 8])
def test_period_triple_odd_and_even_lengths(small_problem, N):
    """The tree reduction pads odd lengths with the identity map: any N composes exactly."""
    Ad, Bd, Q, R = small_problem
    rng = np.random.default_rng(N)
    reps = -(-N // Ad.shape[-3])
    Ad_N = np.concatenate([Ad] * reps, -3)[..., :N, :, :]
    Bd_N = np.concatenate([Bd] * reps, -3)[..., :N, :, :]
    P_end = np.stack([_spd(rng, Q.shape[0]) for _ in range(Ad.shape[0])])
    A, G, H = period_triple(Ad_N, Bd_N, Q, R)
    At = np.swapaxes(A, -1, -2)
    P_triple = H + At @ P_end @ np.linalg.solve(np.eye(Q.shape[0]) + G @ P_end, A)
    P_sweep, _, _ = riccati_sweep(Ad_N, Bd_N, Q, R, P_end)
    assert _rel(P_triple, P_sweep) <= 1e-12


def test_single_period_is_one_plain_sweep_from_Q(small_problem):
    Ad, Bd, Q, R = small_problem
    sol = periodic_lqr(Ad, Bd, Q, R, terminal="single-period", keep_S=True)
    P_end = np.broadcast_to(Q, Ad.shape[:-3] + Q.shape).copy()
    P0, K, S = riccati_sweep(Ad, Bd, Q, R, P_end, keep=True)
    np.testing.assert_array_equal(sol.K, K)
    np.testing.assert_array_equal(sol.S, S)
    np.testing.assert_array_equal(sol.S0, P0)
    np.testing.assert_array_equal(sol.S[..., -1, :, :], P_end)
    assert sol.sweeps == 1
    with pytest.raises(ValueError, match="terminal"):
        periodic_lqr(Ad, Bd, Q, R, terminal="bogus")


@pytest.mark.parametrize("terminal", ["periodic", "single-period"])
def test_gains_satisfy_riccati_recursion(small_problem, terminal):
    Ad, Bd, Q, R = small_problem
    sol = periodic_lqr(Ad, Bd, Q, R, terminal=terminal, keep_S=True)
    K, S = sol.K, sol.S
    N = Ad.shape[-3]
    T = lambda X: np.swapaxes(X, -1, -2)  # noqa: E731
    for k in range(N):
        A, B, Sn = Ad[:, k], Bd[:, k], S[:, k + 1]
        K_expected = np.linalg.solve(R + T(B) @ Sn @ B, T(B) @ Sn @ A)
        assert _rel(K[:, k], K_expected) <= 1e-12
        Acl = A - B @ K[:, k]
        S_joseph = Q + T(K[:, k]) @ R @ K[:, k] + T(Acl) @ Sn @ Acl
        assert _rel(S[:, k], S_joseph) <= 1e-12
        np.testing.assert_array_equal(S[:, k], T(S[:, k]))  # symmetric
        assert np.linalg.eigvalsh(S[:, k]).min() > 0
    np.testing.assert_array_equal(sol.S0, S[:, 0])
    if terminal == "periodic":  # the cost-to-go is periodic: P_N = P_0
        assert _rel(S[:, N], S[:, 0]) <= 1e-10


def test_monodromy_is_the_closed_loop_product(small_problem):
    Ad, Bd, Q, R = small_problem
    sol = periodic_lqr(Ad, Bd, Q, R)
    Phi = monodromy(Ad, Bd, sol.K)
    for i in range(Ad.shape[0]):
        M = np.eye(Ad.shape[-1])
        for k in range(Ad.shape[-3]):
            M = (Ad[i, k] - Bd[i, k] @ sol.K[i, k]) @ M
        assert _rel(Phi[i], M) <= 1e-14
        assert spectral_radius(Phi[i]) == pytest.approx(np.abs(np.linalg.eigvals(M)).max())
    assert np.all(spectral_radius(Phi) < 1)
    assert _rel(sol.Phi, Phi) <= 1e-12  # accumulated inside the final sweep


@pytest.fixture(scope="module")
def lqr11():
    """A random problem of the flight size: n = 11, m = 4, N = 40 steps, 11 points (not a
    multiple of the kernel's lane count)."""
    rng = np.random.default_rng(2024)
    b, N, n, m = 11, 40, 11, 4
    Ad = np.eye(n) + rng.normal(size=(b, N, n, n)) * 0.05
    Bd = rng.normal(size=(b, N, n, m)) * 0.05
    return Ad, Bd, _spd(rng, n), _spd(rng, m)


@pytest.mark.needs_cc
# the compiled kernel in use, not only a compiler: GAINSCHED_NATIVE=0 switches it off too
@pytest.mark.skipif(not native_available(), reason="no C compiler: numpy recursion only")
@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_kernel_equals_numpy_recursion(lqr11, threads):
    """c/riccati.c and the numpy fallback run the same recursion: P, K, S, Phi, G agree."""
    Ad, Bd, Q, R = lqr11
    P = np.zeros(Ad.shape[:1] + Q.shape)
    steps = [39, 0, 17, 5]
    c = sweep(Ad, Bd, Q, R, P, steps=steps, triple=True, threads=threads, use_native=True)
    py = sweep(Ad, Bd, Q, R, P, steps=steps, triple=True, use_native=False)
    for name in ("P0", "K", "S", "Phi", "G"):
        assert _rel(getattr(c, name), getattr(py, name)) <= 1e-12, name
    sol_c = periodic_lqr(Ad, Bd, Q, R, use_native=True)
    sol_py = periodic_lqr(Ad, Bd, Q, R, use_native=False)
    assert sol_c.sweeps == sol_py.sweeps
    assert _rel(sol_c.K, sol_py.K) <= 1e-10


@pytest.mark.slow
@pytest.mark.needs_cc
# the compiled kernel in use, not only a compiler: GAINSCHED_NATIVE=0 switches it off too
@pytest.mark.skipif(not native_available(), reason="no C compiler: numpy recursion only")
def test_kernel_bits_do_not_depend_on_vector_width(lqr11, monkeypatch):
    """Every vector variant this CPU runs (AVX-512 8 lanes, AVX2 4, baseline 2) gives the
    same bits: committed tables do not depend on the machine that built them. Sizes
    11 x 4 (specialised code) and 6 x 3 (generic code). (An FMA-contracted build differs:
    this test fails on it.)"""
    variants = native.vector_variants()
    with ThreadPoolExecutor(2) as ex:  # a few seconds per compile
        paths = list(ex.map(lambda f: native.build("riccati", f), variants))
    assert all(p is not None for p in paths), variants
    if len(paths) == 1:
        pytest.skip("this CPU runs only the baseline variant")
    Ad, Bd, Q, R = lqr11
    small = (Ad[:5, :9, :6, :6], Bd[:5, :9, :6, :3], Q[:6, :6], R[:3, :3])
    results = []
    for path in paths:
        lib = lqr._configure(ctypes.CDLL(str(path)))
        monkeypatch.setattr(lqr, "_kernel", lambda lib=lib: lib)
        out = []
        for A, B, Qp, Rp in ((Ad, Bd, Q, R), small):
            P = np.zeros(A.shape[:1] + Qp.shape)
            sw = sweep(A, B, Qp, Rp, P, steps=[0, 5, 3], triple=True, threads=2, use_native=True)
            out += [sw.P0, sw.K, sw.S, sw.Phi, sw.G]
        results.append(out)
    for flags, out in zip(variants[1:], results[1:], strict=True):
        for i, (x, y) in enumerate(zip(out, results[0], strict=True)):
            assert np.array_equal(x, y), (flags, variants[0], i)


@pytest.mark.needs_cc
# the compiled kernel in use, not only a compiler: GAINSCHED_NATIVE=0 switches it off too
@pytest.mark.skipif(not native_available(), reason="no C compiler: numpy recursion only")
def test_kernel_reads_any_layout(lqr11):
    """The kernel reads A_k, B_k at their strides: steps innermost and points reversed
    (negative strides) give the bits of C order."""
    Ad, Bd, Q, R = lqr11
    P = np.zeros(Ad.shape[:1] + Q.shape)

    def run(A, B):
        sw = sweep(A, B, Q, R, P, steps=[0, 7], triple=True, use_native=True)
        return [sw.P0, sw.K, sw.S, sw.Phi, sw.G]

    def steps_inner(X):
        return np.moveaxis(np.moveaxis(X, 1, -1).copy(), -1, 1)

    ref = run(Ad, Bd)
    A_in, B_in = steps_inner(Ad), steps_inner(Bd)
    assert A_in.strides[1] == 8 and not A_in.flags.c_contiguous
    for x, y in zip(run(A_in, B_in), ref, strict=True):
        np.testing.assert_array_equal(x, y)
    rev = run(Ad[::-1].copy()[::-1], Bd[::-1].copy()[::-1])
    for x, y in zip(rev, ref, strict=True):
        np.testing.assert_array_equal(x, y)


def test_requested_steps_equal_all_steps(lqr11):
    """Gains kept at a few steps only are those of the full sweep (memory-bounded grid)."""
    Ad, Bd, Q, R = lqr11
    full = periodic_lqr(Ad, Bd, Q, R, keep_S=True)
    steps = np.array([3, 0, 21])
    part = periodic_lqr(Ad, Bd, Q, R, keep_S=True, steps=steps)
    np.testing.assert_array_equal(part.K, full.K[:, steps])
    np.testing.assert_array_equal(part.S, full.S[:, steps])
    np.testing.assert_array_equal(part.Phi, full.Phi)


# ----------------------------------------------------------------------------- tilt 0 = DARE


@pytest.fixture(scope="module", params=[3.0, 9.0, 15.0], ids=lambda v: f"{v:g}mps")
def tilt0(request, paper_config):
    sol, (Ad, Bd, K_steps) = solve_circle(paper_config, request.param, [0.0], keep_steps=True)
    n = Ad.shape[-1]
    Qx = np.zeros((n, n))
    Qx[:11, :11] = paper_config.control.Q
    return sol, Ad[0], Bd[0], K_steps[0], Qx, np.asarray(paper_config.control.R)


def test_tilt0_gains_equal_dare(tilt0):
    sol, Ad, Bd, K_steps, Qx, R = tilt0
    # at tilt 0 the linearisation is the same at every step (the problem is time-invariant)
    assert _rel(Ad, Ad[0]) <= 1e-13 and _rel(Bd, Bd[0]) <= 1e-13
    K_dare, S_dare, E = dlqr(Ad[0], Bd[0], Qx, R)
    assert np.abs(E).max() < 1
    assert _rel(K_steps, K_dare) <= 1e-8  # every step of the period
    assert _rel(sol.K[0], K_dare) <= 1e-8  # every stored azimuth
    assert _rel(sol.S[0], S_dare) <= 1e-8


def test_tilt0_gains_do_not_depend_on_xi(tilt0):
    sol, *_ = tilt0
    K = sol.K[0]  # (n_xi, 4, n)
    assert np.all(np.isfinite(K))
    assert _rel(K, K[0]) <= 1e-10


# ----------------------------------------------------------------------------- closed loop


def test_table_closed_loop_stable_at_every_feasible_circle(paper_table):
    t = paper_table
    rho = t.spectral_radius  # (tilt, speed)
    feasible = np.all(t.reasons == 0, axis=-1)
    assert feasible.sum() >= 50  # the paper grid is mostly feasible
    assert np.all(np.isfinite(rho[feasible]))
    assert np.all(rho[feasible] < 1), f"unstable circles: {np.argwhere(feasible & (rho >= 1))}"
    assert np.all(np.isnan(rho[~feasible])), "infeasible circles must have no spectral radius"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("speed", "tilt_deg"), [(3.0, 0.0), (9.0, 20.0), (12.0, 28.0), (14.0, 40.0)],
    ids=["3-0", "9-20", "12-28", "14-40-offsets"]
)
def test_monodromy_recomputed(paper_config, paper_table, speed, tilt_deg):
    a = np.deg2rad(tilt_deg)
    sol, (Ad, Bd, K) = solve_circle(paper_config, speed, [a], keep_steps=True)
    rho = spectral_radius(monodromy(Ad, Bd, K))[0]
    assert rho < 1
    assert rho == pytest.approx(sol.spectral_radius[0], rel=1e-12)
    i = int(np.flatnonzero(np.isclose(paper_table.tilt, a))[0])
    j = int(np.flatnonzero(paper_table.speed == speed)[0])
    assert rho == pytest.approx(paper_table.spectral_radius[i, j], rel=1e-9)
