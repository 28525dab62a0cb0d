"""The nominal in closed form when every effect is a pure COG velocity drag.

Paper eqs. 15-18 with the eq. 17 typo corrected (the tangential-acceleration
term is ``r xi''``, not ``r xi'``): the roll carries the tangential force
balance, the tether the radial one, ``delta = pi/2``, ``theta = chi = 0``,
``psi = xi``. :func:`state_from_roll` is shared with the numerical trim
(:mod:`gainsched.schedule.trim`), which serves every other effect.
"""

from __future__ import annotations

import numpy as np

from ..config import N_STATE, balance
from ..model.effects import polynomial_drag
from .path import AzimuthPath

# polynomial_drag: the drag law the closed form takes (re-exported for the firmware's
# feed-forward, which builds it from the table's drag coefficients, not from the model)
__all__ = ["state_from_roll", "state_from_attitude", "closed_form", "polynomial_drag"]


def state_from_roll(path: AzimuthPath, phi, dphi, ddphi):
    """Nominal reduced state and its derivative from the path and the roll profile (eqs. 15-16)."""
    return state_from_attitude(path, (phi, dphi, ddphi))


def _state_from_roll(path: AzimuthPath, phi, dphi, ddphi):
    """Eqs. 15-16 as written in the paper: :func:`state_from_attitude` without offsets.

    Kept in this operation order (not the general formula with zero offsets, which
    rounds differently in the last bit) so that tables stay byte-identical to those
    built before the offsets existed; tests/schedule/test_offsets.py holds the two equal.
    """
    n = path.t.shape[0]
    xd, xdd = path.d[0], path.d[1]
    sp, cp = np.sin(phi), np.cos(phi)
    s = np.zeros((n, N_STATE), dtype=np.result_type(phi, dphi, ddphi, float))
    s[:, 0] = np.pi / 2
    s[:, 1] = path.xi
    s[:, 3] = xd
    s[:, 4] = phi
    s[:, 7:10] = np.stack([dphi, xd * sp, xd * cp], -1)  # eq. 15
    sdot = np.zeros_like(s)
    sdot[:, 1] = xd
    sdot[:, 3] = xdd
    sdot[:, 4] = dphi
    sdot[:, 7:10] = np.stack(  # eq. 16
        [ddphi, xd * dphi * cp + xdd * sp, -xd * dphi * sp + xdd * cp], -1
    )
    return s, sdot


def state_from_attitude(path: AzimuthPath, roll, pitch=None, yaw=None):
    """Nominal reduced state and its derivative on the great circle (``delta = pi/2``)
    from the path and the attitude: roll ``phi``, pitch offset ``theta`` and yaw offset
    ``chi = psi - xi``, each given as ``(value, rate, acceleration)`` arrays (n,), rad,
    rad/s, rad/s^2 (None: zero).

    The body rates are the ZYX Euler kinematics of ``R_CB = Rz(xi + chi) Ry(theta)
    Rx(phi)`` (paper eq. 2)::

        wx = phi' - psi' sin(theta)
        wy = theta' cos(phi) + psi' cos(theta) sin(phi)
        wz = -theta' sin(phi) + psi' cos(theta) cos(phi)

    with ``psi' = xi' + chi'``; with ``theta = chi = 0`` they are paper eq. 15 and their
    derivative eq. 16.

    Returns ``s, s_dot``, shapes (n, 10).
    """
    n = path.t.shape[0]
    if pitch is None and yaw is None:
        return _state_from_roll(path, *roll)
    zero = (0.0, 0.0, 0.0)
    p, p1, p2 = roll
    th, th1, th2 = zero if pitch is None else pitch
    c, c1, c2 = zero if yaw is None else yaw
    xd, xdd = path.d[0], path.d[1]
    ps1, ps2 = xd + c1, xdd + c2  # psi = xi + chi
    sp, cp, st, ct = np.sin(p), np.cos(p), np.sin(th), np.cos(th)
    dtype = np.result_type(p, p1, p2, th, th1, th2, c, c1, c2, float)
    s = np.zeros((n, N_STATE), dtype=dtype)
    sdot = np.zeros_like(s)
    s[:, 0] = np.pi / 2
    s[:, 1] = path.xi
    s[:, 3] = xd
    s[:, 4], s[:, 5], s[:, 6] = p, th, c
    s[:, 7] = p1 - ps1 * st
    s[:, 8] = th1 * cp + ps1 * ct * sp
    s[:, 9] = -th1 * sp + ps1 * ct * cp
    sdot[:, 1] = xd
    sdot[:, 3] = xdd
    sdot[:, 4], sdot[:, 5], sdot[:, 6] = p1, th1, c1
    sdot[:, 7] = p2 - ps2 * st - ps1 * ct * th1
    sdot[:, 8] = (th2 * cp - th1 * sp * p1 + ps2 * ct * sp - ps1 * st * th1 * sp
                  + ps1 * ct * cp * p1)
    sdot[:, 9] = (-th2 * sp - th1 * cp * p1 + ps2 * ct * cp - ps1 * st * th1 * cp
                  - ps1 * ct * sp * p1)
    return s, sdot


def closed_form(model, path: AzimuthPath, alpha: float, D):
    """Closed-form roll, input and tension for drag-only effects (paper eqs. 15-18)."""
    m, g, r = model.m, model.g, model.r
    xi, (xd, xdd, xddd, xdddd) = path.xi, path.d
    sa, ca = np.sin(alpha), np.cos(alpha)
    v, vd, vdd = r * xd, r * xdd, r * xddd
    Dv, D1, D2 = D(v)
    # tangential balance T_C sin(phi) = -m N, normal T_C cos(phi) = m Dn (shared with the
    # config's plausibility check, gainsched.config.balance)
    N, Dn, H, tension = balance(m, g, r, sa, ca, xi, xd, xdd, Dv)
    N1 = r * xddd - g * sa * np.sin(xi) * xd + D1 * vd / m
    N2 = r * xdddd - g * sa * (np.cos(xi) * xd**2 + np.sin(xi) * xdd) + (D2 * vd**2 + D1 * vdd) / m
    phi = np.arctan2(-N, Dn)
    dphi = -Dn * N1 / H
    ddphi = -Dn * (N2 * H - 2 * N * N1**2) / H**2
    s, sdot = state_from_roll(path, phi, dphi, ddphi)
    w, wd = s[:, 7:10], sdot[:, 7:10]
    J = model.J
    tau = wd @ J.T + np.cross(w, w @ J.T)  # tether torque is zero on the nominal (x_B || e)
    T_C = m * np.sqrt(H)
    u = np.concatenate([T_C[:, None], tau], -1) @ model.alloc_inv.T
    return s, sdot, u, tension
