"""The one geometry module and the one body wrench (gainsched/model/geometry.py,
Model.body_wrench): checked against central differences, closed forms, their
inverses, and each other's one-sample and batched forms."""

import numpy as np
import pytest

from gainsched.model.effects import Kinematics
from gainsched.model.geometry import (
    attachment_from_cog,
    cog_from_attachment,
    pose_angles_from_pose,
    pose_from_reduced,
    spherical_from_point,
    tether_direction,
    wrap_angle,
)
from gainsched.rotations import R_IC_from_tilt, matrix_from_euler_zyx

RNG = np.random.default_rng(7)
P_E = np.array([-0.05, 0.0, 0.0])


def _states(n):
    z = np.zeros((n, 10))
    z[:, 0] = RNG.uniform(0.3, 2.8, n)  # delta
    z[:, 1] = RNG.uniform(-np.pi, np.pi, n)  # xi
    z[:, 2:4] = RNG.normal(0, 1, (n, 2))
    z[:, 4:6] = RNG.uniform(-1.2, 1.2, (n, 2))  # |theta| < pi/2
    z[:, 6] = RNG.uniform(-np.pi, np.pi, n)
    z[:, 7:10] = RNG.normal(0, 1, (n, 3))
    return z


def test_tether_direction_derivatives_match_central_differences():
    delta, xi = RNG.uniform(0.2, 2.9, 50), RNG.uniform(-3, 3, 50)
    d = tether_direction(delta, xi)
    h = 1e-6

    def e(a, b):
        return tether_direction(a, b).e

    np.testing.assert_allclose(np.linalg.norm(d.e, axis=-1), 1.0, atol=1e-15)
    np.testing.assert_allclose(d.e_delta, (e(delta + h, xi) - e(delta - h, xi)) / (2 * h),
                               atol=1e-9)
    np.testing.assert_allclose(d.e_xi, (e(delta, xi + h) - e(delta, xi - h)) / (2 * h),
                               atol=1e-9)
    h = 1e-4
    e_dx = (e(delta + h, xi + h) - e(delta + h, xi - h) - e(delta - h, xi + h)
            + e(delta - h, xi - h)) / (4 * h * h)
    e_xx = (e(delta, xi + h) - 2 * e(delta, xi) + e(delta, xi - h)) / (h * h)
    np.testing.assert_allclose(d.e_delta_xi, e_dx, atol=1e-6)
    np.testing.assert_allclose(d.e_xi_xi, e_xx, atol=1e-6)


def test_tether_acceleration_matches_second_difference_along_a_path():
    """e''(t) along delta(t), xi(t) against the central second difference (h = 1e-4 s)."""
    t = np.linspace(0, 2, 21)

    def angles(t):
        return 1.2 + 0.3 * np.sin(2 * t), 0.7 * t + 0.2 * np.cos(3 * t)

    dl, xi = angles(t)
    dl_d, xi_d = 0.6 * np.cos(2 * t), 0.7 - 0.6 * np.sin(3 * t)
    dl_dd, xi_dd = -1.2 * np.sin(2 * t), -1.8 * np.cos(3 * t)
    d = tether_direction(dl, xi)
    h = 1e-4
    num = (tether_direction(*angles(t + h)).e - 2 * d.e + tether_direction(*angles(t - h)).e)
    np.testing.assert_allclose(d.acceleration(dl_d, xi_d, dl_dd, xi_dd), num / h**2, atol=1e-6)
    num1 = (tether_direction(*angles(t + h)).e - tether_direction(*angles(t - h)).e) / (2 * h)
    np.testing.assert_allclose(d.rate(dl_d, xi_d), num1, atol=1e-7)


def test_spherical_from_point_inverts_the_tether_direction():
    delta, xi = RNG.uniform(0.01, 3.13, 100), RNG.uniform(-np.pi + 1e-9, np.pi, 100)
    dist, d2, x2 = spherical_from_point(2.5 * tether_direction(delta, xi).e)
    np.testing.assert_allclose(dist, 2.5, rtol=1e-15)
    np.testing.assert_allclose(d2, delta, atol=1e-13)
    np.testing.assert_allclose(x2, xi, atol=1e-13)


