"""The LQR system of a circle at every control step: exact at a few azimuths, carried to
all N steps by trigonometric interpolation.

The nominal, and hence every entry of the discrete system ``(A_k, B_k)``, is an analytic
periodic function of the azimuth, so its Fourier series converges exponentially:
:func:`discrete_system` computes the exact (complex-step) Jacobians and their exact
zero-order-hold discretisation at ``M`` equally spaced azimuths (64-128 on the paper
grid) and interpolates them to the N steps with :func:`periodic_interp`, checked to
:data:`LIN_TOL` (docs/performance.md).
"""

from __future__ import annotations

import numpy as np

from .linearize import discretize, jacobians, lqr_system
from .nominal import circle_is_rough, circle_nominal

__all__ = ["LIN_TOL", "discrete_system", "periodic_interp"]

#: relative accuracy demanded of the interpolated linearisation (see discrete_system)
LIN_TOL = 1e-10


def _discrete_at(model, speed, tilts, n, dt, odd=False):
    """Zero-order-hold LQR system at ``n`` equally spaced steps of the circle, all tilts;
    with ``odd`` at the odd ones alone (those the ``n / 2`` steps lack)."""
    zs, us = [], []
    pick = slice(1, None, 2) if odd else slice(None)
    for a in tilts:
        nom = circle_nominal(model, speed, a, n)
        zs.append(nom.z[pick])
        us.append(nom.u[pick])
    A, B = jacobians(model, np.stack(zs), np.stack(us), np.asarray(tilts)[:, None])
    return discretize(*lqr_system(A, B, model.config.control.integrators), dt)


def _rel_err(X, Y, offset=None):
    scale = np.abs(Y if offset is None else Y - offset).max()
    return np.abs(X - Y).max() / scale if scale > 0 else np.abs(X - Y).max()


def periodic_interp(X, N):
    """Trigonometric interpolation of M equally spaced samples of periodic functions to N.

    The same interpolant as ``scipy.signal.resample(X, N, axis=1)`` (for even M < N:
    the Nyquist term split evenly between +M/2 and -M/2), evaluated as one matrix
    product of the N x M basis ``cos(j theta_k), sin(j theta_k)`` with the Fourier
    coefficients. The FFT of length N that resample does costs more than the product
    at every control rate tried and grows faster than N when N has large prime
    factors (N is the step count per period, not a chosen length); the product is
    linear in N. Angles are reduced exactly in integers (``j k mod N``), so the basis
    is accurate to rounding.

    Parameters
    ----------
    X : ndarray, shape (b, M, ...)   samples at azimuths 2 pi m / M, M even
    N : int   number of output samples, N > M

    Returns
    -------
    ndarray, shape (b, N, ...)   values at azimuths 2 pi k / N (a view; the steps are the
        slowest axis in memory, the points next: each step's blocks are contiguous)
    """
    b, M = X.shape[:2]
    h = M // 2
    Y = np.moveaxis(X, 1, 0).reshape(M, -1)
    F = np.fft.rfft(Y, axis=0) / M  # (h + 1, R)
    coef = np.concatenate([F[:1].real, 2.0 * F[1:h].real, F[h:].real, -2.0 * F[1:h].imag])
    r = (np.arange(N)[:, None] * np.arange(h + 1)[None, :]) % N  # j k mod N, exact
    angle = 2.0 * np.pi / N * np.arange(N)
    basis = np.concatenate([np.cos(angle)[r], np.sin(angle)[r[:, 1:h]]], axis=1)
    out = (basis @ coef).reshape((N, b) + X.shape[2:])
    return np.moveaxis(out, 0, 1)


def discrete_system(model, speed, tilts, N, dt, *, tol=LIN_TOL, m0=32):
    """``(A_d, B_d)`` of the LQR system at the N control steps of one period (batched).

    The nominal, and hence every entry of A_k and B_k, is an analytic periodic
    function of the azimuth, so its Fourier series converges exponentially: the
    exact (complex-step) Jacobians and their exact discretisation are computed at
    ``M`` equally spaced azimuths and carried to the N steps by trigonometric
    interpolation (:func:`periodic_interp`). M doubles from ``m0`` until the
    interpolation from M/2 samples reproduces the M samples to ``tol`` (relative to
    ``|A_d - I|`` and ``|B_d|``); the M-sample interpolation is then used, whose error
    is smaller still. On the paper grid M = 64 gives 2e-15. With ``N <= M`` the
    steps are computed directly, and so are those of tilts whose nominal is not smooth at
    the trim's resolution (:func:`~gainsched.schedule.nominal.circle_is_rough`: its
    series would not converge before M reaches N).

    Returns
    -------
    A_d : ndarray (n_a, N, n, n); B_d : ndarray (n_a, N, n, 4); M : int (N if direct);
    err : float   the last interpolation check (0 if direct); M and err are arrays (n_a,)
        when some tilts were computed directly and others not
    """
    rough = np.array([N > 2 * m0 and circle_is_rough(model, speed, a, N) for a in tilts])
    if rough.any() and not rough.all():  # each part its own way, put back in tilt order
        smooth, direct = (discrete_system(model, speed, np.asarray(tilts)[p], N, dt, tol=tol,
                                          m0=m0) for p in (~rough, rough))
        Ad, Bd = (np.empty((rough.size,) + x.shape[1:]) for x in direct[:2])
        Ad[~rough], Ad[rough], Bd[~rough], Bd[rough] = smooth[0], direct[0], smooth[1], direct[1]
        return Ad, Bd, np.where(rough, N, smooth[2]), np.where(rough, 0.0, smooth[3])
    if N <= 2 * m0 or rough.all():
        Ad, Bd = _discrete_at(model, speed, tilts, N, dt)
        return Ad, Bd, N, 0.0
    # [A_d | B_d] side by side, so that one interpolation carries both
    M = m0
    AB_M = np.concatenate(_discrete_at(model, speed, tilts, M, dt), axis=-1)
    n = AB_M.shape[-2]
    I = np.eye(n)
    while True:
        if 2 * M >= N:
            Ad, Bd = _discrete_at(model, speed, tilts, N, dt)
            return Ad, Bd, N, 0.0
        # the even steps of 2M are the M steps: only the odd ones are new (every step is
        # linearised and discretised on its own, so the bits are those of all 2M at once)
        AB_2M = np.empty((AB_M.shape[0], 2 * M) + AB_M.shape[2:])
        AB_2M[:, 0::2] = AB_M
        AB_2M[:, 1::2] = np.concatenate(_discrete_at(model, speed, tilts, 2 * M, dt, odd=True),
                                        axis=-1)
        AB = periodic_interp(AB_M, 2 * M)
        err = max(_rel_err(AB[..., :n], AB_2M[..., :n], I),
                  _rel_err(AB[..., n:], AB_2M[..., n:]))
        M, AB_M = 2 * M, AB_2M
        if err <= tol:
            AB = periodic_interp(AB_M, N)
            return AB[..., :n], AB[..., n:], M, err
