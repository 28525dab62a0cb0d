"""The control loops: the path controller of paper Sec. IV and the firmware's whole
control step, flying a scenario on a plant."""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..config import N_STATE, Config
from ..constants import INTEGRATORS
from ..errors import GainschedWarning, InputError
from ..firmware.runtime import NO_GAINS, UNUSABLE, status_text
from ..model.geometry import wrap_angle
from ..model.reduced import Model
from ..rotations import (
    matrix_from_euler_zyx_scalar,
    matrix_from_quaternion,
    quaternion_from_matrix_scalar,
)
from ..schedule.nominal import circle_offsets, nominal_from_path
from ..schedule.path import AzimuthPath
from ..schedule.trim import TrimError
from ._estimator import _Estimator
from ._plant import DelayedCommands, _Plant
from ._result import SimResult, _Record
from ._scenario import Scenario, profile_path
from ._schedulers import Scheduler

__all__ = [
    "LOOKUP_BITS",
    "simulate",
    "uncompensated_latency_text",
]


#: the lookup's status bits (SimResult.status) among the firmware controller's
LOOKUP_BITS = 0xFF

#: steps per block of gain lookups of a scheduler with ``batch`` (bounds the memory)
_LOOKUP_BLOCK = 1000


def simulate(design: Config, scheduler, scenario: Scenario, plant: Config | None = None,
             progress=None, controller: str = "path", command_delay: float = 0.0) -> SimResult:
    """Fly a scenario in closed loop: the scheduled LQR on the nonlinear tethered vehicle.

    The control law of paper Sec. IV, ``u = u_d - K(xi_d, xi_d', alpha) (x - x_d)``, at the
    design's control rate: ``x`` is the LQR state (the 10 reduced states, the azimuth error from
    continuous azimuths, plus the integral states of ``[control]`` and the design model's effect
    states, a motor lag's thrusts, which no sensor measures: they are predicted from the applied
    input with the design model, as a firmware can), ``(x_d, u_d)`` the nominal of the reference
    path and ``K`` the scheduled gains, looked up at the reference. The plant is integrated by
    fixed-step RK4 with the input held over each step (zero-order hold); the commands saturate
    at the plant's thrust limits; the flight stops cleanly when the tether goes slack.

    Parameters
    ----------
    design : Config
        The model the tables were built from: the nominal ``(x_d, u_d)`` along the reference,
        the control step ``control.dt`` (s), the integral states and the tension margin.
    scheduler : Scheduler or callable
        The gains at the reference: a :class:`Scheduler` (:func:`table_scheduler`,
        :func:`runtime_scheduler`, :func:`c_runtime_scheduler`; one that is ``batched``
        is asked for blocks of steps at once, the same numbers), or a plain callable
        ``(xi, xi_dot, alpha) -> (K (4, n), status)`` (rad, rad/s, rad; N per unit of LQR
        state). Where a lookup is unusable (``NO_GAINS``, bad input) the last good gains
        are flown (``SimResult.held``), as the firmware does.
    scenario : Scenario
        The flight: circle, speed profile, duration, sensing, initial error.
    plant : Config, optional
        The truth that is flown: its own parameters, effects, link model (rigid or
        elastic) and thrust limits (N). Default: ``design`` (a perfect model).
    progress : callable, optional
        ``progress(100)`` after every 100 steps (a progress bar's increment).
    controller : {"path", "firmware"}, default "path"
        ``"path"``: the law above in Python, the nominal ``(x_d, u_d)`` from the design
        model along the reference (closed form or trim), the state from the sensing
        below. ``"firmware"``: the firmware's whole control step
        (:mod:`gainsched.firmware.controller`, docs/runtime.md), sensors in, thrusts out,
        with only what a firmware has (the table's lookup, the drag-only closed form with
        the table's correction, its own estimator): the C controller through ctypes with
        ``c_runtime_scheduler`` (software in the loop), its Python reference with
        ``table_scheduler``. Ideal sensing gives it the true COG kinematics; motion
        capture the delayed noisy poses, the gyro and the accelerometer (the plant's
        specific force), its pose delay set to the latency unless
        ``sensing.latency_compensation`` is false.
    command_delay : float, default 0
        Extra delay from a command to the motors, s (>= 0): the plant applies ``(1 - f)
        u_{k-d} + f u_{k-d-1}``, ``command_delay / dt = d + f`` (docs/margins.md).

    Returns
    -------
    SimResult
        Time histories at the control rate from t = 0: ``round(duration / dt) + 1`` samples,
        fewer when the tether went slack.

    Raises
    ------
    InputError
        No usable gains where the flight starts or no nominal along it (no trim), or
        ``controller="firmware"`` on a C runtime without closed-form constants.
    ValueError
        ``controller`` is neither ``"path"`` nor ``"firmware"``, ``"firmware"`` with a
        scheduler that is no :class:`Scheduler` (a plain callable), or a negative
        ``command_delay``.

    Examples
    --------
    Half a second of the level 8 m/s circle, started 0.01 rad out of the plane (the
    scenario's initial error):

    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> table = gs.load_table("tables/paper.h5")
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> res = gs.simulate(cfg, gs.table_scheduler(table), scn)
    >>> res.t.shape, res.z.shape, res.u.shape, res.slack_time
    ((501,), (501, 10), (501, 4), None)
    >>> f"{1000 * gs.metrics(res)['max_out_of_plane_m']:.0f} mm"
    '15 mm'

    The same gains on a vehicle 10 % heavier than the design (a plant of its own):

    >>> heavy = gs.config_from_text(cfg.text.replace("mass = 0.5 ", "mass = 0.55"), "heavy")
    >>> res = gs.simulate(cfg, gs.table_scheduler(table), scn, plant=heavy)
    >>> f"{1000 * gs.metrics(res)['max_out_of_plane_m']:.0f} mm"
    '37 mm'
    """
    plant = design if plant is None else plant
    if not (np.isfinite(command_delay) and command_delay >= 0):
        raise ValueError(f"command_delay must be >= 0 s, got {command_delay!r}")
    P, dmodel = _Plant(plant, scenario.gamma), Model(design)
    dt = design.control.dt
    if command_delay > 0:
        P = DelayedCommands(P, command_delay / dt)
    t = np.arange(int(round(scenario.duration / dt)) + 1) * dt
    path = profile_path(scenario, dmodel.r, t)
    if controller == "path":
        return _fly_path(design, scheduler, scenario, plant, P, dmodel, path, progress)
    if controller == "firmware":  # no trim of the design model: only what a firmware has
        return _fly_firmware(design, scheduler, scenario, plant, P, path, progress)
    raise ValueError(f"controller must be 'path' or 'firmware', got {controller!r}")


