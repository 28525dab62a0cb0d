"""The bounded least-squares solver of the fits.

The weighted residual ``r`` of a candidate, linearised in a parameter step ``d``
(``r + J d``, ``J`` the forward-difference Jacobian), has per flight and axis the
quadratic form ``|r + J d|^2 = c + 2 b^T d + d^T A d``: :func:`_stats` gives
``(A, b, c)`` and :func:`_sq` ``c`` alone, to be summed over the flights a fit or a
leave-one-flight-out fold uses. :func:`_qp` minimises ``d^T A d + 2 b^T d`` inside the
parameter bounds ``lo <= d <= hi``: exactly, over every active set, for up to three
parameters; for more, bounded-variable least squares (BVLS: P. B. Stark and
R. L. Parker, "Bounded-variable least-squares: an algorithm and applications",
Computational Statistics 10, 1995; :func:`scipy.optimize.lsq_linear`) on the Cholesky
factor of ``A`` (:func:`_qp_bvls`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np


def _sq(vecs) -> np.ndarray:
    """Sum of squares per flight and axis, shape (n_flights, n_axes)."""
    return np.array([[float(np.sum(v * v)) for v in f.values()] for f in vecs])


def _stats(vecs, jac):
    """Per flight and axis: (A (k,k), b (k,), c) of ||r + J d||^2."""
    nf, na = len(vecs), len(vecs[0])
    k = len(jac)
    A = np.zeros((nf, na, k, k))
    b = np.zeros((nf, na, k))
    c = np.zeros((nf, na))
    for i, f in enumerate(vecs):
        for a_i, a in enumerate(f):
            r = f[a]
            c[i, a_i] = float(np.sum(r * r))
            for j in range(k):
                Jj = jac[j][i][a]
                b[i, a_i, j] = float(np.sum(Jj * r))
                for l in range(j, k):
                    A[i, a_i, j, l] = A[i, a_i, l, j] = float(np.sum(Jj * jac[l][i][a]))
    return A, b, c


def _qp(A, b, lo, hi):
    """argmin of d^T A d + 2 b^T d over lo <= d <= hi: exact active sets for k <= 3
    parameters, bounded least squares (BVLS) on the Cholesky factor for more."""
    k = b.size
    if k > 3:
        return _qp_bvls(A, b, lo, hi)
    best, best_val = None, math.inf
    Ar = A + 1e-12 * np.trace(A) / max(k, 1) * np.eye(k) + 1e-300 * np.eye(k)
    for pattern in itertools.product((0, 1, 2), repeat=k):  # free / at lo / at hi
        d = np.where(np.array(pattern) == 1, lo, np.where(np.array(pattern) == 2, hi, 0.0))
        free = np.array(pattern) == 0
        if free.any():
            rhs = -(b[free] + A[np.ix_(free, ~free)] @ d[~free])
            try:
                d[free] = np.linalg.solve(Ar[np.ix_(free, free)], rhs)
            except np.linalg.LinAlgError:
                continue
        if np.any(d < lo - 1e-15 * (1 + abs(lo))) or np.any(d > hi + 1e-15 * (1 + abs(hi))):
            continue
        val = float(d @ A @ d + 2 * b @ d)
        if val < best_val:
            best, best_val = d, val
    return (np.zeros(k) if best is None else best), (0.0 if best is None else best_val)


def _qp_bvls(A, b, lo, hi):
    """:func:`_qp` for many parameters: ``d^T A d + 2 b^T d = |L^T d + L^-1 b|^2 -
    |L^-1 b|^2`` with ``A = L L^T``, minimised by scipy's bounded-variable least squares."""
    from scipy.linalg import cho_factor, solve_triangular
    from scipy.optimize import lsq_linear

    k = b.size
    Ar = A + (1e-12 * np.trace(A) / k + 1e-300) * np.eye(k)
    L = cho_factor(Ar, lower=True)[0]
    L = np.tril(L)
    y = solve_triangular(L, -b, lower=True)
    sol = lsq_linear(L.T, y, bounds=(lo, hi), method="bvls")
    d = np.clip(sol.x, lo, hi)
    return d, float(d @ A @ d + 2 * b @ d)
