"""The on-board sensors and the markers calibrated against each other: the gyro's scale
and bias per body axis, the small rotation of the motion capture's marker frame, and the
accelerometer's scale and bias per axis where the logs have one.

A MEMS gyro reads ``s omega + b`` per axis, with scale factors ``s`` a few percent off 1
and biases ``b`` of the order of 0.01 rad/s before it is calibrated. The motion capture
measures the same body rates independently: differentiated, its attitude gives ``omega``
(:mod:`gainsched.analysis.compare`, step 2). So the calibration is fitted before any
dynamics is (a sensor error read as dynamics tells a wrong story: a gyro 3 % off shows
in the angular accelerations as an inertia or a thrust error):

    reading(t) = diag(s) dR omega(t) + b + noise          (x, y, z in B)

where ``omega`` are the pose's rates in the body frame the config believes (its
``[sensors] marker_rotation_deg`` applied) and ``dR`` the rotation still between that
frame and the gyro's (a rigid body defined on the markers is a degree or two off the
vehicle's axes: each body rate then leaks into the other axes, 0.2 rad/s at 8 rad/s of
yaw and 1.5 deg). It is linear in ``A = diag(s) dR`` and ``b``: a least-squares plane
per axis (the row of ``A`` and the bias), then ``s_j = |row j of A|`` and ``dR`` the
rotation nearest the normalised rows (polar decomposition).

The readings are delayed by ``analysis.latency_s`` onto the pose's clock and smoothed by
the pose's own Savitzky-Golay filter (both sides then see the same filter), then both
are averaged over :data:`WINDOW_S`: the relation is kept by any linear filter both sides
pass through, and the rates differentiated from the pose are noisy (0.06 rad/s at 200
Hz with 0.2 deg of attitude noise), which would bias the fitted scale towards 0 and the
bias with it (errors in the regressor: 0.1 % and 0.004 rad/s on 20 s flights at the 0.1
s window alone). 95 % intervals from the leave-one-flight-out estimates (the jackknife:
the samples of one flight are correlated, the flights are not), with Student's t on
``flights - 1`` degrees of freedom; the held-out fall of the residual ``reading - (A
omega + b)`` against the config's calibration, each flight predicted by the fit to the
others, above the fit's own residual (the noise).

The accelerometer the same way, once the rotation is known: its reading against the
specific force the pose gives, ``f = R_CB^T (a - g)`` in the config's body frame turned
by ``dR``, a line per axis, ``reading_j = s_j (dR f)_j + b_j`` (a MEMS accelerometer's
scale is good to 1-3 % and its bias to 0.1 m/s^2 uncalibrated; read as dynamics, 2 %
of a 140 m/s^2 centripetal acceleration is a thrust or mass error of 2.8 m/s^2).

A parameter is **off** when its estimate differs from the config's by more than its
95 % interval and by more than a tolerance below which a calibration changes nothing a
controller or a fit notices (:data:`SCALE_TOL`, :data:`BIAS_TOL`, :data:`ROTATION_TOL`,
:data:`ACCEL_BIAS_TOL`; the rotation's three Z-Y-X angles against 0); the calibration
is **accepted** when some parameter is off and, for each sensor with one off, the
held-out fall on the axes it changes is at least :data:`MIN_FALL`. Only the parameters
that are off are changed (the others keep the config's values, reported); the
rotation's angles change together.

Reference for the sensor model: P. Corke, "Robotics, Vision and Control", 3rd ed.,
Springer, 2023, sec. 3.4 (inertial sensors: a gyroscope's scale factor and bias).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import savgol_filter
from scipy.stats import t as student_t

from ...config import Config, Sensors
from ...rotations import euler_zyx_from_matrix, matrix_from_euler_zyx_scalar

#: a scale factor within this of the config's is left as it is (0.2 %: below what a
#: loop or a fit notices; a MEMS gyro's scale factor is good to 1-3 % uncalibrated)
SCALE_TOL = 2e-3
#: a bias within this of the config's is left as it is, rad/s (0.1 deg/s: a MEMS gyro's
#: bias instability is of this order, so a smaller correction is not a calibration)
BIAS_TOL = 2e-3
#: a marker-frame rotation angle within this of none is left as it is, rad (0.1 deg: the
#: attitude noise of a motion capture is 0.1-0.2 deg per pose)
ROTATION_TOL = float(np.deg2rad(0.1))
#: an accelerometer bias within this of the config's is left as it is, m/s^2 (a MEMS
#: accelerometer's bias instability is of this order)
ACCEL_BIAS_TOL = 0.02
#: an accelerometer scale factor within this of the config's is left as it is (0.5 %: a
#: calibrated MEMS accelerometer's; the circles excite the lateral and thrust axes' forces
#: too little from flight to flight to tell a finer one)
ACCEL_SCALE_TOL = 5e-3
#: the least held-out fall of the residual above the noise (on the axes a calibration
#: changes) for it to be accepted
MIN_FALL = 0.8

#: both sides of the line averaged over this, s: the pose's rate noise then falls to
#: about 0.01 rad/s (the attitude noise over the window), far below the rates' spread
WINDOW_S = 0.5

_AXES = "xyz"


@dataclass(frozen=True)
class AxisLines:
    """One sensor's lines ``reading_j = s_j x_j + b_j`` per body axis, fitted.

    Attributes
    ----------
    scale, bias : ndarray, shape (3,)
        Scale factors (-) and biases (the sensor's unit) of the x, y, z axes.
    scale_ci, bias_ci : ndarray, shape (3,)
        Half-widths of their 95 % intervals (leave-one-flight-out jackknife).
    before, after : ndarray, shape (3,)
        Held-out RMS of ``reading - prediction`` per axis with the config's calibration
        and with the fitted one.
    floor : ndarray, shape (3,)
        The full fit's residual RMS per axis: the noise of the comparison.
    """

    scale: np.ndarray
    bias: np.ndarray
    scale_ci: np.ndarray
    bias_ci: np.ndarray
    before: np.ndarray
    after: np.ndarray
    floor: np.ndarray

    def off(self, config_scale, config_bias, tols: tuple[float, float],
            kind: str) -> dict[str, bool]:
        """Per parameter (``<kind>_scale_x`` ... ``<kind>_bias_z``): off the config's
        values by more than its interval and its tolerance (``tols``: scale, bias)."""
        out = {}
        for what, est, ci, cfg, tol in (("scale", self.scale, self.scale_ci, config_scale,
                                         tols[0]),
                                        ("bias", self.bias, self.bias_ci, config_bias,
                                         tols[1])):
            for j in range(3):
                d = abs(float(est[j]) - cfg[j])
                out[f"{kind}_{what}_{_AXES[j]}"] = bool(d > ci[j] and d > tol)
        return out

    def fall(self, axes) -> float:
        """The held-out fall of the residual above the noise on ``axes`` (indices):
        ``1 - excess_after / excess_before``, each ``sqrt(sum(rms^2 - floor^2))`` over
        those axes (in units of their floors); nan with none."""
        j = list(axes)
        if not j:
            return float("nan")
        w = 1.0 / np.maximum(self.floor[j], 1e-12) ** 2
        excess = lambda rms: np.sqrt(np.sum(  # noqa: E731
            w * np.maximum(rms[j] ** 2 - self.floor[j] ** 2, 0.0)))
        before = excess(self.before)
        return float(1.0 - excess(self.after) / before) if before > 0 else 0.0

    def text(self, unit: str) -> str:
        return (f"scale {_fmt(self.scale, self.scale_ci, '')}; bias "
                f"{_fmt(self.bias, self.bias_ci, unit)} (x, y, z)")

    def to_json(self, kind: str) -> dict:
        out = {}
        for what, est, ci in (("scale", self.scale, self.scale_ci),
                              ("bias", self.bias, self.bias_ci)):
            for j in range(3):
                out[f"{kind}_{what}_{_AXES[j]}"] = {"value": float(est[j]),
                                                    "ci95": float(ci[j])}
        return {"parameters": out, "rms_before": self.before.tolist(),
                "rms_after": self.after.tolist(), "noise": self.floor.tolist()}


def _fmt(est, ci, unit: str) -> str:
    return ", ".join(f"{e:.4g} +- {c:.1g}" for e, c in zip(est, ci, strict=True)) + unit


@dataclass(frozen=True)
class SensorCalibration:
    """The sensors calibrated against the motion capture (the module docstring).

    Attributes
    ----------
    gyro : AxisLines
        The gyro's scale factors (-) and biases (rad/s) against the pose's body rates
        (the held-out RMS of the rates, rad/s).
    rotation : ndarray, shape (3,)
        The rotation ``dR`` still between the config's body frame and the gyro's, as
        Z-Y-X Euler angles (roll, pitch, yaw), rad.
    rotation_ci : ndarray, shape (3,)
        Half-widths of their 95 % intervals, rad.
    accel : AxisLines or None
        The accelerometer's scale factors (-) and biases (m/s^2) against the pose's
        specific force; None without an accelerometer in the logs.
    config : Sensors
        The config's calibration (``[sensors]``).
    flights, samples : int
        Flights and samples the fit used.
    """

    gyro: AxisLines
    rotation: np.ndarray
    rotation_ci: np.ndarray
    accel: AxisLines | None
    config: Sensors
    flights: int
    samples: int

    @property
    def scale(self) -> np.ndarray:
        """The gyro's scale factors, (3,)."""
        return self.gyro.scale

    @property
    def bias(self) -> np.ndarray:
        """The gyro's biases, (3,) rad/s."""
        return self.gyro.bias

    @property
    def off(self) -> dict[str, bool]:
        """Per parameter (``gyro_scale_x`` ... ``gyro_bias_z``, ``marker_roll``,
        ``marker_pitch``, ``marker_yaw``, ``accel_scale_x`` ... ``accel_bias_z``):
        whether it differs from the config's by more than its 95 % interval and its
        tolerance."""
        c = self.config
        out = self.gyro.off(c.gyro_scale, c.gyro_bias, (SCALE_TOL, BIAS_TOL), "gyro")
        for j in range(3):
            d = abs(float(self.rotation[j]))
            out[_name("marker", j)] = bool(d > self.rotation_ci[j] and d > ROTATION_TOL)
        if self.accel is not None:
            out.update(self.accel.off(c.accel_scale, c.accel_bias,
                                      (ACCEL_SCALE_TOL, ACCEL_BIAS_TOL), "accel"))
        return out

    @property
    def rotated(self) -> bool:
        """Some angle of the marker frame's rotation is off."""
        return any(self.off[_name("marker", j)] for j in range(3))

    def _changed(self, kind: str) -> list[int]:
        """The axes of sensor ``kind`` a parameter off changes (a rotation: the gyro's
        three; the accelerometer is judged on its own lines, the rotation applied)."""
        off, turned = self.off, kind == "gyro" and self.rotated
        return [j for j in range(3) if off.get(f"{kind}_scale_{_AXES[j]}")
                or off.get(f"{kind}_bias_{_AXES[j]}") or turned]

    @property
    def axes_changed(self) -> list[int]:
        """The body axes (0, 1, 2) with a parameter off (all three for a rotation)."""
        return sorted(set(self._changed("gyro")) | set(self._changed("accel")))

    @property
    def fall(self) -> float:
        """The smallest held-out fall of the sensors with a parameter off
        (:meth:`AxisLines.fall` on the axes it changes); nan with none."""
        falls = [lines.fall(self._changed(kind)) for kind, lines in
                 (("gyro", self.gyro), ("accel", self.accel))
                 if lines is not None and self._changed(kind)]
        return min(falls) if falls else float("nan")

    @property
    def accepted(self) -> bool:
        """Some parameter is off and :attr:`fall` is at least :data:`MIN_FALL`."""
        return bool(self.axes_changed) and self.fall >= MIN_FALL

    def sensors(self) -> Sensors:
        """The calibration to write: the parameters that are off at their estimates, the
        others at the config's values; a rotation that is off turns the config's marker
        frame, ``R_MB <- R_MB dR^T`` (angles rounded to 1e-4 deg)."""
        off, c = self.off, self.config
        pick = lambda kind, est, cfg: tuple(  # noqa: E731
            round(float(est[j]), 6) if off.get(f"{kind}_{_AXES[j]}") else cfg[j]
            for j in range(3))
        rot = c.marker_rotation
        if self.rotated:
            rot = tuple(float(np.deg2rad(round(float(a), 4))) for a in self.marker_deg())
        a = self.accel
        return Sensors(pick("gyro_scale", self.gyro.scale, c.gyro_scale),
                       pick("gyro_bias", self.gyro.bias, c.gyro_bias), rot,
                       c.accel_scale if a is None else pick("accel_scale", a.scale,
                                                            c.accel_scale),
                       c.accel_bias if a is None else pick("accel_bias", a.bias,
                                                           c.accel_bias))

    def values(self) -> dict[str, float]:
        """Every estimate by name (``gyro_scale_x`` ... ``accel_bias_z``; the marker
        angles of the frame as fitted, ``marker_roll`` ..., deg)."""
        out = {}
        for kind, lines in (("gyro", self.gyro), ("accel", self.accel)):
            if lines is not None:
                for what, est in (("scale", lines.scale), ("bias", lines.bias)):
                    out.update({f"{kind}_{what}_{_AXES[j]}": float(est[j]) for j in range(3)})
        out.update({_name("marker", j): float(a) for j, a in enumerate(self.marker_deg())})
        return out

    def marker_deg(self) -> np.ndarray:
        """The body's roll, pitch, yaw in the markers' frame as fitted, deg (3,)."""
        R_MB = self.config.R_MB @ matrix_from_euler_zyx_scalar(*self.rotation).T
        return np.rad2deg(np.array(euler_zyx_from_matrix(R_MB)))

    def applied(self, config: Config) -> Config:
        """``config`` with :meth:`sensors` (a model variant: its text is the base's;
        :func:`~gainsched.analysis.diagnose.apply_diagnosis` writes the text)."""
        return dataclasses.replace(config, sensors=self.sensors())

    def sentence(self) -> str:
        """One line: the verdict on the sensors, with the estimates and the held-out fall."""
        what = (f"gyro {self.gyro.text(' rad/s')}; body in the markers' frame at "
                f"{_fmt(self.marker_deg(), np.rad2deg(self.rotation_ci), ' deg')} (roll, "
                "pitch, yaw)")
        if self.accel is not None:
            what += f"; accelerometer {self.accel.text(' m/s^2')}"
        what += "; 95 %"
        if not self.axes_changed:
            return (f"sensors against the motion capture: calibrated as the config says "
                    f"({what})")
        changed = ", ".join(k for k, v in self.off.items() if v)
        state = "accepted" if self.accepted else f"not accepted (fall below {MIN_FALL:.0%})"
        return (f"sensor calibration {state}: {what}; off: {changed}; held-out residual "
                f"above noise -{self.fall:.0%}")

    def to_json(self) -> dict:
        return {"gyro": self.gyro.to_json("gyro"),
                "marker": {_name("marker", j): {"value": float(self.rotation[j]),
                                                "ci95": float(self.rotation_ci[j])}
                           for j in range(3)},
                "marker_deg_written": self.marker_deg().tolist(),
                "accelerometer": None if self.accel is None else self.accel.to_json("accel"),
                "off": self.off, "accepted": self.accepted,
                "fall": None if np.isnan(self.fall) else self.fall,
                "flights": self.flights, "samples": self.samples,
                "written": dataclasses.asdict(self.sensors()) if self.accepted else None,
                "units": {"gyro_scale": "-", "gyro_bias": "rad/s", "marker": "rad",
                          "accel_scale": "-", "accel_bias": "m/s^2"}}


def _window(m):
    """The 0.5 s average's length (odd samples) and the samples it leaves, of segment
    ``m``; None when none are left."""
    n = min(2 * int(round(WINDOW_S / m.dt / 2)) + 1, 2 * ((m.n_core - 1) // 4) + 1)
    c = slice(m.core.start + n // 2, m.core.stop - n // 2)
    return (n, c) if c.stop - c.start >= 1 else None


def _samples(config: Config, measured):
    """Per flight (source): the gyro's readings and the pose's body rates, and the
    accelerometer's readings and the pose's specific force in the config's body frame
    (None without one), each on the pose's clock, smoothed as the pose, averaged over
    :data:`WINDOW_S`, core samples: ``[(gyro, omega, accel, force), ...]``, each (n, 3)."""
    lat = config.analysis.latency_s
    sens = config.sensors
    by_flight: dict[str, list] = {}
    for m in measured:
        if m.gyro is None or m.n_core < 1 or _window(m) is None:
            continue
        n, c = _window(m)

        def mean(x, m=m, n=n, c=c, smooth=True):
            if smooth:
                x = savgol_filter(x, m.window, m.order, axis=0, mode="interp")
            return uniform_filter1d(x, n, axis=0)[c]

        row = [mean(sens.readings(m.gyro_delayed(lat))), mean(m.z[:, 7:10], smooth=False)]
        if m.accel is not None:
            # R_CB^T (a - g) at the IMU (the frame centre: the COG's minus its lever)
            force = np.einsum("nji,nj->ni", m.R, m.a - m.cog_lever() - m.gravity_C)
            row += [mean(sens.accel_readings(m.accel_delayed(lat))),
                    mean(force, smooth=False)]
        else:
            row += [None, None]
        by_flight.setdefault(m.source, []).append(row)
    out = []
    for rows in by_flight.values():
        cat = [None if rows[0][k] is None or any(r[k] is None for r in rows)
               else np.concatenate([r[k] for r in rows]) for k in range(4)]
        out.append(cat)
    return out


def _name(kind: str, j: int) -> str:
    """A parameter's name: ``gyro_scale_x`` ... ``marker_yaw``."""
    return f"marker_{('roll', 'pitch', 'yaw')[j]}" if kind == "marker" else f"{kind}_{_AXES[j]}"


def _fit(y, x):
    """The least-squares ``y = A x + b`` (rows (n, 3)), ``A = diag(s) dR``: ``(s, b,
    angles, A)``, ``angles`` the Z-Y-X Euler angles of ``dR`` (rad), the rotation nearest
    the rows of ``A`` normalised (polar decomposition)."""
    X = np.concatenate([x, np.ones((len(x), 1))], -1)
    coef = np.linalg.lstsq(X, y, rcond=None)[0]  # (4, 3): column j is row j of A and b_j
    A, b = coef[:3].T, coef[3]
    s = np.linalg.norm(A, axis=1)
    U, _, Vt = np.linalg.svd(A / s[:, None])
    dR = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return s, b, np.array(euler_zyx_from_matrix(dR)), A


def _lines(y, x):
    """Per axis, the least-squares ``y_j = s_j x_j + b_j``: ``(s, b)``, each (3,)."""
    s, b = np.empty(3), np.empty(3)
    for j in range(3):
        A = np.stack([x[:, j], np.ones(len(x))], -1)
        s[j], b[j] = np.linalg.lstsq(A, y[:, j], rcond=None)[0]
    return s, b


def _jackknife(folds, est):
    """Half-widths of the 95 % intervals of ``est`` from its leave-one-flight-out
    ``folds`` (Student's t on ``flights - 1`` degrees of freedom)."""
    n = len(folds)
    q = float(student_t.ppf(0.975, n - 1))
    return q * np.sqrt((n - 1) / n * np.sum((np.asarray(folds) - est) ** 2, axis=0))


def _accel_lines(flights, dR, config: Config) -> AxisLines | None:
    """The accelerometer's lines against the pose's specific force turned by ``dR``."""
    if any(f[2] is None for f in flights):
        return None
    ys = [f[2] for f in flights]
    xs = [f[3] @ dR.T for f in flights]
    y, x = np.concatenate(ys), np.concatenate(xs)
    s, b = _lines(y, x)
    folds = [_lines(np.concatenate(ys[:k] + ys[k + 1:]), np.concatenate(xs[:k] + xs[k + 1:]))
             for k in range(len(flights))]
    sens = config.sensors
    held = np.concatenate([yk - (sk * xk + bk) for yk, xk, (sk, bk)
                           in zip(ys, xs, folds, strict=True)])
    return AxisLines(s, b, _jackknife([f[0] for f in folds], s),
                     _jackknife([f[1] for f in folds], b),
                     np.sqrt(np.mean((y - sens.accel_readings(x)) ** 2, axis=0)),
                     np.sqrt(np.mean(held ** 2, axis=0)),
                     np.sqrt(np.mean((y - (s * x + b)) ** 2, axis=0)))


def sensor_calibration(config: Config, measured) -> SensorCalibration | None:
    """The gyro's scale and bias per axis, the marker frame's rotation and the
    accelerometer's scale and bias per axis, fitted against the motion capture.

    Parameters
    ----------
    config : Config
        Its ``[sensors]`` is the calibration the measurement was corrected with (and the
        one the fit is judged against); its ``analysis.latency_s`` puts the readings on
        the pose's clock.
    measured : list of Measured
        The segments of :func:`~gainsched.analysis.compare.compare` (``.measured``).

    Returns
    -------
    SensorCalibration or None
        None when fewer than two flights have a gyro (no held-out check).

    Examples
    --------
    >>> import glob
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> c = gs.compare(cfg, sorted(glob.glob("examples/flights/*.csv")))
    >>> cal = gs.sensor_calibration(cfg, c.measured)
    >>> cal.accepted, bool(np.all(np.abs(cal.scale - 1) < 0.01))  # the example gyro is right
    (False, True)
    """
    flights = _samples(config, measured)
    if len(flights) < 2:
        return None
    ys, xs = [f[0] for f in flights], [f[1] for f in flights]
    y, x = np.concatenate(ys), np.concatenate(xs)
    est = _fit(y, x)
    folds = [_fit(np.concatenate(ys[:k] + ys[k + 1:]), np.concatenate(xs[:k] + xs[k + 1:]))
             for k in range(len(flights))]
    ci = [_jackknife([f[i] for f in folds], est[i]) for i in range(3)]
    held = np.concatenate([yk - (xk @ fk[3].T + fk[1])
                           for yk, xk, fk in zip(ys, xs, folds, strict=True)])
    gyro = AxisLines(est[0], est[1], ci[0], ci[1],
                     np.sqrt(np.mean((y - config.sensors.readings(x)) ** 2, axis=0)),
                     np.sqrt(np.mean(held ** 2, axis=0)),
                     np.sqrt(np.mean((y - (x @ est[3].T + est[1])) ** 2, axis=0)))
    dR = matrix_from_euler_zyx_scalar(*est[2])
    return SensorCalibration(gyro, est[2], ci[2], _accel_lines(flights, dR, config),
                             config.sensors, len(flights), len(y))
