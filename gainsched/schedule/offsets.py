"""Attitude offsets of the nominal: a trim that lets the tether carry the yaw torque.

On a great circle the closed-form nominal (paper eqs. 15-18) keeps ``theta = chi =
0`` and leaves the motors to make every torque. At high speed and tilt the roll
and yaw torques it asks for need motor thrusts below the minimum (down to -0.85 N
at 40 deg and 15 m/s on the paper vehicle). The tether is attached ``L_e`` behind
the COG, so a small yaw or pitch offset turns the tension (tens of newtons there)
into a torque: about 0.1 N m per degree at 15 m/s, more than the motors' yaw
authority.

:func:`solve_offsets` chooses smooth periodic offsets ``theta(xi)``, ``chi(xi)``,
Fourier series in the azimuth up to :data:`HARMONICS`, of least mean square over
the circle, such that the trim of the full model (any effects,
:mod:`gainsched.schedule.trim`) keeps every motor inside ``[thrust_min + margin,
thrust_max - margin]`` and both offsets within the configured bound. Where the
zero-offset nominal is feasible the least-squares optimum is zero offsets, so the
nominal is exactly today's. The problem is an SLSQP over the ``2 (2 H + 1)``
coefficients; each evaluation is the collocation trim of the roll and thrusts for
those offsets, and the constraint gradients come from the implicit function
theorem on that trim's Newton Jacobian (one extra linear solve), not from finite
differences. The bounds hold for the commanded thrusts (with a motor lag: ``T + tau
T'``) at :data:`FINE` points per node of the collocation's interpolant, so that the
nominal between the nodes keeps them too. The collocation solves for the actual thrusts,
as the trim's does (the model at given thrusts never goes through the thrust modifiers);
the bounds are on the interpolant of the node values of the modifiers' input (the
commands, or a motor lag's states), taken from the modifiers' inverse at the nodes, with
their gradients by the chain rule through it (:func:`_inputs_at_nodes`). The bounds are
linear in those node values: put on the inverse of the interpolated actual thrusts
instead, a command near zero thrust moves by tens of newtons per degree of offset
(momentum theory's thrust goes as the command's 3/2 power there, paper eq. 29), which
SLSQP does not follow (measured).
scipy's SLSQP is the optimizer; the collocation and its sensitivities are ours because
no library offers this trim (see :mod:`gainsched.schedule.trim`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from ..constants import COMPLEX_STEP
from ..model.thrustmap import thrust_partials
from .closedform import state_from_attitude
from .path import AzimuthPath, circle_path, period
from .trim import (
    TrimError,
    fourier_operators,
    fourier_samples,
    initial_guess,
    local_jacobians,
    newton,
    newton_step,
    sub_path,
    thrust_inputs,
)

__all__ = [
    "HARMONICS",
    "AttitudeOffsets",
    "solve_offsets",
    "mirrored_coefficients",
    "shifted_coefficients",
    "series",
]

#: highest harmonic of the azimuth in the offset series
HARMONICS = 3
#: collocation nodes of the optimisation (the nominal itself is then trimmed with the
#: trim's own resolution); with the bounds at FINE points per node, 32 nodes give the
#: offsets of 64 to 3e-6 deg on the paper grid
N_NODES = 32
#: the commanded thrusts are bounded at FINE points per node (the collocation's
#: trigonometric interpolant), not at the nodes alone: a thrust bulges past its node
#: values by several mN between 32 nodes
FINE = 8
#: the bounds are imposed this much inside the config's (N), for the difference between
#: the optimisation's collocation and the nominal's. While a check on CHECK_SAMPLES
#: samples of the circle finds a motor outside by ``d`` N, the next round (at most
#: ROUNDS in all, each from the last one's offsets) moves the bounds in by ``max(safety,
#: 1.5 d)`` more: doubling them for an interpolation bulge of a few mN, and in one round
#: past the dip of a thrust the 32 nodes cannot resolve (momentum theory's floored inflow
#: on a motor near its minimum: 40-90 mN). On the paper grid the check never
#: fails: one SLSQP per circle.
NODE_SAFETY_N = 2e-3
ROUNDS = 3
CHECK_SAMPLES = 1024
#: the optimisation variables are the coefficients in degrees (objective of order 1)
_DEG = np.pi / 180
#: SLSQP's stopping tolerance (deg^2 in the objective, N in the sum of the bounds'
#: violations): the offsets to about 1e-5 deg. At 1e-10 it took the rounding-level
#: violations of its 2048 bounds for ones it could remove, and a circle that had converged
#: in 5 iterations ran 69 (10 m/s, 40 deg with a motor lag)
FTOL = 1e-8


def _basis(xi, harmonics: int):
    """Fourier basis in the azimuth and its first two derivatives, each (n, 2 H + 1):
    columns ``1, cos(k xi), sin(k xi)`` for k = 1..H."""
    k = np.arange(1, harmonics + 1)
    c, s = np.cos(np.outer(xi, k)), np.sin(np.outer(xi, k))
    one, zero = np.ones((np.size(xi), 1)), np.zeros((np.size(xi), 1))
    return (np.concatenate([one, c, s], 1), np.concatenate([zero, -k * s, k * c], 1),
            np.concatenate([zero, -(k**2) * c, -(k**2) * s], 1))


def _harmonic_signs(nb: int) -> np.ndarray:
    """``(-1)^k`` for k = 1..H of a series with ``nb = 2 H + 1`` coefficients."""
    return (-1.0) ** np.arange(1, (nb - 1) // 2 + 1)


def mirrored_coefficients(coef):
    """Offsets of the direction mirror S2 (``xi -> pi - xi``; theta keeps its sign, chi
    flips, docs/conventions.md): ``coef (..., 2, 2 H + 1)`` -> the same shape.
    cos(k (pi - xi)) = (-1)^k cos(k xi), sin(k (pi - xi)) = -(-1)^k sin(k xi)."""
    sgn = _harmonic_signs(np.shape(coef)[-1])
    m = np.concatenate([[1.0], sgn, -sgn])
    return np.asarray(coef) * m * np.array([[1.0], [-1.0]])


def shifted_coefficients(coef):
    """Offsets of the tilt-sign map S1 (the same circle with ``xi -> xi + pi``): cos and
    sin of ``k (xi + pi)`` are ``(-1)^k`` times those of ``k xi``; ``(..., 2, 2 H + 1)``."""
    sgn = _harmonic_signs(np.shape(coef)[-1])
    return np.asarray(coef) * np.concatenate([[1.0], sgn, sgn])


def series(coef, xi) -> np.ndarray:
    """Evaluate offsets at azimuths: ``coef (m, 2, 2 H + 1)``, ``xi (m,)`` rad ->
    ``(m, 4)`` = theta rad, d theta / d xi, chi rad, d chi / d xi."""
    B, B1, _ = _basis(xi, (np.shape(coef)[-1] - 1) // 2)
    val = np.einsum("mj,maj->ma", B, coef)
    slope = np.einsum("mj,maj->ma", B1, coef)
    return np.stack([val[:, 0], slope[:, 0], val[:, 1], slope[:, 1]], -1)


@dataclass(frozen=True)
class AttitudeOffsets:
    """Pitch and yaw offsets of a nominal as Fourier series in the azimuth.

    ``theta(xi) = pitch[0] + sum_k pitch[k] cos(k xi) + pitch[H + k] sin(k xi)``, the same
    for ``chi(xi)`` with ``yaw``; k = 1..H.

    Attributes
    ----------
    pitch, yaw : ndarray, shape (2 H + 1,), rad
    """

    pitch: np.ndarray
    yaw: np.ndarray

    @property
    def harmonics(self) -> int:
        return (self.pitch.size - 1) // 2

    def along(self, path: AzimuthPath):
        """``(pitch, yaw)`` along ``path``, each ``(value rad, rate rad/s, acceleration
        rad/s^2)`` with the time derivatives through ``xi(t)``."""
        B, B1, B2 = _basis(path.xi, self.harmonics)
        xd, xdd = path.d[0], path.d[1]
        out = []
        for c in (self.pitch, self.yaw):
            f1 = B1 @ c
            out.append((B @ c, xd * f1, xd**2 * (B2 @ c) + xdd * f1))
        return tuple(out)

    def mirrored(self) -> AttitudeOffsets:
        """The offsets of the direction mirror S2 (``xi -> pi - xi``; theta keeps its sign,
        chi flips, docs/conventions.md): cos(k (pi - xi)) = (-1)^k cos(k xi),
        sin(k (pi - xi)) = -(-1)^k sin(k xi)."""
        pitch, yaw = mirrored_coefficients(np.stack([self.pitch, self.yaw]))
        return AttitudeOffsets(pitch, yaw)


def solve_offsets(model, speed: float, alpha: float, *, bound: float,
                  harmonics: int = HARMONICS, n_nodes: int = N_NODES):
    """The least-mean-square offsets that keep the circle's motors in range (module doc).

    Parameters
    ----------
    model : Model
    speed : float, m/s
        Signed COG speed of the constant-speed circle.
    alpha : float, rad
        Circle tilt.
    bound : float, rad
        Largest ``|theta|`` and ``|chi|`` allowed anywhere on the circle (at the nodes).

    Returns
    -------
    AttitudeOffsets or None
        None when no offsets within ``bound`` keep the motors in range (or the trim
        fails on the way).

    Example
    -------
    >>> a = np.deg2rad(40)                                                  # doctest: +SKIP
    >>> off = solve_offsets(model, 15.0, a, bound=np.deg2rad(10))           # doctest: +SKIP
    >>> z, z_dot, u, tension = trim_path(model, path, a, offsets=off)       # doctest: +SKIP
    """
    from .trim import trim_path

    cfg = model.config
    lo = cfg.vehicle.thrust_min + cfg.feasibility.thrust_margin
    hi = cfg.vehicle.thrust_max - cfg.feasibility.thrust_margin
    Tp = period(speed, model.r)
    check = circle_path(speed, model.r, np.arange(CHECK_SAMPLES) * (Tp / CHECK_SAMPLES))
    safety, off = NODE_SAFETY_N, None
    for _ in range(ROUNDS):
        off = _solve(model, speed, alpha, bound, harmonics, n_nodes, lo + safety, hi - safety,
                     start=off)
        if off is None:
            return None
        try:
            u = trim_path(model, check, alpha, periodic=True, offsets=off)[2]
        except TrimError:
            return None
        outside = max(float(np.max(lo - u)), float(np.max(u - hi)))
        if outside <= 0.0:
            return off
        safety += max(safety, 1.5 * outside)
        if lo + safety >= hi - safety:  # no room left between the bounds
            return None
    return None


def _command_map(model, P, P1):
    """The linear map from the node thrusts (n, 4) to the commanded thrusts at the fine
    points, (f, n): the interpolant ``P`` itself, or with the one stateful effect the trim
    supports (the motor lag, whose states are the actual thrusts) its command ``T + tau
    T'`` (:meth:`~gainsched.model.effects.Effect.steady_states`, linear in the thrust
    trajectory), ``P`` and ``P1`` the interpolant's value and rate."""
    lag = [e for e in model.effects if e.n_states]
    return P if not lag else lag[0].steady_states(P, P1)[1]


