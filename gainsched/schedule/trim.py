"""Numerical trim: the nominal of any set of effects (paper Sec. III, for any effects).

Along a prescribed azimuth path xi(t) the nominal keeps ``delta = pi/2`` and
given pitch and yaw offsets ``theta, chi`` (zero unless
:mod:`gainsched.schedule.offsets` chose them) and leaves the roll ``phi(t)`` and
the four motor thrusts free. At every node the model must give ``delta'' = 0``,
the path's ``xi''`` and the ``omega'`` the attitude kinematics derive from the
angles (eq. 16 without offsets): five equations in five unknowns per node,
coupled through ``phi'`` and ``phi''``.

The free thrusts are the actual ones, after every thrust modifier and a motor lag: the
motion asks for them, so they are as smooth as it is, and the model's equations at given
thrusts do not go through the modifiers. The commands (with a motor lag, its states and
the command from the lag's inverse) come point by point from the modifiers' inverse
(:mod:`gainsched.model.thrustmap`); momentum theory's floored inflow (paper eq. 29) turns
them sharply where the actual thrusts are smooth.

``phi`` is represented by its node values with a linear differentiation
operator: a Fourier (spectral) one for whole periodic circles, a quintic
interpolating spline for manoeuvres. Newton's method on all nodes at once; the
local partial derivatives come from complex steps (exact to rounding), and
the chain rule through the differentiation operators assembles the Jacobian.
With a motor lag its states are the modifiers' input (the actual thrusts without
modifiers) and the command follows from the lag's inverse.

Dense linear algebra is fine: 64 periodic nodes (a few hundred spline nodes)
give a 320 x 320 (a few thousand) system, and the Newton step eliminates the thrusts
node by node; no library offers this particular
collocation, hence the hand-written solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import make_interp_spline

from ..constants import COMPLEX_STEP, N_STATE
from ..errors import GainschedError
from ..model.thrustmap import input_from_thrust
from .closedform import closed_form, state_from_attitude
from .path import AzimuthPath

__all__ = ["trim_path", "solve_circles", "is_rough", "TrimError",
           # the collocation kernels the attitude offsets reuse (schedule/offsets.py)
           "fourier_operators", "fourier_samples", "sub_path", "local_jacobians",
           "newton_step", "newton", "initial_guess", "thrust_inputs"]

#: nodes of the periodic collocation: the interpolated nominal of 64 meets the model to
#: 1e-11 (relative) at 1024 samples per circle with rotor drag, motor lag or momentum
#: theory, and its thrusts equal those of 128 nodes to 4e-12 N
N_FOURIER = 64
N_SPLINE_MAX = 600
#: the largest roll change (rad) one Newton step of a collocation takes at any node (and a
#: thrust change at most the motors' range): a longer step is shortened to it. Near a
#: command at which the thrust modifiers' slope vanishes (momentum theory's thrust goes as
#: the command's 3/2 power near zero) a full step is long and heads for a spurious
#: solution whose roll winds around the circle: inside the offsets' search at 13 m/s, 37 deg
#: with momentum theory and a motor lag, roll to 96 rad and commands to 3.7e3 N, where
#: SLSQP stays for hundreds of trims without the limit. The physical nominal is reached
#: in far shorter steps, which the limit leaves as they are.
MAX_ROLL_STEP = 0.5

#: the interpolated nominal of a whole circle is taken as it is when its node equations
#: hold to this (relative to max(1, xi'^2), as the collocation's tolerance) at the check's
#: eight samples per node interval (:func:`_circle`): then every sampling of the circle
#: is the interpolant of its nodes (tension included) and the model is not evaluated
#: there; else the thrusts are solved sample by sample. The Fourier interpolant of a whole
#: circle meets it (residuals <= 3e-10 on the paper's grid with rotor drag: thrusts within
#: 4e-11 N of the polished ones); the splines of manoeuvres, checked at their samples,
#: mostly do not.
POLISH_TOL = 1e-8
#: the commands at a circle's samples are taken as smooth when the trigonometric
#: interpolant of the node commands meets them to this (N, relative to max(1, |u|)); else
#: the linearisation is computed at every step (:func:`is_rough`)
COMMAND_TOL = 1e-8

@dataclass
class Solutions:
    """What the trims of one model have solved, kept with the model (:attr:`Model.memo
    <gainsched.model.reduced.Model>`, :func:`solutions`) for as long as it lives: a grid's
    job asks for one circle's nominal at several sample counts (the feasibility check,
    the offsets' check, the table's azimuths, the linearisation), and what is solved on
    a circle's nodes does not depend on them. The same inputs give the same values, so
    keeping them changes no bit of a table. A circle's key is :func:`_circle_key` (speed,
    starting azimuth, tilt, offsets).

    Attributes
    ----------
    nodes : dict
        Per circle: its Fourier collocation's node solution ``(phi (n,), T (n, 4))``.
    circles : dict
        Per circle and node count: the node rows its samplings interpolate and whether
        the interpolant meets the model (:func:`_circle`).
    samples : dict
        Per circle and samples: the thrusts solved sample by sample of a circle whose
        interpolant misses the model.
    inputs : dict
        Per circle and samples: the thrust modifiers' input (and its rate) from their
        inverse at the samples of a circle whose commands are rough (the grid's nominal
        and its linearisation both sample the N control steps).
    offsets : dict
        Per ``(speed, tilt)``: the circle's attitude offsets, or None
        (:func:`gainsched.schedule.nominal.circle_offsets`).
    """

    nodes: dict = field(default_factory=dict)
    circles: dict = field(default_factory=dict)
    samples: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    offsets: dict = field(default_factory=dict)


def solutions(model) -> Solutions:
    """The :class:`Solutions` kept with ``model`` (empty on first use)."""
    return model.memo.setdefault(Solutions, Solutions())


class TrimError(GainschedError):
    """The trim did not converge."""


def fourier_operators(n: int, T: float):
    """Spectral first and second derivative matrices on n equispaced nodes of period T."""
    k = np.fft.fftfreq(n, d=T / n) * 2 * np.pi
    if n % 2 == 0:
        k1 = k.copy()
        k1[n // 2] = 0.0  # the Nyquist mode has no well-defined odd derivative
    else:
        k1 = k
    eye = np.eye(n)
    F = np.fft.fft(eye, axis=0)
    D1 = np.real(np.fft.ifft(1j * k1[:, None] * F, axis=0))
    D2 = np.real(np.fft.ifft(-(k**2)[:, None] * F, axis=0))
    return D1, D2


def _fourier_coefficients(values, T: float):
    """Coefficients ``c (..., m)`` and angular frequencies ``w (m,)`` rad/s of the
    trigonometric interpolant of node values (..., n) of period T (s):
    ``f(t) = Re sum_k c_k exp(i w_k t)``; for even n the Nyquist coefficient is split
    between +n/2 and -n/2 so that the interpolant is real (m = n + 1)."""
    n = values.shape[-1]
    c = np.fft.fft(values, axis=-1) / n
    k = np.fft.fftfreq(n, d=1.0 / n)
    if n % 2 == 0:
        c = np.concatenate([c, c[..., n // 2 : n // 2 + 1] / 2], -1)
        c[..., n // 2] /= 2
        k = np.concatenate([k, [n / 2]])
    return c, 2 * np.pi * k / T, k.astype(int)


def _fourier_eval(values, T: float, t):
    """Evaluate the trigonometric interpolant of node values (..., n) and two derivatives at t."""
    c, w, _ = _fourier_coefficients(values, T)
    E = np.exp(1j * np.outer(t, w))  # (len t, n)
    f = np.real(E @ c.T)
    f1 = np.real(E @ (1j * w * c).T)
    f2 = np.real(E @ (-(w**2) * c).T)
    return f, f1, f2


def fourier_samples(values, T: float, n_out: int):
    """:func:`_fourier_eval` at the ``n_out`` equally spaced times ``j T / n_out`` of one
    period, shapes (n_out, ...) like it, by one inverse FFT of length ``n_out``: at those
    times ``exp(i w_k t_j)`` depends on ``k mod n_out`` alone, so the coefficients are
    folded onto ``n_out`` frequencies (aliasing, exactly) and transformed, O(n_out log
    n_out) where the general form spends a complex exponential per sample and node."""
    c, w, k = _fourier_coefficients(values, T)
    out = []
    for coef in (c, 1j * w * c, -(w**2) * c):
        folded = np.zeros((n_out,) + coef.shape[:-1], dtype=complex)
        np.add.at(folded, k % n_out, np.moveaxis(coef, -1, 0))
        out.append(np.real(np.fft.ifft(folded, axis=0)) * n_out)
    return tuple(out)


def sub_path(path: AzimuthPath, idx) -> AzimuthPath:
    """The samples ``idx`` (index or mask over the samples) of ``path``."""
    return AzimuthPath(path.t[idx], path.xi[idx], tuple(d[idx] for d in path.d))


def _local(model, path: AzimuthPath, alpha, phi, dphi, ddphi, T, offsets=None):
    """Residuals (n, 5) of the node equations, and the full state and its derivative.

    ``offsets``: ``(pitch, yaw)``, each ``(value, rate, acceleration)`` at the nodes, or None.
    ``T`` (n, 4): the actual thrusts.
    """
    pitch, yaw = (None, None) if offsets is None else offsets
    s, sdot = state_from_attitude(path, (phi, dphi, ddphi), pitch, yaw)
    n_x = model.n_extra
    if n_x:  # a motor lag: its states stand in (the node equations do not depend on
        # them at given actual thrusts)
        z = np.concatenate([s.astype(T.dtype), T], -1)
    else:
        z = s.astype(np.result_type(s, T))
    ev = model.evaluate(z, T, alpha, thrust=T)
    res = np.stack(
        [
            ev.z_dot[:, 2],
            ev.z_dot[:, 3] - sdot[:, 3],
            ev.z_dot[:, 7] - sdot[:, 7],
            ev.z_dot[:, 8] - sdot[:, 8],
            ev.z_dot[:, 9] - sdot[:, 9],
        ],
        -1,
    )
    return res, z, sdot, ev


def local_jacobians(model, path, alpha, phi, dphi, ddphi, T, offsets=None, *,
                     wrt_offsets=False, thrust_only=False):
    """d res / d(phi, phi', phi'', T1..T4) per node by complex steps, shape (n, 5, 7); with
    ``wrt_offsets`` six more columns, d res / d(theta, theta', theta'', chi, chi', chi'');
    with ``thrust_only`` the four thrust columns alone, shape (n, 5, 4).

    The complex steps of every column go through the model in one evaluation (the nodes
    repeated once per column): the model's cost is per call more than per node."""
    h = COMPLEX_STEP
    n = np.size(phi)
    first = 3 if thrust_only else 0  # the first column computed
    m = (13 if wrt_offsets else 7) - first
    tile = np.tile(np.arange(n), m)
    roll = [(np.asarray(x, dtype=complex) * np.ones(n))[tile] for x in (phi, dphi, ddphi)]
    off = [np.zeros(n * m, dtype=complex) for _ in range(6)] if offsets is None else [
        (np.asarray(x, dtype=complex) * np.ones(n))[tile] for tri in offsets for x in tri]
    Tc = T.astype(complex)[tile]
    for j in range(first, 3):
        roll[j][j * n:(j + 1) * n] += 1j * h
    for j in range(4):
        Tc[(3 + j - first) * n:(4 + j - first) * n, j] += 1j * h
    if wrt_offsets:
        for j in range(6):
            off[j][(7 + j - first) * n:(8 + j - first) * n] += 1j * h
    o = (tuple(off[:3]), tuple(off[3:]))
    a = alpha if np.ndim(alpha) == 0 else np.asarray(alpha)[tile]  # a tilt per node
    res = np.imag(_local(model, sub_path(path, tile), a, *roll, Tc, o)[0]) / h
    return res.reshape(m, n, 5).transpose(1, 2, 0)


def newton_step(Jl, D1, D2, res, circles=1):
    """The solution ``(d phi (n, ...), d T (n, 4, ...))`` of the collocation system
    ``J x = res`` by eliminating the thrusts. J is the (5n, 5n) Jacobian of all node
    residuals in (phi nodes, T1 nodes, ..., T4 nodes) from the local partials ``Jl``
    (n, 5, >= 7): equation i's rows are ``diag(Jl[:, i, 0]) + Jl[:, i, 1] D1 +
    Jl[:, i, 2] D2`` in phi and ``diag(Jl[:, i, 3 + j])`` in T_j; ``res`` (n, 5) or
    (n, 5, k) for k right-hand sides. With ``circles`` m > 1, ``Jl`` and ``res`` hold m
    circles' collocations on the same n nodes one after the other (m n rows) and the
    result is ``(d phi (m, n), d T (m, n, 4))``: the m roll systems are solved as one
    stack.

    The thrusts enter each node's five equations only at that node (a 5 x 4 block
    ``B_k``), so the vector ``q_k`` orthogonal to ``B_k``'s columns (the last column of
    its complete QR) leaves one equation per node in the roll alone, an (n, n) system;
    the thrusts follow node by node from the QR. The same solution as the dense
    (5n, 5n) solve, for about 1/100 of its cost at n = 128 (hand-written: no library
    solves this bordered collocation structure)."""
    n = D1.shape[0]
    r = res if res.ndim == 3 else res[..., None]
    B = Jl[:, :, 3:7]
    Q, R = np.linalg.qr(B, mode="complete")  # (m n, 5, 5), (m n, 5, 4)
    q = Q[:, :, 4]
    c = np.einsum("ni,nij->nj", q, Jl[:, :, :3]).reshape(circles, n, 3)
    M = c[..., 0, None] * np.eye(n) + c[..., 1, None] * D1 + c[..., 2, None] * D2
    d_phi = np.linalg.solve(M, np.einsum("ni,nik->nk", q, r).reshape(circles, n, -1))
    derivs = [x.reshape(circles * n, 1, -1) for x in (d_phi, D1 @ d_phi, D2 @ d_phi)]
    rest = r - sum(Jl[:, :, j, None] * derivs[j] for j in range(3))
    d_T = np.linalg.solve(R[:, :4, :], np.einsum("nij,nik->njk", Q[:, :, :4], rest))
    if circles > 1:
        return d_phi[..., 0], d_T[..., 0].reshape(circles, n, 4)
    if res.ndim == 2:
        return d_phi[0, :, 0], d_T[..., 0]
    return d_phi[0], d_T


def _newton_circles(model, nodes, alphas, D1, D2, phi, T, tol=1e-11, max_iter=40):
    """:func:`newton` of the zero-offset circles at the tilts ``alphas`` (m,) rad on the
    same ``nodes``, from ``phi`` (m, n) and ``T`` (m, n, 4), in one model evaluation per
    step: a circle leaves the batch once its own residual meets ``tol``. Returns one
    ``(phi, T)`` per circle, None for a circle that did not converge."""
    m, n = phi.shape
    scale = max(1.0, float(np.abs(nodes.d[0]).max()) ** 2)
    out = [None] * m
    live = np.arange(m)
    for _ in range(max_iter):
        flat = sub_path(nodes, np.tile(np.arange(n), live.size))
        a = np.repeat(alphas[live], n)
        roll = (phi[live], phi[live] @ D1.T, phi[live] @ D2.T)
        res = _local(model, flat, a, *(x.reshape(-1) for x in roll), T[live].reshape(-1, 4))[0]
        done = np.abs(res).reshape(live.size, -1).max(1) < tol * scale
        for j in live[done]:
            out[j] = (phi[j].copy(), T[j].copy())
        if done.all():
            break
        keep = np.repeat(~done, n)
        live = live[~done]
        flat = sub_path(flat, np.flatnonzero(keep))
        roll = [x[~done] for x in roll]
        Jl = local_jacobians(model, flat, a[keep], *(x.reshape(-1) for x in roll),
                              T[live].reshape(-1, 4))
        d_phi, d_T = _limited(model, *newton_step(Jl, D1, D2, res[keep], circles=live.size))
        phi[live] -= d_phi
        T[live] -= d_T
    return out


def _limited(model, d_phi, d_T):
    """The Newton step ``(d phi (..., n) rad, d T (..., n, 4) N)`` shortened, per circle
    (leading axes), so that no node's roll moves by more than :data:`MAX_ROLL_STEP` and no
    thrust by more than the motors' range; a step within both is returned bit for bit."""
    v = model.config.vehicle
    size = np.maximum(np.abs(d_phi).max(-1) / MAX_ROLL_STEP,
                      np.abs(d_T).max((-2, -1)) / (v.thrust_max - v.thrust_min))
    f = 1.0 / np.maximum(size, 1.0)  # exactly 1 unless the step is long
    return d_phi * f[..., None], d_T * f[..., None, None]


def newton(model, path, alpha, D1, D2, phi, T, tol=1e-11, max_iter=40, offsets=None):
    """Newton's method on the collocation residual of one circle: the roll angle ``phi``
    (n,) rad and thrusts ``T`` (n, 4) N at the n nodes from a guess, or TrimError after
    ``max_iter`` steps (tolerance ``tol`` on the residual, relative to the path's speed)."""
    scale = max(1.0, float(np.abs(path.d[0]).max()) ** 2)
    for _ in range(max_iter):
        dphi, ddphi = D1 @ phi, D2 @ phi
        res = _local(model, path, alpha, phi, dphi, ddphi, T, offsets)[0]
        if np.abs(res).max() < tol * scale:
            return phi, T
        Jl = local_jacobians(model, path, alpha, phi, dphi, ddphi, T, offsets)
        d_phi, d_T = _limited(model, *newton_step(Jl, D1, D2, res))
        phi = phi - d_phi
        T = T - d_T
    raise TrimError(f"trim did not converge (residual {np.abs(res).max():.3g})")


def initial_guess(model, path, alpha):
    """Closed-form nominal of the drag-like effects alone."""
    base = model.drag_part()
    s, _, u, _ = closed_form(base, path, alpha, base.closed_form_drag())
    return s[:, 4], u


def _solve_thrust(model, path, alpha, phi, dphi, ddphi, T, tol=1e-12, max_iter=20,
                  offsets=None, res=None):
    """Per-point Newton on the four thrusts for the xi'' and omega' equations (phi fixed):
    the thrusts (n, 4), N. The points are independent, so a point stops when its residual
    is below ``tol`` (relative to max(1, max |T|)) and the rest go on alone. ``res``: the
    node-equation residuals (n, 5) at ``T`` if the caller has them. Raises TrimError when
    a point has not converged after ``max_iter`` steps."""
    T = np.array(T, dtype=float)
    idx = np.arange(T.shape[0])

    def at(i):  # the arguments of the points i
        return (sub_path(path, i), alpha, phi[i], dphi[i], ddphi[i], T[i],
                None if offsets is None else tuple(tuple(x[i] for x in o) for o in offsets))

    for step in range(max_iter + 1):
        res = (_local(model, *at(idx))[0] if res is None else res)[:, 1:]
        moving = ~(np.abs(res).max(1) < tol * max(1.0, np.abs(T).max()))  # NaN moves
        if not moving.any():
            return T
        idx, res = idx[moving], res[moving]
        if step == max_iter:
            break
        Jl = local_jacobians(model, *at(idx), thrust_only=True)[:, 1:]
        T[idx] -= np.linalg.solve(Jl, res[..., None])[..., 0]
        res = None
    raise TrimError(f"per-sample thrust trim did not converge at {idx.size} samples "
                    f"(residual {np.abs(res).max():.3g})")


def _rough(res, xd) -> bool:
    """Whether the node-equation residuals ``res`` (n, 5) of an interpolated nominal miss
    :data:`POLISH_TOL` in the thrust equations (relative to max(1, xi'^2), xi' (n,) rad/s)."""
    return bool(np.abs(res[:, 1:]).max() > POLISH_TOL * max(1.0, float(np.abs(xd).max()) ** 2))


def _circle_key(path: AzimuthPath, alpha: float, offsets=None):
    """The cache key of a whole circle's collocation: (xi' rad/s, first xi rad, tilt rad,
    the offsets' coefficients)."""
    return (float(path.d[0][0]), float(path.xi[0]), float(alpha), None if offsets is None
            else (offsets.pitch.tobytes(), offsets.yaw.tobytes()))


def _nodes(path: AzimuthPath, n: int | None = None):
    """``n`` equal steps (default the collocation's :data:`N_FOURIER` nodes) of one period
    of the whole circle ``path`` starts (its first sample and azimuth rate), and the
    period, s."""
    n = N_FOURIER if n is None else n
    xd, t0 = path.d[0][0], path.t[0]
    Tp = 2 * np.pi / abs(xd)
    tn = t0 + np.arange(n) * (Tp / n)
    z0 = np.zeros_like(tn)
    return AzimuthPath(tn, path.xi[0] + xd * (tn - t0), (np.full_like(tn, xd), z0, z0, z0)), Tp


def solve_circles(model, path: AzimuthPath, alphas) -> Solutions:
    """Solve the Fourier collocations of the whole circle ``path`` starts at the tilts
    ``alphas`` (rad), without offsets, in one batched Newton (:func:`_newton_circles`), and
    keep them in the model's :class:`Solutions` (returned), which :func:`trim_path` reads:
    a grid's job asks for every tilt of a speed, and the model's cost is per evaluation
    more than per node (a seventh of the evaluations). Each circle stops when its own
    residual meets the tolerance, as alone; one that does not converge is left out (to
    :func:`trim_path`, which raises)."""
    kept = solutions(model)
    cache = kept.nodes
    todo = [float(a) for a in alphas if _circle_key(path, a) not in cache]
    if len(todo) < 2:
        return kept
    nodes, Tp = _nodes(path)
    D1, D2 = fourier_operators(N_FOURIER, Tp)
    guesses = [initial_guess(model, nodes, a) for a in todo]
    phi = np.stack([g[0] for g in guesses])
    T = np.stack([g[1] for g in guesses])
    with np.errstate(all="ignore"):  # a diverging circle is left out, not raised here
        solved = _newton_circles(model, nodes, np.array(todo), D1, D2, phi, T)
    for a, sol in zip(todo, solved, strict=True):
        if sol is not None:
            cache[_circle_key(path, a)] = sol
    return kept


def thrust_inputs(model, s, T, alpha, rates=None, start=None, where="samples"):
    """:func:`~gainsched.model.thrustmap.input_from_thrust` ``(T0, T0_dot)``, or TrimError
    naming how many of the ``where`` it did not converge at."""
    T0, T0_dot, ok = input_from_thrust(model, s, T, alpha, rates, start=start)
    if not ok.all():
        raise TrimError(f"no command gives the nominal's thrusts at {int((~ok).sum())} "
                        f"{where} (the thrust modifiers' inverse did not converge)")
    return T0, T0_dot


def _smooth_samples() -> int:
    """Samples per period at which a solved circle's interpolant is checked against the
    model once (:func:`_circle`): eight per node interval. The interpolant meets the model
    at its nodes, and its residual between them is a smooth periodic function of about the
    nodes' bandwidth, so eight samples per interval find its largest value to a few
    percent, well inside the margin of :data:`POLISH_TOL` (the paper's grid with rotor
    drag, a motor lag or momentum theory: residuals <= 3e-10 against 1e-8)."""
    return 8 * N_FOURIER


def _circle(model, path: AzimuthPath, alpha: float, offsets=None):
    """The Fourier collocation of the whole circle ``path`` starts (solved once, cached per
    model and circle) and what every sampling of it needs, computed once at
    :func:`_smooth_samples` samples (the nodes among them): one model evaluation and, with
    thrust modifiers, their inverse.

    Returns ``(key, rows, smooth)``: the circle's cache key; the node values (6, or 10
    with modifiers, N_FOURIER) the samples interpolate: the roll (rad), the actual thrusts
    (N), the tension (N) and, with thrust modifiers, their input (N); and ``(meets,
    smooth_input)``: whether the interpolant meets the model's equations to
    :data:`POLISH_TOL` (else every sampling solves its thrusts sample by sample), and
    whether the interpolant of the node inputs meets their inverse, and with a motor lag
    the command from its rate, to :data:`COMMAND_TOL` (else every sampling takes the
    inverse at its samples).
    """
    nodes, Tp = _nodes(path)
    key = _circle_key(path, alpha, offsets)
    kept = solutions(model)
    cache = kept.circles
    if (key, N_FOURIER) in cache:
        return (key, *cache[key, N_FOURIER])
    solved = kept.nodes
    D1, D2 = fourier_operators(N_FOURIER, Tp)
    off_n = None if offsets is None else offsets.along(nodes)
    if key not in solved:
        phi0, u0 = initial_guess(model, nodes, alpha)
        solved[key] = newton(model, nodes, alpha, D1, D2, phi0, u0, offsets=off_n)
    phi_n, T_n = solved[key]
    n = _smooth_samples()
    check = _nodes(path, n)[0]
    f, f1, f2 = fourier_samples(np.vstack([phi_n, T_n.T]), Tp, n)
    off = None if offsets is None else offsets.along(check)
    res, z, sdot, ev = _local(model, check, alpha, f[:, 0], f1[:, 0], f2[:, 0], f[:, 1:], off)
    rows = [phi_n, T_n.T, ev.tension[:: n // N_FOURIER]]
    smooth_input = True
    if model.thrust_modifiers:
        s_n, _ = state_from_attitude(nodes, (phi_n, D1 @ phi_n, D2 @ phi_n),
                                     *((None, None) if off_n is None else off_n))
        rows.append(thrust_inputs(model, s_n, T_n, alpha, where="nodes")[0].T)
        g, g1, _ = fourier_samples(rows[-1], Tp, n)
        s = z[:, :N_STATE]
        exact = _commands(model, alpha, s, sdot, f[:, 1:], f1[:, 1:], start=g)
        interpolated = _lagged(model, s, sdot, g, g1)
        scale = COMMAND_TOL * max(1.0, float(np.abs(exact[2]).max()))
        smooth_input = all(np.abs(x - y).max() <= scale
                           for x, y in zip(exact, interpolated, strict=True))
    cache[key, N_FOURIER] = (np.vstack(rows), (not _rough(res, check.d[0]), smooth_input))
    return (key, *cache[key, N_FOURIER])


def _periodic_guess(model, path: AzimuthPath, alpha: float, offsets=None):
    """The Fourier collocation of a whole circle (:func:`_circle`) interpolated to
    ``path``'s samples.

    Returns ``(key, (phi, phi', phi'', T, T', tension, T0, T0'), (meets, smooth_input))``:
    the circle's cache key; the roll (rad, rad/s, rad/s^2), actual thrusts (N, N/s) and
    tension (N) at the samples, shapes (n,), (n, 4) and (n,), and the interpolant of the
    thrust modifiers' input at the nodes and its rate (n, 4) N, N/s (None without
    modifiers); and what :func:`_circle` found of the circle.
    """
    t = path.t
    key, rows, found = _circle(model, path, alpha, offsets)
    Tp = 2 * np.pi / abs(path.d[0][0])
    tt = t - t[0]
    if np.allclose(tt, np.arange(t.size) * (Tp / t.size), rtol=0.0, atol=1e-12 * Tp):
        # one period in equal steps (to rounding: the steps' times come from the period
        # the caller computed)
        f, f1, f2 = fourier_samples(rows, Tp, t.size)
    else:
        f, f1, f2 = _fourier_eval(rows, Tp, tt)
    T0, T0_dot = (f[:, 6:], f1[:, 6:]) if model.thrust_modifiers else (None, None)
    return key, (f[:, 0], f1[:, 0], f2[:, 0], f[:, 1:5], f1[:, 1:5], f[:, 5], T0, T0_dot), found


def _lagged(model, s, sdot, T0, T0_dot):
    """The state, its derivative and the commands ``(z (n, n_z), z_dot (n, n_z), u (n,
    4))`` of the reduced states ``s, sdot`` (n, 10) and the thrust modifiers' input ``T0``
    (n, 4) N with its rate ``T0_dot`` N/s: with a motor lag its states are ``T0`` and the
    command comes from its inverse, else the commands are ``T0``."""
    lag = [e for e in model.effects if e.n_states]
    if not lag:
        return s, sdot, T0
    _, u = lag[0].steady_states(T0, T0_dot)
    return np.concatenate([s, T0], -1), np.concatenate([sdot, T0_dot], -1), u


def _commands(model, alpha, s, sdot, T, T_dot, start=None, key=None):
    """:func:`_lagged` of the reduced states ``s, sdot`` (n, 10) and the actual thrusts
    ``T`` (n, 4) N with their rate ``T_dot`` N/s: the thrust modifiers' input from their
    inverse (:func:`~gainsched.model.thrustmap.input_from_thrust`, from ``start`` (n, 4) N
    if given; the actual thrusts themselves without modifiers), computed once per ``key``
    (a circle's samples: :attr:`Solutions.inputs`) if given. Raises TrimError where the inverse did
    not converge."""
    T0, T0_dot = T, T_dot
    if model.thrust_modifiers:
        cache = {} if key is None else solutions(model).inputs
        if key not in cache:
            rates = (sdot, T_dot) if model.n_extra else None
            cache[key] = thrust_inputs(model, s, T, alpha, rates, start)
        T0, T0_dot = (None if x is None else x.copy() for x in cache[key])  # callers own
    return _lagged(model, s, sdot, T0, T0_dot)


def is_rough(model, path: AzimuthPath, alpha: float, offsets=None) -> bool:
    """Whether the nominal of the whole circle ``path`` starts (:func:`trim_path`,
    periodic) is not smooth at the collocation's resolution: the interpolant of the nodes
    misses the model by more than :data:`POLISH_TOL` (its thrusts are solved sample by
    sample), or the commands miss the interpolant of the node commands by more than
    :data:`COMMAND_TOL` (momentum theory's floored inflow, say), checked once per circle
    (:func:`_circle`). A rough nominal's linearisation is not carried by a Fourier series
    of a few azimuths."""
    return not all(_circle(model, path, alpha, offsets)[2])


def trim_path(model, path: AzimuthPath, alpha: float, *, periodic: bool | None = None,
              offsets=None):
    """Nominal ``(z, z_dot, u, tension)`` along ``path`` for the model's effects.

    Parameters
    ----------
    model : Model
    path : AzimuthPath
        Azimuth profile; for ``periodic=True`` the samples must cover exactly one
        period of a constant-speed circle, equally spaced (as ``circle_nominal`` makes).
    alpha : float, rad
    periodic : bool, optional
        Fourier collocation (default when the path has constant xi').
    offsets : AttitudeOffsets, optional
        Pitch and yaw offsets ``theta(xi), chi(xi)`` (:mod:`gainsched.schedule.offsets`);
        default zero.

    Returns
    -------
    z : ndarray (N, n_z); z_dot : ndarray (N, n_z); u : ndarray (N, 4), N; tension : ndarray (N,), N
    """
    stateful = [e for e in model.effects if e.n_states]
    if len(stateful) > 1 or (stateful and stateful[0].n_states != 4):
        raise TrimError("the trim supports one stateful effect whose states are the 4 thrusts")
    xd = path.d[0]
    if periodic is None:
        periodic = bool(np.allclose(xd, xd[0]) and np.all(path.d[1] == 0))
    t = path.t
    off = None if offsets is None else offsets.along(path)
    if periodic:
        key, (phi, dphi, ddphi, T, T_dot, tension, start, start_dot), (meets, smooth_input) = (
            _periodic_guess(model, path, alpha, offsets))
        pkey = (key, N_FOURIER, t.tobytes())  # this circle at these samples
        if meets:  # the interpolant meets the model: no evaluation at the samples
            z, sdot = state_from_attitude(path, (phi, dphi, ddphi),
                                          *((None, None) if off is None else off))
            if smooth_input and start is not None:  # and the commands their inverse
                z, z_dot, u = _lagged(model, z, sdot, start, start_dot)
                return z, z_dot, u, tension
        else:  # the thrusts sample by sample (cached per circle and samples)
            cache = solutions(model).samples
            if pkey not in cache:
                cache[pkey] = _solve_thrust(model, path, alpha, phi, dphi, ddphi, T, offsets=off)
            T = cache[pkey]
            _, z, sdot, ev = _local(model, path, alpha, phi, dphi, ddphi, T, off)
            tension = ev.tension
    else:
        start = pkey = None
        idx = np.unique(np.linspace(0, t.size - 1, min(t.size, N_SPLINE_MAX)).round().astype(int))
        nodes = sub_path(path, idx)
        spl = make_interp_spline(nodes.t, np.eye(idx.size), k=5)
        D1, D2 = spl(nodes.t, nu=1), spl(nodes.t, nu=2)
        phi0, u0 = initial_guess(model, nodes, alpha)
        off_n = None if offsets is None else offsets.along(nodes)
        phi_n, T_n = newton(model, nodes, alpha, D1, D2, phi0, u0, offsets=off_n)
        phi, dphi, ddphi = (spl(t, nu=k) @ phi_n for k in range(3))
        T = spl(t) @ T_n
        T_dot = spl(t, nu=1) @ T_n
        res, z, sdot, ev = _local(model, path, alpha, phi, dphi, ddphi, T, off)
        if _rough(res, xd):
            T = _solve_thrust(model, path, alpha, phi, dphi, ddphi, T, offsets=off, res=res)
            res, z, sdot, ev = _local(model, path, alpha, phi, dphi, ddphi, T, off)
        tension = ev.tension
    z, z_dot, u = _commands(model, alpha, z[:, :N_STATE], sdot, T, T_dot, start, pkey)
    return z, z_dot, u, tension
