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
  on the unit circle (numpy's roots and brentq on f), to 1e-6 of a sample.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from gainsched.schedule.margins import (
    delay_margin,
    gain_margins,
    monodromy_with,
    spectral_radius,
)


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
