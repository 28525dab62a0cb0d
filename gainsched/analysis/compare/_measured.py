"""The measurement: one log segment in reduced coordinates, differentiated
(:class:`Measured`, :func:`measure`).

Steps 1-2 of the pipeline that :mod:`gainsched.analysis.compare` describes
(docs/model-vs-measurement.md): the pose in reduced coordinates (the conversion of
:func:`gainsched.model.maximal.reduced_from_maximal`), then the Savitzky-Golay
derivatives and the exact kinematics (paper eq. 9 corrected) per gap-free segment.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.ndimage import convolve1d
from scipy.signal import savgol_coeffs, savgol_filter

from ...config import Config, Sensors
from ...errors import InputError
from ...model.effects import cog_offset, effects_from_specs
from ...model.geometry import (
    attachment_from_cog,
    cog_from_attachment,
    spherical_from_point,
    tether_direction,
)
from ...rotations import (
    R_IC_from_tilt,
    euler_zyx_from_matrix,
    matrix_from_euler_zyx,
    matrix_from_quaternion,
    up_C_from_tilt,
)
from ..logs import FlightLog


@functools.lru_cache(maxsize=64)
def _savgol_kernel(window: int, order: int, deriv: int, delta: float) -> np.ndarray:
    """Convolution coefficients of :func:`scipy.signal.savgol_filter` (computed once)."""
    return savgol_coeffs(window, order, deriv=deriv, delta=delta)


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


def _delayed(t, x, latency):
    """``x(t - latency)`` by linear interpolation (held at the first sample), x shape (N, k)."""
    if latency == 0:
        return x
    tq = t - latency
    return np.stack([np.interp(tq, t, x[:, j]) for j in range(x.shape[1])], -1)


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
    p_e : (3,) m
        The attachment point in B from the COG the COG's kinematics (``p, v, a``) were
        computed with: ``(-L_e, 0, 0)`` minus the config's centre-of-mass offset
        (``[effects.cog_offset]``; the pose is the frame centre's).
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
    p_e: np.ndarray = field(default_factory=lambda: np.zeros(3))
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
        pose's attitude, plus gravity and :meth:`cog_lever`, projected, then smoothed like
        the prediction: on
        the path axes a circle's acceleration is constant, in C it turns), else the
        twice-differentiated pose (``a``) projected. The accelerometer's is exact on
        :attr:`core` only, the samples its callers take (the smoothing's convolution
        without the end fits, which are ``savgol_filter``'s interior bit for bit: a fit
        that moves the latency refilters it at every step, and the end fits were most of
        that work)."""
        if self.accel is None:
            return self.derived("acc_pose", lambda: np.einsum("nij,nj->ni", self.axes, self.a))
        hit = self.cache.get("acc_imu")
        if hit is None or hit[0] != latency:  # one latency kept: a fit moves it step by step
            f_C = np.einsum("nij,nj->ni", self.R, _delayed(self.t, self.accel, latency))
            a_path = np.einsum("nij,nj->ni", self.axes, f_C + self.gravity_C + self.cog_lever())
            self.cache["acc_imu"] = (latency, convolve1d(
                a_path, _savgol_kernel(self.window, self.order, 0, 1.0), axis=0,
                mode="constant"))
        return self.cache["acc_imu"][1]

    def with_attachment(self, p_e) -> Measured:
        """The same segment with the COG's kinematics for the attachment point ``p_e`` (3,),
        m, in B from the COG (another centre-of-mass offset, the attachment offset the
        same): ``p_q = p_t - R_CB p_e`` and its derivatives move by the difference
        (:func:`_reconstruct`), the pose's channels stay; what :func:`measure` would give
        with that offset, without differentiating the pose again."""
        dp = np.asarray(p_e, dtype=float) - self.p_e
        w = self.z[:, 7:10]
        move = lambda v: np.einsum("nij,nj->ni", self.R, v)  # noqa: E731
        return dataclasses.replace(
            self, p=self.p - move(np.broadcast_to(dp, w.shape)), v=self.v - move(np.cross(w, dp)),
            a=self.a - self._lever(dp), p_e=np.asarray(p_e, dtype=float), cache={})

    def _lever(self, r) -> np.ndarray:
        """``R_CB (omega' x r + omega x (omega x r))``, (N, 3) m/s^2 in C: the acceleration
        of the point at ``r`` (3,), m, in B relative to the body's reference point."""
        w = self.z[:, 7:10]
        arm = np.cross(self.omega_dot, r) + np.cross(w, np.cross(w, r))
        return np.einsum("nij,nj->ni", self.R, arm)

    def cog_lever(self) -> np.ndarray:
        """The COG's acceleration relative to the frame centre (where the IMU sits, with
        the markers), ``R_CB (omega' x d + omega x (omega x d))``, (N, 3) m/s^2 in C, for
        the COG at ``d = (-L_e, 0, 0) - p_e`` from it (``[effects.cog_offset]``; zeros
        without one): the IMU's acceleration plus it is the COG's."""
        d = np.array([-self.L_e, 0.0, 0.0]) - self.p_e
        return self._lever(d) if d.any() else np.zeros_like(self.a)

    def omega_dot_measured(self, latency: float) -> np.ndarray:
        """The measured body angular acceleration (N, 3), rad/s^2, on the pose's clock:
        from the gyro when there is one (delayed by ``latency`` s, like the commands it
        is compared with), else from the pose."""
        if self.gyro_dot is None:
            return self.omega_dot
        return _delayed(self.t, self.gyro_dot, latency)

    def gyro_delayed(self, latency: float) -> np.ndarray:
        """The gyro's body rates (N, 3), rad/s, delayed by ``latency`` s onto the pose's
        clock (as :meth:`omega_dot_measured` delays their derivative); needs a gyro."""
        return _delayed(self.t, self.gyro, latency)

    def accel_delayed(self, latency: float) -> np.ndarray:
        """The accelerometer's specific force (N, 3), m/s^2, delayed by ``latency`` s onto
        the pose's clock; needs an accelerometer."""
        return _delayed(self.t, self.accel, latency)

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


