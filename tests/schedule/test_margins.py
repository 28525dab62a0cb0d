"""Stability margins of the periodic closed loop (issue 56): gainsched/schedule/margins.py.

Checked against answers found another way:
- a scalar loop ``x+ = a x - g b k x``: the gain margins ``(a -+ 1) / (b k)`` in closed form,
  for any period length and batched (to 1e-9);
- a multi-input LTI loop as a periodic one of constant samples: the margins are those of
  ``A - g B K``, found independently as the g where an eigenvalue's modulus is 1 by
  root-finding (scipy's brentq) on the eigenvalues of the LTI matrix;
- a time-varying periodic loop: at the margin the monodromy's spectral radius is 1, and
  just inside it below 1 (the definition);
- the delay margin of a scalar loop: the delay at which the characteristic polynomial of
  the interpolated-hold loop, ``z^(d+2) - a z^(d+1) + b k ((1 - f) z + f)``, has a root
  on the unit circle (numpy's roots and brentq on f), to 1e-6 of a sample;
- the compiled kernel against its numpy fallback, its vector variants bit for bit, and
  the delayed loop's low-rank image against its whole monodromy on a paper circle (its
  image found over the period's last span, or over the whole period when that fails);
- the build: the level circle of the paper vehicle solved by the periodic solver over its
  N constant steps has the margins of its one-step LTI loop found by brentq on the
  eigenvalues of ``A - g B K`` (to 1e-6), and the DARE path stores the same.
"""

from __future__ import annotations

import ctypes
import io
from concurrent.futures import ThreadPoolExecutor

import h5py
import numpy as np
import pytest
from scipy.optimize import brentq

from gainsched import native
from gainsched.config import config_from_text
from gainsched.errors import InputError
from gainsched.schedule import margins as mg
from gainsched.schedule.grid import build_grid, solve_circle
from gainsched.schedule.margins import (
    delay_margin,
    gain_margins,
    loop_margins,
    monodromy_with,
    spectral_radius,
)
from gainsched.schedule.tables import table_bytes, table_from_bytes
from gainsched.schedule.viewer import margin_lines

from support import paper_config_text, small_config


@pytest.mark.parametrize("N", [1, 5, 36])
def test_the_gain_margins_of_a_scalar_loop_are_the_closed_form(N):
    a = np.array([1.1, 0.9, 1.3])
    bk = np.array([0.6, 1.2, 0.8])
    Ad = np.broadcast_to(a[:, None, None, None], (3, N, 1, 1))
    Bd = np.broadcast_to(bk[:, None, None, None], (3, N, 1, 1))
    K = np.ones((3, N, 1, 1))
    down, up = gain_margins(Ad, Bd, K)
    np.testing.assert_allclose(up, (a + 1) / bk, rtol=1e-9)
    np.testing.assert_allclose(down, np.maximum((a - 1) / bk, 0.0), rtol=1e-9, atol=1e-12)
    assert down[1] == 0.0  # 0.9 is stable with the input off: no lower margin


def _lti_loop(seed=0):
    """A stable LQR loop of a random 4-state, 2-input discrete system."""
    from scipy.linalg import solve_discrete_are

    rng = np.random.default_rng(seed)
    A = np.eye(4) + 0.1 * rng.standard_normal((4, 4))
    B = 0.1 * rng.standard_normal((4, 2))
    P = solve_discrete_are(A, B, np.eye(4), np.eye(2))
    K = np.linalg.solve(np.eye(2) + B.T @ P @ B, B.T @ P @ A)
    return A, B, K


def _lti_margin(A, B, K, mask, lo, hi):
    """The first g from ``lo`` toward ``hi`` where rho(A - B diag(g on mask) K) = 1."""
    rho = lambda g: np.abs(np.linalg.eigvals(A - (B * np.where(mask, g, 1.0)) @ K)).max()  # noqa: E731
    grid = np.linspace(lo, hi, 2001)
    r = np.array([rho(g) for g in grid])
    i = int(np.argmax(r >= 1.0))
    if r[i] < 1.0:
        return np.inf if hi > lo else 0.0
    return brentq(lambda g: rho(g) - 1.0, grid[i - 1], grid[i], xtol=1e-14)


@pytest.mark.parametrize("inputs", [None, [0], [1]], ids=["all", "input0", "input1"])
def test_the_margins_of_an_lti_loop_flown_as_a_periodic_one(inputs):
    A, B, K = _lti_loop()
    N = 12
    Ad, Bd, Kd = (np.broadcast_to(X, (1, N) + X.shape) for X in (A, B, K))
    down, up = gain_margins(Ad, Bd, Kd, inputs=inputs)
    mask = np.ones(2, bool) if inputs is None else np.isin(np.arange(2), inputs)
    up_ref = _lti_margin(A, B, K, mask, 1.0, 10.0)
    down_ref = _lti_margin(A, B, K, mask, 1.0, 0.0)
    assert up[0] == pytest.approx(up_ref, rel=1e-6) if np.isfinite(up_ref) else np.isinf(up[0])
    assert down[0] == pytest.approx(down_ref, rel=1e-6, abs=1e-9)


