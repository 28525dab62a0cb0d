"""Rotation matrices, Euler angles and quaternions (conventions: docs/conventions.md).

Conventions: ``R_AB`` maps B-coordinates to A-coordinates. Euler angles are
Z-Y-X (``R_CB = Rz(psi) @ Ry(theta) @ Rx(phi)``, paper eq. 2). Quaternions are
Hamilton, scalar first ``(w, x, y, z)``. Every function broadcasts over leading
batch dimensions and is complex-step safe (no ``abs``, no ``conj``).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ._vec import stack3

__all__ = [
    "Rx",
    "Ry",
    "Rz",
    "matrix_from_euler_zyx",
    "matrix_from_euler_zyx_scalar",
    "matrix_entries_from_quaternion",
    "euler_zyx_from_matrix",
    "matrix_from_quaternion",
    "quaternion_from_matrix",
    "skew",
    "euler_zyx_rates_from_body_rates",
    "R_IC_from_tilt",
    "up_C_from_tilt",
]


def _stack3x3(a00, a01, a02, a10, a11, a12, a20, a21, a22):
    """The (..., 3, 3) matrices of nine broadcastable entries, row by row (assigned into
    one array: ``np.stack`` of rows costs ~10 us a call in its Python wrapper)."""
    entries = (a00, a01, a02, a10, a11, a12, a20, a21, a22)
    shape = np.broadcast_shapes(*(np.shape(a) for a in entries))
    out = np.empty(shape + (9,), dtype=np.result_type(*entries))
    for k, a in enumerate(entries):
        out[..., k] = a
    return out.reshape(shape + (3, 3))


def Rx(a):
    """Rotation about x by angle ``a`` (rad, any shape) -> shape ``a.shape + (3, 3)``."""
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(c), np.zeros_like(c)
    return _stack3x3(o, z, z, z, c, -s, z, s, c)


def Ry(a):
    """Rotation about y by angle ``a`` (rad) -> shape ``a.shape + (3, 3)``."""
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(c), np.zeros_like(c)
    return _stack3x3(c, z, s, z, o, z, -s, z, c)


def Rz(a):
    """Rotation about z by angle ``a`` (rad) -> shape ``a.shape + (3, 3)``."""
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(c), np.zeros_like(c)
    return _stack3x3(c, -s, z, s, c, z, z, z, o)


def _euler_zyx_entries(cph, sph, cth, sth, cps, sps):
    """The nine entries of ``Rz(psi) Ry(theta) Rx(phi)`` from the angles' cosines and
    sines, row by row (scalars or arrays alike: one formula, so the batched and the
    scalar forms give the same bits)."""
    return (
        cps * cth, -sps * cph + cps * sth * sph, sps * sph + cps * sth * cph,
        sps * cth, cps * cph + sps * sth * sph, -cps * sph + sps * sth * cph,
        -sth, cth * sph, cth * cph,
    )


def matrix_from_euler_zyx(phi, theta, psi):
    """``R = Rz(psi) @ Ry(theta) @ Rx(phi)`` (paper eq. 2); angles in rad, broadcastable,
    real or complex -> shape (..., 3, 3).

    The product written out, in the same operations as
    :func:`matrix_from_euler_zyx_scalar`: a stacked matrix product costs ~5x more on the
    model's batches (and goes through BLAS, whose kernels round differently).

    Example
    -------
    >>> R = matrix_from_euler_zyx(np.array([0.3]), np.array([-0.2]), np.array([1.1]))
    >>> bool(np.allclose(R[0], Rz(1.1) @ Ry(-0.2) @ Rx(0.3), rtol=0, atol=1e-15))
    True
    """
    return _stack3x3(*_euler_zyx_entries(np.cos(phi), np.sin(phi), np.cos(theta),
                                         np.sin(theta), np.cos(psi), np.sin(psi)))


def matrix_from_euler_zyx_scalar(phi: float, theta: float, psi: float) -> np.ndarray:
    """:func:`matrix_from_euler_zyx` of three real scalars (rad), shape (3, 3).

    The one-sample form for per-step code (the simulator's sensors): scalar math
    costs ~2 us where the batched form spends ~50 us in numpy's per-call overhead.
    ``matrix_from_euler_zyx_scalar(alpha, 0, gamma)`` is ``R_IC`` (paper eq. 1).
    """
    return np.array(_euler_zyx_entries(math.cos(phi), math.sin(phi), math.cos(theta),
                                       math.sin(theta), math.cos(psi), math.sin(psi))
                    ).reshape(3, 3)


def euler_zyx_from_matrix(R):
    """Inverse of :func:`matrix_from_euler_zyx` for ``|theta| < pi/2``.

    Returns ``(phi, theta, psi)`` in rad, each of shape ``R.shape[:-2]``.
    """
    phi = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    theta = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    psi = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return phi, theta, psi


def matrix_entries_from_quaternion(w, x, y, z):
    """The nine entries of the rotation matrix of a unit quaternion ``(w, x, y, z)``, row
    by row: ``R_00, R_01, .., R_22`` (scalars or arrays alike; the per-step simulators'
    scalar math takes them as Python floats).

    Examples
    --------
    >>> R = gs.rotations.matrix_entries_from_quaternion(np.cos(0.5), 0.0, 0.0, np.sin(0.5))
    >>> bool(np.allclose(np.reshape(R, (3, 3)), gs.rotations.Rz(1.0)))
    True
    """
    return (
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    )


def matrix_from_quaternion(q):
    """Rotation matrix from a unit quaternion ``q = (w, x, y, z)``, shape (..., 4).

    One real quaternion, shape (4,), takes scalar math (the per-step simulators: ~3 us
    where the batched form spends ~70 us in numpy's per-call overhead); the same
    operations in the same order, so the same bits.
    """
    if np.ndim(q) == 1 and np.asarray(q).dtype == np.float64:
        return np.array(matrix_entries_from_quaternion(*np.asarray(q).tolist())).reshape(3, 3)
    return _stack3x3(*matrix_entries_from_quaternion(*(q[..., i] for i in range(4))))


def quaternion_from_matrix(R):
    """Unit quaternion ``(w, x, y, z)`` with ``w >= 0`` from rotation matrices (..., 3, 3).

    Shepperd's method: pick the largest of the four squared components to
    avoid cancellation (numpy has no batched version of this).
    """
    R = np.asarray(R, dtype=float)
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    cand = np.stack(
        [tr, R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]], axis=-1
    )  # proportional to 4w^2-1, ...
    k = np.argmax(cand, axis=-1)
    q = np.empty(R.shape[:-2] + (4,))
    m = k == 0
    s = np.sqrt(1.0 + tr[m]) * 2
    q[m] = np.stack(
        [0.25 * s, (R[m, 2, 1] - R[m, 1, 2]) / s, (R[m, 0, 2] - R[m, 2, 0]) / s,
         (R[m, 1, 0] - R[m, 0, 1]) / s], axis=-1)
    m = k == 1
    s = np.sqrt(1.0 + R[m, 0, 0] - R[m, 1, 1] - R[m, 2, 2]) * 2
    q[m] = np.stack(
        [(R[m, 2, 1] - R[m, 1, 2]) / s, 0.25 * s, (R[m, 0, 1] + R[m, 1, 0]) / s,
         (R[m, 0, 2] + R[m, 2, 0]) / s], axis=-1)
    m = k == 2
    s = np.sqrt(1.0 + R[m, 1, 1] - R[m, 0, 0] - R[m, 2, 2]) * 2
    q[m] = np.stack(
        [(R[m, 0, 2] - R[m, 2, 0]) / s, (R[m, 0, 1] + R[m, 1, 0]) / s, 0.25 * s,
         (R[m, 1, 2] + R[m, 2, 1]) / s], axis=-1)
    m = k == 3
    s = np.sqrt(1.0 + R[m, 2, 2] - R[m, 0, 0] - R[m, 1, 1]) * 2
    q[m] = np.stack(
        [(R[m, 1, 0] - R[m, 0, 1]) / s, (R[m, 0, 2] + R[m, 2, 0]) / s,
         (R[m, 1, 2] + R[m, 2, 1]) / s, 0.25 * s], axis=-1)
    return np.where(q[..., :1] < 0, -q, q)


def quaternion_from_matrix_scalar(R) -> np.ndarray:
    """:func:`quaternion_from_matrix` of one rotation matrix (3, 3) in scalar math (the
    one-sample form for per-step code: ~3 us where the batched form spends ~120 us)."""
    r = np.asarray(R, dtype=float).tolist()
    tr = r[0][0] + r[1][1] + r[2][2]
    k = max(range(4), key=(tr, r[0][0], r[1][1], r[2][2]).__getitem__)  # first largest
    if k == 0:
        s = math.sqrt(1.0 + tr) * 2
        q = (0.25 * s, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s)
    elif k == 1:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        q = ((r[2][1] - r[1][2]) / s, 0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s)
    elif k == 2:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        q = ((r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s)
    else:
        s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
        q = ((r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s)
    return -np.array(q) if q[0] < 0 else np.array(q)


def skew(v):
    """Cross-product matrix ``[v x]`` of vectors ``v``, shape (..., 3) -> (..., 3, 3)."""
    z = np.zeros_like(v[..., 0])
    return _stack3x3(z, -v[..., 2], v[..., 1], v[..., 2], z, -v[..., 0], -v[..., 1], v[..., 0], z)


def euler_zyx_rates_from_body_rates(phi, theta, omega_B):
    """Z-Y-X Euler angle rates ``(phi', theta', psi')`` from body rates.

    Parameters
    ----------
    phi, theta : ndarray, rad
    omega_B : ndarray, shape (..., 3), rad/s

    Returns
    -------
    ndarray, shape (..., 3), rad/s
    """
    wx, wy, wz = omega_B[..., 0], omega_B[..., 1], omega_B[..., 2]
    sp, cp = np.sin(phi), np.cos(phi)
    ct, tt = np.cos(theta), np.tan(theta)
    return stack3(wx + (sp * wy + cp * wz) * tt, cp * wy - sp * wz, (sp * wy + cp * wz) / ct)


def up_C_from_tilt(alpha_C):
    """The inertial up direction in the circle frame, ``R_IC^T (0, 0, 1) = (0, sin a,
    cos a)`` (independent of the heading gamma), shape alpha_C.shape + (3,).

    A real scalar tilt is looked up in a cache (read-only result): a flight or a circle
    asks for its one tilt at every step, and the batched form costs ~17 us a call.
    """
    if isinstance(alpha_C, (float, int, np.floating, np.integer)):
        return _up_C_one(float(alpha_C))
    return _up_C(alpha_C)


def _up_C(alpha_C):
    a = np.asarray(alpha_C)
    return np.stack([np.zeros_like(a, dtype=float), np.sin(a), np.cos(a)], axis=-1)


@lru_cache(maxsize=256)
def _up_C_one(alpha_C: float) -> np.ndarray:
    up = _up_C(alpha_C)
    up.setflags(write=False)
    return up


def R_IC_from_tilt(alpha_C, gamma_C=0.0):
    """Circle-to-inertial rotation ``R_IC = Rz(gamma_C) @ Rx(alpha_C)`` (paper eq. 1), rad."""
    return Rz(np.asarray(gamma_C, dtype=float)) @ Rx(np.asarray(alpha_C, dtype=float))