def _refuse_to_engage(scenario: Scenario, status: int, speed: float, alpha: float):
    """The InputError of a flight whose table has no usable gains where it starts."""
    return InputError(
        scenario.origin, "speed",
        f"the table has no usable gains where the flight starts ({status_text(status)}"
        f" at speed {speed:.3g} m/s, tilt "
        f"{math.degrees(alpha):.3g} deg): a firmware would refuse to engage")


class _PathGains:
    """The path controller's gains at each step of the reference: one lookup per step,
    or blocks of :data:`_LOOKUP_BLOCK` steps from a ``batched`` :class:`Scheduler`; an
    unusable lookup (``NO_GAINS``, bad input) flies the last good gains, the firmware's
    policy, and where there are none yet the flight is refused."""

    def __init__(self, scheduler, path, alpha: float, scenario: Scenario, radius: float):
        self.scheduler, self.alpha, self.scenario, self.radius = (scheduler, alpha, scenario,
                                                                  radius)
        self.xi_ref, self.xi_dot_ref = path.xi, path.d[0]
        self.batch = (scheduler.batch if isinstance(scheduler, Scheduler) and scheduler.batched
                      else None)
        self.K_blk = self.S_blk = None
        self.K_good = None  # the last usable gains (held through NO_GAINS / bad lookups)

    def __call__(self, k: int):
        """``(K, status, held)`` of step ``k`` (held: the last good gains are flown)."""
        if self.batch is None:
            K, status = self.scheduler(self.xi_ref[k], self.xi_dot_ref[k], self.alpha)
        else:
            j = k % _LOOKUP_BLOCK
            if j == 0:
                blk = slice(k, k + _LOOKUP_BLOCK)
                self.K_blk, S_blk = self.batch(self.xi_ref[blk], self.xi_dot_ref[blk],
                                               self.alpha)
                self.S_blk = S_blk.tolist()
            K, status = self.K_blk[j], self.S_blk[j]
        if status & UNUSABLE:  # the firmware policy: hold the last good gains
            if self.K_good is None:
                raise _refuse_to_engage(self.scenario, status,
                                        self.xi_dot_ref[k] * self.radius, self.alpha)
            return self.K_good, status, True
        self.K_good = K
        return K, status, False


