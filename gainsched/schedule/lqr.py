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
  triples compose exactly, the period's triple comes from one sweep that folds
  the steps in (:func:`period_triple`), and composing the period triple with
  itself doubles the horizon (2^k periods after k doublings, quadratic
  convergence). One last ordinary sweep from the converged P gives the
  per-step gains and the closed-loop monodromy.
- ``"single-period"``: the paper's literal horizon of one period with ``Q_e = Q``.

The sweeps run in a compiled kernel (``c/riccati.c``, see :mod:`gainsched.native`)
when a C compiler is present, else in batched numpy doing the same recursion;
both give the same gains to rounding (checked in the tests).

Naming follows python-control: gains ``K``, Riccati solution ``S``, closed-loop
eigenvalues ``E``; ``u = u_d - K (x - x_d)``.
"""

from __future__ import annotations

import ctypes
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_are

from .. import native
from ..errors import GainschedError

__all__ = [
    "PeriodicLQR",
    "periodic_lqr",
    "periodic_cost",
    "period_triple",
    "riccati_sweep",
    "sweep",
    "RiccatiSweep",
    "native_available",
    "dlqr",
    "monodromy",
    "spectral_radius",
    "stability_scale",
]


@dataclass(frozen=True)
class PeriodicLQR:
    """Result of :func:`periodic_lqr` (batch shape ``b``).

    Attributes
    ----------
    K : ndarray, shape (*b, N_out, m, n)   gains at the requested steps (default: all N)
    S : ndarray, shape (*b, N_out (+1), n, n) or None   cost-to-go P_k at the same steps
        (``keep_S=True``; with all steps, P_N is appended)
    S0 : ndarray, shape (*b, n, n)   P at the period start
    sweeps : int   periods of horizon folded into the terminal cost (2^doublings; 0 for
        single-period), plus the final sweep
    Phi : ndarray, shape (*b, n, n)   closed-loop monodromy ``prod_k (A_k - B_k K_k)``
    """

    K: np.ndarray
    S: np.ndarray | None
    S0: np.ndarray
    sweeps: int
    Phi: np.ndarray


@dataclass(frozen=True)
class RiccatiSweep:
    """Result of :func:`sweep` (batch shape ``b``).

    P0 : (*b, n, n) cost-to-go at step 0; K : (*b, n_out, m, n) and S : (*b, n_out, n, n)
    at the requested steps (None if none); Phi, G : (*b, n, n) the accumulated period map
    (``triple=True``), else None.
    """

    P0: np.ndarray
    K: np.ndarray | None
    S: np.ndarray | None
    Phi: np.ndarray | None
    G: np.ndarray | None


def _kernel():
    return _configure(native.load("riccati"))


def _configure(lib):
    """Declare the C signatures of a loaded ``riccati`` library (None passes through)."""
    if lib is not None and not hasattr(lib, "_gs_ready"):
        dp = ctypes.POINTER(ctypes.c_double)
        lib.gs_riccati.restype = ctypes.c_int
        sp = ctypes.POINTER(ctypes.c_ssize_t)
        lib.gs_riccati.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_ssize_t,
                                   ctypes.c_ssize_t, ctypes.c_ssize_t, dp, sp, dp, sp, dp, dp,
                                   dp, ctypes.POINTER(ctypes.c_int), ctypes.c_int, dp, dp,
                                   ctypes.c_int, dp, dp]
        lib.gs_lanes.restype = ctypes.c_int
        lib._gs_ready = True
    return lib


def native_available() -> bool:
    """Whether the compiled Riccati kernel is in use (else the numpy recursion)."""
    return _kernel() is not None


def _ptr(x):
    return None if x is None else x.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _strides(X):
    """Element strides of a float64 array, as the kernel's ``ptrdiff_t[ndim]``."""
    return (ctypes.c_ssize_t * X.ndim)(*(s // X.itemsize for s in X.strides))


def _aligned(X):
    """X as float64 whose strides are whole elements (a copy only if they are not)."""
    X = np.asarray(X, dtype=float)
    return X if all(s % X.itemsize == 0 for s in X.strides) else np.ascontiguousarray(X)


def _sweep_native(lib, Ad, Bd, Q, R, P, slot, n_out, K, S, triple, Phi, G, threads):
    b, N, n, m = Bd.shape
    lanes = lib.gs_lanes()
    n_groups = -(-b // lanes)
    slot_p = None if slot is None else slot.ctypes.data_as(ctypes.POINTER(ctypes.c_int))
    args = (_ptr(Ad), _strides(Ad), _ptr(Bd), _strides(Bd), _ptr(Q), _ptr(R), _ptr(P), slot_p,
            n_out, _ptr(K), _ptr(S), int(triple), _ptr(Phi), _ptr(G))

    def run(g0, g1):  # ctypes releases the GIL: threads run in parallel
        if lib.gs_riccati(n, m, N, b, g0, g1, *args) != 0:
            raise GainschedError(f"Riccati kernel: size n={n}, m={m} beyond its limits")

    bounds = np.linspace(0, n_groups, min(threads, n_groups) + 1).round().astype(int)
    if len(bounds) <= 2:
        run(0, n_groups)
    else:
        with ThreadPoolExecutor(len(bounds) - 1) as ex:
            list(ex.map(run, bounds[:-1], bounds[1:]))


def _sweep_numpy(Ad, Bd, Q, R, P, slot, K, S, triple, Phi, G):
    """The recursion of ``c/riccati.c`` with batched numpy (the fallback)."""
    T = lambda X: np.swapaxes(X, -1, -2)  # noqa: E731
    for k in range(Ad.shape[1] - 1, -1, -1):
        A, B = Ad[:, k], Bd[:, k]
        PA = P @ A
        Rb = R + T(B) @ (P @ B)
        BtPA = T(B) @ PA
        Kk = np.linalg.solve(Rb, BtPA)
        if triple:
            V = Phi @ B
            G += V @ np.linalg.solve(Rb, T(V))
            G[:] = 0.5 * (G + T(G))
            Phi[:] = Phi @ (A - B @ Kk)
        P = Q + (T(A) @ PA - T(BtPA) @ Kk)  # = Q + A^T P (A - B K)
        P = 0.5 * (P + T(P))
        if slot is not None and slot[k] >= 0:
            if K is not None:
                K[:, slot[k]] = Kk
            if S is not None:
                S[:, slot[k]] = P
    return P


def sweep(Ad, Bd, Q, R, P, *, steps=None, keep_S=True, triple=False, threads=1,
          use_native=None) -> RiccatiSweep:
    """One backward Riccati sweep over k = N-1 .. 0 from the terminal cost P (batched).

    ``P <- Q + A_k^T P (A_k - B_k K_k)`` with ``K_k = (R + B_k^T P B_k)^-1 B_k^T P A_k``
    (paper eq. 23), computed as ``Q + (A_k^T P A_k - (B_k^T P A_k)^T K_k)``. With
    ``triple`` the sweep also accumulates the period map of the
    doubling algorithm (``Phi <- Phi Acl_k``, ``G <- G + Phi B_k Rb_k^-1 B_k^T Phi^T``
    from ``Phi = I, G = 0``): from ``P = 0`` that is the period triple, from the periodic
    P it is the closed-loop monodromy.

    Parameters
    ----------
    Ad : ndarray, shape (*b, N, n, n); Bd : ndarray, shape (*b, N, n, m)
    Q : ndarray, shape (n, n); R : ndarray, shape (m, m); P : ndarray, shape (*b, n, n)
    steps : sequence of int, optional
        Steps whose gains (and, with ``keep_S``, cost-to-go) are returned, in this order.
    threads : int
        Threads of the compiled kernel (points are split between them).
    use_native : bool, optional
        Force (True) or forbid (False) the compiled kernel; default: use it if available.
    """
    bshape = Ad.shape[:-3]
    N, n, m = Ad.shape[-3], Ad.shape[-1], Bd.shape[-1]
    # any layout (the kernel takes strides): grid.periodic_interp returns strided views
    Ad = _aligned(Ad).reshape(-1, N, n, n)
    Bd = _aligned(Bd).reshape(-1, N, n, m)
    b = Ad.shape[0]
    P = np.array(np.broadcast_to(P, bshape + (n, n)), dtype=float, order="C").reshape(b, n, n)
    Q = np.ascontiguousarray(Q, dtype=float)
    R = np.ascontiguousarray(R, dtype=float)
    slot = K = S = Phi = G = None
    n_out = 0
    if steps is not None:
        steps = np.asarray(steps, dtype=int)
        n_out = steps.size
        slot = np.full(N, -1, dtype=np.intc)
        if np.unique(steps).size != n_out:
            raise ValueError("steps must be distinct")
        slot[steps] = np.arange(n_out)
        K = np.empty((b, n_out, m, n))
        S = np.empty((b, n_out, n, n)) if keep_S else None
    if triple:
        Phi = np.broadcast_to(np.eye(n), (b, n, n)).copy()
        G = np.zeros((b, n, n))
    lib = _kernel() if use_native is not False else None
    if use_native and lib is None:
        raise GainschedError("the compiled Riccati kernel is not available")
    if lib is not None:
        _sweep_native(lib, Ad, Bd, Q, R, P, slot, n_out, K, S, triple, Phi, G, threads)
    else:
        P = _sweep_numpy(Ad, Bd, Q, R, P, slot, K, S, triple, Phi, G)
    shape = lambda X: None if X is None else X.reshape(bshape + X.shape[1:])  # noqa: E731
    return RiccatiSweep(shape(P), shape(K), shape(S), shape(Phi), shape(G))


def riccati_sweep(Ad, Bd, Q, R, P, *, keep=False, use_native=None):
    """One backward sweep from the terminal P, all steps kept (see :func:`sweep`).

    Returns
    -------
    P0 : ndarray (*b, n, n); K : ndarray (*b, N, m, n) or None; S : (*b, N+1, n, n) or None
    """
    N = Ad.shape[-3]
    sw = sweep(Ad, Bd, Q, R, P, steps=np.arange(N) if keep else None, use_native=use_native)
    if not keep:
        return sw.P0, None, None
    P_end = np.broadcast_to(P, sw.P0.shape)
    return sw.P0, sw.K, np.concatenate([sw.S, P_end[..., None, :, :]], axis=-3)


def periodic_lqr(Ad, Bd, Q, R, *, terminal="periodic", Q_e=None, tol=1e-11, max_sweeps=60,
                 keep_S=False, steps=None, threads=1, use_native=None) -> PeriodicLQR:
    """Finite-horizon LQR over one period with a periodic (or fixed) terminal cost.

    Parameters
    ----------
    Ad, Bd : ndarray, shapes (*b, N, n, n), (*b, N, n, m)
        Discrete system of the N steps of one period.
    Q, R : ndarray, shapes (n, n), (m, m)
        Stage weights (paper eq. 23-24).
    terminal : {"periodic", "single-period"}
    Q_e : ndarray, shape (n, n), optional
        Terminal weight for ``"single-period"`` (default Q).
    tol : float
        Relative change of P at the period start that ends the doubling.
    steps : sequence of int, optional
        Steps whose gains are returned (default all N); memory then does not grow with N.
    """
    Q_e = Q if Q_e is None else Q_e
    P = np.broadcast_to(Q_e, Ad.shape[:-3] + Q.shape)
    sweeps = 0
    kw = dict(threads=threads, use_native=use_native)
    if terminal == "periodic":
        P, doublings = periodic_cost(Ad, Bd, Q, R, tol=tol, max_doublings=max_sweeps, **kw)
        sweeps = 2**doublings
    elif terminal != "single-period":
        raise ValueError(f"unknown terminal cost {terminal!r}")
    all_steps = steps is None
    steps = np.arange(Ad.shape[-3]) if all_steps else steps
    sw = sweep(Ad, Bd, Q, R, P, steps=steps, keep_S=keep_S, triple=True, **kw)
    S = sw.S
    if keep_S and all_steps:
        S = np.concatenate([S, np.broadcast_to(P, sw.P0.shape)[..., None, :, :]], axis=-3)
    return PeriodicLQR(sw.K, S, sw.P0, sweeps + 1, sw.Phi)


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


def period_triple(Ad, Bd, Q, R, *, threads=1, use_native=None):
    """The Riccati map of a whole period as one triple ``(A, G, H)``.

    Folding the steps one at a time into the triple of the later steps is the
    composition rule of :func:`_compose` with a rank-m ``G_1 = B R^-1 B^T``, which
    reduces to a Riccati step from ``P = H`` (Woodbury): the period triple is one
    sweep from ``P = 0`` that also accumulates ``Phi`` and ``G`` (:func:`sweep`).
    """
    P0 = np.zeros(Ad.shape[:-3] + Q.shape)
    sw = sweep(Ad, Bd, Q, R, P0, triple=True, threads=threads, use_native=use_native)
    return sw.Phi, sw.G, sw.P0


def periodic_cost(Ad, Bd, Q, R, *, tol=1e-11, max_doublings=60, threads=1, use_native=None):
    """Periodic cost-to-go at the period start (the limit of repeated sweeps).

    Returns ``(P, doublings)``; the horizon behind P is ``2^doublings`` periods.
    """
    A, G, H = period_triple(Ad, Bd, Q, R, threads=threads, use_native=use_native)
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


def stability_scale(dt: float, max_time_constant_s: float | None) -> float:
    """The factor ``exp(dt / tau_max)`` that gives an LQR a prescribed degree of stability.

    Minimising the exponentially weighted cost ``sum exp(2 k dt / tau_max) (x_k^T Q x_k +
    u_k^T R u_k)`` is the ordinary LQR of the scaled system ``(c A_k, c B_k)`` with ``c =
    exp(dt / tau_max)`` (Anderson & Moore, *Optimal Control: Linear Quadratic Methods*,
    Prentice Hall 1990, the regulator with a prescribed degree of stability). Its
    gains stabilise the scaled loop, and the real loop's ``A_k - B_k K_k = (c A_k - c B_k
    K_k) / c``: over a period of N steps the real monodromy is ``c^-N`` times the scaled
    one, so every closed-loop mode has ``|lambda| < exp(-T / tau_max)``, a time constant
    below ``tau_max``, by construction.

    Parameters
    ----------
    dt : float
        Discretisation step, s.
    max_time_constant_s : float or None
        The bound ``tau_max``, s; None: no bound (factor 1).

    Returns
    -------
    float
        ``exp(dt / tau_max)``, or exactly 1.0 without a bound.
    """
    return 1.0 if max_time_constant_s is None else math.exp(dt / max_time_constant_s)


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
