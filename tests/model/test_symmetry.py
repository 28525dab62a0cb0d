"""Symmetries S1 (tilt sign) and S2 (direction), proven against direct solves.

Derivation: ``docs/symmetry.md``. The stored gains use the azimuth grid
``xi_j = 2 pi j / n_xi``; a reversed circle (negative speed) is sampled at
``xi_j = -2 pi j / n_xi`` (the same times, the path runs backwards).

- S1: ``K(xi, xi', -a) = K(xi + pi, xi', a)``: index shift by n_xi / 2.
- S2: ``K(xi, -xi', a) = P_u K(pi - xi, xi', a) P_x``: for the reversed sample j,
  ``pi - xi_j = pi + 2 pi j / n_xi``, again index j + n_xi / 2.
"""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.config import N_STATE, config_from_text, load_config, set_values
from gainsched.errors import InputError
from gainsched.model.effects import (
    CogOffset,
    Drag,
    MotorEfficiency,
    MotorLag,
    RotorDrag,
    ThrustMotorCurve,
    ThrustScale,
)
from gainsched.model.reduced import Model
from gainsched.model.symmetry import (
    P_U,
    STATE_SIGNS,
    effect_symmetry_errors,
    fundamental_from_query,
    mirror_effects,
    mirror_gain,
    mirror_state,
    state_mirror,
    table_refusal,
)
from gainsched.rotations import R_IC_from_tilt, Rz
from gainsched.schedule.grid import mirror_config, solve_circle
from gainsched.schedule.nominal import circle_nominal

from support import PAPER_TOML, paper_config_text

SPEED = 8.0  # m/s; (8 m/s, +-20 deg) is feasible all around the circle
TILT = np.deg2rad(20.0)
N_XI = 12


def _rel(X, Y):
    return np.abs(X - Y).max() / np.abs(Y).max()


def _config(extra_effects=None, azimuth_integral=False):
    """The paper config at N_XI azimuths with ``extra_effects`` (dotted keys) added."""
    text = paper_config_text(grid__azimuth_samples=N_XI, **(extra_effects or {}))
    cfg = config_from_text(text, "symmetry.toml")
    if azimuth_integral:  # the along-track integral, mirrored like xi
        cfg = cfg.with_values({"control.azimuth_integral": True,
                               "control.Q": [3, 0.2, 1, 1, 1, 2, 0.5, 1, 1, 1, 0.5, 2.0]})
    return cfg


EXTRA = {"effects.rotor_drag.k_rd": 0.02, "effects.motor_lag.tau": 0.03}


#: an empirical law of the azimuth (diagnose's thrust_azimuth): S1 and S2 by construction
EMPIRICAL = {"effects.thrust_azimuth.a1": -0.03, "effects.thrust_azimuth.b1": 0.02,
             "effects.thrust_azimuth.a2": 0.01, "effects.thrust_azimuth.b3": -0.01}


@pytest.fixture(scope="module",
                params=["paper", "with-effects", "azimuth-integral", "empirical-azimuth"])
def quadrants(request):
    """Direct solves in all four quadrants (+-speed, +-tilt) at N_XI azimuths."""
    cfg = {"paper": lambda: _config(), "with-effects": lambda: _config(EXTRA),
           "azimuth-integral": lambda: _config(EXTRA, azimuth_integral=True),
           "empirical-azimuth": lambda: _config(EMPIRICAL)}[request.param]()
    sols = {
        (sv, sa): solve_circle(cfg, sv * SPEED, [sa * TILT]) for sv in (1, -1) for sa in (1, -1)
    }
    for s in sols.values():
        assert np.all(s.reasons == 0)
    return cfg, sols


