"""The thrust modifiers as a map from their input to the actual thrusts, and its inverse.

:meth:`~gainsched.model.reduced.Model.thrust` makes the actual motor thrusts ``F`` from the
commands ``u``: the stateful effects first (a motor lag hands on its states ``x``), then
the :attr:`~gainsched.model.reduced.Model.thrust_modifiers` (thrust scale, thrust change
with airspeed, momentum theory, ...). The trim (:mod:`gainsched.schedule.trim`) solves
for the actual thrusts, which are as smooth as the motion they drive, and takes the
input of the modifiers (``u``, or the lag's ``x``) from them here. Momentum theory's
floored inflow (paper eq. 29) makes that input turn sharply where the actual thrusts do
not: solved point by point it costs a few evaluations of the modifiers, where solving
for it through the whole model cost the model's.

No library inverts a batch of these 4-vector maps; the Newton below is a few lines.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..constants import COMPLEX_STEP, N_STATE

__all__ = ["thrust_from_input", "input_from_thrust", "thrust_partials"]



def thrust_from_input(model, T0, kin):
    """The actual thrusts (..., 4) N the model's thrust modifiers make of their input ``T0``
    (..., 4) N (the commands, or a motor lag's states) at the kinematics ``kin``
    (:class:`~gainsched.model.effects.Kinematics`, broadcast against ``T0``'s batch).
    Complex-step safe."""
    T = T0
    for eff in model.thrust_modifiers:
        T = eff.modify_thrust(T, kin, T0[..., :0])
    return T


def _rows(model, s_rows, alpha):
    """The kinematics of states ``s_rows`` (..., k, >= 10) whose axis before the last
    enumerates complex steps, the tilt ``alpha`` (float, or (...)) broadcast along it."""
    a = np.asarray(alpha)[..., None] if np.ndim(alpha) else alpha
    return model.effect_kinematics(s_rows, a)


def _batch(model, s, alpha):
    """The kinematics of states ``s`` (..., >= 10) with an axis before the last for the
    complex steps of four motors, shapes (..., 1, 3)."""
    return _rows(model, s[..., None, :], alpha)


def _jacobian(model, T0, kin):
    """``d T_i / d T0_j`` (..., 4, 4) at the input ``T0`` (..., 4) N and the kinematics
    ``kin`` of :func:`_batch`, by complex steps."""
    G = thrust_from_input(model, T0[..., None, :] + 1j * COMPLEX_STEP * np.eye(4), kin)
    return np.swapaxes(np.imag(G), -1, -2) / COMPLEX_STEP


def _take(kin, idx):
    """The kinematics of :func:`_batch` at the points ``idx``: every field that has the
    points' axis (the batched ones, with the motors' axis after it: two dimensions or
    more) indexed, the rest (a scalar tilt, the wind) as they are."""
    return dataclasses.replace(kin, **{
        f.name: getattr(kin, f.name)[idx] for f in dataclasses.fields(kin)
        if np.ndim(getattr(kin, f.name)) >= 2})


def _per_motor(model, T0, kin) -> bool:
    """Whether the thrust modifiers act motor by motor at the first point: the off-diagonal
    of their 4 x 4 Jacobian is zero there (one point's complex steps)."""
    J = _jacobian(model, T0[:1], _take(kin, slice(0, 1)))
    return not np.any(J * (1.0 - np.eye(4)))  # none: no point, nothing coupled


def input_from_thrust(model, s, T, alpha, rates=None, *, start=None, tol=1e-13, max_iter=30):
    """The input of the thrust modifiers that gives the actual thrusts ``T`` at states
    ``s``: Newton's method point by point from ``start``, each point until it has
    converged.

    The Newton steps take each motor's thrust as a function of its own input, its
    derivative by one complex step of all four inputs at once: exact for every library
    modifier, which act motor by motor; for a modifier that couples the motors the steps
    are those of a quasi-Newton method, whose result is checked the same way. The rate
    divides by each motor's slope where the modifiers act motor by motor (their Jacobian
    is diagonal at the first point), else solves with the whole 4 x 4 Jacobian.

    Parameters
    ----------
    model : Model
    s : ndarray, shape (n, >= 10)
        States (reduced state first), rad, rad/s.
    T : ndarray, shape (n, 4), N
        Actual thrusts.
    alpha : float or ndarray, shape (n,), rad
        Circle tilt.
    rates : tuple of ndarray, optional
        ``(s_dot (n, >= 10), T_dot (n, 4) N/s)``: also return the input's rate, by the
        implicit function theorem, ``J^-1 (T' - d thrust / d s s')``.
    start : ndarray, shape (n, 4), N, optional
        Where Newton starts; default ``T`` itself (exact in one step for a thrust scale).
    tol : float
        A point has converged when the thrusts it makes are within ``tol max(1, |T|)`` N.
    max_iter : int
        Newton steps at most.

    Returns
    -------
    T0 : ndarray, shape (n, 4), N
    T0_dot : ndarray, shape (n, 4), N/s, or None without ``rates``
    converged : ndarray of bool, shape (n,)

    Example
    -------
    >>> T0, _, ok = input_from_thrust(model, s, T, alpha)                  # doctest: +SKIP
    >>> np.abs(model.evaluate(s, T0, alpha).T - T).max() < 1e-12           # doctest: +SKIP
    True
    """
    T0 = np.array(T if start is None else start, dtype=float)
    scale = tol * np.maximum(1.0, np.abs(T).max(-1))
    kin = _batch(model, s, alpha)
    idx = np.arange(T.shape[0])
    converged = np.zeros(T.shape[0], dtype=bool)
    slope = np.ones_like(T0)  # d T_i / d T0_i at the points' last input
    for step in range(max_iter + 1):
        G = thrust_from_input(model, T0[idx, None, :] + 1j * COMPLEX_STEP, _take(kin, idx))[:, 0]
        miss = np.real(G) - T[idx]
        slope[idx] = np.imag(G) / COMPLEX_STEP
        done = np.abs(miss).max(-1) <= scale[idx]
        converged[idx[done]] = True
        if done.all() or step == max_iter:
            break
        idx, miss = idx[~done], miss[~done]
        d = slope[idx]
        T0[idx] -= miss / np.where(d != 0.0, d, 1.0)
    if rates is None:
        return T0, None, converged
    s_dot, T_dot = rates
    # d thrust / d s s', one complex step
    moved = _batch(model, s + 1j * COMPLEX_STEP * s_dot, alpha)
    rhs = T_dot - np.imag(thrust_from_input(model, T0[:, None, :], moved)[:, 0]) / COMPLEX_STEP
    if _per_motor(model, T0, kin):
        return T0, rhs / slope, converged
    J = _jacobian(model, T0, kin)
    return T0, np.linalg.solve(J, rhs[..., None])[..., 0], converged


def thrust_partials(model, s, T0, alpha):
    """The thrust modifiers' partial derivatives at states ``s`` (..., >= 10) and input
    ``T0`` (..., 4) N by complex steps: ``d F / d s`` (..., 4, 10) and ``d F / d T0``
    (..., 4, 4) (the linearisation of a circle whose commands are sharp:
    :mod:`gainsched.schedule.discrete`)."""
    moved = _rows(model, s[..., None, :N_STATE] + 1j * COMPLEX_STEP * np.eye(N_STATE), alpha)
    F_s = thrust_from_input(model, T0[..., None, :], moved)
    return (np.swapaxes(np.imag(F_s), -1, -2) / COMPLEX_STEP,
            _jacobian(model, T0, _batch(model, s, alpha)))
