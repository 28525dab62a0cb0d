"""Rotation matrices, Euler angles and quaternions: :mod:`gainsched.rotations`, re-exported.

The rotations are pure geometry, no vehicle in them: they live in the base layer so
that the firmware (which must not import the model, docs/architecture.md) takes the
same functions; the model modules keep importing them from here.
"""

from __future__ import annotations

from ..rotations import (
    R_IC_from_tilt,
    Rx,
    Ry,
    Rz,
    euler_zyx_from_matrix,
    euler_zyx_rates_from_body_rates,
    matrix_from_euler_zyx,
    matrix_from_euler_zyx_scalar,
    matrix_from_quaternion,
    quaternion_from_matrix,
    quaternion_from_matrix_scalar,
    skew,
    up_C_from_tilt,
)

__all__ = [
    "Rx",
    "Ry",
    "Rz",
    "matrix_from_euler_zyx",
    "matrix_from_euler_zyx_scalar",
    "euler_zyx_from_matrix",
    "matrix_from_quaternion",
    "quaternion_from_matrix",
    "quaternion_from_matrix_scalar",
    "skew",
    "euler_zyx_rates_from_body_rates",
    "R_IC_from_tilt",
    "up_C_from_tilt",
]
