"""The grid sweep: nominal, linearisation, periodic LQR at every (speed, tilt) circle.

One job per speed (in config order, so results are deterministic, and on
pinned numerics, so they are the same on every machine: :mod:`.reproducible`);
inside a job every tilt is solved at once as a batch. The step count per
period is ``N = 2 round(T / (2 dt))`` (even, so that the symmetry maps land on
steps) and the discretisation uses ``dt_k = T / N``, within 0.15 % of the
control period on the paper grid. The linearisation is exact at 64-128
azimuths and carried to every step by trigonometric interpolation, checked
to 1e-10 (:func:`discrete_system`); tilt-0 circles, time-invariant unless an
effect changes with the azimuth, are solved by the DARE. Gains at the azimuth
grid are interpolated linearly between the two steps that bracket each grid
azimuth; only those steps' gains are kept, so memory does not grow with the
number of steps.

A circle with any infeasible sample (slack, thrust limits, trim failure) has
no gains: NaN in K, and the reason bits say why.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields

import numpy as np

from ..constants import N_INPUT, N_STATE, TILT_BATCH, Reason
from ..errors import InputError
from ..model.effects import registered_effects, registered_effects_context
from ..model.reduced import Model
from ..model.symmetry import (
    SYMMETRY_TOL,
    azimuth_invariance_error,
    mirror_effects,
    table_refusal,
)
from ..native.reproducible import blas_single_thread, ensure_blas_single_thread
from .bounds import check_gain_cap, check_margin_bounds
from .discrete import LIN_TOL, discrete_at, discrete_system, periodic_interp
from .jobs import run_jobs
from .lqr import dlqr, periodic_lqr, spectral_radius, stability_scale
from .margins import MARGIN_DELAY_XTOL, MARGIN_XTOL, loop_margins, surrogate_block
from .modes import MODE_COUNT, floquet_modes
from .nominal import circle_nominal, circle_offsets
from .offsets import HARMONICS
from .path import circle_path, period
from .trim import TrimError, solve_circles

__all__ = ["CircleSolution", "solve_circle", "solve_speed", "solve_speed_and_image",
           "build_grid", "GridResult",
           "grid_from_solutions",
           "steps_per_period",
           "discrete_system", "periodic_interp", "check_effect_symmetries", "mirror_config",
           "level_circle_invariant", "LIN_TOL",
           "SYMMETRY_TOL"]



def check_effect_symmetries(config) -> None:
    """Refuse effects that break the symmetries the table relies on.

    The table stores ``alpha >= 0, xi' > 0`` and the runtime maps every other query
    there (S1, S2; docs/symmetry.md); an effect tied to an inertial heading or azimuth
    would make those maps wrong without a sign. An effect whose class gives a
    ``table_refusal`` (flight time, a wind) is refused with that reason. Raises
    :class:`InputError` naming the config file and ``effects.<kind>``
    (:func:`~gainsched.model.symmetry.table_refusal`).

    A vehicle that is not its own mirror image (:func:`mirror_config`) is not refused: its
    table holds both flight directions (:attr:`GridResult.reverse`), which the Python
    runtime, the simulator and the C runtime (``gs_table.reverse``) fly.
    """
    for eff in Model(config).effects:
        reason = table_refusal(eff)
        if reason:
            raise InputError(config.source, f"effects.{eff.kind}",
                             f"{reason}: simulate and diagnose with it, build tables without it")


def mirror_config(config):
    """The config of the vehicle's mirror image under S2 (docs/symmetry.md), or None when
    the vehicle is its own image: ``config`` with the parameters of the effects that
    differ on the image (:func:`~gainsched.model.symmetry.mirror_effects`: a lateral
    centre of mass changes sign, per-motor parameters swap 1 <-> 4, 2 <-> 3). Its
    circles flown forwards are the vehicle's flown backwards, mirrored:
    ``K(pi - xi, -xi', a) = P_u K_image(xi, xi', a) P_x``.

    Parameters
    ----------
    config : Config

    Returns
    -------
    Config or None
        The image's config (errors point at ``config``'s source), or None.
    """
    image = mirror_effects(Model(config).effects)
    if not image:
        return None
    return config.with_values({f"effects.{kind}.{name}": value
                               for kind, values in image.items()
                               for name, value in values.items()})


def level_circle_invariant(model) -> bool:
    """Whether every effect of ``model`` looks the same at every azimuth of a level circle
    (:func:`~gainsched.model.symmetry.azimuth_invariance_error` within
    :data:`SYMMETRY_TOL`): then a tilt-0 circle is time-invariant, solved by the DARE and
    stored with one gain per speed; otherwise (an empirical azimuth law) it is solved
    like a tilted one and stored per azimuth (docs/table-format.md)."""
    return all(azimuth_invariance_error(e) <= SYMMETRY_TOL for e in model.effects)


def steps_per_period(speed: float, r: float, dt: float) -> int:
    """Even number of control steps closest to one period."""
    return max(2, 2 * int(round(period(speed, r) / (2 * dt))))


@dataclass(frozen=True)
class _Circles:
    """The fields of solved circles, written once: one speed's tilts
    (:class:`CircleSolution`) or every (tilt, speed) circle of a grid
    (:class:`GridResult`, the same arrays stacked with the speed after the tilt axis;
    ``steps`` and ``dt`` then per speed). Their docstrings give the shapes."""

    K: np.ndarray
    S: np.ndarray
    u_d: np.ndarray
    phi_d: np.ndarray
    tension: np.ndarray
    reasons: np.ndarray
    spectral_radius: np.ndarray
    sweeps: np.ndarray
    lin_samples: np.ndarray
    lin_error: np.ndarray
    steps: int | np.ndarray
    dt: float | np.ndarray
    offsets: np.ndarray
    mode_tau: np.ndarray
    mode_frequency: np.ndarray
    mode_damping: np.ndarray
    mode_shape: np.ndarray
    gain_max_free: np.ndarray
    gain_margin: np.ndarray
    input_margin: np.ndarray
    delay_margin: np.ndarray
    crossover: np.ndarray


@dataclass(frozen=True)
class CircleSolution(_Circles):
    """The periodic LQR solution of one speed at several tilts: what a table holds of it.

    Returned by :func:`solve_circle`; every array has the tilt as its leading axis
    (``n_a`` tilts), then the ``n_xi`` grid azimuths ``xi_j = 2 pi j / n_xi`` (rad) where
    it has them. ``n`` is the LQR state dimension (11 for configs/paper.toml: the order
    of :func:`gainsched.schedule.linearize.lqr_state_names`, docs/conventions.md), the 4
    inputs are the motor thrusts T1..T4 (N). A circle with any infeasible sample (slack
    tether, thrust limits, trim failure) has no gains: NaN in ``K``, ``S`` and
    ``spectral_radius``, and ``reasons`` says why.

    Attributes
    ----------
    K : ndarray, shape (n_a, n_xi, 4, n)
        Gains at the grid azimuths for ``u = u_d - K (x - x_d)``, N per state unit
        (N/rad, N s/rad, N/(rad s) for the integral); NaN where infeasible.
    S : ndarray, shape (n_a, n_xi, n, n)
        Riccati cost-to-go at the grid azimuths; NaN where infeasible.
    u_d : ndarray, shape (n_a, n_xi, 4)
        Nominal motor thrusts T1..T4, N (paper eqs. 15-18); NaN where the trim failed.
    phi_d : ndarray, shape (n_a, n_xi)
        Nominal roll, rad.
    tension : ndarray, shape (n_a, n_xi)
        Nominal tether tension, N (negative: the tether would have to push).
    reasons : ndarray of uint8, shape (n_a, n_xi)
        Feasibility bits, 0 = feasible (:class:`gainsched.constants.Reason`: 1 slack,
        2 thrust below minimum, 4 thrust above maximum, 8 trim failed, 16 this sample
        is fine but another one of the circle is not).
    spectral_radius : ndarray, shape (n_a,)
        Spectral radius of the closed-loop monodromy over one period (< 1: stable);
        NaN if infeasible.
    sweeps : ndarray of int32, shape (n_a,)
        Periods folded into the periodic terminal cost plus the final sweep; -1 for a
        tilt-0 circle solved by the DARE (infinite horizon), 0 if infeasible.
    lin_samples : ndarray of int32, shape (n_a,)
        Azimuths of exact linearisation, interpolated to every step
        (:func:`discrete_system`); 1 for a tilt-0 circle solved by the DARE, ``steps``
        when computed at every step, 0 if infeasible.
    lin_error : ndarray, shape (n_a,)
        Relative error of that interpolation check (0 when computed directly; NaN if
        infeasible).
    steps : int
        Control steps per period, ``N = 2 round(T / (2 dt_c))`` (even), with ``T = 2 pi
        r / speed`` and ``dt_c`` the configured control period.
    dt : float
        Discretisation step ``T / N``, s (within 0.15 % of ``dt_c`` on the paper grid).
    offsets : ndarray, shape (n_a, 2, 2 H + 1)
        Fourier coefficients in the azimuth (``[c0, a_1..a_H, b_1..b_H]``, rad, H = 3) of
        the nominal's pitch and yaw offsets
        (:class:`~gainsched.schedule.offsets.AttitudeOffsets`); zero for none.
    mode_tau : ndarray, shape (n_a, M)
        Time constants of the M slowest closed-loop Floquet modes, slowest first, s
        (:mod:`gainsched.schedule.modes`; M = 4, a complex pair counts once); NaN if
        infeasible.
    mode_frequency : ndarray, shape (n_a, M)
        Their frequencies, rad/s (0: real; a periodic loop's principal value).
    mode_damping : ndarray, shape (n_a, M)
        Their damping ratios (1: real).
    mode_shape : ndarray, shape (n_a, M, n)
        Their eigenvectors' magnitudes in the states' units, largest entry 1.
    gain_max_free : ndarray, shape (n_a,)
        Largest gain magnitude at the grid azimuths of the LQR without
        ``[control] max_time_constant_s`` (the price of the bound is ``max |K|`` against
        it; the same as ``max |K|`` without a bound), N per state unit; NaN if infeasible.
    gain_margin : ndarray, shape (n_a, 2)
        The loop's gain margins, down and up, broken at the thrust commands of all four
        motors at once: the factors on the commands at which a Floquet multiplier reaches
        the unit circle (:mod:`gainsched.schedule.margins`; 0: stable with the feedback
        off, inf: stable beyond :data:`~gainsched.schedule.margins.G_MAX`); NaN if
        infeasible or ``[control] margins = false``.
    input_margin : ndarray, shape (n_a, 4, 2)
        The same for each motor's command alone (T1..T4; down, up).
    delay_margin : ndarray, shape (n_a,)
        The extra delay on the commands that puts a multiplier on the unit circle, s
        (inf: beyond :data:`~gainsched.schedule.margins.TAU_MAX_S`); NaN as above.
    crossover : ndarray, shape (n_a,)
        The frequency of that multiplier, the loop's crossover, rad/s
        (:func:`~gainsched.schedule.margins.crossover_frequency`; a tilted circle's the
        alias nearest its level circle's); NaN where none or as above.
    """

    @classmethod
    def empty(cls, n_a: int, n_xi: int, n: int, steps: int, dt: float) -> CircleSolution:
        """A solution of ``n_a`` tilts with nothing solved yet, to be filled in place:
        NaN gains, nominal and figures, ``reasons`` "trim failed", no offsets.

        Parameters
        ----------
        n_a, n_xi, n : int   tilts, grid azimuths, LQR states
        steps : int   control steps per period; dt : float   their length, s
        """
        def nan(*shape):
            return np.full(shape, np.nan)

        return cls(nan(n_a, n_xi, 4, n), nan(n_a, n_xi, n, n), nan(n_a, n_xi, 4),
                   nan(n_a, n_xi), nan(n_a, n_xi),
                   np.full((n_a, n_xi), Reason.TRIM_FAILED, dtype=np.uint8), nan(n_a),
                   np.zeros(n_a, dtype=np.int32), np.zeros(n_a, dtype=np.int32), nan(n_a),
                   steps, dt, np.zeros((n_a, 2, 2 * HARMONICS + 1)), nan(n_a, MODE_COUNT),
                   nan(n_a, MODE_COUNT), nan(n_a, MODE_COUNT), nan(n_a, MODE_COUNT, n),
                   nan(n_a), nan(n_a, 2), nan(n_a, N_INPUT, 2), nan(n_a), nan(n_a))


def _sample_steps(N, n_xi):
    """Steps bracketing the grid azimuths 2 pi j / n_xi and the linear weights.

    Returns ``(steps, lo, hi, w)``: the distinct steps to keep, and for every grid
    azimuth the indices into ``steps`` of its two bracketing steps and the weight of
    the upper one.
    """
    pos = np.arange(n_xi) * (N / n_xi)
    k = np.floor(pos).astype(int)
    steps, inv = np.unique(np.concatenate([k, (k + 1) % N]), return_inverse=True)
    return steps, inv[:n_xi], inv[n_xi:], pos - k


def _sample(X, lo, hi, w):
    """Linear interpolation along axis 1 between the kept steps (see :func:`_sample_steps`)."""
    w = w.reshape((1, w.size) + (1,) * (X.ndim - 2))
    return (1 - w) * X[:, lo] + w * X[:, hi]


def _tilt0(model, config, speed, N, dt, Qx):
    """Tilt 0 with effects that keep the rotation about the vertical
    (:func:`level_circle_invariant`): the circle's linearisation is the same at every
    azimuth, so the periodic problem is time-invariant and its solution is the DARE's,
    exactly. Returns ``K (4, n), S (n, n), spectral radius``, the modes of ``A - B K``
    (:func:`~gainsched.schedule.modes.floquet_modes` with the step ``dt``), max |K|
    without the config's ``max_time_constant_s`` (the same K without one) and the step's
    ``A (n, n), B (n, 4)``."""
    Ad, Bd = discrete_at(model, speed, [0.0], 1, dt)
    A, B = Ad[0, 0], Bd[0, 0]
    scale = stability_scale(dt, config.control.max_time_constant_s)
    K, S, E = dlqr(A, B, Qx, config.control.R)
    gain_max_free = float(np.abs(K).max())
    if scale != 1.0:  # the prescribed degree of stability: the DARE of the scaled system
        K, S, _ = dlqr(scale * A, scale * B, Qx, config.control.R)
        E = np.linalg.eigvals(A - B @ K)
    return (K, S, float(np.abs(E).max()) ** N, floquet_modes(A - B @ K, dt), gain_max_free,
            A, B)


def solve_circle(config, speed: float, tilts, *, keep_steps=False, dare_tilt0=None,
                 margins=None):
    """Solve the periodic LQR of one circle speed at several tilts (one batch).

    For each tilt the nominal (paper eqs. 15-18, with pitch and yaw offsets where
    ``[feasibility] attitude_offsets = "free"`` needs them) is checked at every control
    step, the model is linearised along it and discretised, and the periodic Riccati
    recursion (paper Sec. IV.B, eq. 23; periodic terminal cost unless the config says
    ``terminal = "single-period"``) gives the gains, kept at the ``n_xi`` grid azimuths.
    This is one job of :func:`build_grid`; call it alone to look at one circle.

    Parameters
    ----------
    config : Config
        The config (:func:`load_config`): vehicle, effects, weights, control rate and
        ``grid.azimuth_samples`` (n_xi).
    speed : float
        Tangential COG speed, m/s (> 0; need not be a grid speed). The azimuth rate is
        ``speed / r``, ``r = rho + L_e`` (``config.radius``, m).
    tilts : array_like of float, shape (n_a,)
        Circle tilts ``alpha_C``, rad (>= 0: the table's fundamental domain).
    keep_steps : bool, default False
        Also return every control step's discrete system and gain, for checks
        (:func:`gainsched.midpoint_check`); every tilt then goes through the periodic
        recursion (no DARE).
    dare_tilt0 : bool or None, default None
        Solve tilt-0 circles by the DARE: a level circle whose effects look the same at
        every azimuth is time-invariant, and its periodic solution is the DARE's,
        exactly. ``None``: when the effects allow it (:func:`level_circle_invariant`), the
        decision :func:`build_grid` takes once per build.
    margins : bool or None, default None
        Compute each loop's stability margins (:mod:`gainsched.schedule.margins`);
        ``None``: as ``[control] margins`` says. Checks that only need the gains pass
        False.

    Returns
    -------
    sol : CircleSolution
        Gains, cost-to-go, nominal and feasibility at the tilts (leading axis) and grid
        azimuths.
    steps : tuple of ndarray or None
        Only with ``keep_steps``: ``(A_d, B_d, K)`` of the ``b`` feasible tilts, in order,
        at all ``N`` steps of the period: shapes (b, N, n, n), (b, N, n, 4), (b, N, 4,
        n); None when no tilt is feasible.

    See Also
    --------
    build_grid : Every (speed, tilt) circle of the config's grid.

    Notes
    -----
    ``N = 2 round(T / (2 dt_c))`` steps per period (even, so that the symmetry maps land
    on steps), discretised with ``dt = T / N``. The linearisation is exact at 64-128
    azimuths and carried to every step by trigonometric interpolation
    (:func:`discrete_system`); the gain at a grid azimuth is interpolated linearly between
    the two steps that bracket it (docs/table-format.md).

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> sol = gs.solve_circle(cfg, 9.0, np.deg2rad([0, 20]))   # 9 m/s, level and 20 deg
    >>> sol.K.shape                                 # (tilt, azimuth, input, state)
    (2, 36, 4, 11)
    >>> sol.steps, round(sol.dt, 7)                 # steps per period, s
    (1118, 0.0009991)
    >>> np.round(sol.spectral_radius, 3).tolist()   # closed loop over a period: stable
    [0.952, 0.952]
    >>> np.round(sol.u_d[1, 0], 3).tolist()         # nominal T1..T4 at 20 deg, xi = 0, N
    [1.412, 1.412, 1.461, 1.461]

    At 2 m/s the 20 deg circle is too slow to keep the tether taut: it has no gains.

    >>> slow = gs.solve_circle(cfg, 2.0, np.deg2rad([0, 20]))
    >>> np.isnan(slow.spectral_radius).tolist()
    [False, True]
    >>> round(float(slow.tension[1].min()), 2)      # N
    -0.43
    >>> int(np.bitwise_or.reduce(slow.reasons[1]))  # slack (1), fine elsewhere (16)
    17
    """
    model = Model(config)
    if dare_tilt0 is None:
        dare_tilt0 = level_circle_invariant(model)
    tilts = np.asarray(tilts, dtype=float)
    margins = config.control.margins if margins is None else margins
    N = steps_per_period(speed, model.r, config.control.dt)
    n_lqr = config.control.n_lqr  # reduced state and integrals; effect states follow
    n = model.n_z - N_STATE + n_lqr
    out = CircleSolution.empty(tilts.size, config.grid.azimuth_samples, n, N,
                               period(speed, model.r) / N)
    ok = np.flatnonzero(_fill_nominals(out, model, speed, tilts) == 0)
    Qx = np.zeros((n, n))
    Qx[:n_lqr, :n_lqr] = config.control.Q
    if dare_tilt0 and not keep_steps and config.control.terminal == "periodic":
        for i in ok[tilts[ok] == 0.0]:
            _fill_tilt0(out, i, model, config, speed, Qx, margins)
        ok = ok[tilts[ok] != 0.0]
    steps = _fill_periodic(out, ok, model, config, speed, tilts, Qx, keep_steps, margins)
    return (out, steps) if keep_steps else out


def _fill_nominals(out: CircleSolution, model, speed, tilts) -> np.ndarray:
    """The nominal of every tilt into ``out`` (feed-forward, roll, tension and reasons at
    the grid azimuths, the attitude offsets); returns the feasibility bits (n_a,) uint8
    of every control step together, 0 where the tilt can have gains."""
    n_xi = out.K.shape[1]
    bad = np.zeros(tilts.size, dtype=np.uint8)
    if model.closed_form_drag() is None:  # the numerical trim: every tilt's at once
        solve_circles(model, circle_path(speed, model.r, np.zeros(1)), tilts)
    for i, a in enumerate(tilts):
        try:
            # feasibility is checked on the nominal at every control step
            bad[i] = np.bitwise_or.reduce(circle_nominal(model, speed, a, out.steps).reasons)
            g = circle_nominal(model, speed, a, n_xi)
        except TrimError:
            bad[i] = Reason.TRIM_FAILED
            continue
        out.u_d[i], out.phi_d[i], out.tension[i] = g.u, g.phi, g.tension
        off = circle_offsets(model, speed, a)
        if off is not None:
            out.offsets[i] = off.pitch, off.yaw
        elsewhere = (g.reasons == 0) & (bad[i] != 0)
        out.reasons[i] = g.reasons | np.where(elsewhere, Reason.ELSEWHERE, 0).astype(np.uint8)
    return bad


def _put_margins(out: CircleSolution, idx, lm) -> None:
    out.gain_margin[idx] = np.stack([lm.gain_down, lm.gain_up], axis=-1)
    out.input_margin[idx] = np.stack([lm.input_down, lm.input_up], axis=-1)
    out.delay_margin[idx], out.crossover[idx] = lm.delay, lm.crossover


def _put_modes(out: CircleSolution, idx, m) -> None:
    out.mode_tau[idx], out.mode_frequency[idx], out.mode_damping[idx], out.mode_shape[idx] = (
        m.tau, m.frequency, m.damping, m.shape)


def _fill_tilt0(out: CircleSolution, i: int, model, config, speed, Qx, margins) -> None:
    """Tilt ``i`` (0) by the DARE (:func:`_tilt0`): infinite horizon, one linearisation."""
    K, S, out.spectral_radius[i], modes, out.gain_max_free[i], A, B = _tilt0(
        model, config, speed, out.steps, out.dt, Qx)
    out.K[i], out.S[i] = K, S
    _put_modes(out, i, modes)
    if margins:  # one step: the period's product is its N-th power
        _put_margins(out, [i], loop_margins(A[None, None], B[None, None], K[None, None],
                                            out.dt, xtol=MARGIN_XTOL,
                                            delay_xtol=MARGIN_DELAY_XTOL))
    out.lin_samples[i], out.lin_error[i], out.sweeps[i] = 1, 0.0, -1  # infinite horizon


def _fill_periodic(out: CircleSolution, ok, model, config, speed, tilts, Qx, keep_steps,
                   margins):
    """The periodic Riccati recursion (paper eq. 23) of the feasible tilts ``ok``, in
    batches of :data:`~gainsched.constants.TILT_BATCH`, into ``out``; returns the steps
    ``(A_d, B_d, K)`` with ``keep_steps`` (see :func:`solve_circle`), else None."""
    N, dt, ctrl = out.steps, out.dt, config.control
    scale = stability_scale(dt, ctrl.max_time_constant_s)
    keep, lo, hi, w = _sample_steps(N, out.K.shape[1])
    kept = []
    # the level circle's delay margin (solved first, by the DARE) starts the tilted
    # circles' search: they lie within a few percent of it on the paper grid
    level = np.flatnonzero((tilts == 0.0) & np.isfinite(out.delay_margin))
    guess = float(out.delay_margin[level[0]]) if level.size else None
    w0 = float(out.crossover[level[0]]) if level.size else None  # picks the alias
    for c in range(0, ok.size, TILT_BATCH):
        idx = ok[c : c + TILT_BATCH]
        Ad, Bd, M, err = discrete_system(model, speed, tilts[idx], N, dt)
        out.lin_samples[idx], out.lin_error[idx] = M, err
        As, Bs = (Ad, Bd) if scale == 1.0 else (scale * Ad, scale * Bd)
        every = keep_steps or margins  # the gains of every step
        sol = periodic_lqr(As, Bs, Qx, ctrl.R, terminal=ctrl.terminal,
                           keep_S=True, steps=None if every else keep)
        # the monodromy of the real loop: prod (A_k - B_k K_k) = scale^-N prod (scaled)
        Phi = sol.Phi if scale == 1.0 else sol.Phi * scale ** -N
        Ks, Ss = sol.K, sol.S
        if every:  # pick the grid's bracketing steps
            Ks, Ss = Ks[:, keep], Ss[:, keep]
        if keep_steps:
            kept.append((Ad, Bd, sol.K))
        if margins:  # the real loop's: the model's A_k, B_k (not the scaled ones)
            _put_margins(out, idx, loop_margins(Ad, Bd, sol.K, dt, xtol=MARGIN_XTOL,
                                                delay_xtol=MARGIN_DELAY_XTOL,
                                                block=surrogate_block(dt), delay_guess=guess,
                                                crossover_guess=w0, monodromy=Phi))
        out.K[idx] = _sample(Ks, lo, hi, w)
        out.S[idx] = _sample(Ss, lo, hi, w)
        out.spectral_radius[idx] = spectral_radius(Phi)
        _put_modes(out, idx, floquet_modes(Phi, N * dt))
        if scale != 1.0:  # the price of the bound: the gains without it
            free = periodic_lqr(Ad, Bd, Qx, ctrl.R, terminal=ctrl.terminal, steps=keep)
            out.gain_max_free[idx] = np.abs(_sample(free.K, lo, hi, w)).max(axis=(1, 2, 3))
        else:
            out.gain_max_free[idx] = np.abs(out.K[idx]).max(axis=(1, 2, 3))
        out.sweeps[idx] = sol.sweeps
    return tuple(np.concatenate(x) for x in zip(*kept, strict=True)) if kept else None


@dataclass(frozen=True)
class GridResult(_Circles):
    """The solved schedule grid: gains and nominal at every (tilt, speed, azimuth) point.

    Returned by :func:`build_grid` and written by :func:`gainsched.write_outputs`. The
    arrays are those of :class:`CircleSolution` with a speed axis after the tilt axis:
    ``n_a`` tilts and ``n_v`` speeds of ``[grid]``, ``n_xi`` azimuths, ``n`` LQR states
    (11 for configs/paper.toml), 4 motor thrusts.

    Attributes
    ----------
    K : ndarray, shape (n_a, n_v, n_xi, 4, n)
        Gains for ``u = u_d - K (x - x_d)``, N per state unit; NaN where infeasible.
    S : ndarray, shape (n_a, n_v, n_xi, n, n)
        Riccati cost-to-go; NaN where infeasible.
    u_d, phi_d, tension, reasons : ndarray, shape (n_a, n_v, n_xi, ...)
        The nominal thrusts (N), roll (rad), tether tension (N) and feasibility bits of
        :class:`CircleSolution`, every speed's stacked after the tilt axis.
    spectral_radius : ndarray, shape (n_a, n_v)
        Closed-loop monodromy spectral radius per circle (< 1: stable); NaN if
        infeasible.
    sweeps : ndarray of int32, shape (n_a, n_v)
        Periods in the terminal cost plus the final sweep (-1: DARE, 0: infeasible).
    lin_samples : ndarray of int32, shape (n_a, n_v)
        Azimuths of exact linearisation per circle (1: DARE, 0: infeasible).
    lin_error : ndarray, shape (n_a, n_v)
        Relative error of the linearisation's interpolation check (NaN: infeasible).
    steps : ndarray of int, shape (n_v,)
        Control steps per period at each speed.
    dt : ndarray, shape (n_v,)
        Discretisation step per speed, s.
    offsets : ndarray, shape (n_a, n_v, 2, 2 H + 1)
        Fourier coefficients (rad, H = 3) of the nominal's pitch and yaw offsets per
        circle; zero for none.
    mode_tau, mode_frequency, mode_damping : ndarray, shape (n_a, n_v, M)
        The M slowest closed-loop Floquet modes per circle, slowest first: time constant
        s, frequency rad/s, damping ratio (as in :class:`CircleSolution`); NaN if
        infeasible.
    mode_shape : ndarray, shape (n_a, n_v, M, n)
        Their eigenvectors' magnitudes in the states' units, largest entry 1.
    gain_max_free : ndarray, shape (n_a, n_v)
        Largest gain magnitude of the LQR without ``max_time_constant_s`` per circle, N
        per state unit (as in :class:`CircleSolution`).
    gain_margin : ndarray, shape (n_a, n_v, 2)
        Gain margins (down, up factors) of all four motors per circle (as in
        :class:`CircleSolution`; NaN without ``[control] margins``).
    input_margin : ndarray, shape (n_a, n_v, 4, 2)
        Those of each motor alone.
    delay_margin : ndarray, shape (n_a, n_v)
        The delay margin per circle, s.
    crossover : ndarray, shape (n_a, n_v)
        The crossover per circle, rad/s.
    level_invariant : bool
        Tilt 0 was solved by the DARE, one gain per speed independent of the azimuth
        (:func:`level_circle_invariant`); False when an effect changes with the azimuth
        of a level circle (the table then stores tilt-0 gains per azimuth).
    reverse : GridResult or None
        The same grid of the vehicle's mirror image (:func:`mirror_config`), whose
        forward circles are the vehicle's reversed ones mirrored (docs/symmetry.md); None
        when the vehicle is its own mirror image.
    """

    level_invariant: bool = True
    reverse: GridResult | None = None

    def gain_max(self) -> np.ndarray:
        """Largest gain magnitude per circle, N per state unit; NaN where infeasible.

        Returns
        -------
        ndarray, shape (n_a, n_v)
        """
        finite = np.isfinite(self.K)
        k_max = np.abs(self.K).max(axis=(2, 3, 4), initial=0.0, where=finite)
        return np.where(finite.any(axis=(2, 3, 4)), k_max, np.nan)


def solve_speed(config, speed: float, tilts, effects=(), dare_tilt0=True) -> CircleSolution:
    """One job of :func:`build_grid`: all tilts of one speed, on one BLAS thread.
    ``effects``: the registered (not built-in) effect classes the config names, which a
    worker process does not know otherwise (they travel with the job, by value)."""
    ensure_blas_single_thread()
    with registered_effects_context(effects):
        return solve_circle(config, speed, tilts, dare_tilt0=dare_tilt0)


def build_grid(config, *, n_jobs=1, progress=None, backend=None) -> GridResult:
    """Solve the periodic LQR at every (speed, tilt) circle of a config's grid.

    One :func:`solve_circle` job per speed of ``[grid] speeds`` (all tilts batched),
    assembled in config order. The result does not depend on ``n_jobs``, ``backend`` or
    the machine's CPU family (pinned numerics, :mod:`gainsched.native.reproducible`), so
    the table written from it is byte-identical everywhere. Publish it with
    :func:`gainsched.write_outputs`.

    Parameters
    ----------
    config : Config
        The config (:func:`gainsched.load_config`); its ``[grid]`` gives the speeds (m/s),
        tilts (rad) and azimuth samples.
    n_jobs : int, default 1
        Worker processes (-1: all cores).
    progress : callable or None, default None
        Called with 1 after each finished speed (e.g. ``tqdm(total=n_v).update``).
    backend : str, optional
        Name of the joblib backend (``"loky"``, ``"threading"``, ``"sequential"``,
        ``"dask"``); default: local pinned worker processes, or Dask when a Dask joblib
        backend is active.

    Returns
    -------
    GridResult
        Arrays over (tilt, speed, azimuth): gains ``K`` (n_a, n_v, n_xi, 4, n), nominal,
        feasibility and closed-loop spectral radius.

    Raises
    ------
    InputError
        An effect of the config breaks the tilt-sign or direction symmetry the table's
        lookups rely on (names the config and ``effects.<kind>``).

    See Also
    --------
    solve_circle : One speed at some tilts.
    gainsched.write_outputs : Write the grid as a table, C header and runtime.

    Examples
    --------
    A small grid of the paper vehicle (2 speeds, 2 tilts, 8 azimuths):

    >>> cfg = gs.load_config("configs/paper.toml")
    >>> small = cfg.with_values({"grid.speeds": [6, 9], "grid.tilts_deg": [0, 20],
    ...                          "grid.azimuth_samples": 8, "name": "small"})
    >>> grid = gs.build_grid(small)
    >>> grid.K.shape                                 # (tilt, speed, azimuth, input, state)
    (2, 2, 8, 4, 11)
    >>> grid.steps.tolist(), bool(np.all(grid.reasons == 0))
    ([1676, 1118], True)
    >>> np.round(grid.spectral_radius, 3).tolist()   # (tilt, speed): all stable
    [[0.84, 0.952], [0.839, 0.952]]
    """
    if config.grid.auto:
        raise InputError(config.source, config.grid.auto_key, "is a range the build chooses "
                         "breakpoints in: build it with gainsched.refine_grid (gainsched "
                         "build does)")
    check_effect_symmetries(config)
    speeds = config.grid.speeds
    tilts = config.grid.tilts
    extra = registered_effects({s.name for s in config.effects})
    invariant = level_circle_invariant(Model(config))  # once per build, not per job
    image = mirror_config(config)
    args = [(config, float(v), tilts, extra, invariant) for v in speeds]
    if image is not None:  # each speed's job solves the vehicle and its mirror image
        args = [(*a, image) for a in args]
    sols = []
    with blas_single_thread():
        for s in run_jobs(args, n_jobs, backend,
                          solve_speed if image is None else solve_speed_and_image):
            sols.append(s)
            if progress is not None:
                progress(1)
    if image is None:
        grid = grid_from_solutions(sols, invariant)
    else:
        grid = dataclasses.replace(
            grid_from_solutions([s[0] for s in sols], invariant),
            reverse=grid_from_solutions([s[1] for s in sols], invariant))
        check_gain_cap(config, grid.reverse)
        check_margin_bounds(config, grid.reverse)
    check_gain_cap(config, grid)
    check_margin_bounds(config, grid)
    return grid


def solve_speed_and_image(config, speed, tilts, effects, dare_tilt0, image):
    """One job of a build whose vehicle is not its own mirror image (:func:`build_grid`,
    the automatic grid's refinement): :func:`solve_speed` of ``config`` and of its mirror
    image ``image`` (:func:`mirror_config`), a pair."""
    return (solve_speed(config, speed, tilts, effects, dare_tilt0),
            solve_speed(image, speed, tilts, effects, dare_tilt0))


def grid_from_solutions(sols, level_invariant: bool) -> GridResult:
    """The :class:`GridResult` of one :class:`CircleSolution` per speed (in axis order),
    each over the same tilts: the arrays stacked with the speed after the tilt axis."""
    per_tilt = {f.name: np.stack([getattr(s, f.name) for s in sols], axis=1)
                for f in fields(CircleSolution) if f.name not in ("steps", "dt")}
    return GridResult(**per_tilt, steps=np.array([s.steps for s in sols]),
                      dt=np.array([s.dt for s in sols]), level_invariant=level_invariant)
