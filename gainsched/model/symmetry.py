"""Exact symmetries of the scheduled problem (paper Sec. IV.C; derivation in
``docs/symmetry.md``).

S1, tilt sign: ``R_IC(-a, g) = R_IC(a, g + pi) Rz(pi)``, so the circle frame of
tilt -a is the frame of tilt a (at another, irrelevant, gamma) turned by pi
about its own z axis: azimuth xi there is xi + pi here, with every other state
unchanged. ``K(xi, xi', -a) = K(xi + pi, xi', a)``.

S2, direction: the mirror ``M = diag(-1, 1, 1)`` in C with the body mirror
``N = diag(1, -1, 1)`` keeps gravity, maps ``R_CB -> M R_CB N`` (a rotation) and
the attachment point at xi to pi - xi. In Euler angles ``psi -> pi - psi``,
``phi -> -phi``, ``theta -> theta``, hence ``chi -> -chi``; body rates
``omega -> -N omega = (-wx, wy, -wz)``. The mirrored X-quad is the same vehicle
with motors 1<->4 and 2<->3 (positions mirror in y, spin directions reverse).
So ``K(pi - xi, -xi', a) = P_u K(xi, xi', a) P_x`` with the signed state
permutation ``P_x`` and the motor permutation ``P_u`` (both involutions).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import block_diag

__all__ = [
    "P_U",
    "STATE_SIGNS",
    "state_mirror",
    "mirror_gain",
    "mirror_state",
    "fundamental_from_query",
]

P_U = np.eye(4)[[3, 2, 1, 0]]
#: signs of the 11 LQR state errors under S2
#: (delta, xi, delta', xi', phi, theta, chi, wx, wy, wz, int delta)
STATE_SIGNS = np.array([1, -1, 1, -1, -1, 1, -1, -1, 1, -1, 1], dtype=float)


def state_mirror(effects=()) -> np.ndarray:
    """``P_x``: the S2 map of the LQR state (11 entries plus effect states), shape (n, n)."""
    blocks = [np.diag(STATE_SIGNS)] + [e.mirror() for e in effects if e.n_states]
    return block_diag(*blocks)


def mirror_gain(K, P_x=None):
    """S2 applied to gains ``K`` (..., 4, n): ``P_u K P_x``. Applied twice: the identity."""
    P_x = np.diag(STATE_SIGNS) if P_x is None else P_x
    return P_U @ K @ P_x


def mirror_state(z):
    """S2 applied to absolute reduced states (..., 10): xi -> pi - xi, signs as STATE_SIGNS."""
    out = z * STATE_SIGNS[:10]
    out[..., 1] = np.pi - z[..., 1]
    return out


def fundamental_from_query(xi, xi_dot, alpha):
    """Map queries to the stored domain (alpha >= 0, xi_dot > 0) with S1 and S2.

    Parameters
    ----------
    xi : ndarray, rad; xi_dot : ndarray, rad/s; alpha : ndarray, rad

    Returns
    -------
    xi_f : ndarray, rad in [0, 2 pi); xi_dot_f, alpha_f : ndarray; mirrored : bool ndarray
        When ``mirrored`` the stored K, u_d, phi_d map back as
        ``P_u K P_x``, ``P_u u_d``, ``-phi_d``.
    """
    xi = np.asarray(xi, dtype=float)
    xi_dot = np.asarray(xi_dot, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    neg = alpha < 0
    xi = np.where(neg, xi + np.pi, xi)  # S1
    alpha = np.abs(alpha)
    mirrored = xi_dot < 0
    xi = np.where(mirrored, np.pi - xi, xi)  # S2
    return np.mod(xi, 2 * np.pi), np.abs(xi_dot), alpha, mirrored