def test_at_the_margin_of_a_periodic_loop_a_multiplier_is_on_the_unit_circle():
    """A loop whose samples vary over the period: rho(Phi(g)) is 1 at each margin and
    below 1 just inside it."""
    A, B, K = _lti_loop(3)
    N = 20
    ph = 2 * np.pi * np.arange(N) / N
    Ad = np.stack([A + 0.05 * np.sin(p) * np.eye(4) for p in ph])[None]
    Bd = np.stack([B * (1 + 0.3 * np.cos(p)) for p in ph])[None]
    Kd = np.broadcast_to(K, (1, N, 2, 4))
    down, up = gain_margins(Ad, Bd, Kd)
    assert 0 <= down[0] < 1 < up[0] < 10
    for g, inside in ((up[0], up[0] * (1 - 1e-6)), (down[0], down[0] * (1 + 1e-6) + 1e-9)):
        if g == 0:
            continue
        rho = spectral_radius(monodromy_with(Ad, Bd, Kd, np.full((1, 2), g)))
        assert rho[0] == pytest.approx(1.0, abs=1e-8)
        assert spectral_radius(monodromy_with(Ad, Bd, Kd, np.full((1, 2), inside)))[0] < 1.0


@pytest.mark.parametrize(("a", "bk"), [(1.0, 0.5), (0.95, 0.3), (1.05, 0.8)])
def test_the_delay_margin_of_a_scalar_loop_is_where_its_polynomial_crosses(a, bk):
    def rho(tau):
        d, f = int(np.floor(tau)), tau - np.floor(tau)
        c = np.zeros(d + 3)
        c[0], c[1] = 1.0, -a
        c[d + 1] += bk * (1 - f)  # z^(d+2) - a z^(d+1) + bk ((1 - f) z + f)
        c[d + 2] += bk * f
        return np.abs(np.roots(c)).max()

    taus = np.linspace(0, 7.999, 8000)
    r = np.array([rho(t) for t in taus])
    i = int(np.argmax(r >= 1.0))
    ref = brentq(lambda t: rho(t) - 1.0, taus[i - 1], taus[i], xtol=1e-12)
    h = 0.004
    Ad, Bd, K = np.full((1, 7, 1, 1), a), np.full((1, 7, 1, 1), bk), np.ones((1, 7, 1, 1))
    tau = delay_margin(Ad, Bd, K, h)
    assert tau[0] / h == pytest.approx(ref, abs=1e-6)


def _scalar_delay_search(monkeypatch, guess):
    """The delay margin of a scalar loop (1.43 samples of 4 ms, in a range of 12.5) and
    the loops evaluated to find it, with ``guess`` times it as the search's guess."""
    h, xtol = 0.004, 1e-6
    Ad, Bd, K = np.full((1, 9, 1, 1), 1.0), np.full((1, 9, 1, 1), 0.5), np.ones((1, 9, 1, 1))
    free = loop_margins(Ad, Bd, K, h, xtol=xtol).delay[0]
    lanes, spectra = [], mg._delay_spectra
    monkeypatch.setattr(mg, "_delay_spectra",
                        lambda *a: lanes.append(a[3].size) or spectra(*a))
    tau = loop_margins(Ad, Bd, K, h, xtol=xtol,
                       delay_guess=None if guess is None else guess * free).delay[0]
    return free, tau, sum(lanes)


@pytest.mark.parametrize("guess", [0.3, 0.9, 0.985, 1.0, 1.003, 1.2, 20.0])
def test_a_guess_of_the_delay_margin_moves_the_search_not_the_margin(monkeypatch, guess):
    """The delay search started around a guess (the build's level circle's margin for its
    tilted circles), however far off (x20: beyond the search range), finds the margin of
    the search without one, within its tolerance."""
    free, tau, _ = _scalar_delay_search(monkeypatch, guess)
    assert tau == pytest.approx(free, rel=2e-6)


def test_a_good_guess_of_the_delay_margin_saves_evaluations(monkeypatch, paper_circle):
    """The build's point of the guess: on the paper's 15 m/s, 20 deg circle (whose level
    circle's margin is 1.3 % above its own), the search from a guess 1.3 % off evaluates
    fewer delayed loops than the scan of the whole range, and finds the same margin."""
    sol, (Ad, Bd, K) = paper_circle
    lanes, spectra = [], mg._delay_spectra
    monkeypatch.setattr(mg, "_delay_spectra",
                        lambda *a: lanes.append(a[3].size) or spectra(*a))
    free = loop_margins(Ad, Bd, K, sol.dt, delay_xtol=1e-4).delay[0]
    none, lanes[:] = sum(lanes), []
    near = loop_margins(Ad, Bd, K, sol.dt, delay_xtol=1e-4, delay_guess=1.013 * free).delay[0]
    assert near == pytest.approx(free, rel=2e-4)
    assert sum(lanes) < none


@pytest.mark.parametrize(("theta", "d"), [(0.2, 3), (0.05, 7), (0.4, 2)])
@pytest.mark.parametrize("N", [1, 40])
def test_the_phase_margin_of_an_lti_loop_is_its_frequency_responses(theta, d, N):
    """A scalar loop ``x+ = a x - b k u_{k-d}`` built to cross at ``exp(i theta)`` with a
    delay of exactly d samples: its crossover is where ``|L(exp(i w h))| = 1``, ``L(z) =
    b k / (z - a)`` (brentq), its phase margin ``pi + arg L`` there, and the delay margin
    times the crossover is that phase margin, to 1e-6; the same loop flown as a period of
    N = 40 constant steps (its multiplier's arg N theta wrapped 1 to 3 turns) has the
    same, its alias picked by a guess 1 % below or above (the paper's tilted circles lie
    within 0.8 % of their level circle's)."""
    h = 0.002
    psi = np.pi - d * theta  # arg(exp(i theta) - a): the loop's phase at the crossover
    bk = np.sin(theta) / np.sin(psi)
    a = np.cos(theta) - bk * np.cos(psi)
    w_ref = brentq(lambda w: abs(np.exp(1j * w * h) - a) - bk, 1e-9, 0.999 * np.pi / h)
    pm_ref = np.pi - np.angle(np.exp(1j * w_ref * h) - a)
    Ad, Bd, K = np.full((2, N, 1, 1), a), np.full((2, N, 1, 1), bk), np.ones((2, N, 1, 1))
    guess = None if N == 1 else np.array([0.99, 1.01]) * theta / h  # below and above
    lm = loop_margins(Ad, Bd, K, h, crossover_guess=guess)
    np.testing.assert_allclose(lm.delay / h, d, rtol=1e-6)
    np.testing.assert_allclose(lm.crossover, w_ref, rtol=1e-6)
    np.testing.assert_allclose(lm.phase, pm_ref, rtol=1e-6)