def _fly_path(design, scheduler, scenario, plant, P, dmodel, path, progress) -> SimResult:
    """``simulate(..., controller="path")``: the law of paper Sec. IV in Python on the
    plant ``P``, the nominal from the design model ``dmodel`` along ``path``, the state
    from the scenario's sensing (:class:`_Estimator`)."""
    dt, alpha, t = design.control.dt, scenario.tilt, path.t
    n_steps = t.size
    # a constant-speed circle flies the table's nominal, attitude offsets included
    offsets = (circle_offsets(dmodel, scenario.speed, alpha) if not scenario.maneuvers
               else None)
    try:
        nom = nominal_from_path(dmodel, path, alpha, offsets=offsets)
    except TrimError as e:  # the design model cannot fly the reference: refuse, one line
        raise InputError(
            scenario.origin, "maneuvers" if scenario.maneuvers else "speed",
            f"the design model `{design.name}` has no nominal along this flight ({e}): "
            "the flight may ask more than the vehicle can fly") from None
    z_d, u_d, tension_d = nom.z[:, :N_STATE], nom.u, nom.tension
    u_min, u_max = plant.vehicle.thrust_min, plant.vehicle.thrust_max

    z0 = z_d[0].copy()
    if scenario.initial_error:
        z0[: len(scenario.initial_error)] += np.asarray(scenario.initial_error)
    x = P.initial(z0, u_d[0])
    sens = scenario.sensing
    rng = np.random.default_rng(sens.seed)
    # a design with effect states (motor lag) predicts them too, from the nominal's start
    est = _Estimator(dmodel, P, sens, dt, alpha, scenario.gamma,
                     np.concatenate([z0, nom.z[0, N_STATE:]]), rng,
                     sensors=(plant.sensors, design.sensors))

    rec = _Record(n_steps, x, P)
    X, Z, Zh, U, TEN, SAT, STAT, HELD = (rec.X, rec.Z, rec.Zh, rec.U, rec.TEN, rec.SAT,
                                         rec.STAT, rec.HELD)
    # per-step work kept to a few small numpy calls: bound methods and arrays looked
    # up once, the LQR error vector (11 + zero-padded effect states) reused
    step, reduced, estimate, predict = P.step, P.reduced, est.estimate, est.predict
    rigid = P.maximal is None
    gains = _PathGains(scheduler, path, alpha, scenario, dmodel.r)
    # integral states of the design (int_delta, int_xi): the errors they integrate
    int_idx = [INTEGRATORS[name] for name in design.control.integrators]
    n_lqr = N_STATE + len(int_idx)
    xerr = np.zeros(n_lqr)
    zx_d = nom.z[:, N_STATE:]  # the nominal's effect states (motor lag: its thrusts)
    n_fx = zx_d.shape[1]
    integ = np.zeros(len(int_idx))
    xi_true = z0[1]  # the plant's azimuth, tracked continuously (elastic links)
    slack_time = None
    n_done = n_steps
    for k in range(n_steps):
        X[k] = x
        z_true = x[:N_STATE] if rigid else reduced(x, xi_true)
        xi_true = z_true[1]
        z_hat = estimate(k, x, z_true)
        # no wrap: the estimate and the reference are continuous azimuths, so the error
        # stays right past half a lap (a lag of 4 rad is a lag, not a lead of 2.3 rad)
        err = z_hat - z_d[k]
        K, status, held = gains(k)
        if held:
            HELD[k] = True
        n = K.shape[-1]
        if n > xerr.size:
            xerr = np.zeros(n)
        xerr[:N_STATE] = err
        xerr[N_STATE:n_lqr] = integ
        if n_fx and n >= n_lqr + n_fx:  # the design's effect states: predicted - nominal
            xerr[n_lqr:n_lqr + n_fx] = est.effect_states - zx_d[k]
        u_raw = u_d[k] - K @ xerr[:n]
        u = np.minimum(np.maximum(u_raw, u_min), u_max)  # np.clip, without its overhead
        SAT[k] = u != u_raw
        x_next, ten = step(x, u, alpha, dt)
        if not rigid:
            Z[k] = z_true
        Zh[k], U[k], TEN[k], STAT[k] = z_hat, u, ten, status & LOOKUP_BITS
        if ten < 0:
            slack_time = float(t[k])
            n_done = k + 1
            break
        predict(u)
        if int_idx:  # (2.3 us a step without integrators otherwise: empty arrays' overhead)
            integ += dt * err[int_idx]
        x = x_next
        if progress is not None and k % 100 == 99:
            progress(100)
    return rec.result(n_done, t, z_d, u_d, tension_d, slack_time, scenario, dmodel.r, design,
                      plant)