def _raw_channels(log: FlightLog, L_e: float, sensors: Sensors, p_I=None, R_IM=None):
    """Raw (d, delta, xi, phi, theta, psi), shape (6, N), from the logged pose (or the given
    p_I (N, 3), R_IM (N, 3, 3)), the markers' attitude turned to the body's by
    ``sensors`` (``[sensors] marker_rotation_deg``); xi and psi unwrapped, psi on the
    branch of xi."""
    R_IC = R_IC_from_tilt(log.alpha_c, log.gamma_c)
    p_C = np.einsum("nj,ji->ni", log.p_I if p_I is None else p_I, R_IC)  # rows R_IC^T p
    R_IM = matrix_from_quaternion(log.q) if R_IM is None else R_IM
    if sensors.marker_rotation != (0.0, 0.0, 0.0):
        R_IM = sensors.body_attitude(R_IM)
    R = np.einsum("ji,njk->nik", R_IC, R_IM)
    d, delta, xi = spherical_from_point(attachment_from_cog(p_C, R, np.array([-L_e, 0.0, 0.0])))
    xi = np.unwrap(xi)
    phi, theta, psi = euler_zyx_from_matrix(R)
    psi = np.unwrap(psi)
    psi += 2 * np.pi * np.round((xi[0] - psi[0]) / (2 * np.pi))  # chi = psi - xi near 0
    return np.stack([d, delta, xi, phi, theta, psi])


def _reconstruct(ch, ch1, ch2, p_e):
    """Kinematics from the smoothed channels (6, N) and their derivatives (rates,
    accelerations); the COG's with the attachment point ``p_e`` (3,), m, in B from it."""
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


def attachment_from_cog_config(config: Config) -> np.ndarray:
    """The attachment point in B from the COG, shape (3,), m, of ``config``:
    ``(-L_e, 0, 0)`` minus its centre-of-mass offset (``[effects.cog_offset]``)."""
    d = cog_offset(effects_from_specs(s for s in config.effects if s.name == "cog_offset"))
    return np.array([-config.tether.attachment_offset, 0.0, 0.0]) - d


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
    raw = _raw_channels(log, L_e, config.sensors)
    ch, ch1, ch2 = _smoothed(raw, n, an.savgol_order, dt)
    p_e = attachment_from_cog_config(config)
    z, acc, p, v, a, R, w_dot, e, axes = _reconstruct(ch, ch1, ch2, p_e)
    h = n // 2
    hc = savgol_coeffs(n, an.savgol_order)[h]
    fit_res = (raw - ch)[:, h : len(log) - h]
    sig = np.sqrt(np.mean(fit_res**2, axis=-1) / max(1e-12, 1 - hc))
    sigma = dict(zip(_CHANNELS, map(float, sig), strict=True))
    gyro, gyro_dot = _gyro(log, an, n, dt, config.sensors)
    if gyro is not None:
        sigma.update(zip(("p", "q", "r"), _imu_sigma(gyro, h), strict=True))
    accel = _accelerometer(log, an, config.sensors)
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
        None if tension is None else np.asarray(tension, float), sigma, L_e, p_e,
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


def _imu_channel(log: FlightLog, column: str, enabled: bool):
    """A logged on-board sensor channel (N, 3), or None without one, with its use
    switched off in ``[analysis]``, or with missing samples."""
    x = log.optional.get(column)
    if not enabled or x is None or not np.all(np.isfinite(x)):
        return None
    return np.asarray(x, float)


def _accelerometer(log: FlightLog, an, sensors: Sensors, noise=None):
    """The logged specific force (N, 3) m/s^2 in B, its calibration ``sensors`` undone
    (``(reading - accel_bias) / accel_scale``), or None (:func:`_imu_channel`)."""
    f = _imu_channel(log, "f_B", an.use_accelerometer)
    if f is None:
        return None
    if not sensors.accel_identity:
        f = sensors.specific_force(f)
    return f if noise is None else f + noise


def _gyro(log: FlightLog, an, n: int, dt: float, sensors: Sensors, noise=None):
    """The logged gyro's body rates (N, 3) rad/s, its calibration ``sensors`` undone
    (``[sensors]``: ``(reading - gyro_bias) / gyro_scale``), and their Savitzky-Golay
    derivative (N, 3) rad/s^2, or ``(None, None)`` (:func:`_imu_channel`)."""
    gyro = _imu_channel(log, "omega_B", an.use_gyro)
    if gyro is None:
        return None, None
    if not sensors.gyro_identity:
        gyro = sensors.body_rates(gyro)
    if noise is not None:  # the noise-floor estimate's: of the body rates' noise level
        gyro = gyro + noise
    return gyro, savgol_filter(gyro, deriv=1, delta=dt, window_length=n,
                               polyorder=an.savgol_order, axis=0, mode="interp")


def _smoothed(raw, window: int, order: int, dt: float):
    """The pose channels ``raw`` (k, N) smoothed and differentiated once and twice along
    the samples (Savitzky-Golay, ``window`` samples, polynomial ``order``, step ``dt`` s):
    ``(ch, ch1, ch2)``, each (k, N), per s and per s^2."""
    kw = dict(window_length=window, polyorder=order, axis=-1, mode="interp")
    return (savgol_filter(raw, deriv=0, **kw), savgol_filter(raw, deriv=1, delta=dt, **kw),
            savgol_filter(raw, deriv=2, delta=dt, **kw))