def test_a_periodic_loops_crossover_needs_a_guess_of_its_alias():
    """A loop of N > 1 steps knows its crossing multiplier's frequency only up to 2 pi /
    T: without a guess its crossover is unknown (NaN), not a wrong alias."""
    Ad, Bd, K = np.full((1, 7, 1, 1), 1.27), np.full((1, 7, 1, 1), 0.35), np.ones((1, 7, 1, 1))
    lm = loop_margins(Ad, Bd, K, 0.002)
    assert np.isfinite(lm.delay[0]) and np.isnan(lm.crossover[0]) and np.isnan(lm.phase[0])


def test_the_builds_tilted_circles_crossovers_are_near_their_level_circles(paper_config):
    """The build picks a tilted circle's alias nearest its level circle's crossover: on
    the paper's circles they lie well inside half an alias step of it (so the pick is
    unambiguous), and the phase margins are those of an LQR loop (above 60 deg)."""
    for v, tilts in ((3.0, [0.0, 20.0]), (15.0, [0.0, 20.0, 37.0])):
        sol = solve_circle(paper_config, v, np.radians(tilts))
        step = 2 * np.pi / (sol.steps * sol.dt)
        assert np.all(np.abs(sol.crossover[1:] - sol.crossover[0]) < 0.25 * step)
        assert np.all(np.degrees(sol.crossover * sol.delay_margin) > 60)


def _periodic_loop(seed=1, b=3, N=40, n=11, m=4):
    """Random stable-ish periodic loops (b, N): A_k near I, small B_k, K_k."""
    rng = np.random.default_rng(seed)
    ph = 2 * np.pi * np.arange(N) / N
    A0 = np.eye(n) + 0.02 * rng.standard_normal((b, n, n))
    Ad = A0[:, None] + 0.01 * np.sin(ph)[None, :, None, None] * rng.standard_normal((b, 1, n, n))
    Bd = 0.05 * rng.standard_normal((b, 1, n, m)) * (1 + 0.3 * np.cos(ph))[None, :, None, None]
    K = rng.standard_normal((b, N, m, n))
    return Ad, Bd, K


def _lanes(Ad, Bd, K):
    """A gain and a delay evaluation of every loop: (log rho of gains, (Y, e) of delays)."""
    b, m = Ad.shape[0], Bd.shape[-1]
    circle = np.repeat(np.arange(b), 3)
    G = np.tile([[0.5] * m, [1.0] * m, [3.0, 1.0, 1.0, 0.2][:m]], (b, 1))
    tau = np.tile([0.0, 2.5, 6.0], b)
    D = 7
    # the build's columns (n + 3): the kernel's specialised paths for 11 x 4 and 15 x 4,
    # generic otherwise
    X0 = np.random.default_rng(2).standard_normal((circle.size, Ad.shape[-1] + D * m,
                                                   mg._columns(Ad.shape[-1])))
    return mg._gain_loops(Ad, Bd, K, circle, G), mg._delay_pass(
        mg._lib(), Ad, Bd, K, circle, tau, D, X0)


#: the kernel's sizes: specialised (the paper's loop, with a motor lag) and generic
KERNEL_SIZES = ((11, 4), (15, 4), (5, 2))