def uncompensated_latency_text(origin, latency: float, speed: float, radius: float) -> str:
    """The warning of a firmware flight whose poses arrive ``latency`` s late while the
    controller's ``pose_delay`` is 0: the estimate settles onto the delayed poses, so it
    lags the vehicle by about ``speed * latency`` (m) along the circle and the controller
    flies that far ahead; nothing in the controller's own signals shows it (docs/runtime.md,
    "Accuracy by sensor configuration")."""
    lead = abs(speed) * latency / radius
    return (f"{origin}: sensing.latency_compensation: the controller's pose_delay is 0 with "
            f"poses {1000 * latency:g} ms late: its estimate lags the vehicle by about "
            f"{lead:.2g} rad along the circle at {abs(speed):g} m/s, which it flies ahead "
            f"(and the out-of-plane error grows); a firmware sets pose_delay to its poses' "
            f"latency")


class _FirmwareSensors:
    """The firmware controller's input row of each step (``gs_ctrl_step``'s inputs,
    :data:`~gainsched.firmware.controller.INPUT_SLICES`): ideal sensing gives the true
    COG kinematics (``FLAG_KINEMATICS``); motion capture gives poses taken every
    ``every`` steps with noise, arriving ``delay`` steps late, the noisy gyro and the
    accelerometer (``FLAG_ACCEL`` unless the scenario flies without it)."""

    def __init__(self, sens, alpha: float, gamma: float, every: int, delay: int, rng,
                 sensors=None):
        from ..firmware.controller import INPUT_SLICES, N_INPUT

        self.sens, self.every, self.delay, self.rng = sens, every, delay, rng
        # the plant's gyro and markers (its config's [sensors]): what the gyro reads of
        # the body rates, the attitude the motion capture reports of the body's
        calibrated = sensors is None or sensors.identity
        self.gyro = None if calibrated else sensors.readings
        self.markers = None if calibrated else sensors.marker_attitude
        self.accel = None if calibrated else sensors.accel_readings
        self.col = INPUT_SLICES
        self.row = np.zeros(N_INPUT)
        self.row[self.col["alpha"]], self.row[self.col["gamma"]] = alpha, gamma
        self.pending: list[tuple[int, np.ndarray, np.ndarray]] = []

    def fill(self, k: int, p_I, v_I, q_IB, w_B, f_B, ref_k) -> np.ndarray:
        """The row of step ``k`` from the true sensors' values and the reference."""
        from ..firmware.controller import FLAG_ACCEL, FLAG_KINEMATICS, FLAG_POSE

        sens, row, col, rng, pending = self.sens, self.row, self.col, self.rng, self.pending
        if sens.ideal:
            row[0] = FLAG_KINEMATICS
            row[col["p_I"]], row[col["v_I"]], row[col["q_IB"]] = p_I, v_I, q_IB
            row[col["gyro"]] = w_B if self.gyro is None else self.gyro(w_B)
        else:
            if k % self.every == 0:  # a pose taken now arrives after the latency
                p_m = p_I + sens.position_noise * rng.standard_normal(3)
                rot = sens.attitude_noise * rng.standard_normal(3)
                R_m = matrix_from_quaternion(q_IB) @ matrix_from_euler_zyx_scalar(*rot)
                if self.markers is not None:
                    R_m = self.markers(R_m)
                pending.append((k + self.delay, p_m, quaternion_from_matrix_scalar(R_m)))
            flags = FLAG_ACCEL if sens.accelerometer else 0
            if pending and pending[0][0] <= k:
                _, p_m, q_m = pending.pop(0)
                flags |= FLAG_POSE
                row[col["p_I"]], row[col["q_IB"]] = p_m, q_m
            row[0] = flags
            row[col["gyro"]] = ((w_B if self.gyro is None else self.gyro(w_B))
                                + sens.gyro_noise * rng.standard_normal(3))
            row[col["accel"]] = ((f_B if self.accel is None else self.accel(f_B))
                                 + sens.accel_noise * rng.standard_normal(3))
        row[col["ref"]] = ref_k
        return row


