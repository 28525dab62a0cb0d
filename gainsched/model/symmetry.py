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

from ..constants import INTEGRATORS
from ..rotations import matrix_from_euler_zyx
from ._base import MIRROR_MOTOR
from .effects import Kinematics

__all__ = [
    "P_U",
    "STATE_SIGNS",
    "REDUCED_SIGNS",
    "lqr_state_signs",
    "state_mirror",
    "mirror_gain",
    "mirror_state",
    "fundamental_from_query",
    "effect_symmetry_errors",
    "azimuth_invariance_error",
    "table_refusal",
    "mirror_effects",
    "SYMMETRY_TOL",
]

#: relative error of :func:`effect_symmetry_errors` up to which an effect keeps a
#: symmetry (round-off of its hooks)
SYMMETRY_TOL = 1e-9

#: the S2 map of the motor thrusts (motor 1 <-> 4, 2 <-> 3)
P_U = np.eye(4)[list(MIRROR_MOTOR)]
#: signs of the 10 reduced-state errors under S2
#: (delta, xi, delta', xi', phi, theta, chi, wx, wy, wz)
REDUCED_SIGNS = np.array([1, -1, 1, -1, -1, 1, -1, -1, 1, -1], dtype=float)
#: signs of the paper's 11 LQR state errors under S2 (reduced state, int delta)
STATE_SIGNS = np.append(REDUCED_SIGNS, 1.0)


def lqr_state_signs(integrators=("int_delta",)) -> np.ndarray:
    """Signs of the LQR state errors under S2: the reduced state, then each integral
    with the sign of the state it integrates (:data:`gainsched.constants.INTEGRATORS`),
    shape (10 + len(integrators),)."""
    return np.concatenate([REDUCED_SIGNS, [REDUCED_SIGNS[INTEGRATORS[n]] for n in integrators]])


def state_mirror(effects=(), integrators=("int_delta",)) -> np.ndarray:
    """``P_x``: the S2 map of the LQR state (reduced state, integrals, effect states),
    shape (n, n)."""
    blocks = [np.diag(lqr_state_signs(integrators))]
    blocks += [e.mirror() for e in effects if e.n_states]
    return block_diag(*blocks)


def mirror_gain(K, P_x=None):
    """S2 applied to gains ``K`` (..., 4, n): ``P_u K P_x``. Applied twice: the identity."""
    P_x = np.diag(STATE_SIGNS) if P_x is None else P_x
    return P_U @ K @ P_x


def mirror_state(z):
    """S2 applied to absolute reduced states (..., 10): xi -> pi - xi, signs as STATE_SIGNS."""
    out = z * REDUCED_SIGNS
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


def _relative(a, b) -> float:
    scale = max(float(np.max(np.abs(a))), float(np.max(np.abs(b))), 1e-300)
    return float(np.max(np.abs(a - b))) / scale


def effect_symmetry_errors(effect, n: int = 64, seed: int = 0) -> dict[str, float]:
    """How far an effect's hooks are from respecting S1 and S2 (0: exactly).

    The table stores ``alpha >= 0, xi' > 0`` only and maps every other query there
    (:func:`fundamental_from_query`), which is exact only when every effect is
    equivariant: under S1 (``R_CB -> Z R_CB``, ``v_C -> Z v_C``, ``p_C -> Z p_C``,
    ``alpha -> -alpha``, ``Z = Rz(pi)``) thrusts and torques stay, forces turn with
    Z; under S2 (``R_CB -> M R_CB N``, ``v_C -> M v_C``, ``p_C -> M p_C``,
    ``omega_B -> -N omega_B``, motors ``P_U``, states :meth:`Effect.mirror`) thrusts
    permute, forces mirror with M and torques map like ``omega_B``. An effect of
    speed, thrust, body rates or height keeps both; one tied to a heading or an
    azimuth in the inertial frame does not. S2 is checked against the effect's mirror
    image (:meth:`Effect.mirror_image`: itself, unless a per-motor or lateral
    parameter makes the mirrored vehicle another one): a vehicle whose image is
    another is served reversed circles from its image's (:func:`mirror_effects`).

    Parameters
    ----------
    effect : Effect
    n : int
        Random kinematic samples (speeds to 20 m/s, positions to 3 m, tilts to 0.8 rad).
    seed : int

    Returns
    -------
    dict
        ``{"S1": error, "S2": error}``: the largest relative difference between the
        hook's output at the mapped kinematics and the mapped output.
    """
    rng = np.random.default_rng(seed)
    R = matrix_from_euler_zyx(*rng.uniform(-1.2, 1.2, (2, n)), rng.uniform(-np.pi, np.pi, n))
    kin = Kinematics(R, rng.normal(0, 8, (n, 3)), rng.normal(0, 2, (n, 3)),
                     rng.normal(0, 2, (n, 3)), rng.uniform(-0.8, 0.8, n))
    T = rng.uniform(1.0, 8.0, (n, 4))
    x = rng.uniform(1.0, 8.0, (n, effect.n_states))
    Z = np.diag([-1.0, -1.0, 1.0])
    M, N = np.diag([-1.0, 1.0, 1.0]), np.diag([1.0, -1.0, 1.0])
    P_x = effect.mirror() if effect.n_states else np.eye(0)
    maps = {
        # kinematics, thrust, state maps, then the output maps (thrust, force, torque, state)
        "S1": (Kinematics(Z @ kin.R_CB, kin.v_C @ Z, kin.omega_B, kin.p_C @ Z, -kin.alpha),
               np.eye(4), np.eye(effect.n_states), Z, np.eye(3)),
        "S2": (Kinematics(M @ kin.R_CB @ N, kin.v_C @ M, -kin.omega_B @ N, kin.p_C @ M,
                          kin.alpha), P_U, P_x, M, -N),
    }
    out = {}
    for name, (kin2, P_T, P_s, F_map, tau_map) in maps.items():
        T2, x2 = T @ P_T.T, x @ P_s.T
        mapped = effect if name == "S1" else effect.mirror_image()
        errs = [_relative(mapped.modify_thrust(T2, kin2, x2),
                          effect.modify_thrust(T, kin, x) @ P_T.T)]
        w1, w2 = effect.wrench(T, kin), mapped.wrench(T2, kin2)
        if w1 is not None:
            errs += [_relative(w2[0], w1[0] @ F_map.T), _relative(w2[1], w1[1] @ tau_map.T)]
        if effect.n_states:
            errs.append(_relative(mapped.state_derivative(x2, T2, kin2),
                                  effect.state_derivative(x, T, kin) @ P_s.T))
        out[name] = max(errs)
    return out


