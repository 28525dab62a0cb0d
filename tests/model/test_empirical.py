"""Empirical effects beyond the library (issue 16): the azimuth thrust series keeps the
table's symmetries by construction, is found by diagnose when nothing physical explains
a residual, and its order is chosen on held-out flights."""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.analysis.diagnose._fit import _one_se_order
from gainsched.analysis.diagnose._lsq import _qp, _qp_bvls
from gainsched.model.effects import (
    AZIMUTH_HARMONICS,
    EFFECTS,
    Kinematics,
    ThrustAzimuth,
    fundamental_azimuth,
)
from gainsched.model.symmetry import (
    azimuth_invariance_error,
    effect_symmetry_errors,
    fundamental_from_query,
)
from gainsched.rotations import matrix_from_euler_zyx

from support import small_config_text


def _kinematics(n=200, seed=3):
    rng = np.random.default_rng(seed)
    R = matrix_from_euler_zyx(*rng.uniform(-1, 1, (2, n)), rng.uniform(-np.pi, np.pi, n))
    xi = rng.uniform(-np.pi, np.pi, n)
    xi_dot = rng.choice([-1.0, 1.0], n) * rng.uniform(0.5, 8.0, n)
    alpha = rng.uniform(-0.7, 0.7, n)
    r = rng.uniform(1.0, 3.0, n)
    p = np.stack([r * np.cos(xi), r * np.sin(xi), rng.normal(0, 0.05, n)], -1)
    v = np.stack([-r * xi_dot * np.sin(xi), r * xi_dot * np.cos(xi), rng.normal(0, 0.3, n)], -1)
    return Kinematics(R, v, rng.normal(0, 1, (n, 3)), p, alpha), xi, xi_dot, alpha


def test_fundamental_azimuth_matches_the_query_maps():
    """Second formulation: the kinematic map (COG azimuth, circulation sign, tilt sign)
    equals the table runtime's query map fundamental_from_query to 1e-12."""
    kin, xi, xi_dot, alpha = _kinematics()
    c, s = fundamental_azimuth(kin)
    xi_f, *_ = fundamental_from_query(xi, xi_dot, alpha)
    np.testing.assert_allclose(c, np.cos(xi_f), atol=1e-12)
    np.testing.assert_allclose(s, np.sin(xi_f), atol=1e-12)


def test_thrust_azimuth_series_and_symmetries():
    """The factor is the Fourier sum written out term by term at the fundamental azimuth;
    it keeps S1 and S2 exactly, and (unlike every built-in physical effect) changes with
    the azimuth of a level circle, which a tilt-0 table with one gain per speed cannot
    hold."""
    rng = np.random.default_rng(0)
    vals = {p.name: float(rng.uniform(-0.05, 0.05)) for p in ThrustAzimuth.params}
    eff = ThrustAzimuth(**vals)
    kin, xi, xi_dot, alpha = _kinematics()
    xi_f = fundamental_from_query(xi, xi_dot, alpha)[0]
    want = 1 + vals["a0"] + sum(vals[f"a{k}"] * np.cos(k * xi_f) + vals[f"b{k}"] * np.sin(k * xi_f)
                                for k in range(1, AZIMUTH_HARMONICS + 1))
    np.testing.assert_allclose(eff.factor(kin), want, rtol=1e-12)
    T = rng.uniform(1, 8, (xi.size, 4))
    np.testing.assert_allclose(eff.modify_thrust(T, kin, None), T * want[:, None], rtol=1e-12)
    assert effect_symmetry_errors(eff) == {"S1": 0.0, "S2": 0.0}
    assert azimuth_invariance_error(eff) > 1e-3
    for kind, cls in EFFECTS.items():
        if cls is not ThrustAzimuth:
            assert azimuth_invariance_error(cls()) <= 1e-12, kind


def test_thrust_azimuth_is_complex_step_safe():
    """The linearisation differentiates by complex step: d factor / d p_C equals central
    differences (1e-7)."""
    eff = ThrustAzimuth(a1=0.03, b2=-0.02, a5=0.01)
    kin, *_ = _kinematics(n=20)
    h = 1e-20
    for j in range(3):
        dp = np.zeros(3)
        dp[j] = 1.0
        cs = eff.factor(Kinematics(kin.R_CB, kin.v_C.astype(complex), kin.omega_B,
                                   kin.p_C + 1j * h * dp, kin.alpha)).imag / h
        e = 1e-6
        fd = (eff.factor(Kinematics(kin.R_CB, kin.v_C, kin.omega_B, kin.p_C + e * dp,
                                    kin.alpha))
              - eff.factor(Kinematics(kin.R_CB, kin.v_C, kin.omega_B, kin.p_C - e * dp,
                                      kin.alpha))) / (2 * e)
        np.testing.assert_allclose(cs, fd, atol=1e-7)