def _firmware_controller(design, scheduler, scenario, path, xi_w, every: int, delay: int):
    """The firmware's nominal along the reference, the controller's parameters and the
    scheduler's controller with them (the C controller, software in the loop, or its
    Python reference); ``lk``, each step's lookup for the Python reference, else None."""
    from ..firmware.controller import Controller, controller_params

    if not isinstance(scheduler, Scheduler):
        raise ValueError("controller='firmware' needs a scheduler with the table's "
                         "controller (table_scheduler, c_runtime_scheduler or "
                         "runtime_scheduler)")
    dt, alpha, sens = design.control.dt, scenario.tilt, scenario.sensing
    ff = scheduler.feedforward(AzimuthPath(path.t, xi_w, path.d), alpha)
    params = controller_params(scheduler.data, pose_period=every * dt,
                               pose_delay=delay * dt if sens.latency_compensation else 0.0)
    if not sens.ideal and delay > 0 and params.pose_delay == 0:
        warnings.warn(uncompensated_latency_text(scenario.origin, sens.latency, scenario.speed,
                                                 design.radius),
                      GainschedWarning, stacklevel=4)
    ctl = scheduler.controller(params)
    lk = None
    if isinstance(ctl, Controller):  # the Python reference takes each step's nominal
        lk = scheduler.batch(xi_w, path.d[0], np.full(path.t.size, alpha))[0]
    return ff, params, ctl, lk