def table_refusal(effect) -> str:
    """Why no gain table can hold ``effect`` at its parameters, one clause; "" when one can.

    The effect's own reason when it gives one (:meth:`Effect.refusal`: flight time, an
    inertial direction), else the first symmetry it breaks beyond :data:`SYMMETRY_TOL`
    (:func:`effect_symmetry_errors`; S2 against its mirror image): the build refuses
    such an effect, and diagnose says so of a term it fits. An effect whose mirror image
    is another (:func:`mirror_effects`) is no reason: the table holds the image's circles
    for the reversed ones.
    """
    reason = effect.refusal()
    if reason:
        return reason
    for name, err in effect_symmetry_errors(effect).items():
        if not err <= SYMMETRY_TOL:
            what = "tilt-sign" if name == "S1" else "direction"
            return (f"breaks the {what} symmetry {name} that the table's query maps rely on "
                    f"(relative error {err:.1e} > {SYMMETRY_TOL:g}; docs/symmetry.md)")
    return ""


def mirror_effects(effects) -> dict[str, dict[str, float]]:
    """The effects that make the vehicle's mirror image another vehicle, with the image's
    parameters: ``{kind: {name: value}}`` of each effect whose :meth:`Effect.mirror_image`
    differs from itself (a centre of mass off the plane of symmetry, unequal motors);
    empty when the vehicle is its own mirror image.

    S2 then maps the vehicle's circles flown one way onto its image's flown the other
    (docs/symmetry.md): ``K(pi - xi, -xi', a) = P_u K_image(xi, xi', a) P_x``, so the
    reversed circles need the image's solution, not the vehicle's own.

    Examples
    --------
    >>> from gainsched.model.effects import CogOffset, Drag
    >>> mirror_effects([Drag(mu1=0.17), CogOffset(x=0.004, y=0.003)])
    {'cog_offset': {'x': 0.004, 'y': -0.003, 'z': 0.0}}
    """
    return {e.kind: e.mirror_values() for e in effects if e.mirror_image() != e}


def azimuth_invariance_error(effect, n: int = 64, seed: int = 0) -> float:
    """How far an effect is from looking the same at every azimuth of a level circle
    (0: exactly), the assumption behind the table's single tilt-0 gain per speed.

    At tilt 0 a rotation ``Z = Rz(beta)`` of the circle frame about its normal maps the
    problem onto itself when every effect is invariant: under ``R_CB -> Z R_CB``,
    ``v_C -> Z v_C``, ``p_C -> Z p_C`` (body rates, thrusts and states unchanged) thrusts,
    torques and state derivatives stay and forces turn with Z. An effect of speed,
    thrust, rates or height keeps it; one of the azimuth
    (:class:`~gainsched.model.effects.ThrustAzimuth`) does not.

    Returns
    -------
    float
        The largest relative difference over random kinematics and angles ``beta``.
    """
    rng = np.random.default_rng(seed)
    R = matrix_from_euler_zyx(*rng.uniform(-1.2, 1.2, (2, n)), rng.uniform(-np.pi, np.pi, n))
    kin = Kinematics(R, rng.normal(0, 8, (n, 3)), rng.normal(0, 2, (n, 3)),
                     rng.normal(0, 2, (n, 3)), np.zeros(n))
    beta = rng.uniform(-np.pi, np.pi, n)
    Z = matrix_from_euler_zyx(np.zeros(n), np.zeros(n), beta)
    kin2 = Kinematics(Z @ kin.R_CB, np.einsum("nij,nj->ni", Z, kin.v_C), kin.omega_B,
                      np.einsum("nij,nj->ni", Z, kin.p_C), kin.alpha)
    T = rng.uniform(1.0, 8.0, (n, 4))
    x = rng.uniform(1.0, 8.0, (n, effect.n_states))
    errs = [_relative(effect.modify_thrust(T, kin2, x), effect.modify_thrust(T, kin, x))]
    w1, w2 = effect.wrench(T, kin), effect.wrench(T, kin2)
    if w1 is not None:
        errs += [_relative(w2[0], np.einsum("nij,nj->ni", Z, w1[0])), _relative(w2[1], w1[1])]
    if effect.n_states:
        errs.append(_relative(effect.state_derivative(x, T, kin2),
                              effect.state_derivative(x, T, kin)))
    return max(errs)
