"""The nominal in closed form when every effect is a pure COG velocity drag.

Paper eqs. 15-18 with the eq. 17 typo corrected (the tangential-acceleration
term is ``r xi''``, not ``r xi'``): the roll carries the tangential force
balance, the tether the radial one, ``delta = pi/2``, ``theta = chi = 0``,
``psi = xi``. :func:`state_from_roll` is shared with the numerical trim
(:mod:`gainsched.schedule.trim`), which serves every other effect.
"""

from __future__ import annotations

import numpy as np

from ..config import N_STATE
from .path import AzimuthPath

__all__ = ["state_from_roll", "closed_form"]


def state_from_roll(path: AzimuthPath, phi, dphi, ddphi):
    """Nominal reduced state and its derivative from the path and the roll profile (eqs. 15-16)."""
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


def closed_form(model, path: AzimuthPath, alpha: float, D):
    """Closed-form roll, input and tension for drag-only effects (paper eqs. 15-18)."""
    m, g, r = model.m, model.g, model.r
    xi, (xd, xdd, xddd, xdddd) = path.xi, path.d
    sa, ca = np.sin(alpha), np.cos(alpha)
    v, vd, vdd = r * xd, r * xdd, r * xddd
    Dv, D1, D2 = D(v)
    # tangential balance T_C sin(phi) = -m N, normal T_C cos(phi) = m Dn
    N = r * xdd + g * sa * np.cos(xi) + Dv / m
    N1 = r * xddd - g * sa * np.sin(xi) * xd + D1 * vd / m
    N2 = r * xdddd - g * sa * (np.cos(xi) * xd**2 + np.sin(xi) * xdd) + (D2 * vd**2 + D1 * vdd) / m
    Dn = g * ca
    H = Dn**2 + N**2
    phi = np.arctan2(-N, Dn)
    dphi = -Dn * N1 / H
    ddphi = -Dn * (N2 * H - 2 * N * N1**2) / H**2
    s, sdot = state_from_roll(path, phi, dphi, ddphi)
    w, wd = s[:, 7:10], sdot[:, 7:10]
    J = model.J
    tau = wd @ J.T + np.cross(w, w @ J.T)  # tether torque is zero on the nominal (x_B || e)
    T_C = m * np.sqrt(H)
    u = np.concatenate([T_C[:, None], tau], -1) @ model.alloc_inv.T
    tension = m * r * xd**2 - m * g * sa * np.sin(xi)  # eq. 18
    return s, sdot, u, tension
