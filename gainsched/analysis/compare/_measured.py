"""Model versus measurement: the residual of the model on flight logs.

The workflow and the statistics are described in docs/model-vs-measurement.md.

Pipeline, per gap-free log segment (:class:`~gainsched.analysis.logs.FlightLog`):

1. **Reduced coordinates from the pose.** The attachment point
   ``p_t = p_q + R_CB p_e`` in the circle frame gives the tether distance
   ``d = |p_t|`` and the spherical angles ``(delta, xi)``; ``R_CB`` gives the
   Z-Y-X Euler angles ``(phi, theta, psi)``, ``chi = psi - xi`` (docs/conventions.md,
   the conversion of :func:`gainsched.model.maximal.reduced_from_maximal`).
   These six channels vary slowly even at 15 m/s (xi and psi grow linearly),
   which is why they, and not the Cartesian pose, are differentiated.
2. **Differentiation.** Savitzky-Golay (:func:`scipy.signal.savgol_filter`,
   window and order from ``[analysis]``) gives each channel and its first two
   derivatives; the COG velocity and acceleration and the body rates and
   their derivatives follow from exact kinematics
   (``p_q'' = p_t'' - R (omega' x p_e + omega x (omega x p_e))``, paper eq. 9
   corrected; Euler rates to body rates). Half a window at each segment end,
   where the filter extrapolates, is dropped from every statistic.
3. **Prediction.** The model's forces for the measured state and the logged
   commands (centred on the sample time: a logged command is held over the
   interval before its sample): thrust along z_B after the thrust modifiers,
   gravity, effect forces and torques (paper eqs. 3, 6, 8, 10), the tether
   tension from the load cell when logged, otherwise solved from the radial
   equation. Stateful effects (motor lag) are run along the log. The
   predicted accelerations are smoothed with the same filter as the
   measurement, so the residual compares like with like.
4. **Residual** ``measured - predicted`` on the axes of :data:`AXES`:
   tangential (along the direction of travel), normal (to the circle plane),
   radial (outward along the tether; only with a load cell, since the
   radial equation is otherwise used up by the tension), the body angular
   accelerations (roll, pitch, yaw), and the tether stretch
   ``d - rho - predicted stretch`` (m; zero for a rigid tether).

Statistics per axis (:func:`axis_stats`): RMS, bias, NRMSE fit %, the noise
floor (the motion-capture noise pushed through the same pipeline), whiteness
(autocorrelation beyond the filter's own support, against a Bartlett band)
and the cross-correlation with the inputs and their rates at +-lags.
:func:`where_it_fails` bins the residual against airspeed, tilt, azimuth,
tension, thrust and time in flight and names the worst regime.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.ndimage import convolve1d, uniform_filter1d
from scipy.signal import correlate, lfilter, savgol_coeffs, savgol_filter

from ...config import Config
from ...constants import BIN_VARIABLES
from ...errors import InputError
from ...model.effects import Effect, Kinematics, wind_in_circle_frame
from ...model.geometry import (
    attachment_from_cog,
    cog_from_attachment,
    spherical_from_point,
    tether_direction,
)
from ...model.reduced import Model
from ...model.rotations import (
    R_IC_from_tilt,
    euler_zyx_from_matrix,
    matrix_from_euler_zyx,
    matrix_from_quaternion,
    up_C_from_tilt,
)
from ..logs import FlightLog, LogWarning, read_log
from ..structure import findings

__all__ = [
    "centred_commands",
    "AXES",
    "UNITS",
    "BIN_VARIABLES",
    "Measured",
    "Residual",
    "AxisStats",
    "Comparison",
    "load_segments",
    "measure",
    "predict",
    "residuals",
    "residual_axes",
    "axis_stats",
    "where_it_fails",
    "compare",
    "tracking_summary",
    "window_samples",
    "noise_floor",
    "AT_NOISE_FLOOR",
    "MOTOR_ORDER_FACTOR",
    "motor_order_fits",
    "check_motor_order",
]

#: Residual axes, in report order.
AXES = ("tangential", "normal", "radial", "roll", "pitch", "yaw", "stretch")
UNITS = {
    "tangential": "m/s^2",
    "normal": "m/s^2",
    "radial": "m/s^2",
    "roll": "rad/s^2",
    "pitch": "rad/s^2",
    "yaw": "rad/s^2",
    "stretch": "m",
}
#: the on-board sensor that measures a translational axis (the rotational: the gyro)
_SENSOR_OF = {"tangential": "accelerometer", "normal": "accelerometer",
              "radial": "accelerometer"}
#: RMS / noise floor below which an axis counts as explained down to the noise
AT_NOISE_FLOOR = 1.25
_INPUT_NAMES = ("T_C", "tau_x", "tau_y", "tau_z")
_CHANNELS = ("d", "delta", "xi", "phi", "theta", "psi")
#: samples of the cubic fit whose residual estimates an IMU channel's noise (gyro, accelerometer)
IMU_NOISE_WINDOW = 5


def window_samples(window_s: float, dt: float, order: int, source="", where="") -> int:
    """Savitzky-Golay window in samples: ``window_s / dt`` rounded to an odd integer > order."""
    n = int(round(window_s / dt))
    n += 1 - n % 2
    if n <= order + 1:
        raise InputError(
            source or "config",
            where or "analysis.savgol_window_s",
            f"{window_s:g} s is {n} samples at {1 / dt:.4g} Hz; needs more than "
            f"savgol_order + 1 = {order + 1}",
        )
    return n


# --------------------------------------------------------------------------- measurement


@dataclass(frozen=True, eq=False)
class Measured:
    """One log segment in reduced coordinates, differentiated (arrays over the whole segment).

    Attributes
    ----------
    name : str
        Flight id (or file name) plus the segment number when the file was split.
    source : str
        The log file.
    alpha, gamma : float, rad
        Circle plane of the flight.
    t : (N,) s
    t_flight : (N,) s
        Time in flight: the log's own clock (``t``; a segment after a gap keeps its times).
    window : int
        Savitzky-Golay window, samples; ``core`` drops half of it at each end.
    order : int
    z : (N, 10)
        Reduced state (delta, xi, delta', xi', phi, theta, chi, omega_B), rad, rad/s.
    acc : (N, 3)
        (delta'', xi'') rad/s^2 and d'' m/s^2.
    d, d_dot : (N,) m, m/s
        Distance anchor -> attachment point and its rate.
    p, v, a : (N, 3) m, m/s, m/s^2
        COG position, velocity and acceleration in the circle frame C.
    R : (N, 3, 3)
        Body -> circle rotation R_CB.
    omega_dot : (N, 3) rad/s^2
        Body angular acceleration.
    e : (N, 3)
        Tether direction (anchor -> attachment point) in C.
    axes : (N, 3, 3)
        Unit path-frame axes in C, rows (tangential along the travel direction,
        normal, radial outward).
    T_cmd : (N, 4) N
        Logged commands (each held over the interval before its sample).
    tension : (N,) N or None
        Load cell.
    raw_sigma : dict
        Noise std of each raw channel (d m; angles rad; the gyro's p, q, r rad/s), from
        the Savitzky-Golay fit residual.
    L_e : float, m
        Attachment offset the reduced coordinates were computed with.
    gyro : (N, 3) rad/s or None
        The logged gyro (on-board time, like the commands), when the log has one and
        ``analysis.use_gyro`` is on.
    gyro_dot : (N, 3) rad/s^2 or None
        Its Savitzky-Golay derivative: the measured body angular acceleration (one
        differentiation; ``omega_dot`` is the pose's, two).
    accel : (N, 3) m/s^2 or None
        The logged accelerometer's specific force in B (on-board time), when the log has
        one and ``analysis.use_accelerometer`` is on.
    gravity_C : (3,) m/s^2
        Gravity in C (what the accelerometer does not sense).
    vbat : (N,) V or None
        The logged battery voltage (on-board time, like the commands; NaN where a sample
        is missing), when the log has one: the state of effects whose ``log_channel`` is
        ``"vbat"`` (:class:`~gainsched.model.effects.ThrustVoltage`).
    """

    name: str
    source: str
    alpha: float
    gamma: float
    t: np.ndarray
    t_flight: np.ndarray
    window: int
    order: int
    z: np.ndarray
    acc: np.ndarray
    d: np.ndarray
    d_dot: np.ndarray
    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    R: np.ndarray
    omega_dot: np.ndarray
    e: np.ndarray
    axes: np.ndarray
    T_cmd: np.ndarray
    tension: np.ndarray | None
    raw_sigma: dict = field(default_factory=dict)
    L_e: float = 0.0
    cache: dict = field(default_factory=dict, repr=False)  # model-independent derived arrays
    gyro: np.ndarray | None = None
    gyro_dot: np.ndarray | None = None
    accel: np.ndarray | None = None
    gravity_C: np.ndarray | None = None
    vbat: np.ndarray | None = None

    def acc_measured(self, latency: float) -> np.ndarray:
        """The measured COG acceleration on the path axes (``axes``: tangential, normal,
        radial), (N, 3) m/s^2, on the pose's clock: from the accelerometer when there is
        one (its specific force delayed by ``latency`` s like the commands, rotated by the
        pose's attitude, plus gravity, projected, then smoothed like the prediction: on
        the path axes a circle's acceleration is constant, in C it turns), else the
        twice-differentiated pose (``a``) projected."""
        if self.accel is None:
            return self.derived("acc_pose", lambda: np.einsum("nij,nj->ni", self.axes, self.a))
        hit = self.cache.get("acc_imu")
        if hit is None or hit[0] != latency:  # one latency kept: a fit moves it step by step
            f_C = np.einsum("nij,nj->ni", self.R, _delayed(self.t, self.accel, latency))
            a_path = np.einsum("nij,nj->ni", self.axes, f_C + self.gravity_C)
            self.cache["acc_imu"] = (latency, savgol_filter(
                a_path, self.window, self.order, axis=0, mode="interp"))
        return self.cache["acc_imu"][1]

    def omega_dot_measured(self, latency: float) -> np.ndarray:
        """The measured body angular acceleration (N, 3), rad/s^2, on the pose's clock:
        from the gyro when there is one (delayed by ``latency`` s, like the commands it
        is compared with), else from the pose."""
        if self.gyro_dot is None:
            return self.omega_dot
        return _delayed(self.t, self.gyro_dot, latency)

    def derived(self, key: str, fn):
        """``fn()`` computed once per segment (kinematics, projections)."""
        if key not in self.cache:
            self.cache[key] = fn()
        return self.cache[key]

    @property
    def dt(self) -> float:
        """Median sample interval, s."""
        return self.derived("dt", lambda: float(np.median(np.diff(self.t))))

    @property
    def core(self) -> slice:
        """Samples where the filter window fits inside the segment."""
        h = self.window // 2
        return slice(h, len(self.t) - h)

    @property
    def n_core(self) -> int:
        return max(0, len(self.t) - 2 * (self.window // 2))


def _raw_channels(log: FlightLog, L_e: float, p_I=None, R_IB=None):
    """Raw (d, delta, xi, phi, theta, psi), shape (6, N), from the logged pose (or the given
    p_I (N, 3), R_IB (N, 3, 3)); xi and psi unwrapped, psi on the branch of xi."""
    R_IC = R_IC_from_tilt(log.alpha_c, log.gamma_c)
    p_C = np.einsum("nj,ji->ni", log.p_I if p_I is None else p_I, R_IC)  # rows R_IC^T p
    R = np.einsum("ji,njk->nik", R_IC, matrix_from_quaternion(log.q) if R_IB is None else R_IB)
    d, delta, xi = spherical_from_point(attachment_from_cog(p_C, R, np.array([-L_e, 0.0, 0.0])))
    xi = np.unwrap(xi)
    phi, theta, psi = euler_zyx_from_matrix(R)
    psi = np.unwrap(psi)
    psi += 2 * np.pi * np.round((xi[0] - psi[0]) / (2 * np.pi))  # chi = psi - xi near 0
    return np.stack([d, delta, xi, phi, theta, psi])


def _reconstruct(ch, ch1, ch2, L_e):
    """Kinematics from the smoothed channels (6, N) and their derivatives (rates, accelerations)."""
    d, delta, xi, phi, theta, psi = ch
    dd_, ddelta, dxi, dphi, dtheta, dpsi = ch1
    d2, ddelta2, dxi2, dphi2, dtheta2, dpsi2 = ch2
    sp, cp, st, ct = np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta)
    w = np.stack(
        [dphi - dpsi * st, dtheta * cp + dpsi * sp * ct, -dtheta * sp + dpsi * cp * ct], -1
    )
    w_dot = np.stack(
        [
            dphi2 - dpsi2 * st - dpsi * dtheta * ct,
            dtheta2 * cp - dtheta * dphi * sp + dpsi2 * sp * ct + dpsi * dphi * cp * ct
            - dpsi * dtheta * sp * st,
            -dtheta2 * sp - dtheta * dphi * cp + dpsi2 * cp * ct - dpsi * dphi * sp * ct
            - dpsi * dtheta * cp * st,
        ],
        -1,
    )
    R = matrix_from_euler_zyx(phi, theta, psi)
    direction = tether_direction(delta, xi)
    e, e_d, e_x = direction.e, direction.e_delta, direction.e_xi
    col = lambda a: a[:, None]  # noqa: E731
    e_dot = direction.rate(ddelta, dxi)
    e_ddot = direction.acceleration(ddelta, dxi, ddelta2, dxi2)
    p_e = np.array([-L_e, 0.0, 0.0])
    w_pe = np.cross(w, p_e)
    p_t = col(d) * e
    v_t = col(dd_) * e + col(d) * e_dot
    a_t = col(d2) * e + 2 * col(dd_) * e_dot + col(d) * e_ddot
    p = cog_from_attachment(p_t, R, p_e)
    v = v_t - np.einsum("nij,nj->ni", R, w_pe)
    a = a_t - np.einsum("nij,nj->ni", R, np.cross(w_dot, p_e) + np.cross(w, w_pe))
    sgn = np.where(dxi < 0, -1.0, 1.0)
    t_hat = e_x / np.linalg.norm(e_x, axis=-1, keepdims=True) * col(sgn)
    axes = np.stack([t_hat, -e_d, e], 1)
    z = np.concatenate(
        [np.stack([delta, xi, ddelta, dxi, phi, theta, psi - xi], -1), w], -1
    )
    acc = np.stack([ddelta2, dxi2, d2], -1)
    return z, acc, p, v, a, R, w_dot, e, axes


def measure(log: FlightLog, config: Config, *, name: str | None = None) -> Measured:
    """Differentiate one log segment (steps 1-2 of the module docstring).

    Raises :class:`InputError` naming the file when the segment is shorter than the window,
    and naming the thrust columns when no sample has a positive commanded thrust (the
    model's forces need it: without it every residual is the whole measured acceleration
    and the thrust-efficiency analysis divides by zero).
    """
    an = config.analysis
    rows = (f"{log.row_label}s {log.where(0).split()[-1]}-{log.where(len(log) - 1).split()[-1]}"
            if len(log) else "no samples")
    if not np.any(np.sum(log.T_cmd, axis=-1) > 0):
        raise InputError(
            log.source,
            f"columns T1, T2, T3, T4, {rows}",
            "the commanded thrust is zero on every sample: a log without thrust commands "
            "cannot be compared with the model",
        )
    dt = float(np.median(np.diff(log.t)))
    n = window_samples(an.savgol_window_s, dt, an.savgol_order, config.source)
    if len(log) < 2 * n + 1:
        raise InputError(
            log.source,
            f"column t, {rows}",
            f"{len(log)} samples, fewer than twice the differentiation window "
            f"({n} samples = analysis.savgol_window_s {an.savgol_window_s:g} s) plus one",
        )
    L_e = config.tether.attachment_offset
    raw = _raw_channels(log, L_e)
    ch, ch1, ch2 = _smoothed(raw, n, an.savgol_order, dt)
    z, acc, p, v, a, R, w_dot, e, axes = _reconstruct(ch, ch1, ch2, L_e)
    h = n // 2
    hc = savgol_coeffs(n, an.savgol_order)[h]
    fit_res = (raw - ch)[:, h : len(log) - h]
    sig = np.sqrt(np.mean(fit_res**2, axis=-1) / max(1e-12, 1 - hc))
    sigma = dict(zip(_CHANNELS, map(float, sig), strict=True))
    gyro, gyro_dot = _gyro(log, an, n, dt)
    if gyro is not None:
        sigma.update(zip(("p", "q", "r"), _imu_sigma(gyro, h), strict=True))
    accel = _accelerometer(log, an)
    if accel is not None:
        sigma.update(zip(("ax", "ay", "az"), _imu_sigma(accel, h), strict=True))
    tension = log.optional.get("tension")
    if tension is not None and not np.all(np.isfinite(tension)):
        tension = None  # a load cell with missing samples is not used (radial equation instead)
    vbat = log.optional.get("vbat")
    base = name or (log.meta.get("flight_id") or Path(log.source).stem or "log")
    if log.n_segments > 1:
        base = f"{base}#{log.segment + 1}"
    return Measured(
        base, str(log.source), log.alpha_c, log.gamma_c, np.asarray(log.t, float),
        np.asarray(log.t, float), n, an.savgol_order, z, acc, ch[0], ch1[0], p, v, a,
        R, w_dot, e, axes, np.asarray(log.T_cmd, float),
        None if tension is None else np.asarray(tension, float), sigma, L_e,
        gyro=gyro, gyro_dot=gyro_dot, accel=accel,
        gravity_C=-config.g * up_C_from_tilt(log.alpha_c),
        vbat=None if vbat is None else np.asarray(vbat, float),
    )


def _imu_sigma(x: np.ndarray, h: int) -> list[float]:
    """White-noise std per column of an IMU channel ``x`` (N, 3), from the residual of a
    5-point cubic fit: short enough to follow the motion (the roll rate moves within the
    pose window), so the residual is noise; samples within ``h`` of the ends left out."""
    hc = savgol_coeffs(IMU_NOISE_WINDOW, 3)[IMU_NOISE_WINDOW // 2]
    res = (x - savgol_filter(x, IMU_NOISE_WINDOW, 3, axis=0))[h : len(x) - h]
    return [float(v) for v in np.sqrt(np.mean(res**2, axis=0) / (1 - hc))]


def _imu_channel(log: FlightLog, column: str, enabled: bool, noise=None):
    """A logged on-board sensor channel (N, 3) plus ``noise`` (N, 3) when given (the
    noise-floor estimate), or None without one, with its use switched off in
    ``[analysis]``, or with missing samples."""
    x = log.optional.get(column)
    if not enabled or x is None or not np.all(np.isfinite(x)):
        return None
    return np.asarray(x, float) if noise is None else np.asarray(x, float) + noise


def _accelerometer(log: FlightLog, an, noise=None):
    """The logged specific force (N, 3) m/s^2 in B, or None (:func:`_imu_channel`)."""
    return _imu_channel(log, "f_B", an.use_accelerometer, noise)


def _gyro(log: FlightLog, an, n: int, dt: float, noise=None):
    """The logged gyro (N, 3) rad/s and its Savitzky-Golay derivative (N, 3) rad/s^2, or
    ``(None, None)`` (:func:`_imu_channel`)."""
    gyro = _imu_channel(log, "omega_B", an.use_gyro, noise)
    if gyro is None:
        return None, None
    return gyro, savgol_filter(gyro, deriv=1, delta=dt, window_length=n,
                               polyorder=an.savgol_order, axis=0, mode="interp")


def _smoothed(raw, window: int, order: int, dt: float):
    """The pose channels ``raw`` (k, N) smoothed and differentiated once and twice along
    the samples (Savitzky-Golay, ``window`` samples, polynomial ``order``, step ``dt`` s):
    ``(ch, ch1, ch2)``, each (k, N), per s and per s^2."""
    kw = dict(window_length=window, polyorder=order, axis=-1, mode="interp")
    return (savgol_filter(raw, deriv=0, **kw), savgol_filter(raw, deriv=1, delta=dt, **kw),
            savgol_filter(raw, deriv=2, delta=dt, **kw))


def _noisy(log: FlightLog, meas: Measured, config: Config, rng, rng_gyro=None,
           rng_accel=None) -> Measured:
    """The same segment with motion-capture noise of the estimated level added once more:
    position noise (std from the tether-distance channel, where attitude noise does not
    enter to first order) and attitude noise (std from the roll and pitch channels); and
    gyro and accelerometer noise of their estimated levels when they are used (from
    ``rng_gyro`` and ``rng_accel``, their own streams, so that the pose's noise does not
    depend on which sensors are used)."""
    an = config.analysis
    sp = meas.raw_sigma["d"]
    sa = 0.5 * (meas.raw_sigma["phi"] + meas.raw_sigma["theta"])
    n = len(log)
    rot = sa * rng.standard_normal((n, 3))
    from ...model.rotations import Rx, Ry, Rz

    R_IB = matrix_from_quaternion(log.q) @ Rz(rot[:, 2]) @ Ry(rot[:, 1]) @ Rx(rot[:, 0])
    raw = _raw_channels(log, meas.L_e, log.p_I + sp * rng.standard_normal((n, 3)), R_IB)
    dt = meas.dt
    ch, ch1, ch2 = _smoothed(raw, meas.window, an.savgol_order, dt)
    z, acc, p, v, a, R, w_dot, e, axes = _reconstruct(ch, ch1, ch2, meas.L_e)
    gyro, gyro_dot = None, None
    if meas.gyro is not None:  # the gyro's own noise, once more
        g_sig = np.array([meas.raw_sigma[k] for k in ("p", "q", "r")])
        gyro, gyro_dot = _gyro(log, an, meas.window, dt,
                               g_sig * (rng_gyro or rng).standard_normal((n, 3)))
    accel = None
    if meas.accel is not None:  # the accelerometer's own noise, once more
        a_sig = np.array([meas.raw_sigma[k] for k in ("ax", "ay", "az")])
        accel = _accelerometer(log, an, a_sig * (rng_accel or rng).standard_normal((n, 3)))
    return Measured(meas.name, meas.source, meas.alpha, meas.gamma, meas.t, meas.t_flight,
                    meas.window, meas.order, z, acc, ch[0], ch1[0], p, v, a, R, w_dot, e, axes,
                    meas.T_cmd, meas.tension, meas.raw_sigma, meas.L_e, gyro=gyro,
                    gyro_dot=gyro_dot, accel=accel, gravity_C=meas.gravity_C,
                    vbat=meas.vbat)


# --------------------------------------------------------------------------- prediction


def _delayed(t, x, latency):
    """``x(t - latency)`` by linear interpolation (held at the first sample), x shape (N, k)."""
    if latency == 0:
        return x
    tq = t - latency
    return np.stack([np.interp(tq, t, x[:, j]) for j in range(x.shape[1])], -1)


def centred_commands(T):
    """Command at the sample time from interval-held commands (mean of the adjacent two)."""
    out = T.copy()
    out[:-1] = 0.5 * (T[:-1] + T[1:])
    return out


def effect_states(eff: Effect, t, T_cmd, kin_fn=None) -> np.ndarray:
    """States of a stateful effect along the log, shape (N, n_states).

    Motor lag is discretised exactly for commands held over each interval
    (``x_k = a x_{k-1} + (1 - a) T_k``, ``a = exp(-dt/tau)``), started in its steady
    state; other stateful effects are integrated with explicit Euler sub-steps.
    """
    exact = eff.states_from_held_commands(t, T_cmd)
    if exact is not None:
        return exact
    x = np.zeros((len(t), eff.n_states))
    sub = 10
    for k in range(1, len(t)):
        xk = x[k - 1]
        h = (t[k] - t[k - 1]) / sub
        kin = kin_fn(k - 1)
        for _ in range(sub):
            xk = xk + h * eff.state_derivative(xk, T_cmd[k], kin)
        x[k] = xk
    return x


def has_channel(meas: Measured, channel: str) -> bool:
    """Whether the segment logged ``channel`` (an effect's ``log_channel``, e.g.
    ``"vbat"``) on every sample: what an effect that takes its states from it needs."""
    x = getattr(meas, channel, None)
    return x is not None and bool(np.all(np.isfinite(x)))


def logged_channel(meas: Measured, eff: Effect, latency: float) -> np.ndarray:
    """The samples of ``eff.log_channel`` (on board, like the commands: delayed by
    ``latency`` s onto the pose's clock), shape (N, ...). Raises InputError naming the
    log and the column when the segment lacks it or misses a sample
    (:func:`check_logged_channels` says so before any prediction)."""
    ch = eff.log_channel
    x = getattr(meas, ch, None)
    if not has_channel(meas, ch):
        what = ("has no such column" if x is None else
                f"misses sample {int(np.flatnonzero(~np.isfinite(x))[0]) + 1} of {x.size}")
        raise InputError(meas.source, f"column {ch}", f"the model's {eff.kind} takes its "
                         f"state from the logged {ch}, and segment {meas.name} {what}")
    x = np.asarray(x, float)
    return _delayed(meas.t, x.reshape(x.shape[0], -1), latency).reshape(x.shape)


def check_logged_channels(model: Model, measured, segs=None) -> None:
    """Every segment has the log columns the model's effects take their states from
    (``Effect.log_channel``: ``vbat`` for ``thrust_voltage``), on every sample; else
    InputError naming the file, the column and the first missing row."""
    for eff in model.effects:
        ch = eff.log_channel
        if not ch:
            continue
        for i, meas in enumerate(measured):
            if has_channel(meas, ch):
                continue
            x = getattr(meas, ch, None)
            seg = segs[i] if segs is not None and i < len(segs) else None
            if x is None:
                raise InputError(meas.source, f"column {ch}", f"missing: the model's "
                                 f"[effects.{eff.kind}] takes its state from the logged "
                                 f"{ch} (docs/flight-log.md)")
            k = int(np.flatnonzero(~np.isfinite(x))[0])
            row = f", {seg.where(k)}" if seg is not None else f", sample {k + 1}"
            raise InputError(meas.source, f"column {ch}{row}", f"missing sample: the model's "
                             f"[effects.{eff.kind}] takes its state from the logged {ch} "
                             "on every sample")


@dataclass(frozen=True, eq=False)
class Prediction:
    """Predicted quantities for one segment (whole segment, before the core cut).

    ``acc`` (N, 3): predicted COG acceleration projected on the path axes (t, n, r),
    smoothed; ``omega_dot`` (N, 3) rad/s^2 smoothed; ``stretch`` (N,) m; ``tension``
    (N,) N used (load cell or radial equation); ``T`` (N, 4) N actual thrust after effects;
    ``inputs`` (N, 4) commanded (T_C, tau_x, tau_y, tau_z) at the sample times;
    ``latency`` s: how far the on-board signals were delayed onto the pose's clock;
    ``omega_dot_pose`` (N, 3) rad/s^2: the prediction smoothed for the pose's angular
    acceleration (``omega_dot`` is filtered like the gyro's when the segment has one).
    """

    acc: np.ndarray
    omega_dot: np.ndarray
    stretch: np.ndarray
    tension: np.ndarray
    T: np.ndarray
    inputs: np.ndarray
    tension_source: str
    latency: float = 0.0
    omega_dot_pose: np.ndarray | None = None


def _kelvin_voigt(f, k, c, dt):
    """Elongation of ``c s' + k s = f`` driven by the tension samples f (exact for f held)."""
    s = f / k
    if c == 0:
        return s
    a = math.exp(-dt * k / c)
    return lfilter([1 - a], [1, -a], s, zi=[a * s[0]])[0]


def _tether_stretch(config: Config, f_t, dt):
    """Predicted stretch (m) of the tether for the tension f_t (N), per ``tether.link``
    (:mod:`gainsched.model.links`): 0 for the rigid link; Kelvin-Voigt ``c s' + k s = f`` for
    the spring-damper; ``f / k_s`` plus Kelvin-Voigt ``(k_p, c)`` for the standard linear
    solid; the lumped-mass chain quasi-statically as its whole-chain spring-damper (node
    dynamics and sag neglected)."""
    teth = config.tether
    if teth.link == "rigid":
        return np.zeros_like(f_t)
    f = np.maximum(f_t, 0.0)
    s = _kelvin_voigt(f, teth.stiffness, teth.damping, dt)
    if teth.link == "sls":
        s = s + f / teth.series_stiffness
    return s


@dataclass(frozen=True)
class _Kin(Kinematics):
    """Kinematics with the body-frame (ground) velocity computed once per segment (still
    air; :func:`predict` builds a plain one in a model's wind)."""

    vB: np.ndarray | None = None

    @property
    def v_B(self):
        return self.vB


def _kinematics(meas: Measured) -> Kinematics:
    def make():
        vB = np.einsum("nji,nj->ni", meas.R, meas.v)
        return _Kin(meas.R, meas.v, meas.z[:, 7:10], meas.p, meas.alpha, meas.gamma, vB=vB)

    return meas.derived("kin", make)


@functools.lru_cache(maxsize=64)
def _savgol_kernel(window: int, order: int, deriv: int, delta: float) -> np.ndarray:
    """Convolution coefficients of :func:`scipy.signal.savgol_filter` (computed once)."""
    return savgol_coeffs(window, order, deriv=deriv, delta=delta)


def _savgol(x, meas: Measured, deriv: int, edges: bool) -> np.ndarray:
    """``savgol_filter(x, meas.window, meas.order, deriv, meas.dt, axis=0, mode="interp")``;
    ``edges=False``: without the end fits, so exact on ``meas.core`` only (the filter's
    interior is this same convolution, bit for bit)."""
    delta = meas.dt if deriv else 1.0
    if edges:
        return savgol_filter(x, meas.window, meas.order, deriv=deriv, delta=delta, axis=0,
                             mode="interp")
    return convolve1d(x, _savgol_kernel(meas.window, meas.order, deriv, delta), axis=0,
                      mode="constant")


def _gyro_operator(x, meas: Measured, edges: bool) -> np.ndarray:
    """A predicted angular acceleration ``x`` (N, k), rad/s^2, through what the gyro's
    went through. The gyro's angular acceleration is the filter's derivative of the
    rate: the prediction gets the same operator (the derivative of its running integral,
    trapezoidal, whose unknown constant the derivative removes exactly), not the
    smoothing; (N, k), rad/s^2 (``edges``: as for :func:`_savgol`)."""
    x_int = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(
        0.5 * (x[1:] + x[:-1]) * np.diff(meas.t)[:, None], axis=0)])
    return _savgol(x_int, meas, 1, edges)


def predict(model: Model, meas: Measured, *, latency: float | None = None,
            inputs: bool = True, edges: bool = True) -> Prediction:
    """The model's accelerations for the measured state and the logged commands (step 3).

    ``latency`` (s, default: the config's ``analysis.latency_s``) delays the commands and
    the load cell (both logged on board) relative to the pose (the pose lags them by it).
    ``edges=False`` is the fast path of the fits: the filtered outputs are exact on
    ``meas.core`` only (no polynomial fits at the ends), and the pose-smoothed angular
    acceleration is left out when a gyro supplies it.
    """
    cfg = model.config
    lat = cfg.analysis.latency_s if latency is None else latency
    T_raw = _delayed(meas.t, meas.T_cmd, lat)
    u = centred_commands(T_raw)
    z = meas.z
    if model.wind_I is None:
        kin = _kinematics(meas)
    else:  # the flight's heading turns the model's wind into its circle frame
        kin = Kinematics(meas.R, meas.v, meas.z[:, 7:10], meas.p, meas.alpha, meas.gamma,
                         model.wind_I)
    if model.n_extra:
        parts = [z]

        def kin_at(k):
            return Kinematics(meas.R[k], meas.v[k], z[k, 7:10], meas.p[k], meas.alpha,
                              meas.gamma, model.wind_I)

        for eff in model.effects:
            if eff.n_states and eff.log_channel:  # the log holds the states (vbat)
                parts.append(eff.states_from_log(logged_channel(meas, eff, lat)))
            elif eff.n_states:
                parts.append(effect_states(eff, meas.t, T_raw, kin_at))
        z = np.concatenate(parts, -1)
    T = model.thrust(z, u, kin)
    F0, tau0 = model.body_wrench(T, kin, meas.alpha)
    m = model.m
    if meas.tension is not None:
        f_t, source = _load_cell(meas, lat), "load cell"
    else:
        f_t, source = np.sum(meas.e * (F0 - m * meas.a), -1), "radial equation"
    a_pred = (F0 - f_t[:, None] * meas.e) / m
    e_B = meas.derived("e_B", lambda: np.einsum("nji,nj->ni", meas.R, meas.e))
    tau = tau0 - f_t[:, None] * model.tether_lever(e_B)
    wd = np.einsum("nk,jk->nj", tau, np.linalg.inv(model.J))
    acc = np.einsum("nij,nj->ni", meas.axes, a_pred)
    if meas.gyro_dot is None or edges:
        sm = _savgol(np.concatenate([acc, wd], -1), meas, 0, edges)
        acc, wd_pose = sm[:, :3], sm[:, 3:]
    else:
        acc, wd_pose = _savgol(acc, meas, 0, edges), None
    wd_gyro = wd_pose
    if meas.gyro_dot is not None:
        wd_gyro = _gyro_operator(wd, meas, edges)
    stretch = _tether_stretch(cfg, f_t, meas.dt)
    inp = np.einsum("nk,jk->nj", u, model.alloc) if inputs else None
    return Prediction(acc, wd_gyro, stretch, f_t, T, inp, source, lat, wd_pose)


# --------------------------------------------------------------------------- residuals


@dataclass(frozen=True, eq=False)
class Residual:
    """Measured, predicted and residual per axis for one segment, core samples only.

    ``measured``, ``predicted``, ``residual``: dict axis -> (n,) arrays, axes as in
    :data:`AXES` (``radial`` only with a load cell); ``variables``: dict of the
    :data:`BIN_VARIABLES` (n,) in their units; ``inputs``: dict name -> (n,) commanded
    (T_C N, tau_x/y/z N m) and their rates (``*_rate``).
    """

    name: str
    source: str
    t: np.ndarray
    measured: dict
    predicted: dict
    residual: dict
    variables: dict
    inputs: dict
    tension_source: str
    window: int

    @property
    def axes(self) -> tuple[str, ...]:
        return tuple(a for a in AXES if a in self.residual)

    def __len__(self):
        return int(self.t.size)


def _load_cell(meas: Measured, latency: float) -> np.ndarray:
    """The logged tension (N), delayed by ``latency`` s: on board, like the commands."""
    return _delayed(meas.t, meas.tension[:, None], latency)[:, 0]


def residual_axes(model: Model, meas: Measured, latency: float | None = None,
                  axes: frozenset | None = None) -> dict:
    """Only the residual per axis (core samples) of one segment: the fast path for fits
    (equal to :func:`_residual`'s bit for bit). ``axes``: the caller needs only these
    (it knows the others unchanged); with a load cell ``{"stretch"}`` alone skips the
    prediction (the stretch depends on the link and the logged tension only)."""
    lat = model.config.analysis.latency_s if latency is None else latency
    c = meas.core
    if axes == {"stretch"} and meas.tension is not None:
        f_t = _load_cell(meas, lat)
        return {"stretch": meas.d[c] - model.rho - _tether_stretch(model.config, f_t, meas.dt)[c]}
    pred = predict(model, meas, latency=lat, inputs=False, edges=False)
    acc_m = meas.acc_measured(lat)[c]
    out = {"tangential": acc_m[:, 0] - pred.acc[c, 0], "normal": acc_m[:, 1] - pred.acc[c, 1]}
    if pred.tension_source == "load cell":
        out["radial"] = acc_m[:, 2] - pred.acc[c, 2]
    wd = meas.omega_dot_measured(pred.latency)
    for j, ax in enumerate(("roll", "pitch", "yaw")):
        out[ax] = wd[c, j] - pred.omega_dot[c, j]
    out["stretch"] = meas.d[c] - model.rho - pred.stretch[c]
    return out


def _residual(model: Model, meas: Measured, pred: Prediction) -> Residual:
    c = meas.core
    acc_m = meas.acc_measured(pred.latency)
    measured = {"tangential": acc_m[c, 0], "normal": acc_m[c, 1]}
    predicted = {"tangential": pred.acc[c, 0], "normal": pred.acc[c, 1]}
    if pred.tension_source == "load cell":
        measured["radial"], predicted["radial"] = acc_m[c, 2], pred.acc[c, 2]
    wd = meas.omega_dot_measured(pred.latency)
    for j, ax in enumerate(("roll", "pitch", "yaw")):
        measured[ax], predicted[ax] = wd[c, j], pred.omega_dot[c, j]
    measured["stretch"] = meas.d[c] - model.rho
    predicted["stretch"] = pred.stretch[c]
    residual = {k: measured[k] - predicted[k] for k in measured}
    v_air = meas.v[c]
    if model.wind_I is not None:  # the model's wind: the speed relative to the air
        v_air = v_air - wind_in_circle_frame(model.wind_I, meas.alpha, meas.gamma)
    speed = np.linalg.norm(v_air, axis=-1)
    variables = {
        "airspeed": speed,
        "tilt": np.full(speed.shape, np.rad2deg(meas.alpha)),
        "azimuth": np.rad2deg(meas.z[c, 1]) % 360.0,
        "tension": pred.tension[c],
        "thrust": np.sum(meas.T_cmd[c], -1),
        "time": meas.t_flight[c],
    }
    inp = {}
    kw = dict(window_length=meas.window, polyorder=meas.order, axis=0, mode="interp")
    rates = savgol_filter(pred.inputs, deriv=1, delta=meas.dt, **kw)
    for j, nm in enumerate(_INPUT_NAMES):
        inp[nm] = pred.inputs[c, j]
        inp[nm + "_rate"] = rates[c, j]
    return Residual(meas.name, meas.source, meas.t[c], measured, predicted, residual, variables,
                    inp, pred.tension_source, meas.window)


def residuals(config: Config, measured, *, effects=None, latency=None,
              model: Model | None = None) -> list[Residual]:
    """Residuals of ``config`` (optionally with other ``effects``) on measured segments."""
    model = model or Model(config, effects)
    return [_residual(model, m, predict(model, m, latency=latency)) for m in measured]


# --------------------------------------------------------------------------- motor order

#: how many times lower the rotational residual RMS must be with the motor commands in
#: another order for :func:`check_motor_order` to refuse a log's order
MOTOR_ORDER_FACTOR = 10.0
#: the 24 orders of four motors, (24, 4), the identity first: order ``P`` reads the tool's
#: motor ``k + 1`` from the log's command column ``P[k]``
_MOTOR_ORDERS = np.array(list(itertools.permutations(range(4))))


def motor_order_fits(model: Model, measured) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """How well each of the 24 motor orders explains the measured rotation, per log file.

    For each segment one prediction (:func:`predict`) gives the rotational residual
    ``r`` (roll, pitch, yaw; core samples) of the log's own order and the actual
    thrusts ``T``; another order ``P`` changes the predicted body angular acceleration
    by ``J^-1 A (T[:, P] - T)`` (``A``: the torque rows of ``model.alloc``), put through
    the filter the measured one went through (:func:`_gyro_operator` with a gyro, the
    smoothing without). This is exact for the library's effects that act on each motor
    alike (the thrust modifiers but ``motor_efficiency``, motor lag), whose torques and
    the tether's tension see the motors only through their summed thrust; unequal
    motor efficiencies make it approximate (to their spread, a few per cent: far below
    the factor a wrong order shows).

    Parameters
    ----------
    model : Model
        The model of the comparison.
    measured : list of Measured
        The differentiated segments.

    Returns
    -------
    dict of str to (ndarray, ndarray)
        By log file (``Measured.source``): the orders, shape (24, 4) (0-based, the
        identity first; :data:`_MOTOR_ORDERS`), and the rotational residual RMS of each,
        shape (24,), rad/s^2, pooled over the file's segments and the three axes.
    """
    B = np.linalg.solve(model.J, model.alloc[1:])  # (3, 4): rad/s^2 per N of each motor
    E = np.eye(4)[:, _MOTOR_ORDERS].transpose(1, 0, 2)  # (24, 4, 4): T[:, P] = T @ E[P]
    D = np.einsum("pik,jk->pij", E - np.eye(4), B)  # (24, 4, 3): the change per N
    sse: dict[str, list] = {}
    for meas in measured:
        pred = predict(model, meas, inputs=False, edges=False)
        c = meas.core
        r = meas.omega_dot_measured(pred.latency)[c] - pred.omega_dot[c]  # (n, 3)
        G = (_gyro_operator(pred.T, meas, False) if meas.gyro_dot is not None
             else _savgol(pred.T, meas, 0, False))[c]  # (n, 4), N
        # |r - G D_P|^2 summed, from the Gram matrices (no (24, n, 3) array)
        GtG, Gtr = G.T @ G, G.T @ r
        acc = sse.setdefault(meas.source, [np.zeros(len(_MOTOR_ORDERS)), 0])
        acc[0] += (np.sum(r * r) - 2 * np.einsum("kj,pkj->p", Gtr, D)
                   + np.einsum("pkj,kl,plj->p", D, GtG, D))
        acc[1] += r.size
    return {src: (_MOTOR_ORDERS, np.sqrt(np.maximum(s, 0.0) / max(n, 1)))
            for src, (s, n) in sse.items()}


def _mapped_order(meta: dict) -> list[int] | None:
    """The channel map's ``motors.order`` a converted log records (``motors_order``,
    ``"[3, 2, 4, 1]"``), or None (no such key, or not four numbers)."""
    try:
        order = [int(i) for i in json.loads(meta["motors_order"])]
    except (KeyError, ValueError, TypeError):
        return None
    return order if len(order) == 4 else None


def check_motor_order(model: Model, measured, segs=None,
                      factor: float = MOTOR_ORDER_FACTOR) -> None:
    """Refuse a log whose motor commands are in the wrong order, before any statistic.

    A map (or a CSV writer) that puts the motors in the wrong order mirrors or swaps the
    commanded torques: the rotational residual is tens of times the right order's, and
    a fit would blame some physical effect. When another of the 24 orders explains the
    measured rotation ``factor`` times better (residual RMS, :func:`motor_order_fits`)
    than the log's, the log's order is wrong; a missing physical effect (motor lag,
    thrust loss, drag) leaves a residual that no order removes, so it never gets there.

    Parameters
    ----------
    model : Model
        The model of the comparison.
    measured : list of Measured
        The differentiated segments.
    segs : list of FlightLog, optional
        Their log segments (same order): a converted PX4 ULog or ROS 2 bag carries its
        map's ``motors_order`` in its metadata, and the error then gives the map's order
        that fits.
    factor : float, default :data:`MOTOR_ORDER_FACTOR`
        How many times lower the residual RMS must be.

    Raises
    ------
    InputError
        Naming the log file and ``motors.order`` (a converted log) or the thrust columns
        (the project's own format), with the order that fits and how much better.
    """
    meta = {m.source: s.meta for m, s in zip(measured, segs or [None] * len(measured),
                                               strict=True) if s is not None}
    for src, (orders, rms) in motor_order_fits(model, measured).items():
        best = int(np.argmin(rms))
        ratio = rms[0] / rms[best] if rms[best] > 0 else math.inf
        if best == 0 or not ratio > factor:
            continue
        P = orders[best]
        fits = (f"the commands fit the measured rotation {ratio:.0f}x better (residual RMS "
                f"{rms[best]:.3g} against {rms[0]:.3g} rad/s^2)")
        old = _mapped_order(meta.get(src, {}))
        if old is not None:
            raise InputError(src, "motors.order", f"{fits} with motors.order = "
                             f"{[old[k] for k in P]} than with the order "
                             f"{old} of the channel map {meta[src].get('channel_map', '')}: "
                             "check the map's motor order")
        cols = ", ".join(f"T{k + 1}" for k in P)
        raise InputError(src, "columns T1, T2, T3, T4", f"{fits} as the tool's motors 1..4 "
                         f"= columns {cols}: are the thrust columns in the tool's motor "
                         "order (docs/conventions.md, Motors)?")


# --------------------------------------------------------------------------- loading


def load_segments(config: Config, logs, channel_map=None, trust=(), progress=None
                  ) -> tuple[list[Measured], list[FlightLog], list[str]]:
    """Read log files (or take :class:`FlightLog` objects) and differentiate every segment.

    ``channel_map``: for PX4 ULogs and ROS 2 bags (:func:`read_log`); their normalised or
    PWM commands reach newtons through the config's ``vehicle.thrust_max`` unless the
    map gives a thrust. The files are checked against the config's vehicle
    (:mod:`gainsched.analysis.logchecks`) except for the checks named in ``trust``.
    Returns (measured segments, the log segments, warnings as text: gaps, dropped
    pieces). ``progress(1)`` is called after each log read (a progress bar's increment).
    """
    segs: list[FlightLog] = []
    notes: list[str] = []
    for item in logs:
        if isinstance(item, FlightLog):
            segs.append(item)
            continue
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LogWarning)
            segs.extend(read_log(item, channel_map=channel_map,
                                 thrust_max=config.vehicle.thrust_max, config=config,
                                 trust=trust))
        notes.extend(str(w.message) for w in caught if issubclass(w.category, LogWarning))
        if progress is not None:
            progress(1)
    if not segs:
        raise InputError("command line", "LOG", "no flight log given")
    names = [s.meta.get("flight_id") or Path(s.source).stem or "log" for s in segs]
    seen: dict[str, int] = {}
    meas = []
    for s, nm in zip(segs, names, strict=True):
        if names.count(nm) > 1 and s.n_segments == 1:
            seen[nm] = seen.get(nm, 0) + 1
            nm = f"{nm}({seen[nm]})"
        meas.append(measure(s, config, name=nm))
    return meas, segs, notes


# --------------------------------------------------------------------------- statistics


@dataclass(frozen=True)
class AxisStats:
    """Statistics of one residual axis over all segments (units: :data:`UNITS`).

    rms, bias (mean), std; fit_percent = 100 (1 - |y - y_hat| / |y - mean y|);
    noise_floor: RMS residual that the measurement noise alone produces.

    Whiteness: the differentiation filter correlates samples closer than its window
    W, so the test looks at lags W, 2W, ... up to ``max_lag_s`` (roughly independent
    estimates) of the residual standardised by its local RMS (:func:`_standardised`;
    ``acf`` is that of the standardised residual): ``Q = sum rho(kW)^2 / var`` with the
    Bartlett variance
    ``var = (1 + 2 sum_{j<W} rho(j)^2) / n``, white when Q is below the 99% point of
    chi-square with as many degrees of freedom as lags. ``acf_band`` is the 95%
    band of a single lag; ``frac_outside`` the fraction of lags >= W outside it.

    Cross-correlation of the standardised residual with each input and its rate over
    +-``max_lag_s``: ``ccf`` maps
    input -> (peak |rho|, lag s at the peak, band, significant); the band is the
    Bartlett band corrected for testing every lag (Bonferroni over the ~2L/W
    independent lags). Positive lag: the residual follows the input.
    """

    axis: str
    unit: str
    n: int
    rms: float
    bias: float
    std: float
    fit_percent: float
    noise_floor: float
    white: bool
    whiteness_q: float
    whiteness_limit: float
    frac_outside: float
    acf_lags: np.ndarray
    acf: np.ndarray
    acf_band: float
    ccf: dict
    ccf_lags: np.ndarray
    ccf_curves: dict

    @property
    def rms_over_noise(self) -> float:
        return self.rms / self.noise_floor if self.noise_floor > 0 else math.nan

    def to_json(self) -> dict:
        return {
            "unit": self.unit, "n": self.n, "rms": self.rms, "bias": self.bias, "std": self.std,
            "fit_percent": self.fit_percent, "noise_floor": self.noise_floor,
            "rms_over_noise": _num(self.rms_over_noise),
            "white": self.white, "whiteness_q": self.whiteness_q,
            "whiteness_limit_99": self.whiteness_limit,
            "acf_frac_outside_band": self.frac_outside, "acf_band_95": self.acf_band,
            "acf": {"lag_s": self.acf_lags.tolist(), "value": self.acf.tolist()},
            "ccf_peaks": {k: {"abs_rho": v[0], "lag_s": v[1], "band": v[2], "significant": v[3]}
                          for k, v in self.ccf.items()},
        }


def _num(x):
    """A float for JSON (None for nan/inf)."""
    return float(x) if x is not None and np.isfinite(x) else None


def _standardised(x: np.ndarray, width: int) -> np.ndarray:
    """``x`` divided by its local RMS (a running mean of ``x^2`` over ``width`` samples).

    The correlation tests pool segments whose noise differs by 20x (the rotational axes'
    noise grows with the tether tension, ~speed^2): unscaled, the fastest flight carries
    the pooled correlation and the Bartlett variance with all n samples is far too small
    (the project's negative control failed the 99 % whiteness test on pitch, Q 18.8 >
    13.3; standardised 3.4). Scaled, every sample counts alike, as the test assumes.
    """
    rms = np.sqrt(uniform_filter1d(x * x, width, mode="nearest"))
    return np.divide(x, rms, out=np.zeros_like(x), where=rms > 0)


def _pooled_corr(xs, ys, max_lag):
    """Cross-correlation of zero-mean series pooled over segments, lags -max_lag..max_lag:
    ``sum_seg sum_t x_t y_{t-k} / sqrt(sum x^2 sum y^2)``."""
    num = np.zeros(2 * max_lag + 1)
    sx = sy = 0.0
    for x, y in zip(xs, ys, strict=True):
        n = x.size
        full = correlate(x, y, mode="full", method="fft")
        lo, hi = n - 1 - max_lag, n + max_lag
        seg = full[max(lo, 0) : hi]
        num[max(0, -lo) : max(0, -lo) + seg.size] += seg
        sx += float(np.sum(x * x))
        sy += float(np.sum(y * y))
    return num / math.sqrt(sx * sy) if sx * sy > 0 else num


def axis_stats(res: list[Residual], axis: str, noise_floor: float = math.nan,
               max_lag_s: float = 0.5) -> AxisStats:
    """Statistics of ``axis`` pooled over segments (see :class:`AxisStats`)."""
    from scipy.stats import chi2, norm

    y = np.concatenate([r.measured[axis] for r in res])
    yh = np.concatenate([r.predicted[axis] for r in res])
    e = y - yh
    n = e.size
    rms = float(np.sqrt(np.mean(e**2)))
    bias = float(np.mean(e))
    den = float(np.linalg.norm(y - y.mean()))
    fit = float(100 * (1 - np.linalg.norm(e) / den)) if den > 0 else math.nan
    dt = float(np.median(np.concatenate([np.diff(r.t) for r in res])))
    W = max(r.window for r in res)
    L = max(2 * W, int(round(max_lag_s / dt)))
    # standardised first, then centred: the raw bias is the loud segments' mean, and
    # taken from a quiet segment it is an offset there that reads as correlation
    zs = [_standardised(r.residual[axis], 4 * L + 1) for r in res]
    z_mean = float(np.mean(np.concatenate(zs)))
    xs = [z - z_mean for z in zs]
    acf = _pooled_corr(xs, xs, L)[L:]
    var1 = (1 + 2 * float(np.sum(acf[1:W] ** 2))) / n
    band = 1.96 * math.sqrt(var1)
    tail = acf[W:]
    frac = float(np.mean(np.abs(tail) > band)) if tail.size else 0.0
    lags = np.arange(W, L + 1, W)
    q = float(np.sum(acf[lags] ** 2) / var1)
    limit = float(chi2.ppf(0.99, lags.size))
    n_ind = max(1.0, (2 * L + 1) / W)
    z = float(norm.ppf(1 - 0.025 / n_ind))
    ccf, curves = {}, {}
    for nm in res[0].inputs:
        us = [r.inputs[nm] - np.mean(r.inputs[nm]) for r in res]
        rho = _pooled_corr(xs, us, L)
        acf_u = _pooled_corr(us, us, W)[W:]
        # Bartlett: var(rho_xu(k)) ~ (1/n) sum_j rho_x(j) rho_u(j); rho_x ~ 0 beyond W
        var = (1 + 2 * float(np.sum(np.abs(acf[1:W] * acf_u[1:W])))) / n
        b = z * math.sqrt(var)
        k = int(np.argmax(np.abs(rho)))
        peak = float(abs(rho[k]))
        ccf[nm] = (peak, float((k - L) * dt), b, peak > b)
        curves[nm] = rho
    return AxisStats(axis, UNITS[axis], n, rms, bias, float(np.std(e)), fit, float(noise_floor),
                     bool(q <= limit), q, limit, frac, np.arange(L + 1) * dt, acf, band, ccf,
                     np.arange(-L, L + 1) * dt, curves)


def noise_floor(config: Config, measured, segs, *, effects=None, latency=None,
                seed: int = 0) -> tuple[dict, dict]:
    """RMS change of each residual axis when measurement noise of the estimated level is
    added once more (motion capture on the raw pose channels, the gyro's on the gyro, the
    accelerometer's on the accelerometer): the residual the noise alone explains.

    Returns ``(floors, pose_floors)``: the floor per axis, and for the axes measured with
    an on-board sensor (rotational: gyro; translational: accelerometer) the floor they
    would have from the pose alone (twice differentiated): what the sensor saves.
    """
    model = Model(config, effects)
    rng, rng_gyro, rng_accel = (np.random.default_rng(seed + i) for i in range(3))
    acc: dict = {}
    pose: dict = {}

    def add(store, ax, d):
        s, k = store.get(ax, (0.0, 0))
        store[ax] = (s + float(np.sum(d * d)), k + d.size)

    for m, s in zip(measured, segs, strict=True):
        p0 = predict(model, m, latency=latency)
        r0 = _residual(model, m, p0)
        mn = _noisy(s, m, config, rng, rng_gyro, rng_accel)
        p1 = predict(model, mn, latency=latency)
        r1 = _residual(model, mn, p1)
        for ax in r0.residual:
            add(acc, ax, r1.residual[ax] - r0.residual[ax])
        c = m.core
        if m.gyro_dot is not None:
            for j, ax in enumerate(("roll", "pitch", "yaw")):
                add(pose, ax, (mn.omega_dot[c, j] - p1.omega_dot_pose[c, j])
                    - (m.omega_dot[c, j] - p0.omega_dot_pose[c, j]))
        if m.accel is not None:
            d1 = np.einsum("nij,nj->ni", mn.axes[c], mn.a[c]) - p1.acc[c]
            d0 = np.einsum("nij,nj->ni", m.axes[c], m.a[c]) - p0.acc[c]
            for j, ax in enumerate(("tangential", "normal", "radial")):
                if ax in r0.residual:
                    add(pose, ax, d1[:, j] - d0[:, j])
    rms = lambda store: {ax: math.sqrt(s / k) for ax, (s, k) in store.items()}  # noqa: E731
    return rms(acc), rms(pose)


# --------------------------------------------------------------------------- where it fails


def _bin_edges(var: str, x: np.ndarray, n_bins: int):
    if var == "azimuth":
        return np.linspace(0.0, 360.0, 13)
    if var == "tilt":
        vals = np.unique(np.round(x, 6))
        if vals.size <= 8:
            mids = (vals[1:] + vals[:-1]) / 2
            return np.concatenate([[vals[0] - 1], mids, [vals[-1] + 1]])
    lo, hi = np.percentile(x, [0.5, 99.5])
    if not hi > lo:
        return np.array([lo - 0.5, hi + 0.5])
    edges = np.linspace(lo, hi, n_bins + 1)
    edges[0], edges[-1] = min(lo, x.min()), max(hi, x.max()) + 1e-9
    return edges


def where_it_fails(res: list[Residual], noise: dict, n_bins: int = 8, min_count: int = 40) -> dict:
    """Residual binned against each of :data:`BIN_VARIABLES`, per axis, and the worst regime.

    Returns ``{"tables": {var: {"edges", "centers", "count", axis: {"rms", "bias"}}},
    "worst": {...}, "sentence": str}``. Bins with fewer than ``min_count`` samples are
    reported but not used to name the worst regime. The worst regime: the axis whose
    RMS is largest against its noise floor; for it the variable whose bins spread most;
    the sentence says whether the residual grows with the variable or concentrates in
    a range of it.
    """
    axes = [a for a in AXES if all(a in r.residual for r in res)]
    X = {v: np.concatenate([r.variables[v] for r in res]) for v in BIN_VARIABLES}
    E = {a: np.concatenate([r.residual[a] for r in res]) for a in axes}
    tables = {}
    for v in BIN_VARIABLES:
        edges = _bin_edges(v, X[v], n_bins)
        idx = np.clip(np.digitize(X[v], edges) - 1, 0, len(edges) - 2)
        count = np.bincount(idx, minlength=len(edges) - 1)
        centers = (edges[1:] + edges[:-1]) / 2
        if v == "tilt" and edges.size - 1 == np.unique(np.round(X[v], 6)).size:
            centers = np.unique(np.round(X[v], 6))  # one bin per flown tilt
        tab = {"edges": edges.tolist(), "centers": centers.tolist(), "count": count.tolist()}
        for a in axes:
            s2 = np.bincount(idx, E[a] ** 2, minlength=len(edges) - 1)
            s1 = np.bincount(idx, E[a], minlength=len(edges) - 1)
            with np.errstate(invalid="ignore", divide="ignore"):
                tab[a] = {"rms": np.sqrt(s2 / count).tolist(), "bias": (s1 / count).tolist()}
        tables[v] = tab
    # the worst axis relative to its noise floor
    ratio = {a: float(np.sqrt(np.mean(E[a] ** 2)) / noise.get(a, math.nan)) for a in axes}
    finite = {a: r for a, r in ratio.items() if np.isfinite(r)}
    worst_axis = max(finite, key=finite.get) if finite else axes[0]
    best = None
    for v in BIN_VARIABLES:
        tab = tables[v]
        cnt = np.array(tab["count"])
        rms = np.array(tab[worst_axis]["rms"])
        ok = cnt >= min_count
        if ok.sum() < 2:
            continue
        spread = float(np.nanmax(rms[ok]) / max(np.nanmin(rms[ok]), 1e-300))
        if best is None or spread > best[1]:
            best = (v, spread)
    out = {"tables": tables, "rms_over_noise": ratio, "worst": None, "sentence": ""}
    unit = UNITS[worst_axis]
    if finite and max(finite.values()) < AT_NOISE_FLOOR:
        out["worst"] = {"axis": worst_axis, "at_noise_floor": True}
        out["sentence"] = (
            f"every axis is within {AT_NOISE_FLOOR:g}x its noise floor (worst: {worst_axis}, "
            f"{ratio[worst_axis]:.2f}x): the model explains these flights down to the "
            "measurement noise"
        )
        return out
    if best is None:
        r_all = float(np.sqrt(np.mean(E[worst_axis] ** 2)))
        out["worst"] = {"axis": worst_axis}
        out["sentence"] = (f"{worst_axis} residual is the largest ({r_all:.3g} {unit} RMS, "
                           f"{ratio[worst_axis]:.1f}x its noise floor) and uniform over the "
                           "flown conditions")
        return out
    v, spread = best
    tab = tables[v]
    cnt = np.array(tab["count"])
    ok = cnt >= min_count
    rms = np.array(tab[worst_axis]["rms"])
    bias = np.array(tab[worst_axis]["bias"])
    centers = np.array(tab["centers"])
    edges = np.array(tab["edges"])
    vu = BIN_VARIABLES[v][0]
    iok = np.flatnonzero(ok)
    k = iok[np.nanargmax(rms[iok])]
    mid = 0.5 * (np.nanmax(rms[iok]) + np.nanmin(rms[iok]))
    high = iok[rms[iok] > mid]
    rank = np.corrcoef(np.arange(iok.size), rms[iok])[0, 1] if iok.size > 2 else 0.0
    others = iok[rms[iok] <= mid]
    r_low = float(np.sqrt(np.sum(rms[others] ** 2 * cnt[others]) / max(1, cnt[others].sum())))
    if v != "azimuth" and k == iok[-1] and rank > 0.7:
        trend = f"grows with {v} above {edges[high.min()]:.3g} {vu}"
    elif v != "azimuth" and k == iok[0] and rank < -0.7:
        trend = f"grows as {v} falls below {edges[high.max() + 1]:.3g} {vu}"
    else:
        lo, hi = edges[k], edges[k + 1]
        trend = f"concentrates at {v} {lo:.3g}-{hi:.3g} {vu}"
    out["worst"] = {"axis": worst_axis, "variable": v, "spread": spread,
                    "bin_center": float(centers[k]), "bin": [float(edges[k]), float(edges[k + 1])],
                    "rms": float(rms[k]), "bias": float(bias[k]),
                    "rms_elsewhere": r_low}
    out["sentence"] = (
        f"{worst_axis} residual {trend} (RMS {rms[k]:.3g} {unit}, bias {bias[k]:+.3g} {unit} "
        f"there vs {r_low:.3g} elsewhere; {ratio[worst_axis]:.1f}x the noise floor overall)"
    )
    return out


# --------------------------------------------------------------------------- one call


@dataclass(frozen=True, eq=False)
class Comparison:
    """The model against flight logs: residuals, statistics per axis, noise floors, where it fails.

    Everything :func:`compare` computes (``gainsched compare``; docs/model-vs-measurement.md).
    The residual axes, in the order of :data:`AXES` and with the units of :data:`UNITS`:
    tangential, normal, radial (m/s^2; radial only when every segment has a load cell),
    roll, pitch, yaw (rad/s^2) and stretch (m). ``cmp.axes`` lists those present,
    ``cmp.normalized_rms()`` is ``sqrt(mean over axes of (RMS / noise floor)^2)`` (1:
    the residual is measurement noise), ``cmp.to_json()`` is the report's JSON and
    ``cmp.sensor_lines()`` says what the on-board sensors saved.

    Attributes
    ----------
    config : Config
        The model that was compared.
    measured : list of Measured
        Every log segment in reduced coordinates, differentiated
        (:class:`~gainsched.analysis.compare.Measured`), in the order of ``segs``.
    residuals : list of Residual
        Per segment, the measured, predicted and residual time series of each axis on
        the core samples (half a differentiation window dropped at each end)
        (:class:`~gainsched.analysis.compare.Residual`).
    stats : dict of str to AxisStats
        By axis: RMS, bias, fit %, noise floor, whiteness and input cross-correlation of
        the residual pooled over the segments, in the axis unit
        (:class:`~gainsched.analysis.compare.AxisStats`; ``rms_over_noise`` is RMS over
        the noise floor).
    noise : dict of str to float
        By axis: the noise floor, the RMS residual the measurement noise alone produces,
        in the axis unit.
    where : dict
        Where the model fails (:func:`where_it_fails`): ``"sentence"`` (str, the worst
        regime in words), ``"worst"`` (dict: the axis and, when binned structure names
        it, the variable and its bin), ``"rms_over_noise"`` (axis to float) and
        ``"tables"`` (the residual binned against airspeed, tilt, azimuth, tension,
        thrust and time).
    notes : list of str
        What reading the logs reported: gaps and dropped short segments.
    segs : list of FlightLog
        The log segments compared.
    tracking : list of dict
        Along-track tracking of each segment with a reference azimuth
        (:func:`tracking_summary`): ``segment``, ``rms_along_track_m``,
        ``max_along_track_m`` (m), ``final_azimuth_error_rad`` (rad), ``lap_slips``.
    structure : list of Finding
        Significant binned structure of the residual (averaged over revolutions, in
        azimuth, airspeed, thrust or time bins), strongest first
        (:func:`gainsched.analysis.structure.findings`; ``f.sentence()`` says it).
    structure_tables : dict of str to dict
        Its tables, ``{variable: {axis: BinnedMean}}``.
    pose_noise : dict of str to float
        For the axes an on-board sensor measured (rotational: the gyro; translational:
        the accelerometer), the noise floor from the pose alone (:func:`noise_floor`), in
        the axis unit: what the sensor saved against ``noise``.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cmp = gs.compare(cfg, ["examples/flights/v9.csv", "examples/flights/v15.csv"])
    >>> cmp.axes
    ('tangential', 'normal', 'radial', 'roll', 'pitch', 'yaw', 'stretch')
    >>> [s.white for s in cmp.stats.values()]  # whiteness of the residual, per axis
    [False, False, True, False, True, True, True]
    >>> [t["segment"] for t in cmp.tracking], len(cmp.residuals), cmp.notes
    (['sim-v9', 'sim-v15'], 2, [])
    """

    config: Config
    measured: list
    residuals: list
    stats: dict
    noise: dict
    where: dict
    notes: list
    segs: list = field(default_factory=list)
    tracking: list = field(default_factory=list)
    #: significant binned structure (:func:`gainsched.analysis.structure.findings`),
    #: strongest first, and its tables ``{variable: {axis: BinnedMean}}``
    structure: list = field(default_factory=list)
    structure_tables: dict = field(default_factory=dict)
    #: the noise floors from the pose alone of the axes an on-board sensor measured
    #: (:func:`noise_floor`; rotational: gyro, translational: accelerometer): what the
    #: sensors saved
    pose_noise: dict = field(default_factory=dict)


    def __repr__(self) -> str:
        """One line: the config, the segments and the normalised RMS (1: measurement noise)."""
        return (f"Comparison({self.config.name!r}, {len(self.measured)} segments, "
                f"normalised RMS {self.normalized_rms():.3g})")
    def sensor_lines(self) -> list[str]:
        """One sentence per axis measured with an on-board sensor: its noise floor with
        the sensor against the pose's alone."""
        return [f"{a}: noise floor {self.noise[a]:.3g} {UNITS[a]} with the "
                f"{_SENSOR_OF.get(a, 'gyro')}, {p:.3g} from the pose alone "
                f"({self.noise[a] / p - 1:+.0%})"
                for a, p in self.pose_noise.items() if a in self.noise and p > 0]

    def _sensor_json(self, axes) -> dict:
        used = {a: p for a, p in self.pose_noise.items() if a in axes}
        return {"used": bool(used), "pose_noise_floor": used,
                "noise_floor": {a: self.noise[a] for a in used}}

    @property
    def axes(self) -> tuple[str, ...]:
        return tuple(self.stats)

    def normalized_rms(self, axes=None) -> float:
        """sqrt(mean over axes of (RMS / noise floor)^2): 1 for a residual of pure noise."""
        axes = axes or self.axes
        return float(np.sqrt(np.mean([(self.stats[a].rms / self.noise[a]) ** 2 for a in axes])))

    def to_json(self) -> dict:
        return {
            "config": {"name": self.config.name, "source": self.config.source,
                       "sha256": self.config.sha256,
                       "effects": {e.name: e.param_dict() for e in self.config.effects},
                       "analysis": {"savgol_window_s": self.config.analysis.savgol_window_s,
                                    "savgol_order": self.config.analysis.savgol_order,
                                    "latency_s": self.config.analysis.latency_s}},
            "segments": [{"name": r.name, "source": r.source, "samples": len(r),
                          "t_start": float(r.t[0]), "t_end": float(r.t[-1]),
                          "tension": r.tension_source, "window_samples": r.window}
                         for r in self.residuals],
            "axes": {a: s.to_json() for a, s in self.stats.items()},
            "normalized_rms": self.normalized_rms(),
            "where_it_fails": {"sentence": self.where["sentence"], "worst": self.where["worst"],
                               "rms_over_noise": self.where["rms_over_noise"],
                               "tables": self.where["tables"]},
            "notes": self.notes,
            "tracking": self.tracking,
            "gyro": self._sensor_json(("roll", "pitch", "yaw")),
            "accelerometer": self._sensor_json(("tangential", "normal", "radial")),
            "structure": {"findings": [f.to_json() for f in self.structure],
                          "tables": {v: {a: bm.to_json() for a, bm in tab.items()}
                                     for v, tab in self.structure_tables.items()}},
        }


def compare(config: Config, logs, *, effects=None, measured=None, segs=None,
            notes=None, channel_map=None, trust=(), progress=None) -> Comparison:
    """Compare the model with flight logs: the residual per axis against its noise floor.

    The whole of ``gainsched compare`` (docs/model-vs-measurement.md): per gap-free log
    segment, the pose in reduced coordinates, differentiated by Savitzky-Golay; the
    model's accelerations for the measured state and the logged commands; the residual
    ``measured - predicted`` on the axes tangential, normal, radial (m/s^2; radial only
    with a load cell), roll, pitch, yaw (rad/s^2) and tether stretch (m); then per axis
    the statistics pooled over the segments, the noise floor (the measurement noise
    pushed through the same pipeline), where the residual concentrates, and the binned
    structure averaged over revolutions.

    Parameters
    ----------
    config : Config
        The model under test: its vehicle, tether, effects and ``[analysis]`` settings
        (Savitzky-Golay window, s, and order; the pose's latency, s; whether to use the
        gyro and the accelerometer columns).
    logs : iterable of str, path-like or FlightLog
        Flight log files (:func:`~gainsched.analysis.logs.read_log`: each split at its
        gaps) or segments already read. Not read when ``measured`` is given.
    effects : tuple of Effect, optional
        Model effects (:mod:`gainsched.model.effects` objects) to predict with instead of
        the config's: a model variant. Default: the config's.
    measured : list of Measured, optional
        The differentiated segments of a previous :func:`load_segments` call with the
        same attachment offset and analysis settings, to skip reading and
        differentiating; give its ``segs`` and ``notes`` too.
    segs : list of FlightLog, optional
        The log segments of ``measured``, in the same order.
    notes : list of str, optional
        The reading notes of ``measured`` (gaps, dropped segments).
    channel_map : ChannelMap, str or path-like, optional
        How PX4 ULogs and ROS 2 bags among ``logs`` hold the channels
        (:func:`~gainsched.analysis.logs.read_log`; default for a ULog: the shipped
        ``px4`` map).
    trust : iterable of str, optional
        Consistency checks of the log files to skip (:func:`~gainsched.analysis.logs.
        read_log`, docs/flight-log.md): ``plane``, ``quaternion``, ``gyro``, ``thrust``,
        ``tension``, ``xi_ref``.
    progress : callable or None, default None
        Called with 1 after each log read (none when ``measured`` is given) and once
        more when the statistics are done (e.g. a progress bar's ``update``).

    Returns
    -------
    Comparison
        Residuals per segment, statistics and noise floor per axis, where it fails, the
        binned structure, tracking, notes.

    Raises
    ------
    InputError
        No log given, a log breaks the format's rules (:func:`read_log`; the file,
        column and row named), a segment is shorter than twice the differentiation
        window, or its commanded thrust is zero on every sample.

    Examples
    --------
    The paper model on the seven example flights (a plant with effects it lacks):

    >>> import glob
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cmp = gs.compare(cfg, sorted(glob.glob("examples/flights/*.csv")))
    >>> for axis, s in cmp.stats.items():
    ...     print(f"{axis:10s} RMS {s.rms:8.3g} {s.unit:7s} {s.rms_over_noise:5.1f}x noise")
    tangential RMS     1.27 m/s^2     4.8x noise
    normal     RMS     1.73 m/s^2     7.1x noise
    radial     RMS    0.302 m/s^2     1.1x noise
    roll       RMS     3.16 rad/s^2  16.3x noise
    pitch      RMS     2.98 rad/s^2   2.2x noise
    yaw        RMS     1.09 rad/s^2   1.2x noise
    stretch    RMS 0.000161 m         1.0x noise
    >>> round(cmp.normalized_rms(), 1)  # 1: nothing but measurement noise
    7.0
    >>> cmp.where["sentence"]
    'roll residual concentrates at tension 26-34.1 N (RMS 5.74 rad/s^2, ...)'
    """
    if measured is None:
        measured, segs, notes = load_segments(config, logs, channel_map, trust, progress)
    model = Model(config, effects)
    check_logged_channels(model, measured, segs)
    check_motor_order(model, measured, segs)
    res = residuals(config, measured, effects=effects, model=model)
    noise, pose_noise = noise_floor(config, measured, segs, effects=effects)
    axes = [a for a in AXES if all(a in r.residual for r in res)]
    stats = {a: axis_stats(res, a, noise[a]) for a in axes}
    where = where_it_fails(res, noise)
    found, tables = findings(res, noise, units=UNITS)
    if progress is not None:
        progress(1)
    return Comparison(config, measured, res, stats, noise, where, list(notes or []), list(segs),
                      tracking_summary(config, measured, segs or []), found, tables, pose_noise)


def tracking_summary(config: Config, measured, segs) -> list[dict]:
    """Along-track tracking of every log segment that carries the reference azimuth
    (``xi_ref``): the measured azimuth of the attachment point (``Measured.z``, already
    reconstructed from the pose) minus the reference, both continuous (the reference put
    on the 2 pi branch of the first sample; a lap behind is -2 pi), and that error times
    the COG radius (m).

    Returns a list of dicts: ``segment`` (the measured segment's name),
    ``rms_along_track_m``, ``max_along_track_m``, ``final_azimuth_error_rad``,
    ``lap_slips``.
    """
    out = []
    for meas, log in zip(measured, segs, strict=True):
        ref = log.optional.get("xi_ref")
        if ref is None or len(log) < 2:
            continue
        xi = meas.z[:, 1]
        ref = np.unwrap(np.asarray(ref, dtype=float))
        ref = ref + 2 * np.pi * np.round((xi[0] - ref[0]) / (2 * np.pi))
        err = xi - ref
        r = config.radius
        out.append({"segment": meas.name,
                    "rms_along_track_m": float(r * np.sqrt(np.mean(err**2))),
                    "max_along_track_m": float(r * np.abs(err).max()),
                    "final_azimuth_error_rad": float(err[-1]),
                    "lap_slips": int(np.abs(err).max() // (2 * np.pi))})
    return out