def test_pose_round_trip_batched_and_one_sample():
    z = _states(200)
    p_q, R = pose_from_reduced(z, 2.0, P_E)
    np.testing.assert_allclose(attachment_from_cog(p_q, R, P_E), 2.0 * tether_direction(
        z[:, 0], z[:, 1]).e, atol=1e-14)
    np.testing.assert_allclose(cog_from_attachment(attachment_from_cog(p_q, R, P_E), R, P_E),
                               p_q, atol=1e-15)
    np.testing.assert_allclose(R, matrix_from_euler_zyx(z[:, 4], z[:, 5], z[:, 6] + z[:, 1]),
                               atol=1e-15)
    xi_ref = z[:, 1] + 2 * np.pi * RNG.integers(-3, 4, 200)  # other branches of xi
    dist, ang = pose_angles_from_pose(p_q, R, P_E, xi_ref)
    np.testing.assert_allclose(dist, 2.0, rtol=1e-14)
    np.testing.assert_allclose(ang[:, 0], z[:, 0], atol=1e-12)
    np.testing.assert_allclose(ang[:, 1], xi_ref, atol=1e-12)
    np.testing.assert_allclose(ang[:, 2:4], z[:, 4:6], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(ang[:, 4] - z[:, 6] + 1.0) - 1.0, 0.0, atol=1e-12)
    assert np.all((ang[:, 4] >= -np.pi) & (ang[:, 4] < np.pi))
    # the one-sample forms (scalar math, the simulator's pose sensor) equal the batched ones
    for k in range(20):
        p1, R1 = pose_from_reduced(z[k], 2.0, P_E)
        np.testing.assert_allclose(p1, p_q[k], atol=1e-15)
        np.testing.assert_allclose(R1, R[k], atol=1e-15)
        d1, a1 = pose_angles_from_pose(p_q[k], R[k], P_E, xi_ref[k])
        assert d1 == pytest.approx(dist[k], abs=1e-15)
        np.testing.assert_allclose(a1, ang[k], atol=1e-13)


def test_body_wrench_closed_forms(model):
    """Hover thrust level in a horizontal plane: only the drag (paper eq. 10) remains;
    a thrust difference gives the allocation torque; a spin gives -omega x J omega."""
    m, g = model.m, model.g
    drag = next(e for e in model.effects if e.kind == "drag")
    v = np.array([3.0, -4.0, 0.0])
    kin = Kinematics(np.eye(3), v, np.zeros(3), np.zeros(3), 0.0)
    F, tau = model.body_wrench(np.full(4, m * g / 4), kin, 0.0)
    np.testing.assert_allclose(F, -(drag.mu1 + 5.0 * drag.mu2) * v, atol=1e-12)
    np.testing.assert_allclose(tau, 0.0, atol=1e-15)
    # motor 1 (+,+) 1 N more: roll and pitch torques l/sqrt2 (1, -1), yaw +kappa
    vk = model.config.vehicle
    kin0 = Kinematics(np.eye(3), np.zeros(3), np.zeros(3), np.zeros(3), 0.0)
    T = np.full(4, m * g / 4) + np.array([1.0, 0, 0, 0])
    F, tau = model.body_wrench(T, kin0, 0.0)
    a = vk.arm_length / np.sqrt(2)
    np.testing.assert_allclose(F, [0, 0, 1.0], atol=1e-12)
    np.testing.assert_allclose(tau, [a, -a, vk.kappa], atol=1e-15)
    # tilted plane: gravity -m g (0, sin a, cos a); spin about a non-principal axis
    w = np.array([1.0, 2.0, 3.0])
    kin1 = Kinematics(np.eye(3), np.zeros(3), w, np.zeros(3), 0.4)
    F, tau = model.body_wrench(np.zeros(4), kin1, 0.4)
    np.testing.assert_allclose(F, -m * g * np.array([0, np.sin(0.4), np.cos(0.4)]), atol=1e-12)
    np.testing.assert_allclose(tau, -np.cross(w, model.J @ w), atol=1e-15)


def test_kinematics_position_and_height(model):
    """Effects see the COG position of the state and its height in the inertial frame."""
    z = _states(30)
    for alpha in (0.0, 0.5):
        kin = model.effect_kinematics(z, alpha)
        np.testing.assert_allclose(kin.p_C, model.cog_position(z), atol=1e-15)
        p_I = kin.p_C @ R_IC_from_tilt(alpha, 1.3).T  # any heading gamma: same height
        np.testing.assert_allclose(kin.height, p_I[:, 2], atol=1e-14)
        np.testing.assert_allclose(kin.v_C, model.kinematics(z)[2], atol=0)


def test_reduced_and_maximal_see_the_same_body_wrench(model):
    """Both formulations evaluate at the same pose with the same effect wrench: the
    maximal model's COG acceleration equals the reduced model's (paper eq. 9)."""
    from gainsched.model.maximal import MaximalModel, maximal_from_reduced

    z = _states(8)
    z[:, 0] = np.pi / 2 + 0.1 * z[:, 0]
    u = np.full(4, 3.0) + RNG.normal(0, 0.3, (8, 4))
    mx = MaximalModel(model, baumgarte=(0.0, 0.0))
    x = maximal_from_reduced(model, z)
    kin_r = model.effect_kinematics(z, 0.3)
    p_q, R = pose_from_reduced(z, model.rho, model.p_e)
    np.testing.assert_allclose(x[:, 0:3], kin_r.p_C, atol=1e-14)
    np.testing.assert_allclose(x[:, 3:6], kin_r.v_C, atol=1e-14)
    a_max = mx.f(x, u, 0.3)[:, 3:6]
    zd = model.f(z, u, 0.3)
    # COG acceleration of the reduced model by a central difference along its own flow
    h = 1e-6
    v_plus = model.effect_kinematics(z + h * zd, 0.3).v_C
    v_minus = model.effect_kinematics(z - h * zd, 0.3).v_C
    np.testing.assert_allclose(a_max, (v_plus - v_minus) / (2 * h), atol=2e-5)
    np.testing.assert_allclose(p_q, kin_r.p_C, atol=0)
