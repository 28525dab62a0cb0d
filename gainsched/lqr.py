"""Finite-horizon discrete LQR over one circle period (paper Sec. IV.B, eq. 23).

The backward Riccati recursion runs batched over operating points (leading
array dimensions), so a grid is never a Python loop over points; only the
steps of the recursion are sequential. Terminal cost:

- ``"periodic"`` (default): the limit of repeating the backward sweep over
  the period until P at the period start stops changing. K(xi) is then the
  gain of the infinite-horizon periodic problem, well defined all around the
  circle. Plain repetition converges at the rate of the slowest closed-loop
  mode, which with the paper's weights is the delta integrator (about 100 s
  time constant: thousands of periods), so the limit is computed by a
  structured doubling algorithm instead: each step's Riccati map
  ``P -> H + A^T P (I + G P)^-1 A`` is a triple (A, G = B R^-1 B^T, H = Q);
  triples compose exactly, the period's triple comes from a batched tree
  reduction over the steps, and composing the period triple with itself
  doubles the horizon (2^k periods after k doublings, quadratic convergence).
  One last ordinary sweep from the converged P gives the per-step gains.
- ``"single-period"``: the paper's literal horizon of one period with ``Q_e = Q``.

Naming follows python-control: gains ``K``, Riccati solution ``S``, closed-loop
eigenvalues ``E``; ``u = u_d - K (x - x_d)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_are

from .errors import GainschedError

__all__ = [
    "PeriodicLQR",
    "periodic_lqr",
    "periodic_cost",
    "period_triple",
    "riccati_sweep",
    "dlqr",
    "monodromy",
    "spectral_radius",
]


@dataclass(frozen=True)
class PeriodicLQR:
    """Result of :func:`periodic_lqr` (batch shape ``b``).

    Attributes
    ----------
    K : ndarray, shape (*b, N, m, n)   gains of the N steps of one period
    S : ndarray, shape (*b, N + 1, n, n) or None   cost-to-go P_k (``keep_S=True``)
    S0 : ndarray, shape (*b, n, n)   P at the period start
    sweeps : int   periods of horizon folded into the terminal cost (2^doublings; 0 for
        single-period), plus the final sweep
    """

    K: np.ndarray
    S: np.ndarray | None
    S0: np.ndarray
    sweeps: int


def riccati_sweep(Ad, Bd, Q, R, P, *, keep=False):
    """One backward sweep over k = N-1 .. 0 starting from the terminal P (batched).

    Parameters
    ----------
    Ad : ndarray, shape (*b, N, n, n); Bd : ndarray, shape (*b, N, n, m)
    Q : ndarray, shape (n, n); R : ndarray, shape (m, m); P : ndarray, shape (*b, n, n)

    Returns
    -------
    P0 : ndarray (*b, n, n); K : ndarray (*b, N, m, n) or None; S : (*b, N+1, n, n) or None
    """
    N = Ad.shape[-3]
    K = np.empty(Bd.shape[:-3] + (N, Bd.shape[-1], Ad.shape[-1])) if keep else None
    S = np.empty(Ad.shape[:-3] + (N + 1,) + Ad.shape[-2:]) if keep else None
    if keep:
        S[..., N, :, :] = P
    for k in range(N - 1, -1, -1):
        A, B = Ad[..., k, :, :], Bd[..., k, :, :]
        BtP = np.swapaxes(B, -1, -2) @ P
        Kk = np.linalg.solve(R + BtP @ B, BtP @ A)
        P = Q + np.swapaxes(A, -1, -2) @ P @ (A - B @ Kk)
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        if keep:
            K[..., k, :, :] = Kk
            S[..., k, :, :] = P
    return P, K, S


def periodic_lqr(Ad, Bd, Q, R, *, terminal="periodic", Q_e=None, tol=1e-11, max_sweeps=200,
                 keep_S=False) -> PeriodicLQR:  # fmt: skip
    """Finite-horizon LQR over one period with a periodic (or fixed) terminal cost.

    Parameters
    ----------
    Ad, Bd : ndarray, shapes (*b, N, n, n), (*b, N, n, m)
        Discrete system of the N steps of one period.
    Q, R : ndarray, shapes (n, n), (m, m)
        Stage weights (paper eq. 23-24).
    terminal : {"periodic", "single-period"}
    Q_e : ndarray, shape (n, n), optional
        Terminal weight for ``"single-period"`` (default Q) and first guess for
        ``"periodic"``.
    tol : float
        Relative change of P at the period start that ends the periodic sweeps.
    """
    Q_e = Q if Q_e is None else Q_e
    P = np.broadcast_to(Q_e, Ad.shape[:-3] + Q.shape).copy()
    sweeps = 0
    if terminal == "periodic":
        P, doublings = periodic_cost(Ad, Bd, Q, R, tol=tol, max_doublings=max_sweeps)
        sweeps = 2**doublings
    elif terminal != "single-period":
        raise ValueError(f"unknown terminal cost {terminal!r}")
    P0, K, S = riccati_sweep(Ad, Bd, Q, R, P, keep=True)
    return PeriodicLQR(K, S if keep_S else None, P0, sweeps + 1)


def _compose(t1, t2):
    """Triple of "segment 1 then segment 2" (segment 1 earlier in time), batched.

    With ``f_i(P) = H_i + A_i^T P (I + G_i P)^-1 A_i`` the value at a segment's start
    for the terminal value P at its end, ``f(P) = f_1(f_2(P))`` has the triple
    ``A = A2 W A1``, ``G = G2 + A2 W G1 A2^T``, ``H = H1 + A1^T H2 W A1`` with
    ``W = (I + G1 H2)^-1`` (the structured doubling algorithm's composition rule).
    """
    A1, G1, H1 = t1
    A2, G2, H2 = t2
    n = A1.shape[-1]
    W = np.linalg.inv(np.eye(n) + G1 @ H2)
    A2W = A2 @ W
    A = A2W @ A1
    G = G2 + A2W @ G1 @ np.swapaxes(A2, -1, -2)
    H = H1 + np.swapaxes(A1, -1, -2) @ H2 @ W @ A1
    sym = lambda X: 0.5 * (X + np.swapaxes(X, -1, -2))  # noqa: E731
    return A, sym(G), sym(H)


def period_triple(Ad, Bd, Q, R):
    """The Riccati map of a whole period as one triple, by a batched tree reduction."""
    n, N = Ad.shape[-1], Ad.shape[-3]
    A = Ad
    G = Bd @ np.linalg.solve(R, np.swapaxes(Bd, -1, -2))
    H = np.broadcast_to(Q, A.shape).copy()
    while N > 1:
        if N % 2:  # pad with the identity map (A = I, G = H = 0) at the end
            pad = A.shape[:-3] + (1, n, n)
            A = np.concatenate([A, np.broadcast_to(np.eye(n), pad)], -3)
            G = np.concatenate([G, np.zeros(pad)], -3)
            H = np.concatenate([H, np.zeros(pad)], -3)
            N += 1
        A, G, H = _compose(
            (A[..., 0::2, :, :], G[..., 0::2, :, :], H[..., 0::2, :, :]),
            (A[..., 1::2, :, :], G[..., 1::2, :, :], H[..., 1::2, :, :]),
        )
        N //= 2
    return A[..., 0, :, :], G[..., 0, :, :], H[..., 0, :, :]


def periodic_cost(Ad, Bd, Q, R, *, tol=1e-11, max_doublings=60):
    """Periodic cost-to-go at the period start (the limit of repeated sweeps).

    Returns ``(P, doublings)``; the horizon behind P is ``2^doublings`` periods.
    """
    A, G, H = period_triple(Ad, Bd, Q, R)
    for k in range(1, max_doublings + 1):
        A, G, H_new = _compose((A, G, H), (A, G, H))
        change = np.abs(H_new - H).max() / np.abs(H_new).max()
        H = H_new
        if change < tol:
            return H, k
    raise GainschedError(f"periodic Riccati did not converge in {2**max_doublings} periods")


def dlqr(A, B, Q, R):
    """Infinite-horizon discrete LQR via scipy's DARE: returns ``K, S, E``."""
    S = solve_discrete_are(A, B, Q, R)
    K = np.linalg.solve(R + B.T @ S @ B, B.T @ S @ A)
    E = np.linalg.eigvals(A - B @ K)
    return K, S, E


def monodromy(Ad, Bd, K):
    """Closed-loop monodromy ``prod_k (A_k - B_k K_k)`` over one period, shape (*b, n, n)."""
    N = Ad.shape[-3]
    M = np.broadcast_to(np.eye(Ad.shape[-1]), Ad.shape[:-3] + Ad.shape[-2:]).copy()
    for k in range(N):
        M = (Ad[..., k, :, :] - Bd[..., k, :, :] @ K[..., k, :, :]) @ M
    return M


def spectral_radius(M):
    """Largest eigenvalue modulus of square matrices (..., n, n)."""
    return np.abs(np.linalg.eigvals(M)).max(-1)