def test_law_names_the_dip():
    eff = ThrustAzimuth(a1=-0.04 * np.cos(np.deg2rad(115)), b1=-0.04 * np.sin(np.deg2rad(115)))
    law = eff.law()
    assert "-4.0% at 115 deg" in law and "+4.0% at 295 deg" in law, law


def test_bounded_least_squares_agrees_with_active_sets():
    """The many-parameter solver (BVLS on the Cholesky factor) against the exact active-set
    enumeration for k <= 3, bounds active or not, to 1e-9."""
    rng = np.random.default_rng(1)
    for k in (1, 2, 3):
        for _ in range(20):
            M = rng.normal(size=(12, k))
            A, b = M.T @ M, rng.normal(size=k) * 3
            lo, hi = -rng.uniform(0.05, 1, k), rng.uniform(0.05, 1, k)
            d1, v1 = _qp(A, b, lo, hi)
            d2, v2 = _qp_bvls(A, b, lo, hi)
            np.testing.assert_allclose(d2, d1, atol=1e-9)
            assert v2 == pytest.approx(v1, abs=1e-9)
    M = rng.normal(size=(40, 13))
    A, b = M.T @ M, rng.normal(size=13)
    d, _ = _qp(A, b, np.full(13, -1e3), np.full(13, 1e3))  # bounds inactive: the solve
    np.testing.assert_allclose(d, np.linalg.solve(A, -b), rtol=1e-8)


def test_one_standard_error_rule():
    """The lowest order whose held-out SSE is within one standard error (flight-to-flight
    spread of the differences) of the best order's."""
    best = np.array([10.0, 11.0, 9.0, 10.0])
    close = best + np.array([0.5, -0.6, 0.9, 0.1])  # +0.9 in sum, SE of the sum 1.28
    far = best + np.array([3.0, 2.5, 3.5, 3.0])  # +12: clearly worse
    assert _one_se_order(np.array([far, close, best])) == 1
    assert _one_se_order(np.array([far, best + 2.0 + np.array([0, 0.1, -0.1, 0]), best])) == 2
    assert _one_se_order(np.array([best])) == 0


def _wake_config(coefficients):
    """configs/paper.toml on a small grid with an empirical azimuth thrust law."""
    from gainsched.config import config_from_text, set_section

    text = small_config_text(name="wake", grid__speeds=[6.0, 9.0], grid__tilts_deg=[0.0, 20.0],
                             grid__azimuth_samples=12)
    text = set_section(text, "effects.thrust_azimuth", [(k, v, None) for k, v in coefficients])
    return config_from_text(text, "wake.toml")


@pytest.mark.slow
def test_tables_hold_an_azimuth_dependent_level_circle():
    """With an effect that changes with the azimuth, a level circle is no longer the same
    everywhere: the build solves tilt 0 by the periodic recursion and stores its gains
    per azimuth. The runtime's direction map (S2) at tilt 0 then reproduces a direct
    solve of the reversed circle (float32, 1e-5), and the header declares the tilt-0
    azimuth count. With the law's coefficients at zero the table keeps one tilt-0 gain
    per speed (the DARE's)."""
    from gainsched.firmware.header import render_header
    from gainsched.firmware.runtime import Interpolator, runtime_data
    from gainsched.model.reduced import Model
    from gainsched.schedule.grid import build_grid, level_circle_invariant, solve_circle
    from gainsched.schedule.tables import table_bytes, table_from_bytes

    cfg = _wake_config([("a1", -0.03), ("b1", 0.02), ("a2", 0.01)])
    assert not level_circle_invariant(Model(cfg))
    table = table_from_bytes(table_bytes(cfg, build_grid(cfg), Model(cfg)))
    assert not table.reasons.any()
    n = table.K.shape[-1]
    assert table.per_azimuth_tilt0 and table.K_tilt0.shape == (2, 12, 4, n)
    K0 = table.K_tilt0
    assert np.abs(K0 - K0.mean(1, keepdims=True)).max() / np.abs(K0).max() > 1e-3
    look = Interpolator(table)
    j = np.arange(12)
    for v in (6.0, 9.0):
        direct = solve_circle(cfg, -v, [0.0])  # the circle flown backwards, at tilt 0
        got = look(-2 * np.pi * j / 12, np.full(12, -v / cfg.radius), 0.0)
        assert not got.status.any()
        rel = np.abs(got.K - direct.K[0]).max() / np.abs(direct.K[0]).max()
        assert rel <= 1e-5, (v, rel)
        np.testing.assert_allclose(got.u_d, direct.u_d[0], rtol=1e-5)
    assert "#define WAKE_N_XI_TILT0 12u" in render_header(runtime_data(table))

    off = _wake_config([("a1", 0.0)])
    assert level_circle_invariant(Model(off))
    table0 = table_from_bytes(table_bytes(off, build_grid(off), Model(off)))
    assert not table0.per_azimuth_tilt0 and table0.K_tilt0.shape == (2, 4, n)