def _fly_firmware(design, scheduler, scenario, plant, P, path, progress) -> SimResult:
    """``simulate(..., controller="firmware")``: the firmware's whole loop, sensors in and
    thrusts out (:mod:`gainsched.firmware.controller`), in C through ctypes or its Python
    reference, on the plant ``P``, its inputs from :class:`_FirmwareSensors`."""
    from ..firmware.controller import CTRL_HELD, CTRL_SATURATED

    dt, alpha, gamma = design.control.dt, scenario.tilt, scenario.gamma
    sens = scenario.sensing
    t = path.t
    n_steps = t.size
    xi_w = wrap_angle(path.xi)
    ref = np.stack([xi_w, *path.d], axis=1)
    every = max(1, int(round(1.0 / (sens.rate_hz * dt))))
    delay = int(round(sens.latency / dt))
    ff, params, ctl, lk = _firmware_controller(design, scheduler, scenario, path, xi_w, every,
                                               delay)
    z_d, u_d, tension_d = ff.x_d.copy(), ff.u_d, ff.tension
    z_d[:, 1] = path.xi  # continuous, as the path controller's
    u_min, u_max = plant.vehicle.thrust_min, plant.vehicle.thrust_max
    z0 = z_d[0].copy()
    z0[1] = path.xi[0]
    if scenario.initial_error:
        z0[: len(scenario.initial_error)] += np.asarray(scenario.initial_error)
    x = P.initial(z0, u_d[0])
    inputs = _FirmwareSensors(sens, alpha, gamma, every, delay,
                              np.random.default_rng(sens.seed), plant.sensors)
    u_now = u_d[0]
    if not sens.ideal:
        p_I, v_I, q_IB, _, _ = P.sensors(x, u_now, alpha, gamma)
        ctl.reset(p_I, v_I, q_IB)  # the estimator starts on the true state
    rec = _Record(n_steps, x, P)
    X, Z, Zh, U, TEN, SAT, STAT, HELD = (rec.X, rec.Z, rec.Zh, rec.U, rec.TEN, rec.SAT,
                                         rec.STAT, rec.HELD)
    CTRL = rec.CTRL = np.zeros(n_steps, dtype=np.int32)
    t_lo, t_hi = (float(np.float32(v)) for v in (params.thrust_min, params.thrust_max))
    # outputs other than N in T1..T4 come back through the thrust curve: a clipped
    # thrust to float32 rounding of the command
    newtons = params.motor_slot == (0, 1, 2, 3) and not params.normalized
    clip_tol = 0.0 if newtons else 1e-5 * max(abs(t_lo), abs(t_hi))
    slack_time = None
    n_done = n_steps
    xi_true = z0[1]
    for k in range(n_steps):
        X[k] = x
        z_true = x[:N_STATE] if P.maximal is None else P.reduced(x, xi_true)
        xi_true = z_true[1]
        row = inputs.fill(k, *P.sensors(x, u_now, alpha, gamma, accel=not sens.ideal), ref[k])
        if lk is not None:
            out, status, z_hat = ctl.step(row, (lk[k], ff.x_d[k], ff.u_d[k],
                                                int(ff.status[k])))
        else:
            out, status, z_hat = ctl.step(row)
        thrust = out if newtons else params.thrust_from_commands(out)  # mixer and motors
        if k == 0 and status & NO_GAINS:
            raise _refuse_to_engage(scenario, status, path.d[0][0] * design.radius, alpha)
        u = np.minimum(np.maximum(thrust, u_min), u_max)
        # clipped: by the plant's limits, or by the controller at the design's
        SAT[k] = (u != thrust) | (bool(status & CTRL_SATURATED) & (
            (np.abs(thrust - t_lo) <= clip_tol) | (np.abs(thrust - t_hi) <= clip_tol)))
        HELD[k] = bool(status & CTRL_HELD)
        CTRL[k] = status
        x_next, ten = P.step(x, u, alpha, dt)
        if P.maximal is not None:
            Z[k] = z_true
        z_hat = z_hat.copy()
        z_hat[1] += 2 * np.pi * np.round((z_true[1] - z_hat[1]) / (2 * np.pi))
        Zh[k], U[k], TEN[k], STAT[k] = z_hat, u, ten, status & LOOKUP_BITS
        if ten < 0:
            slack_time = float(t[k])
            n_done = k + 1
            break
        x, u_now = x_next, u
        if progress is not None and k % 100 == 99:
            progress(100)
    return rec.result(n_done, t, z_d, u_d, tension_d, slack_time, scenario, design.radius,
                      design, plant)