def _inputs_at_nodes(model, nodes, alpha, D1, D2, phi, T, off, dphi_dp, dT_dp, trip,
                     start=None):
    """The thrust modifiers' input ``T0`` (n, 4) N at the nodes of a solved collocation
    (roll ``phi`` (n,) rad, actual thrusts ``T`` (n, 4) N, offsets ``off`` along the nodes)
    and its sensitivity to the offsets' coefficients (n, 4, 2 nb) N per coefficient, from
    those of the roll and the actual thrusts (``dphi_dp`` (n, 2 nb), ``dT_dp`` (n, 4,
    2 nb)) by the chain rule through ``F(s, T0) = T``: ``dT0/dp = F_T0^-1 (dT/dp - F_s
    ds/dp)``, ``ds/dp`` through the attitude (roll and offsets, each with its two time
    derivatives) by complex steps of :func:`state_from_attitude`; ``trip`` the offsets'
    node values and time derivatives per coefficient (3 of (n, nb)); ``start`` (n, 4) N
    where the inverse starts (the last search point's, default ``T``)."""
    roll = (phi, D1 @ phi, D2 @ phi)
    angles = [roll, *off]  # roll, pitch, yaw: each (value, rate, acceleration)
    s, _ = state_from_attitude(nodes, *angles)
    T0 = thrust_inputs(model, s, T, alpha, start=start, where="nodes")[0]
    F_s, F_T0 = thrust_partials(model, s, T0, alpha)
    n, nb = phi.size, trip[0].shape[1]
    # d s / d (each angle and its derivatives): 9 complex steps in one evaluation, the
    # nodes repeated once per step (n, 10, 9)
    h = COMPLEX_STEP
    tile = np.tile(np.arange(n), 9)
    moved = [[np.asarray(x, dtype=complex)[tile] for x in angle] for angle in angles]
    for k in range(9):
        moved[k // 3][k % 3][k * n:(k + 1) * n] += 1j * h
    s_c = state_from_attitude(sub_path(nodes, tile), *map(tuple, moved))[0]
    ds_dq = (np.imag(s_c) / h).reshape(9, n, -1).transpose(1, 2, 0)
    # d (angles) / dp (n, 9, 2 nb): the roll's through the trim, each offset's own series
    dq_dp = np.zeros((n, 9, 2 * nb))
    for j, D in enumerate((None, D1, D2)):
        dq_dp[:, j] = dphi_dp if D is None else D @ dphi_dp
    for a in range(2):
        for j in range(3):
            dq_dp[:, 3 + 3 * a + j, a * nb:(a + 1) * nb] = trip[j]
    ds_dp = ds_dq @ dq_dp  # (n, 10, 2 nb)
    return T0, np.linalg.solve(F_T0, dT_dp - F_s @ ds_dp[:, :F_s.shape[-1]])


def _solve(model, speed, alpha, bound, harmonics, n_nodes, lo, hi, start=None):
    """One SLSQP at node thrust bounds ``[lo, hi]`` (N) from the offsets ``start`` (default
    zero); None if it fails."""
    Tp = period(speed, model.r)
    t = np.arange(n_nodes) * (Tp / n_nodes)
    nodes = circle_path(speed, model.r, t)
    D1, D2 = fourier_operators(n_nodes, Tp)
    # the commands between the nodes: the collocation's own trigonometric interpolant at
    # FINE times the nodes (a smooth thrust bulges past its node values by about
    # A k^2 h^2 / 8, several mN at 32 nodes, more than the safety)
    P, P1, _ = fourier_samples(np.eye(n_nodes), Tp, FINE * n_nodes)
    command = _command_map(model, P, P1)
    B, _, _ = _basis(nodes.xi, harmonics)
    nb = B.shape[1]
    state = dict(zip(("phi", "T"), initial_guess(model, nodes, alpha), strict=True), T0=None)
    cache: dict[bytes, tuple] = {}

    def offsets_of(x):
        return AttitudeOffsets(x[:nb] * _DEG, x[nb:] * _DEG)

    dB = _basis(nodes.xi, harmonics)
    xd = nodes.d[0]
    # node values and time derivatives of the offsets per coefficient (n, nb)
    trip = (dB[0], xd[:, None] * dB[1], xd[:, None] ** 2 * dB[2])
    modifiers = bool(model.thrust_modifiers)

    def solve(p):
        key = p.tobytes()
        if key not in cache:
            off = offsets_of(p).along(nodes)
            # the trim in actual thrusts (the model at given thrusts never goes through the
            # modifiers; without modifiers they are the commands)
            phi, T = newton(model, nodes, alpha, D1, D2, state["phi"], state["T"],
                             offsets=off)
            state["phi"], state["T"] = phi, T
            # implicit function theorem: R(y(p), p) = 0  ->  dy/dp = -R_y^-1 R_p
            Jl = local_jacobians(model, nodes, alpha, phi, D1 @ phi, D2 @ phi, T, off,
                                  wrt_offsets=True)
            Rp = np.zeros((n_nodes, 5, 2 * nb))
            for a in range(2):
                Rp[:, :, a * nb:(a + 1) * nb] = sum(
                    Jl[:, :, 7 + 3 * a + j, None] * trip[j][:, None] for j in range(3))
            d_phi, d_T = newton_step(Jl, D1, D2, Rp)  # (n, 2 nb), (n, 4, 2 nb), negated
            T0, dT0 = (T, -d_T) if not modifiers else _inputs_at_nodes(
                model, nodes, alpha, D1, D2, phi, T, off, -d_phi, -d_T, trip, state["T0"])
            state["T0"] = T0
            cache.clear()
            dU = np.einsum("fn,nmp->mfp", command, dT0).reshape(-1, 2 * nb)
            cache[key] = (command @ T0, dU * _DEG)
        return cache[key]

    G = B.T @ B / n_nodes  # mean square of a series over the nodes: c^T G c

    def objective(p):
        return float(p[:nb] @ G @ p[:nb] + p[nb:] @ G @ p[nb:])

    def objective_grad(p):
        return np.concatenate([2 * G @ p[:nb], 2 * G @ p[nb:]])

    def thrust_margins(p):
        T = solve(p)[0]
        return np.concatenate([(T - lo).T.reshape(-1), (hi - T).T.reshape(-1)])

    def thrust_margins_grad(p):
        dT = solve(p)[1]  # rows: motor-major nodes, as thrust_margins
        return np.concatenate([dT, -dT])

    Z = np.zeros_like(B)
    A_bound = np.concatenate([np.block([[B, Z], [Z, B]]), -np.block([[B, Z], [Z, B]])])
    constraints = [
        {"type": "ineq", "fun": thrust_margins, "jac": thrust_margins_grad},
        {"type": "ineq", "fun": lambda x: bound / _DEG - A_bound @ x, "jac": lambda x: -A_bound},
    ]
    try:
        x0 = np.zeros(2 * nb) if start is None else np.concatenate([start.pitch, start.yaw]) / _DEG
        sol = minimize(objective, x0, jac=objective_grad, method="SLSQP",
                       constraints=constraints, options={"maxiter": 100, "ftol": FTOL})
        if not sol.success or np.min(thrust_margins(sol.x)) < -1e-6 or np.min(
                bound / _DEG - A_bound @ sol.x) < -1e-7:
            return None
    except (TrimError, np.linalg.LinAlgError):
        return None
    return offsets_of(sol.x)