def _shift(X):
    """Value at xi_j + pi from values at xi_j (j = 0..n-1): index j + n/2."""
    return np.roll(X, -(X.shape[0] // 2), axis=0)


@pytest.mark.slow
def test_S1_tilt_sign_gains(quadrants):
    _, sols = quadrants
    K_pos = sols[1, 1].K[0]
    K_neg = sols[1, -1].K[0]
    assert _rel(K_neg, _shift(K_pos)) <= 1e-8
    assert _rel(sols[1, -1].S[0], _shift(sols[1, 1].S[0])) <= 1e-8
    assert sols[1, -1].spectral_radius[0] == pytest.approx(sols[1, 1].spectral_radius[0], rel=1e-10)


def test_S2_direction_gains(quadrants):
    cfg, sols = quadrants
    P_x = state_mirror(Model(cfg).effects, cfg.control.integrators)
    K_fwd = sols[1, 1].K[0]
    K_rev = sols[-1, 1].K[0]  # sample j at xi = -2 pi j / n_xi
    assert _rel(K_rev, mirror_gain(_shift(K_fwd), P_x)) <= 1e-8
    # cost-to-go transforms as P_x S P_x
    assert _rel(sols[-1, 1].S[0], P_x @ _shift(sols[1, 1].S[0]) @ P_x) <= 1e-8
    assert sols[-1, 1].spectral_radius[0] == pytest.approx(sols[1, 1].spectral_radius[0], rel=1e-10)


def test_S2_nominal(quadrants):
    """u_d maps with P_U, phi_d with -1; tension does not change. (1e-10: with motor lag the
    nominal comes from the numerical trim, converged to ~1e-12.)"""
    _, sols = quadrants
    fwd, rev = sols[1, 1], sols[-1, 1]
    np.testing.assert_allclose(rev.u_d[0], _shift(fwd.u_d[0]) @ P_U.T, rtol=0, atol=1e-10)
    np.testing.assert_allclose(rev.phi_d[0], -_shift(fwd.phi_d[0]), rtol=0, atol=1e-10)
    np.testing.assert_allclose(rev.tension[0], _shift(fwd.tension[0]), rtol=1e-10)


def test_S1_nominal(quadrants):
    _, sols = quadrants
    pos, neg = sols[1, 1], sols[1, -1]
    np.testing.assert_allclose(neg.u_d[0], _shift(pos.u_d[0]), rtol=0, atol=1e-10)
    np.testing.assert_allclose(neg.phi_d[0], _shift(pos.phi_d[0]), rtol=0, atol=1e-10)
    np.testing.assert_allclose(neg.tension[0], _shift(pos.tension[0]), rtol=1e-10)


def test_fundamental_from_query_reproduces_direct_solves(quadrants):
    """Each quadrant's direct gains are the stored (+speed, +tilt) gains looked up through
    fundamental_from_query and mapped back with P_u K P_x when mirrored."""
    cfg, sols = quadrants
    P_x = state_mirror(Model(cfg).effects, cfg.control.integrators)
    r = cfg.radius
    K_stored = sols[1, 1].K[0]
    u_stored = sols[1, 1].u_d[0]
    for (sv, sa), sol in sols.items():
        j = np.arange(N_XI)
        xi_q = sv * 2 * np.pi * j / N_XI
        xi_f, xd_f, a_f, mirrored = fundamental_from_query(
            xi_q, np.full(N_XI, sv * SPEED / r), np.full(N_XI, sa * TILT)
        )
        np.testing.assert_allclose(xd_f, SPEED / r)
        np.testing.assert_allclose(a_f, TILT)
        assert np.all(mirrored == (sv < 0))
        idx = np.rint(xi_f / (2 * np.pi / N_XI)).astype(int) % N_XI
        np.testing.assert_allclose(idx * 2 * np.pi / N_XI, xi_f, rtol=0, atol=1e-12)
        K = K_stored[idx]
        u = u_stored[idx]
        if sv < 0:
            K = mirror_gain(K, P_x)
            u = u @ P_U.T
        assert _rel(sol.K[0], K) <= 1e-8, (sv, sa)
        np.testing.assert_allclose(sol.u_d[0], u, rtol=0, atol=1e-10)


def test_fundamental_from_query_domain():
    rng = np.random.default_rng(42)
    k = 4000
    xi = rng.uniform(-20, 20, k)
    xd = rng.uniform(0.1, 10, k) * rng.choice([-1.0, 1.0], k)
    a = rng.uniform(-1.4, 1.4, k)
    xi_f, xd_f, a_f, mirrored = fundamental_from_query(xi, xd, a)
    assert np.all(a_f >= 0) and np.all(xd_f > 0)
    assert np.all((xi_f >= 0) & (xi_f < 2 * np.pi))
    np.testing.assert_array_equal(a_f, np.abs(a))
    np.testing.assert_array_equal(xd_f, np.abs(xd))
    np.testing.assert_array_equal(mirrored, xd < 0)
    # every quadrant is hit, and the fundamental domain maps to itself
    assert len({(s1, s2) for s1, s2 in zip(np.sign(xd), np.sign(a), strict=True)}) == 4
    inside = (a >= 0) & (xd > 0)
    np.testing.assert_allclose(xi_f[inside], np.mod(xi[inside], 2 * np.pi), rtol=0, atol=1e-12)
    # the expected azimuth in each quadrant (S1: + pi at negative tilt; S2: pi - xi)
    xi_s1 = np.where(a < 0, xi + np.pi, xi)
    expect = np.where(xd < 0, np.pi - xi_s1, xi_s1)
    d = np.mod(xi_f - expect + np.pi, 2 * np.pi) - np.pi
    assert np.abs(d).max() <= 1e-12


def test_maps_are_involutions():
    rng = np.random.default_rng(9)
    K = rng.normal(size=(5, 4, 11))
    np.testing.assert_array_equal(mirror_gain(mirror_gain(K)), K)
    effects = (MotorLag(tau=0.03), Drag(mu1=0.1), RotorDrag(k_rd=0.02))
    P_x = state_mirror(effects)
    assert P_x.shape == (15, 15)
    np.testing.assert_array_equal(P_x @ P_x, np.eye(15))
    K15 = rng.normal(size=(5, 4, 15))
    np.testing.assert_array_equal(mirror_gain(mirror_gain(K15, P_x), P_x), K15)
    np.testing.assert_array_equal(P_U @ P_U, np.eye(4))
    z = rng.normal(size=(7, 10))
    np.testing.assert_allclose(mirror_state(mirror_state(z)), z, rtol=0, atol=1e-15)
    # S1 twice: (xi, a) -> (xi + pi, -a) -> (xi + 2 pi, a), the same point
    xi = rng.uniform(0, 2 * np.pi, 7)
    a = rng.uniform(0.1, 1.0, 7)
    xi1, _, a1, _ = fundamental_from_query(xi + np.pi, np.ones(7), -a)
    xi2, _, a2, _ = fundamental_from_query(xi, np.ones(7), a)
    np.testing.assert_allclose(np.mod(xi1 + np.pi, 2 * np.pi), np.mod(xi2 + np.pi, 2 * np.pi))
    np.testing.assert_array_equal(a1, a2)


def test_circle_frame_identity():
    """R_IC(-a, g) = R_IC(a, g + pi) Rz(pi): the basis of S1."""
    for a in (0.1, 0.35, 0.7, 1.2):
        for g in (0.0, 0.4, -2.0):
            lhs = R_IC_from_tilt(-a, g)
            rhs = R_IC_from_tilt(a, g + np.pi) @ Rz(np.pi)
            np.testing.assert_allclose(lhs, rhs, rtol=0, atol=1e-15)


# ------------------------------------------------------------------ the vector field


def _models():
    cfg = load_config(PAPER_TOML)
    ext = Model(
        cfg,
        effects=(
            MotorLag(tau=0.03),
            Drag(mu1=0.172, mu2=0.0025),
            RotorDrag(k_rd=0.02),
            ThrustScale(k_T=0.9),
        ),
    )
    # a centre of mass off the frame centre in the vehicle's plane of symmetry (x, z): the
    # levers change, the mirror S2 still holds (a lateral y does not: the test below)
    cog = Model(cfg, effects=(Drag(mu1=0.172, mu2=0.0025), CogOffset(x=0.004, z=-0.003)))
    return {"paper": Model(cfg), "extended": ext, "cog_offset_xz": cog}


MODELS = _models()


def _random_states(rng, n_z, k):
    z = np.empty((k, n_z))
    z[:, 0] = np.pi / 2 + rng.normal(0.0, 0.1, k)
    z[:, 1] = rng.uniform(0.0, 2 * np.pi, k)
    z[:, 2] = rng.normal(0.0, 0.5, k)
    z[:, 3] = rng.uniform(-9.0, 9.0, k)
    z[:, 4:7] = rng.normal(0.0, 0.3, (k, 3))
    z[:, 7:10] = rng.normal(0.0, 3.0, (k, 3))
    z[:, N_STATE:] = rng.uniform(0.5, 2.5, (k, n_z - N_STATE))
    return z


def _z_mirror(model):
    """The S2 map of the full model state z (reduced state plus effect states): the LQR map
    ``state_mirror`` without the integrator row/column."""
    P = state_mirror(model.effects)
    keep = [i for i in range(P.shape[0]) if i != N_STATE]
    return P[np.ix_(keep, keep)]


@pytest.mark.parametrize("name", list(MODELS))
def test_vector_field_S2_equivariant(name):
    """f(mirror(z), P_U u, a) = mirror_derivative(f(z, u, a))."""
    model = MODELS[name]
    rng = np.random.default_rng(2026)
    k = 50
    z = _random_states(rng, model.n_z, k)
    u = rng.uniform(0.3, 3.0, (k, 4))
    a = rng.uniform(-0.7, 0.7, k)
    P = _z_mirror(model)
    zm = z @ P.T
    zm[:, :N_STATE] = mirror_state(z[:, :N_STATE])  # xi -> pi - xi (affine)
    f = model.f(z, u, a)
    fm = model.f(zm, u @ P_U.T, a)
    np.testing.assert_allclose(fm, f @ P.T, rtol=0, atol=1e-11 * np.abs(f).max())
    np.testing.assert_allclose(P[:N_STATE, :N_STATE], np.diag(STATE_SIGNS[:N_STATE]))
    # the tension is invariant too
    t = model.evaluate(z, u, a).tension
    tm = model.evaluate(zm, u @ P_U.T, a).tension
    np.testing.assert_allclose(tm, t, rtol=0, atol=1e-11 * np.abs(t).max())


#: vehicles whose mirror image under S2 is another vehicle: a centre of mass off the plane
#: of symmetry, unequal motors (each with the drag of the paper)
ASYMMETRIC = {
    "cog_lateral": (CogOffset(x=0.004, y=0.003, z=-0.002),),
    "motor_efficiency": (MotorEfficiency(eta1=0.93, eta2=1.0, eta3=1.02, eta4=0.98),),
    "thrust_motor": (ThrustMotorCurve(a1=-0.05, a3=0.03, b2=0.004),),
}


@pytest.mark.parametrize("name", list(ASYMMETRIC))
def test_an_asymmetric_vehicle_is_S2_equivariant_with_its_mirror_image(name):
    """The vector-field check of S2 between the vehicle and its mirror image
    (``Effect.mirror_image``: the COG's y negated, motors 1 <-> 4 and 2 <-> 3 swapped):
    ``f_image(mirror(z), P_U u) = mirror(f(z, u))`` to round-off, while the vehicle
    against itself misses by far more (why its reversed circles need the image)."""
    cfg = load_config(PAPER_TOML)
    effects = (Drag(mu1=0.172, mu2=0.0025), *ASYMMETRIC[name])
    model = Model(cfg, effects=effects)
    image = Model(cfg, effects=tuple(e.mirror_image() for e in effects))
    rng = np.random.default_rng(2028)
    z = _random_states(rng, model.n_z, 50)
    u = rng.uniform(0.3, 3.0, (50, 4))
    a = rng.uniform(-0.7, 0.7, 50)
    P = _z_mirror(model)
    zm = z @ P.T
    zm[:, :N_STATE] = mirror_state(z[:, :N_STATE])
    f = model.f(z, u, a)
    scale = np.abs(f).max()
    np.testing.assert_allclose(image.f(zm, u @ P_U.T, a), f @ P.T, rtol=0, atol=1e-11 * scale)
    assert np.abs(model.f(zm, u @ P_U.T, a) - f @ P.T).max() / scale > 1e-4
    assert list(mirror_effects(effects)) == [ASYMMETRIC[name][0].kind]
    # the hooks' check takes S2 against the image: a table can hold the vehicle, its
    # reversed circles from the image's (tests/schedule/test_directions.py)
    assert effect_symmetry_errors(ASYMMETRIC[name][0])["S2"] <= 1e-12
    assert table_refusal(ASYMMETRIC[name][0]) == ""


def test_a_symmetric_vehicle_is_its_own_mirror_image():
    """x and z of the COG, equal motors: no image to build (``mirror_config`` None)."""
    assert mirror_effects([CogOffset(x=0.004, z=-0.003), ThrustScale(k_T=0.9),
                           MotorEfficiency(eta1=0.95, eta2=0.95, eta3=0.95, eta4=0.95)]) == {}
    assert mirror_config(load_config(PAPER_TOML)) is None


def test_reversed_circles_of_an_asymmetric_vehicle_are_its_images_mirrored():
    """Direct solves: the reversed circle of a vehicle with its COG 3 mm to the side and a
    weak motor equals its mirror image's forward circle mapped by S2 (``K -> P_u K P_x``,
    ``u_d -> P_u u_d``, ``phi_d -> -phi_d``) to 1e-8, and differs from the vehicle's own
    forward circle mapped so (the symmetric table's answer) by far more."""
    text = set_values(paper_config_text(grid__azimuth_samples=N_XI), {
        "effects.cog_offset.y": 0.003, "effects.cog_offset.x": 0.002,
        "effects.motor_efficiency.eta1": 0.94})
    cfg = config_from_text(text, "asymmetric.toml")
    image = mirror_config(cfg)
    spec = {e.name: e.param_dict() for e in image.effects}
    assert spec["cog_offset"]["y"] == -0.003 and spec["cog_offset"]["x"] == 0.002
    assert spec["motor_efficiency"]["eta4"] == 0.94 and spec["motor_efficiency"]["eta1"] == 1.0
    rev = solve_circle(cfg, -SPEED, [TILT])
    fwd_image = solve_circle(image, SPEED, [TILT])
    fwd_own = solve_circle(cfg, SPEED, [TILT])
    assert np.all(rev.reasons == 0) and np.all(fwd_image.reasons == 0)
    P_x = state_mirror(Model(cfg).effects, cfg.control.integrators)
    assert _rel(rev.K[0], mirror_gain(_shift(fwd_image.K[0]), P_x)) <= 1e-8
    np.testing.assert_allclose(rev.u_d[0], _shift(fwd_image.u_d[0]) @ P_U.T, rtol=0,
                               atol=1e-10)
    np.testing.assert_allclose(rev.phi_d[0], -_shift(fwd_image.phi_d[0]), rtol=0, atol=1e-10)
    # the vehicle's own forward circle, mirrored: 2.2 N and 26 % off (measured)
    assert np.abs(rev.u_d[0] - _shift(fwd_own.u_d[0]) @ P_U.T).max() > 1.0  # N
    assert _rel(rev.K[0], mirror_gain(_shift(fwd_own.K[0]), P_x)) > 0.1


@pytest.mark.parametrize("name", list(MODELS))
def test_vector_field_S1_invariant(name):
    """f(z with xi + pi, u, -a) = f(z, u, a): the same physical state."""
    model = MODELS[name]
    rng = np.random.default_rng(2027)
    k = 50
    z = _random_states(rng, model.n_z, k)
    u = rng.uniform(0.3, 3.0, (k, 4))
    a = rng.uniform(-0.7, 0.7, k)
    z1 = z.copy()
    z1[:, 1] += np.pi
    f = model.f(z, u, a)
    np.testing.assert_allclose(model.f(z1, u, -a), f, rtol=0, atol=1e-11 * np.abs(f).max())


def test_nominal_state_mirror():
    """The reversed nominal is the mirrored forward nominal, state by state."""
    model = MODELS["paper"]
    n = 16
    fwd = circle_nominal(model, SPEED, TILT, n)
    rev = circle_nominal(model, -SPEED, TILT, n)
    expect = mirror_state(_shift(fwd.z))  # at pi - xi_j = pi + 2 pi j / n
    d = rev.z - expect
    d[:, 1] = np.mod(d[:, 1] + np.pi, 2 * np.pi) - np.pi  # xi modulo 2 pi
    assert np.abs(d).max() <= 1e-12
    np.testing.assert_allclose(rev.u, _shift(fwd.u) @ P_U.T, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(rev.reasons, _shift(fwd.reasons))


# ------------------------------------------------------------------ weights must respect S2


def _weights_text(R=None, Q=None):
    text = _config().text
    if R is not None:
        text = set_values(text, {"control.R": R})
    if Q is not None:
        text = set_values(text, {"control.Q": [[float(x) for x in row] for row in Q]})
    return text


def _coupled_Q():
    Q = np.diag([3, 0.2, 1, 1, 1, 2, 0.5, 1, 1, 1, 0.5])
    Q[4, 5] = Q[5, 4] = 0.3  # phi-theta coupling: phi flips under S2, theta does not
    return Q


def test_symmetric_weights_keep_S2():
    """Weights invariant under S2 (R11 = R44, R22 = R33) keep the mirrored gains exact."""
    cfg = config_from_text(_weights_text(R=[1, 2, 2, 1]), "weights.toml")
    fwd = solve_circle(cfg, SPEED, [TILT]).K[0]
    rev = solve_circle(cfg, -SPEED, [TILT]).K[0]
    assert _rel(rev, mirror_gain(_shift(fwd))) <= 1e-8


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [(dict(R=[1, 2, 1, 1]), "control.R"), (dict(Q=_coupled_Q()), "control.Q")],
    ids=["R-not-motor-swap-invariant", "Q-couples-flipped-and-kept-states"],
)
def test_weights_breaking_S2_are_rejected(kwargs, key):
    """The table stores only xi_dot > 0 and serves xi_dot < 0 through S2, which holds only
    if P_x Q P_x = Q and P_u R P_u = R. Otherwise the mirrored gains are wrong (32 % for
    R = diag(1, 2, 1, 1), 0.6 % for the coupled Q), so such a config must be refused."""
    with pytest.raises(InputError) as exc:
        config_from_text(_weights_text(**kwargs), "weights.toml")
    assert exc.value.where == key


@pytest.mark.slow
def test_offset_circle_quadrants():
    """40 deg, 15 m/s on configs/paper.toml has pitch and yaw offsets (issue 15): the four
    quadrants solved directly (each with its own offset optimisation) keep S1 and S2:
    gains, nominal and the offsets' Fourier coefficients (theta keeps its sign, chi flips
    under S2; both read at xi + pi under S1). Measured: gains 8e-13, offsets 1e-14."""
    from gainsched.schedule.offsets import mirrored_coefficients, shifted_coefficients

    cfg = _config()
    assert cfg.feasibility.attitude_offsets == "free"
    speed, tilt = 15.0, np.deg2rad(40.0)
    sols = {(sv, sa): solve_circle(cfg, sv * speed, [sa * tilt])
            for sv in (1, -1) for sa in (1, -1)}
    for s in sols.values():
        assert np.all(s.reasons == 0) and np.abs(s.offsets[0]).max() > 1e-3
    fwd = sols[1, 1]
    P_x = state_mirror(Model(cfg).effects, cfg.control.integrators)
    assert _rel(sols[1, -1].K[0], _shift(fwd.K[0])) <= 1e-8
    assert _rel(sols[-1, 1].K[0], mirror_gain(_shift(fwd.K[0]), P_x)) <= 1e-8
    np.testing.assert_allclose(sols[-1, 1].u_d[0], _shift(fwd.u_d[0]) @ P_U.T, rtol=0, atol=1e-8)
    np.testing.assert_allclose(sols[-1, 1].phi_d[0], -_shift(fwd.phi_d[0]), rtol=0, atol=1e-8)
    np.testing.assert_allclose(sols[1, -1].u_d[0], _shift(fwd.u_d[0]), rtol=0, atol=1e-8)
    # offsets, as series in the absolute azimuth: S1 reads the circle at xi + pi, S2 at
    # pi - xi with chi's sign flipped (measured 1e-14)
    np.testing.assert_allclose(sols[1, -1].offsets[0], shifted_coefficients(fwd.offsets[0]),
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(sols[-1, 1].offsets[0], mirrored_coefficients(fwd.offsets[0]),
                               rtol=0, atol=1e-9)