@pytest.mark.skipif(not native.available("loops"), reason="no C compiler")
@pytest.mark.parametrize("sizes", KERNEL_SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_the_loop_kernel_and_its_numpy_fallback_agree(monkeypatch, sizes):
    """Both kernels against the numpy recursion, through renormalisations of the state
    while the ring holds commands written before them (40 steps, a renormalisation every
    16, delays to 6 samples)."""
    Ad, Bd, K = _periodic_loop(n=sizes[0], m=sizes[1])
    g_c, (Y_c, e_c) = _lanes(Ad, Bd, K)
    monkeypatch.setattr(mg, "_lib", lambda: None)
    g_n, (Y_n, e_n) = _lanes(Ad, Bd, K)
    np.testing.assert_allclose(g_c, g_n, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(Y_c * 2.0 ** e_c[:, None, None], Y_n * 2.0 ** e_n[:, None, None],
                               rtol=1e-10, atol=1e-12 * np.abs(Y_n).max())


def test_the_loop_kernel_bits_do_not_depend_on_vector_width(monkeypatch):
    """Every vector variant this CPU runs gives the same bits (the margins are stored in
    the table, which is byte-identical on every machine); sizes 11 x 4 and 15 x 4
    (specialised) and 5 x 2 (generic)."""
    variants = native.vector_variants()
    with ThreadPoolExecutor(2) as ex:
        paths = list(ex.map(lambda f: native.build("loops", f), variants))
    if any(p is None for p in paths):
        pytest.skip("no C compiler")
    if len(paths) == 1:
        pytest.skip("this CPU runs only the baseline variant")
    results = []
    for path in paths:
        lib = ctypes.CDLL(str(path))
        monkeypatch.setattr(native, "load", lambda name, lib=lib: lib)
        out = []
        for sizes in KERNEL_SIZES:
            g, (Y, e) = _lanes(*_periodic_loop(n=sizes[0], m=sizes[1]))
            out += [g, Y, e]
        results.append(out)
    for other in results[1:]:
        for a, b in zip(results[0], other, strict=True):
            assert np.array_equal(a, b)


@pytest.mark.skipif(not native.available("loops"), reason="no C compiler")
@pytest.mark.parametrize("sizes", KERNEL_SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("block", [1, 4])
def test_a_calls_last_few_lanes_take_the_row_path_to_the_same_bits(sizes, block):
    """A call's last group of few lanes runs each lane on its own, its matrices' rows to
    vectors (a lane vector would be mostly empty): the same bits as the lanes computed
    together, every step and the scan's surrogate of blocks."""
    Ad, Bd, K = _periodic_loop(n=sizes[0], m=sizes[1])
    circle = np.repeat(np.arange(3), 6)  # 18 lanes: full lane vectors at every width
    G = np.random.default_rng(3).uniform(0.2, 3.0, (circle.size, sizes[1]))
    together = mg._gain_spectra(Ad, Bd, K, circle, G, block)
    alone = np.concatenate([mg._gain_spectra(Ad, Bd, K, circle[i:i + 1], G[i:i + 1], block)
                            for i in range(circle.size)])
    assert np.array_equal(together, alone)


@pytest.fixture(scope="module")
def paper_circle(paper_config):
    """The paper vehicle's 15 m/s circle at 20 deg: its steps and solution."""
    sol, steps = solve_circle(paper_config, 15.0, np.radians([20.0]), keep_steps=True)
    return sol, steps


def _whole_delayed_monodromy(Ad, Bd, K, tau_steps):
    """The reference: the delayed loop's whole monodromy, the product of its one-step
    matrices on the state ``[x, u_{k-1}, .., u_{k-D}]`` (shift register, interpolated
    hold), as ``(M, e)``: ``M 2^e``; a formulation of its own, not the kernel's ring."""
    n, m = Ad.shape[-1], Bd.shape[-1]
    tau = np.asarray(tau_steps, float)
    D = int(np.floor(np.max(tau))) + 1
    d = np.floor(tau).astype(int)
    f = tau - d
    na = n + D * m
    batch = np.broadcast_shapes(Ad.shape[:-3], tau.shape)
    M = np.broadcast_to(np.eye(na), batch + (na, na)).copy()
    e = np.zeros(batch)
    # weights of the held commands u_{k-j}, j = 0..D, on the applied input
    j = np.arange(D + 1)
    w = (np.where(j == d[..., None], 1.0 - f[..., None], 0.0)
         + np.where(j == d[..., None] + 1, f[..., None], 0.0))  # (*batch, D + 1)
    for k in range(Ad.shape[-3]):
        A, B, Kk = Ad[..., k, :, :], Bd[..., k, :, :], K[..., k, :, :]
        T = np.zeros(batch + (na, na))
        # applied = w0 u_k + sum_{j>=1} w_j u_{k-j}, u_k = -K x
        T[..., :n, :n] = A - w[..., 0, None, None] * (B @ Kk)
        for jj in range(1, D + 1):
            cols = slice(n + (jj - 1) * m, n + jj * m)
            T[..., :n, cols] = w[..., jj, None, None] * B
        T[..., n:n + m, :n] = -Kk  # the register: u_k enters, the rest shift down
        for jj in range(1, D):
            T[..., n + jj * m:n + (jj + 1) * m, n + (jj - 1) * m:n + jj * m] = np.eye(m)
        M = T @ M
        if (k + 1) % mg._RENORM == 0:
            M, e = mg._rescaled(M, e)
    return M, e


def test_the_delayed_loops_low_rank_image_has_the_whole_monodromys_multipliers(paper_circle):
    """The delayed loop's multipliers from its image on 14 columns (the build's) are those
    of the whole (n + D m)-square monodromy, to 1e-9, below, near and beyond the margin."""
    sol, (Ad, Bd, K) = paper_circle
    tau = np.array([4.0, 12.5, 13.0, 20.25])
    circle = np.zeros(tau.size, int)
    low = mg._delay_loops(Ad, Bd, K, circle, tau)
    whole = [mg._log_rho(*_whole_delayed_monodromy(Ad[0], Bd[0], K[0], np.array(t)))
             for t in tau]
    np.testing.assert_allclose(low, whole, atol=1e-9)
    assert low[0] < 0 < low[-1]  # a stable and an unstable delay


def test_a_monodromy_at_hand_gives_the_loops_margins_without_forming_it(monkeypatch,
                                                                        paper_circle):
    """The build hands the solver's monodromy to the margins (its multipliers as the loop
    is): the same margins as with the monodromy formed by the kernel, to the build's
    tolerances, and one loop fewer evaluated."""
    sol, (Ad, Bd, K) = paper_circle
    lanes, spectra = [], mg._gain_spectra
    monkeypatch.setattr(mg, "_gain_spectra",
                        lambda *a: lanes.append(a[3].size) or spectra(*a))
    kw = dict(xtol=mg.MARGIN_XTOL, delay_xtol=mg.MARGIN_DELAY_XTOL, block=32)
    formed = loop_margins(Ad, Bd, K, sol.dt, **kw)
    count, lanes[:] = sum(lanes), []
    Phi = monodromy_with(Ad, Bd, K, np.ones(4))
    given = loop_margins(Ad, Bd, K, sol.dt, monodromy=Phi, **kw)
    assert sum(lanes) == count - 1
    for a, b, tol in ((given.gain_down, formed.gain_down, kw["xtol"]),
                      (given.delay, formed.delay, kw["delay_xtol"])):
        np.testing.assert_allclose(a, b, rtol=tol)


def test_a_span_too_short_for_the_image_falls_back_to_the_whole_period(monkeypatch,
                                                                       paper_circle):
    """The delayed loop's image is found over the period's last span (0.3 s, or 20
    delays): the start propagated over that span, then Q over the period. A span too short
    for the fast modes to decay (8 steps) fails the check, and the start goes over the
    whole period: the multipliers of the whole monodromy either way, to 1e-9."""
    sol, (Ad, Bd, K) = paper_circle
    N, passes, run = Ad.shape[1], [], mg._delay_pass
    monkeypatch.setattr(mg, "_delay_pass",
                        lambda lib, A, *a: passes.append(A.shape[1]) or run(lib, A, *a))
    for tau, decay, expect in ((12.5, mg._decay_steps(sol.dt), [300, N]),
                               (12.5, 8, [8, N, N, N])):
        monkeypatch.setattr(mg, "_DECAY_DELAYS", 20 if decay > 8 else 0)  # 8 steps alone
        passes.clear()
        got = mg._delay_spectra(Ad, Bd, K, np.zeros(1, int), np.array([tau]), decay)
        assert passes == expect
        whole = mg._log_rho(*_whole_delayed_monodromy(Ad[0], Bd[0], K[0], np.array(tau)))
        assert got[0, 0].real == pytest.approx(whole, abs=1e-9)


def test_a_motor_lags_delayed_loop_has_its_image_on_its_columns(monkeypatch):
    """A motor lag's loop has 15 states: its delayed loop's numerical rank over a period
    is above the paper's 14 columns, and the whole monodromy was formed at nearly every
    evaluation. On n + 3 columns (18) its image passes the check over the period's last
    span (two passes, the whole monodromy never formed), with the whole monodromy's
    multipliers to 1e-9, below and beyond the margin."""
    cfg = config_from_text(paper_config_text(**{"effects.motor_lag.tau": 0.035}), "lag.toml")
    sol, (Ad, Bd, K) = solve_circle(cfg, 9.0, np.radians([20.0]), keep_steps=True)
    assert Ad.shape[-1] == 15 and mg._columns(15) == 18
    columns, run = [], mg._delay_pass
    monkeypatch.setattr(mg, "_delay_pass",
                        lambda lib, A, *a: columns.append(a[-1].shape[-1]) or run(lib, A, *a))
    for tau in (8.0, 1.5 * sol.delay_margin[0] / sol.dt):
        columns.clear()
        got = mg._delay_spectra(Ad, Bd, K, np.zeros(1, int), np.array([tau]),
                                mg._decay_steps(sol.dt))
        assert columns == [18, 18]
        whole = mg._log_rho(*_whole_delayed_monodromy(Ad[0], Bd[0], K[0], np.array(tau)))
        assert got[0, 0].real == pytest.approx(whole, abs=1e-9)
    assert got[0, 0].real > 0  # beyond the margin: unstable


def test_a_crossing_just_outside_the_surrogates_check_is_bracketed_by_widening():
    """The real loop checks a bracket 1e-3 of the margin wide around the surrogate's
    crossing; a down margin of 3 % makes that 3e-5 in p, less than the surrogate's error
    there. The check widens (4x, up to 3 times) on the side the crossing lies beyond and
    finds it, instead of searching the real loop again from 0: here a surrogate 5e-5 off
    a crossing at p = 0.97 (a factor of 0.03)."""
    from gainsched.schedule.crossings import first_crossings

    def line(offset, seen=None):
        def spectra(pair, P):
            if seen is not None:
                seen.extend(P.tolist())
            x = P - 0.97 - offset
            return (10.0 * x - 3.0 * x ** 2 + 0j)[:, None]
        return spectra

    seen = []
    s0 = line(0.0)(None, np.zeros(1))
    p = first_crossings(line(0.0, seen), np.ones((1, 1)), s0, 1e-6,
                        lambda pair, P: np.maximum(1.0 - P, 1e-12), surrogate=line(5e-5))
    assert p[0, 0] == pytest.approx(0.97, abs=1e-6 * 0.03)
    assert min(seen) > 0.969, seen  # no search again from p = 0


def _lti_margins(A, B, K, mask):
    """The first g below and above 1 where rho(A - B diag(g on mask) K) = 1 (brentq on a
    fine scan of the eigenvalues; 0 / inf where none)."""
    rho = lambda g: np.abs(np.linalg.eigvals(A - (B * np.where(mask, g, 1.0)) @ K)).max() - 1  # noqa: E731
    out = []
    for grid in (np.linspace(1.0, 0.0, 401), np.linspace(1.0, mg.G_MAX, 401)):
        r = np.array([rho(g) for g in grid])
        i = int(np.argmax(r >= 0))
        out.append(brentq(rho, grid[i - 1], grid[i], xtol=1e-14) if r[i] >= 0
                   else (0.0 if grid[-1] == 0 else np.inf))
    return out


def test_a_level_circle_solved_periodically_has_its_lti_loops_margins(paper_config):
    """The level circle is time-invariant: solved by the periodic solver over its N
    steps (every step the same A, B and, to the recursion's convergence, K), its gain
    margins are those of the one-step loop ``A - g B K``, all motors and each alone, to
    1e-6; and the DARE path, which the build takes, stores the same."""
    cfg = paper_config.with_values({"grid.azimuth_samples": 8})
    periodic, (Ad, Bd, K) = solve_circle(cfg, 9.0, [0.0], keep_steps=True)
    dare = solve_circle(cfg, 9.0, [0.0])
    A, B, Kd = Ad[0, 0], Bd[0, 0], dare.K[0, 0]
    np.testing.assert_allclose(K[0], np.broadcast_to(Kd, K[0].shape), atol=1e-9)
    for j, mask in enumerate([np.ones(4, bool)] + [np.eye(4, dtype=bool)[i] for i in range(4)]):
        ref = _lti_margins(A, B, Kd, mask)
        got = periodic.gain_margin[0] if j == 0 else periodic.input_margin[0, j - 1]
        stored = dare.gain_margin[0] if j == 0 else dare.input_margin[0, j - 1]
        for g, r, s in zip(got, ref, stored, strict=True):
            assert g == pytest.approx(r, rel=1e-6, abs=1e-9)
            assert s == pytest.approx(r, rel=1e-6, abs=1e-9)
    assert periodic.delay_margin[0] == pytest.approx(dare.delay_margin[0], rel=1e-6)


def _delayed_step(A, B, K, tau):
    """The one-step matrix of the loop ``x+ = A x + B ((1 - f) u_{k-d} + f u_{k-d-1})``,
    ``u = -K x``, tau = d + f samples, on ``[x, u_{k-1}, .., u_{k-D}]``: formed whole, the
    reference the margins' search no longer forms for a time-invariant loop."""
    n, m = B.shape
    d, f = int(np.floor(tau)), tau - np.floor(tau)
    D = d + 2
    F = np.zeros((n + D * m, n + D * m))
    F[:n, :n] = A
    for j, w in ((d, 1.0 - f), (d + 1, f)):  # the applied command u_{k-j}, weight w
        if j == 0:
            F[:n, :n] -= w * B @ K
        else:
            F[:n, n + (j - 1) * m:n + j * m] += w * B
    F[n:n + m, :n] = -K
    for j in range(1, D):
        F[n + j * m:n + (j + 1) * m, n + (j - 1) * m:n + j * m] = np.eye(m)
    return F


def test_a_level_circles_delay_margin_at_4_khz_is_its_whole_step_matrixs(paper_config):
    """At 4 kHz the level circle's one-step delayed loop has 11 + 4 D rows (815 over the
    50 ms searched: its eigenvalues were 4x the rest of the build); its delay margin is
    searched on 0.3 s of its steps instead (14 columns). Against the whole one-step matrix
    formed here: stable 1e-4 below the margin, unstable 1e-4 above, and its multiplier
    nearest the unit circle at the margin has the crossover's frequency to the build's
    1e-4 (the arg a power of the step leaves only modulo 2 pi / 1201: its aliases are 19 %
    apart at this crossover)."""
    cfg = paper_config.with_values({"control.rate_hz": 4000.0, "grid.azimuth_samples": 8})
    _, (Ad, Bd, _) = solve_circle(cfg, 12.0, [0.0], keep_steps=True)  # its A, B
    sol = solve_circle(cfg, 12.0, [0.0])  # the build's: the DARE and one step
    A, B, K, h = Ad[0, 0], Bd[0, 0], sol.K[0, 0], sol.dt
    tau, w = sol.delay_margin[0] / h, sol.crossover[0]
    assert mg._decay_steps(h) > 1000 and 40 < tau < 80, (mg._decay_steps(h), tau)

    def rho(t):
        return np.abs(np.linalg.eigvals(_delayed_step(A, B, K, t))).max()

    assert rho(tau * (1 - 1e-4)) < 1.0 < rho(tau * (1 + 1e-4))
    lam = np.linalg.eigvals(_delayed_step(A, B, K, tau))
    on = lam[np.argmin(np.abs(np.abs(lam) - 1.0))]
    assert abs(np.angle(on)) / h == pytest.approx(w, rel=1e-4)


def test_the_gain_scans_surrogate_spans_32_ms_at_any_rate(paper_config):
    """The gain scan's surrogate blocks span 32 ms: 32 steps at 1 kHz, 128 at 4 kHz
    (surrogate_block), and the margins it leads to are the real loop's: on a 4 kHz circle
    tilted 20 deg, every gain margin (all motors, each alone) equals the search without
    a surrogate to the build's 1e-6."""
    cfg = paper_config.with_values({"control.rate_hz": 4000.0, "grid.azimuth_samples": 8})
    sol, (Ad, Bd, K) = solve_circle(cfg, 12.0, [np.deg2rad(20.0)], keep_steps=True)
    assert mg.surrogate_block(1e-3) == 32 and mg.surrogate_block(sol.dt) == 128
    got, ref = (loop_margins(Ad, Bd, K, sol.dt, xtol=1e-6, block=b)
                for b in (mg.surrogate_block(sol.dt), 1))
    for name in ("gain_down", "gain_up", "input_down", "input_up"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=2e-6)


def test_the_table_stores_the_builds_margins_and_serves_them():
    """The build's margins are the table's (``Table.margins()``: every circle; with a
    speed and a tilt: that circle), covered by the checksums; a table built with
    ``[control] margins = false`` has none and says so."""


    cfg = small_config()
    grid = build_grid(cfg)
    data = table_bytes(cfg, grid)
    table = table_from_bytes(data)
    lm = table.margins()
    np.testing.assert_array_equal(lm.gain_down, grid.gain_margin[..., 0])
    np.testing.assert_array_equal(lm.input_up, grid.input_margin[..., 1])
    np.testing.assert_array_equal(lm.delay, grid.delay_margin)
    np.testing.assert_array_equal(lm.crossover, grid.crossover)
    assert np.all(lm.delay[np.isfinite(grid.spectral_radius)] > 0)
    one = table.margins(9, 20)
    assert one.delay == grid.delay_margin[1, 1] and one.input_down.shape == (4,)
    assert one.phase == grid.crossover[1, 1] * grid.delay_margin[1, 1]
    with pytest.raises(ValueError, match=r"speed = 7 is not on the grid: \[6\.0, 9\.0\]"):
        table.margins(7, 20)
    with h5py.File(io.BytesIO(data), "r+") as f:  # an edited margin
        f["closed_loop/delay_margin"][0, 0] *= 2
        f.flush()
        edited = f.id.get_file_image()
    with pytest.raises(InputError, match="closed_loop/delay_margin"):
        table_from_bytes(edited)
    off = small_config(**{"control.margins": False})
    bare = table_from_bytes(table_bytes(off, build_grid(off)))
    assert bare.loop_margins is None
    with pytest.raises(ValueError, match=r"margins = false"):
        bare.margins()
    assert "rebuild" in margin_lines(bare)[0]


def test_a_delay_bound_the_weights_miss_fails_the_build_naming_the_circle(paper_config,
                                                                          tmp_path):
    """``[control] min_delay_margin_ms`` above what the paper's weights reach at 15 m/s,
    40 deg fails the build with one line naming the config, the key, the circle and the
    margin it reached (exit 2, nothing written); a bound below it builds."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    cut = {"grid.speeds": [9, 15], "grid.tilts_deg": [0, 40], "grid.azimuth_samples": 8,
           "name": "bounded"}
    grid = build_grid(paper_config.with_values(cut))
    worst = 1e3 * np.nanmin(grid.delay_margin)
    assert 12.5 < worst < 13.0 and np.nanargmin(grid.delay_margin) == 3  # 15 m/s, 40 deg
    path = tmp_path / "bounded.toml"
    path.write_text(paper_config.with_values({**cut, "control.min_delay_margin_ms": 13.0}).text)
    r = CliRunner().invoke(cli, ["build", str(path), "-o", str(tmp_path / "out")])
    assert r.exit_code == 2, r.output
    assert r.output.strip() == (
        f"gainsched: error: {path}: control.min_delay_margin_ms: 13 ms is not met: the "
        f"delay margin is {worst:.2f} ms at 15 m/s, tilt 40 deg: raise R or lower Q (a "
        "slower loop takes more delay)")
    assert not (tmp_path / "out").exists()
    ok = paper_config.with_values({**cut, "control.min_delay_margin_ms": 12.5,
                                   "control.min_gain_margin_db": 20.0})
    assert np.array_equal(build_grid(ok).delay_margin, grid.delay_margin)


def test_a_gain_bound_names_the_margin_nearest_to_0_db_and_which_way_to_go(paper_config):
    """The gain bound is met by every margin (all motors and each alone, down and up):
    the nearest to 0 dB fails, named with its circle and the weights that move it."""
    from types import SimpleNamespace

    from gainsched.schedule.bounds import check_margin_bounds

    cfg = paper_config.with_values({"grid.speeds": [9, 15], "grid.tilts_deg": [0, 40],
                                    "control.min_gain_margin_db": 6.0})
    gain = np.array([[[0.1, np.inf], [0.2, 8.0]], [[np.nan, np.nan], [0.3, 4.0]]])
    motor = np.broadcast_to([0.0, np.inf], (2, 2, 4, 2)).copy()
    motor[1, 1, 2] = [0.6, np.inf]  # T3 alone at 15 m/s, 40 deg: -4.4 dB down
    grid = SimpleNamespace(gain_margin=gain, input_margin=motor, delay_margin=None)
    with pytest.raises(InputError, match=r"control\.min_gain_margin_db: 6 dB is not met: the "
                       r"gain margin down of T3 alone is 4\.44 dB at 15 m/s, tilt 40 deg: "
                       r"raise Q or lower R \(more feedback\)"):
        check_margin_bounds(cfg, grid)
    motor[1, 1, 2] = [0.0, np.inf]
    gain[0, 1, 1] = 1.9  # all motors at 15 m/s, level: up +5.58 dB
    with pytest.raises(InputError, match=r"the gain margin up of all motors is 5\.58 dB at "
                       r"15 m/s, tilt 0 deg: raise R or lower Q \(softer gains\)"):
        check_margin_bounds(cfg, grid)
    gain[0, 1, 1] = 2.0  # +6.02 dB: met
    check_margin_bounds(cfg, grid)


@pytest.fixture(scope="module")
def small_table(tmp_path_factory):
    """A small paper table (9, 15 m/s; 0, 40 deg; 8 azimuths) on disk."""
    from gainsched.firmware.outputs import write_outputs

    cfg = small_config(**{"grid.speeds": [9, 15], "grid.tilts_deg": [0, 40]})
    out = tmp_path_factory.mktemp("small")
    return write_outputs(out, cfg, build_grid(cfg))[0]


def _lag_report(ci):
    """A diagnose report whose fit is a motor lag of 30 ms +- ``ci`` s."""
    return {"accepted": "motor_lag", "ranking": ["motor_lag"], "candidates": {
        "motor_lag": {"params": {"tau": {"estimate": 0.03, "ci95": ci, "unit": "s"}},
                      "heldout_rms_reduction": 0.8}}}


def test_check_uncertain_flies_the_tables_gains_over_the_fits_box(small_table, tmp_path):
    """``gainsched check TABLE --uncertain REPORT``: a 30 +- 5 ms motor lag the table was
    not built for keeps every loop stable (exit 0), with the worst multiplier, the plant
    and its margins printed; the delay margin falls from the table's by about the lag's
    phase. A wide interval (30 +- 100 ms) crosses 1 and the command says so: exit 1, the
    last line naming the parameter and the value; the box's corner below 0 is no model
    and is listed as skipped."""
    import json

    from click.testing import CliRunner

    from gainsched.cli import cli
    from gainsched.schedule.tables import load_table

    narrow, wide = tmp_path / "narrow.json", tmp_path / "wide.json"
    narrow.write_text(json.dumps(_lag_report(0.005)))
    wide.write_text(json.dumps(_lag_report(0.1)))
    r = CliRunner().invoke(cli, ["check", str(small_table), "--uncertain", str(narrow),
                                 "--samples", "2"])
    assert r.exit_code == 0, r.output
    lines = r.output.strip().splitlines()
    assert "5 plants of the diagnosis's 95 % box (motor_lag: tau 0.03 +- 0.005 s" in lines[0]
    assert lines[1].startswith("  worst multiplier 0.9") and "with tau = " in lines[1]
    assert lines[-1] == "  PASS: every loop stable over the box"
    delay = [x for x in lines if "extra delay" in x][0]
    ms = float(delay.split("extra delay ")[1].split(" ms")[0])
    table_ms = 1e3 * np.nanmin(load_table(small_table).margins().delay)
    assert 0.2 * table_ms < ms < 0.8 * table_ms  # a 25-35 ms lag eats most of it
    r = CliRunner().invoke(cli, ["check", str(small_table), "--uncertain", str(wide),
                                 "--samples", "1"])
    assert r.exit_code == 1, r.output
    last = r.output.strip().splitlines()[-1]
    assert last.startswith("  FAIL: motor_lag.tau at 0.13 makes the loop unstable "
                           "(multiplier "), last
    assert "skipped: corner -0.07: must be in" in r.output


def test_check_uncertain_gives_the_phase_margin_of_the_tables_own_plant(small_table):
    """A box around the table's own drag (1e-9 wide): every plant is the table's model.
    On the level circles (constant gains) the check's loops are the build's, so the
    crossovers are the stored ones to 1e-6; on the tilted ones the check flies the
    table's 8 azimuth samples interpolated where the build had every step's gains, and
    the crossovers agree to 1e-3 (the right alias: they lie 9 rad/s or more apart), the
    delay margins to 1e-2. The phase margin line is printed, within 1 deg of the table's
    own. A 30 +- 5 ms motor lag the table was not built for lowers the worst phase
    margin."""
    from gainsched.schedule.tables import config_from_table, load_table
    from gainsched.sim.plan import focus_values
    from gainsched.sim.uncertain import uncertain_loops

    table = load_table(small_table)
    own = focus_values(config_from_table(table), "drag")
    report = {"accepted": "drag", "ranking": ["drag"], "candidates": {"drag": {
        "params": {"mu1": {"estimate": own[0], "ci95": 1e-9, "unit": ""},
                   "mu2": {"estimate": own[1], "ci95": 1e-9, "unit": ""}},
        "heldout_rms_reduction": 0.8}}}
    u = uncertain_loops(table, report, samples=0)
    stored = table.margins()
    assert np.isfinite(stored.crossover).all() and np.isfinite(u.margins.crossover).all()
    np.testing.assert_allclose(u.margins.crossover[0], stored.crossover[0], rtol=1e-6)
    np.testing.assert_allclose(u.margins.crossover, stored.crossover, rtol=1e-3)
    np.testing.assert_allclose(u.margins.delay, stored.delay, rtol=1e-2)
    line = [x for x in u.lines("t.h5") if "phase margin at the crossover" in x]
    deg = np.degrees(np.nanmin(u.margins.phase))
    assert len(line) == 1 and f"{deg:.1f} deg" in line[0], (line, deg)
    assert abs(deg - np.degrees(np.nanmin(stored.phase))) < 1.0
    lag = uncertain_loops(table, _lag_report(0.005), samples=0)
    assert np.nanmin(lag.margins.phase) < np.nanmin(stored.phase) - np.radians(5)


def test_check_uncertain_holds_a_parameter_the_fit_did_not_identify(small_table):
    """A fit's parameter without a finite 95 % interval (the diagnosis does not write its
    estimate: the config keeps its own value) is held at the table config's value in
    every plant, not at its estimate nor at infinite corners, and the check says so;
    the identified one spans its box (2 corners, not 4)."""
    from gainsched.schedule.tables import load_table
    from gainsched.sim.uncertain import plant_count, uncertain_loops

    report = {"accepted": "drag", "ranking": ["drag"], "candidates": {"drag": {
        "params": {"mu1": {"estimate": 0.18, "ci95": 0.01, "unit": ""},
                   "mu2": {"estimate": 0.5, "ci95": float("inf"), "unit": ""}},
        "heldout_rms_reduction": 0.8}}}
    u = uncertain_loops(load_table(small_table), report, samples=1)
    assert u.held == ("mu2",) and u.kinds == ("estimate", "corner", "corner", "sample")
    assert plant_count(report, 1) == len(u.kinds)  # the progress bar's total
    np.testing.assert_array_equal(u.plants[:, 1], 0.0025)  # the config's mu2, not 0.5
    np.testing.assert_allclose(u.plants[:3, 0], [0.18, 0.17, 0.19])
    assert u.stable and np.isfinite(u.rho[np.isfinite(u.rho)]).all()
    text = "\n".join(u.lines("t.h5"))
    assert "(drag: mu1 0.18 +- 0.01; mu2 0.0025 held;" in text
    assert "not identified by the fit (no finite 95 % interval): mu2" in text
    assert u.to_json()["held"] == ["mu2"]
