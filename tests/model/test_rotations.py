"""Rotations (gainsched.rotations) against scipy.spatial.transform.Rotation.

Conventions (docs/conventions.md): ``R_CB = Rz(psi) Ry(theta) Rx(phi)`` (intrinsic
z-y-x), quaternions Hamilton, scalar first, rotating body vectors into I.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gainsched import rotations as rot

RNG = np.random.default_rng(13)
ANGLES = np.column_stack([RNG.uniform(-np.pi, np.pi, 200), RNG.uniform(-1.5, 1.5, 200),
                          RNG.uniform(-np.pi, np.pi, 200)])


def test_elementary_rotations_match_scipy():
    a = ANGLES[:, 0]
    for R, axis in ((rot.Rx, "x"), (rot.Ry, "y"), (rot.Rz, "z")):
        ref = Rotation.from_euler(axis, a[:, None]).as_matrix()
        np.testing.assert_allclose(R(a), ref, atol=1e-15)


def test_euler_zyx_matches_scipy_and_round_trips():
    phi, theta, psi = ANGLES.T
    R = rot.matrix_from_euler_zyx(phi, theta, psi)
    ref = Rotation.from_euler("ZYX", np.column_stack([psi, theta, phi])).as_matrix()
    np.testing.assert_allclose(R, ref, atol=1e-14)
    back = np.stack(rot.euler_zyx_from_matrix(R), -1)
    np.testing.assert_allclose(back, ANGLES, atol=1e-12)


def test_quaternion_matches_scipy_and_round_trips():
    R = Rotation.from_euler("ZYX", ANGLES[:, ::-1]).as_matrix()
    q = rot.quaternion_from_matrix(R)
    xyzw = Rotation.from_matrix(R).as_quat()
    ref = np.column_stack([xyzw[:, 3], xyzw[:, :3]])  # scalar first
    sign = np.sign(np.sum(q * ref, -1))[:, None]  # q and -q are one rotation
    np.testing.assert_allclose(q, sign * ref, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)
    np.testing.assert_allclose(rot.matrix_from_quaternion(q), R, atol=1e-14)


def test_skew_is_the_cross_product():
    a, b = RNG.normal(size=(2, 50, 3))
    np.testing.assert_allclose(rot.skew(a) @ b[..., None], np.cross(a, b)[..., None],
                               atol=1e-15)


def test_euler_rates_against_a_central_difference():
    """omega_B -> (phi', theta', psi'): integrate R' = R skew(omega_B) a small step and
    compare the change of the Euler angles (central difference, h = 1e-6 s)."""
    from scipy.linalg import expm

    phi, theta, psi = 0.3, -0.4, 1.1
    omega_B = np.array([0.7, -1.2, 2.0])  # rad/s
    R = rot.matrix_from_euler_zyx(phi, theta, psi)
    h = 1e-6
    ang = [np.array(rot.euler_zyx_from_matrix(R @ expm(s * h * rot.skew(omega_B))))
           for s in (1, -1)]
    fd = (ang[0] - ang[1]) / (2 * h)
    rates = rot.euler_zyx_rates_from_body_rates(phi, theta, omega_B)
    np.testing.assert_allclose(rates, fd, rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("tilt_deg, gamma_deg", [(0, 0), (20, 0), (40, 30)])
def test_circle_frame_is_Rz_Rx(tilt_deg, gamma_deg):
    a, g = np.deg2rad(tilt_deg), np.deg2rad(gamma_deg)
    ref = Rotation.from_euler("ZX", [g, a]).as_matrix()  # intrinsic: Rz(gamma) Rx(alpha)
    np.testing.assert_allclose(rot.R_IC_from_tilt(a, g), ref, atol=1e-15)
    # gravity in C is -g (0, sin alpha, cos alpha) (docs/conventions.md)
    np.testing.assert_allclose(rot.R_IC_from_tilt(a, g).T @ [0, 0, -1.0],
                               [0, -np.sin(a), -np.cos(a)], atol=1e-15)


def test_one_quaternion_takes_the_scalar_path_with_the_same_bits():
    """The one-sample form of matrix_from_quaternion (the per-step simulators) equals the
    batched form bit for bit, and a non-unit or complex quaternion keeps the batched path
    (complex steps)."""
    R = Rotation.from_euler("ZYX", ANGLES[:, ::-1]).as_matrix()
    q = rot.quaternion_from_matrix(R) * RNG.uniform(0.9, 1.1, (len(R), 1))  # not unit
    batched = rot.matrix_from_quaternion(q)
    one = np.stack([rot.matrix_from_quaternion(qi) for qi in q])
    assert one.shape == batched.shape == (len(R), 3, 3)
    assert np.array_equal(one, batched)
    qc = q[0] + 1e-20j * np.arange(4)
    Rc = rot.matrix_from_quaternion(qc)
    assert np.iscomplexobj(Rc)
    np.testing.assert_allclose(Rc.real, batched[0], rtol=1e-15, atol=0)


@pytest.mark.parametrize("alpha", [0.0, 0.35, -0.7, np.float64(1.2), 1])
def test_up_direction_of_one_tilt_is_cached_with_the_same_bits(alpha):
    """A scalar tilt's up direction comes from a cache: the same bits as the batched form,
    read-only so that no caller can change it for the next."""
    batched = rot.up_C_from_tilt(np.array([alpha, alpha], dtype=float))[0]
    one = rot.up_C_from_tilt(alpha)
    assert one.shape == (3,) and np.array_equal(one, batched)
    assert rot.up_C_from_tilt(alpha) is one
    with pytest.raises(ValueError, match="read-only"):
        one[0] = 1.0


@pytest.mark.parametrize("dtype", [float, complex])
def test_small_vector_helpers_are_numpys_forms_bit_for_bit(dtype):
    """gainsched._vec's cross and dot (the hot paths' forms) equal np.cross and np.sum bit for
    bit, on batches, one vector, broadcast against a constant vector, real and complex
    (complex steps ride through them)."""
    from gainsched import _vec

    a = RNG.normal(size=(64, 3)).astype(dtype)
    b = RNG.normal(size=(64, 3)).astype(dtype)
    if dtype is complex:
        a = a + 1e-20j * RNG.normal(size=a.shape)
    for x, y in ((a, b), (a[5], b[7]), (a, b[0]), (a[3], b)):
        c = _vec.cross(x, y)
        assert c.shape == np.cross(x, y).shape and np.array_equal(c, np.cross(x, y))
        d = _vec.dot(x, y)
        assert np.array_equal(d, np.sum(x * y, axis=-1))
    R = rot.matrix_from_euler_zyx(*ANGLES[:4].T)  # mv, mtv: R v and R^T v (summation order
    # is einsum's, not matmul's: equal to rounding)
    np.testing.assert_allclose(_vec.mv(R, a[:4]), (R @ a[:4, :, None])[..., 0], rtol=1e-14)
    np.testing.assert_allclose(_vec.mtv(R, a[:4]),
                               (np.swapaxes(R, -1, -2) @ a[:4, :, None])[..., 0], rtol=1e-14)


def test_batched_euler_matrix_is_the_scalar_form_and_the_product():
    """Issue 39: the batched Z-Y-X matrix, written out, has the entries of the one-sample
    scalar form bit for bit (one formula) and equals Rz Ry Rx as matrix products to
    rounding."""
    phi, theta, psi = ANGLES.T
    R = rot.matrix_from_euler_zyx(phi, theta, psi)
    for k in range(0, len(phi), 17):
        np.testing.assert_array_equal(R[k], rot.matrix_from_euler_zyx_scalar(*ANGLES[k]))
    np.testing.assert_allclose(R, rot.Rz(psi) @ rot.Ry(theta) @ rot.Rx(phi), rtol=0,
                               atol=4e-16)
