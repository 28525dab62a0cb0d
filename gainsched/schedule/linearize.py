"""Linearisation along the nominal and zero-order-hold discretisation (paper Sec. IV.B).

Jacobians are exact: complex-step differentiation of the batched model
(``f(z + i h e_j)`` has imaginary part ``h df/dz_j`` to rounding, no
subtractive cancellation). The LQR state appends the integral states after the
ten reduced states: the delta error's (paper Sec. IV.B) and, optionally, the
azimuth error's (the along-track integral); effect states follow.
"""

from __future__ import annotations

import numpy as np

from ..config import N_STATE
from ..constants import COMPLEX_STEP, INTEGRATORS, REDUCED_NAMES

__all__ = [
    "jacobians",
    "lqr_system",
    "discretize",
    "expm_batched",
    "lqr_state_names",
    "STATE_NAMES",
    "REDUCED_NAMES",
    "INPUT_NAMES",
]

#: the paper's LQR state (reduced state and the delta integral)
STATE_NAMES = REDUCED_NAMES + ("int_delta",)
INPUT_NAMES = ("T1", "T2", "T3", "T4")


def jacobians(model, z, u, alpha, thrust=None):
    """Exact ``A = df/dz`` and ``B = df/du`` by complex steps; with the actual thrusts
    ``thrust`` the model at given thrusts (:meth:`~gainsched.model.reduced.Model.evaluate`)
    and also ``B_F = df/dF``.

    Parameters
    ----------
    z : ndarray, shape (..., n_z); u : ndarray, shape (..., 4), N; alpha : float or ndarray, rad
    thrust : ndarray, shape (..., 4), N, optional

    Returns
    -------
    A : ndarray, shape (..., n_z, n_z); B : ndarray, shape (..., n_z, 4)
    B_F : ndarray, shape (..., n_z, 4), only with ``thrust``
    """
    z = np.asarray(z, dtype=float)
    u = np.asarray(u, dtype=float)
    given = thrust is not None
    n_z = z.shape[-1]
    shape = np.broadcast_shapes(z.shape[:-1], u.shape[:-1], *(
        (np.shape(thrust)[:-1],) if given else ()))
    # one batched evaluation for all perturbation directions: axis -2 enumerates them
    k = n_z + (8 if given else 4)
    E = np.eye(k) * (1j * COMPLEX_STEP)
    zc = np.broadcast_to(z[..., None, :], shape + (k, n_z)) + E[:, :n_z]
    uc = np.broadcast_to(u[..., None, :], shape + (k, 4)) + E[:, n_z:n_z + 4]
    Fc = np.broadcast_to(thrust[..., None, :], shape + (k, 4)) + E[:, n_z + 4:] if given else None
    a = np.asarray(alpha)[..., None] if np.ndim(alpha) else alpha
    J = np.imag(model.evaluate(zc, uc, a, thrust=Fc).z_dot) / COMPLEX_STEP  # row j = d f / d x_j
    J = np.swapaxes(J, -1, -2)
    return (J[..., :n_z], J[..., n_z:n_z + 4]) + ((J[..., n_z + 4:],) if given else ())


def lqr_system(A, B, integrators=("int_delta",)):
    """Augment with the integral states: LQR state ``(s[0:10], integrals, effect states)``.

    Parameters
    ----------
    A : ndarray, shape (..., n_z, n_z); B : ndarray, shape (..., n_z, 4)
        Continuous-time Jacobians of the full state (reduced state, effect states).
    integrators : sequence of str
        Names from :data:`gainsched.constants.INTEGRATORS`, in that order: each adds a
        state whose rate is the error of the reduced state it integrates.

    Returns ``(A_x, B_x)`` of shapes (..., n, n) and (..., n, 4), n = n_z + len(integrators).
    """
    n_z, n_i = A.shape[-1], len(integrators)
    n = n_z + n_i
    idx = [i if i < N_STATE else i + n_i for i in range(n_z)]  # z index -> x index
    Ax = np.zeros(A.shape[:-2] + (n, n))
    Bx = np.zeros(B.shape[:-2] + (n, B.shape[-1]))
    Ax[..., np.ix_(idx, idx)[0], np.ix_(idx, idx)[1]] = A
    Bx[..., idx, :] = B
    for j, name in enumerate(integrators):  # d/dt int(s_i - s_i,d) = s_i error
        Ax[..., N_STATE + j, INTEGRATORS[name]] = 1.0
    return Ax, Bx


def lqr_state_names(model, integrators=None):
    """Names of the LQR state entries: the reduced state, the integrals (default: the
    model's config's), the effect states."""
    if integrators is None:
        integrators = model.config.control.integrators
    extra = [f"{e.kind}_{i}" for e in model.effects for i in range(e.n_states)]
    return REDUCED_NAMES + tuple(integrators) + tuple(extra)


_TAYLOR_DEGREE = 14


def expm_batched(M):
    """Matrix exponential of a batch (..., n, n) by scaling and squaring a Taylor series.

    scipy.linalg.expm accepts batches but picks a Pade degree and scaling per
    matrix; one scaling for the whole batch keeps everything in a few batched
    matmuls (about 2x faster than scipy's batched expm on these 15 x 15 blocks,
    ``make bench``). With
    ``||M / 2^s||_1 <= 1/2`` the truncation error of degree 14 is below
    ``0.5^15 / 15! ~ 2e-17`` relative, i.e. rounding level (checked against
    scipy's expm in the tests).
    """
    norm = np.abs(M).sum(-2).max() if M.size else 0.0
    s = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0.5 else 0
    X = M / 2.0**s
    n = M.shape[-1]
    E = np.broadcast_to(np.eye(n), M.shape).copy()
    for k in range(_TAYLOR_DEGREE, 0, -1):  # Horner: I + X/1 (I + X/2 (I + ...))
        E = np.eye(n) + (X @ E) / k
    for _ in range(s):
        E = E @ E
    return E


def discretize(A, B, dt):
    """Zero-order hold: ``expm([[A, B], [0, 0]] dt)`` (batched, see :func:`expm_batched`).

    Returns ``(A_d, B_d)`` with the shapes of ``A`` and ``B``.
    """
    n, m = A.shape[-1], B.shape[-1]
    M = np.zeros(A.shape[:-2] + (n + m, n + m))
    M[..., :n, :n] = A * dt
    M[..., :n, n:] = B * dt
    E = expm_batched(M)
    return E[..., :n, :n], E[..., :n, n:]
