"""Geometry of the tethered vehicle, written once (docs/conventions.md).

The tether runs from the anchor (origin of the circle frame C) to the attachment
point ``p_t = rho e(delta, xi)``, with the unit direction

    e(delta, xi) = (sin delta cos xi, sin delta sin xi, cos delta)       (paper Sec. II)

The COG sits at ``p_q = p_t - R_CB p_e`` with ``p_e = (-L_e, 0, 0)`` in B (the
attachment ``L_e`` behind the COG). The reduced pose coordinates of a pose are the
spherical angles ``(delta, xi)`` of the attachment point and the Z-Y-X Euler angles
``(phi, theta, psi)`` of ``R_CB`` with ``chi = psi - xi`` (paper eq. 2).

The reduced model (:mod:`gainsched.model.reduced`), the maximal model
(:mod:`gainsched.model.maximal`), the model-versus-measurement comparison and the
simulator's pose sensor all call these functions. Everything broadcasts over
leading batch dimensions and is complex-step safe where the reduced model needs it
(:class:`TetherDirection`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._vec import dot, mv, stack3
from ..rotations import (
    euler_zyx_from_matrix,
    matrix_from_euler_zyx,
    matrix_from_euler_zyx_scalar,
)

__all__ = [
    "TetherDirection",
    "tether_direction",
    "spherical_from_point",
    "attachment_from_cog",
    "cog_from_attachment",
    "pose_angles_from_pose",
    "pose_from_reduced",
    "wrap_angle",
]


def wrap_angle(a):
    """Angle ``a`` (rad) wrapped to [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


@dataclass(frozen=True)
class TetherDirection:
    """The tether direction ``e(delta, xi)`` in C and its partial derivatives.

    All attributes have shape (..., 3) and are dimensionless; ``e_delta_delta = -e``.

    Attributes
    ----------
    e : ndarray
        ``(sin delta cos xi, sin delta sin xi, cos delta)``.
    e_delta, e_xi : ndarray
        ``de/ddelta``, ``de/dxi``.
    e_delta_xi, e_xi_xi : ndarray
        ``d2e/(ddelta dxi)``, ``d2e/dxi2``.
    """

    e: np.ndarray
    e_delta: np.ndarray
    e_xi: np.ndarray
    e_delta_xi: np.ndarray
    e_xi_xi: np.ndarray

    def rate(self, delta_dot, xi_dot):
        """``e' = e_delta delta' + e_xi xi'``, shape (..., 3), 1/s; rates in rad/s."""
        return self.e_delta * delta_dot[..., None] + self.e_xi * xi_dot[..., None]

    def velocity_products(self, delta_dot, xi_dot):
        """The part of ``e''`` without angular accelerations, shape (..., 3), 1/s^2:
        ``-e delta'^2 + 2 e_delta_xi delta' xi' + e_xi_xi xi'^2`` (rates in rad/s)."""
        return (
            -self.e * (delta_dot * delta_dot)[..., None]
            + 2 * self.e_delta_xi * (delta_dot * xi_dot)[..., None]
            + self.e_xi_xi * (xi_dot * xi_dot)[..., None]
        )

    def acceleration(self, delta_dot, xi_dot, delta_ddot, xi_ddot):
        """``e''``, shape (..., 3), 1/s^2, from the angular rates (rad/s) and
        accelerations (rad/s^2)."""
        return (
            self.e_delta * delta_ddot[..., None]
            + self.e_xi * xi_ddot[..., None]
            + self.velocity_products(delta_dot, xi_dot)
        )


def tether_direction(delta, xi) -> TetherDirection:
    """:class:`TetherDirection` at polar angle ``delta`` and azimuth ``xi``.

    Parameters
    ----------
    delta, xi : ndarray, shape (...), rad
        Broadcastable; real or complex (complex-step derivatives).

    Example
    -------
    >>> import numpy as np
    >>> d = tether_direction(np.array(np.pi / 2), np.array(0.0))
    >>> np.round(d.e, 12).tolist(), np.round(d.e_xi, 12).tolist()
    ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    """
    sd, cd, sx, cx = np.sin(delta), np.cos(delta), np.sin(xi), np.cos(xi)
    if np.ndim(sd) == 0 and np.ndim(sx) == 0 and np.result_type(sd, sx) == np.float64:
        # one real direction (the per-step plants): the same products, without the
        # stacking overhead (bit for bit the batched values)
        sd, cd, sx, cx = float(sd), float(cd), float(sx), float(cx)
        return TetherDirection(
            e=np.array([sd * cx, sd * sx, cd]),
            e_delta=np.array([cd * cx, cd * sx, -sd]),
            e_xi=np.array([-sd * sx, sd * cx, 0.0]),
            e_delta_xi=np.array([-cd * sx, cd * cx, 0.0]),
            e_xi_xi=np.array([-sd * cx, -sd * sx, 0.0]),
        )
    return TetherDirection(
        e=stack3(sd * cx, sd * sx, cd),
        e_delta=stack3(cd * cx, cd * sx, -sd),
        e_xi=stack3(-sd * sx, sd * cx, 0.0),
        e_delta_xi=stack3(-cd * sx, cd * cx, 0.0),
        e_xi_xi=stack3(-sd * cx, -sd * sx, 0.0),
    )


def spherical_from_point(p):
    """Distance and spherical angles of points ``p`` (..., 3), m, in C.

    Returns
    -------
    dist : ndarray, shape (...), m
    delta : ndarray, shape (...), rad in [0, pi]
        Angle from the C z axis.
    xi : ndarray, shape (...), rad in (-pi, pi]
        Azimuth from the C x axis.
    """
    p = np.asarray(p, dtype=float)
    dist = np.sqrt(dot(p, p))
    delta = np.arctan2(np.hypot(p[..., 0], p[..., 1]), p[..., 2])
    xi = np.arctan2(p[..., 1], p[..., 0])
    return dist, delta, xi


def attachment_from_cog(p_q, R_CB, p_e):
    """Attachment point ``p_t = p_q + R_CB p_e`` (..., 3), m, in C.

    Parameters
    ----------
    p_q : ndarray, shape (..., 3), m
        COG position in C.
    R_CB : ndarray, shape (..., 3, 3)
        Body-to-circle rotation.
    p_e : ndarray, shape (3,), m
        Attachment point in B relative to the COG, ``(-L_e, 0, 0)``.
    """
    return p_q + mv(R_CB, p_e)


def cog_from_attachment(p_t, R_CB, p_e):
    """COG position ``p_q = p_t - R_CB p_e`` (..., 3), m, in C (inverse of
    :func:`attachment_from_cog`)."""
    return p_t - mv(R_CB, p_e)


def pose_angles_from_pose(p_q, R_CB, p_e, xi_ref=None):
    """Reduced pose angles of COG positions and attitudes in C.

    Parameters
    ----------
    p_q : ndarray, shape (..., 3), m
        COG position in C.
    R_CB : ndarray, shape (..., 3, 3)
        Body-to-circle rotation.
    p_e : ndarray, shape (3,), m
        Attachment point in B relative to the COG.
    xi_ref : ndarray or float, rad, optional
        When given, ``xi`` is put on the branch (xi + 2 pi k) nearest to it.

    Returns
    -------
    dist : ndarray, shape (...), m
        Distance of the attachment point from the anchor.
    angles : ndarray, shape (..., 5), rad
        ``(delta, xi, phi, theta, chi)``: ``xi`` in (-pi, pi] unless ``xi_ref``,
        ``chi = psi - xi`` wrapped to [-pi, pi).
    """
    if np.ndim(p_q) == 1 and np.ndim(R_CB) == 2 and xi_ref is not None:
        return _pose_angles_one(p_q, R_CB, p_e, float(xi_ref))
    dist, delta, xi = spherical_from_point(attachment_from_cog(p_q, R_CB, p_e))
    if xi_ref is not None:
        xi = xi + 2 * np.pi * np.round((np.asarray(xi_ref) - xi) / (2 * np.pi))
    phi, theta, psi = euler_zyx_from_matrix(R_CB)
    return dist, np.stack([delta, xi, phi, theta, wrap_angle(psi - xi)], -1)


def pose_from_reduced(z, rho, p_e):
    """COG position and attitude of reduced states (inverse of :func:`pose_angles_from_pose`).

    Parameters
    ----------
    z : ndarray, shape (..., >= 7)
        ``(delta, xi, delta', xi', phi, theta, chi, ...)``, rad (rates unused).
    rho : float, m
        Distance of the attachment point from the anchor (the tether length).
    p_e : ndarray, shape (3,), m
        Attachment point in B relative to the COG.

    Returns
    -------
    p_q : ndarray, shape (..., 3), m
        COG position in C, ``rho e(delta, xi) - R_CB p_e``.
    R_CB : ndarray, shape (..., 3, 3)
        ``Rz(chi + xi) Ry(theta) Rx(phi)`` (paper eq. 2).
    """
    z = np.asarray(z)
    if z.ndim == 1 and not np.iscomplexobj(z):
        return _pose_from_reduced_one(z, rho, p_e)
    R = matrix_from_euler_zyx(z[..., 4], z[..., 5], z[..., 6] + z[..., 1])
    return cog_from_attachment(rho * tether_direction(z[..., 0], z[..., 1]).e, R, p_e), R


# One-sample forms of the two pose conversions, in scalar math: the simulator's pose
# sensor calls them once per sample, where numpy's per-operation overhead (~80 us per
# call for the batched forms) would cost more than the plant step. Same formulas;
# tests/model/test_geometry.py checks them against the batched forms.


def _pose_from_reduced_one(z, rho, p_e):
    R = matrix_from_euler_zyx_scalar(z[4], z[5], z[6] + z[1])
    sd = math.sin(z[0])
    p_t = rho * np.array([sd * math.cos(z[1]), sd * math.sin(z[1]), math.cos(z[0])])
    return p_t - R @ p_e, R


def _pose_angles_one(p_q, R_CB, p_e, xi_ref):
    p_t = p_q + R_CB @ p_e
    dist = math.sqrt(p_t[0] ** 2 + p_t[1] ** 2 + p_t[2] ** 2)
    delta = math.atan2(math.hypot(p_t[0], p_t[1]), p_t[2])
    xi = math.atan2(p_t[1], p_t[0])
    xi = xi + 2 * math.pi * round((xi_ref - xi) / (2 * math.pi))
    phi = math.atan2(R_CB[2, 1], R_CB[2, 2])
    theta = math.asin(min(max(-R_CB[2, 0], -1.0), 1.0))
    psi = math.atan2(R_CB[1, 0], R_CB[0, 0])
    return dist, np.array([delta, xi, phi, theta, wrap_angle(psi - xi)])
