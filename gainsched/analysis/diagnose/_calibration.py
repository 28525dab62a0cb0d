"""The gyroscope and the markers calibrated against each other: the gyro's scale and bias
per body axis, and the small rotation of the motion capture's marker frame.

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

A parameter is **off** when its estimate differs from the config's by more than its
95 % interval and by more than a tolerance below which a calibration changes nothing a
controller or a fit notices (:data:`SCALE_TOL`, :data:`BIAS_TOL`, :data:`ROTATION_TOL`;
the rotation's three Z-Y-X angles against 0); the calibration is **accepted** when some
parameter is off and the held-out fall on the axes it changes is at least
:data:`MIN_FALL`. Only the parameters that are off are changed (the others keep the
config's values, reported); the rotation's angles change together.

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
#: the least held-out fall of the residual above the noise (on the axes a calibration
#: changes) for it to be accepted
MIN_FALL = 0.8

#: both sides of the line averaged over this, s: the pose's rate noise then falls to
#: about 0.01 rad/s (the attitude noise over the window), far below the rates' spread
WINDOW_S = 0.5

_AXES = "xyz"


@dataclass(frozen=True)
class GyroCalibration:
    """The gyro's calibration fitted against the motion capture's body rates.

    Attributes
    ----------
    scale, bias : ndarray, shape (3,)
        The fitted scale factors (-) and biases (rad/s) of the x, y, z axes.
    rotation : ndarray, shape (3,)
        The rotation ``dR`` still between the config's body frame and the gyro's, as
        Z-Y-X Euler angles (roll, pitch, yaw), rad.
    scale_ci, bias_ci, rotation_ci : ndarray, shape (3,)
        Half-widths of their 95 % intervals (leave-one-flight-out jackknife).
    before, after : ndarray, shape (3,)
        Held-out RMS of ``reading - prediction`` per axis, rad/s, with the config's
        calibration and with the fitted one.
    floor : ndarray, shape (3,)
        The full fit's residual RMS per axis, rad/s: the noise of the comparison.
    config : Sensors
        The config's calibration (``[sensors]``).
    flights, samples : int
        Flights and samples the fit used.
    """

    scale: np.ndarray
    bias: np.ndarray
    rotation: np.ndarray
    scale_ci: np.ndarray
    bias_ci: np.ndarray
    rotation_ci: np.ndarray
    before: np.ndarray
    after: np.ndarray
    floor: np.ndarray
    config: Sensors
    flights: int
    samples: int

    @property
    def off(self) -> dict[str, bool]:
        """Per parameter (``gyro_scale_x`` ... ``gyro_bias_z``, ``marker_roll``,
        ``marker_pitch``, ``marker_yaw``): whether it differs from the config's by more
        than its 95 % interval and its tolerance."""
        out = {}
        for kind, est, ci, cfg, tol in (
                ("gyro_scale", self.scale, self.scale_ci, self.config.gyro_scale, SCALE_TOL),
                ("gyro_bias", self.bias, self.bias_ci, self.config.gyro_bias, BIAS_TOL),
                ("marker", self.rotation, self.rotation_ci, (0.0, 0.0, 0.0), ROTATION_TOL)):
            for j in range(3):
                d = abs(float(est[j]) - cfg[j])
                out[_name(kind, j)] = bool(d > ci[j] and d > tol)
        return out

    @property
    def rotated(self) -> bool:
        """Some angle of the marker frame's rotation is off."""
        return any(self.off[_name("marker", j)] for j in range(3))

    @property
    def axes_changed(self) -> list[int]:
        """The body axes (0, 1, 2) with a parameter off (all three for a rotation)."""
        off = self.off
        return [j for j in range(3) if off[f"gyro_scale_{_AXES[j]}"]
                or off[f"gyro_bias_{_AXES[j]}"] or self.rotated]

    @property
    def fall(self) -> float:
        """The held-out fall of the residual above the noise on :attr:`axes_changed`:
        ``1 - excess_after / excess_before``, each ``sqrt(sum(rms^2 - floor^2))`` over
        those axes (in units of their floors); nan with none."""
        j = self.axes_changed
        if not j:
            return float("nan")
        w = 1.0 / np.maximum(self.floor[j], 1e-12) ** 2
        excess = lambda rms: np.sqrt(np.sum(w * np.maximum(rms[j] ** 2 - self.floor[j] ** 2,  # noqa: E731
                                                            0.0)))
        before = excess(self.before)
        return float(1.0 - excess(self.after) / before) if before > 0 else 0.0

    @property
    def accepted(self) -> bool:
        """Some parameter is off and the held-out fall is at least :data:`MIN_FALL`."""
        return bool(self.axes_changed) and self.fall >= MIN_FALL

    def sensors(self) -> Sensors:
        """The calibration to write: the parameters that are off at their estimates, the
        others at the config's values; a rotation that is off turns the config's marker
        frame, ``R_MB <- R_MB dR^T`` (angles rounded to 1e-4 deg)."""
        off = self.off
        pick = lambda kind, est, cfg: tuple(  # noqa: E731
            round(float(est[j]), 6) if off[f"gyro_{kind}_{_AXES[j]}"] else cfg[j]
            for j in range(3))
        rot = self.config.marker_rotation
        if self.rotated:
            R_MB = self.config.R_MB @ matrix_from_euler_zyx_scalar(*self.rotation).T
            rot = tuple(float(np.deg2rad(round(float(np.rad2deg(a)), 4)))
                        for a in euler_zyx_from_matrix(R_MB))
        return Sensors(pick("scale", self.scale, self.config.gyro_scale),
                       pick("bias", self.bias, self.config.gyro_bias), rot)

    def applied(self, config: Config) -> Config:
        """``config`` with :meth:`sensors` (a model variant: its text is the base's;
        :func:`~gainsched.analysis.diagnose.apply_candidate` writes the text)."""
        return dataclasses.replace(config, sensors=self.sensors())

    def values(self) -> dict[str, float]:
        """Every parameter's estimate by name (``gyro_scale_x`` ... ``gyro_bias_z``)."""
        out = {f"gyro_scale_{_AXES[j]}": float(self.scale[j]) for j in range(3)}
        out.update({f"gyro_bias_{_AXES[j]}": float(self.bias[j]) for j in range(3)})
        out.update({_name("marker", j): float(self.rotation[j]) for j in range(3)})
        return out

    def sentence(self) -> str:
        """One line: the verdict on the gyro, with the estimates and the held-out fall."""
        fmt = lambda est, ci, unit: ", ".join(  # noqa: E731
            f"{e:.4g} +- {c:.1g}" for e, c in zip(est, ci, strict=True)) + unit
        R_MB = self.config.R_MB @ matrix_from_euler_zyx_scalar(*self.rotation).T
        body = np.rad2deg(euler_zyx_from_matrix(R_MB))  # the markers' frame as fitted
        what = (f"scale {fmt(self.scale, self.scale_ci, '')}; bias "
                f"{fmt(self.bias, self.bias_ci, ' rad/s')} (x, y, z); body in the markers' "
                f"frame at {fmt(body, np.rad2deg(self.rotation_ci), ' deg')} (roll, pitch, "
                "yaw; 95 %)")
        if not self.axes_changed:
            return (f"gyro against the motion capture: calibrated as the config says "
                    f"({what})")
        changed = ", ".join(k for k, v in self.off.items() if v)
        state = "accepted" if self.accepted else f"not accepted (fall below {MIN_FALL:.0%})"
        return (f"gyro calibration {state}: {what}; off: {changed}; held-out residual "
                f"above noise -{self.fall:.0%}")

    def to_json(self) -> dict:
        return {"values": self.values(),
                "ci95": {**{f"gyro_scale_{_AXES[j]}": float(self.scale_ci[j])
                            for j in range(3)},
                         **{f"gyro_bias_{_AXES[j]}": float(self.bias_ci[j])
                            for j in range(3)},
                         **{_name("marker", j): float(self.rotation_ci[j])
                            for j in range(3)}},
                "off": self.off, "accepted": self.accepted,
                "fall": None if np.isnan(self.fall) else self.fall,
                "rms_before": self.before.tolist(), "rms_after": self.after.tolist(),
                "noise": self.floor.tolist(), "flights": self.flights,
                "samples": self.samples,
                "written": dataclasses.asdict(self.sensors()) if self.accepted else None,
                "units": {"gyro_scale": "-", "gyro_bias": "rad/s", "marker": "rad"}}


def _samples(config: Config, measured):
    """Per flight (source): the readings on the pose's clock, smoothed, and the pose's
    body rates, core samples, stacked: ``[(reading (n, 3), omega (n, 3)), ...]``."""
    lat = config.analysis.latency_s
    by_flight: dict[str, list] = {}
    for m in measured:
        if m.gyro is None or m.n_core < 1:
            continue
        reading = config.sensors.readings(m.gyro_delayed(lat))  # the gyro's own numbers
        smooth = savgol_filter(reading, m.window, m.order, axis=0, mode="interp")
        n = min(2 * int(round(WINDOW_S / m.dt / 2)) + 1, 2 * ((m.n_core - 1) // 4) + 1)
        c = slice(m.core.start + n // 2, m.core.stop - n // 2)
        if c.stop - c.start < 1:
            continue
        by_flight.setdefault(m.source, []).append(
            (uniform_filter1d(smooth, n, axis=0)[c], uniform_filter1d(m.z[:, 7:10], n, axis=0)[c]))
    return [(np.concatenate([a for a, _ in v]), np.concatenate([w for _, w in v]))
            for v in by_flight.values()]


def _name(kind: str, j: int) -> str:
    """A parameter's name: ``gyro_scale_x`` ... ``marker_yaw``."""
    return f"marker_{('roll', 'pitch', 'yaw')[j]}" if kind == "marker" else f"{kind}_{_AXES[j]}"


def _fit(y, x):
    """The least-squares ``y = A x + b`` (rows (n, 3)), ``A = diag(s) dR``: ``(s, b,
    angles)``, each (3,), ``angles`` the Z-Y-X Euler angles of ``dR`` (rad), the rotation
    nearest the rows of ``A`` normalised (polar decomposition)."""
    X = np.concatenate([x, np.ones((len(x), 1))], -1)
    coef = np.linalg.lstsq(X, y, rcond=None)[0]  # (4, 3): column j is row j of A and b_j
    A, b = coef[:3].T, coef[3]
    s = np.linalg.norm(A, axis=1)
    U, _, Vt = np.linalg.svd(A / s[:, None])
    dR = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return s, b, np.array(euler_zyx_from_matrix(dR)), A


def gyro_calibration(config: Config, measured) -> GyroCalibration | None:
    """The gyro's scale and bias per axis fitted against the motion capture's rates.

    Parameters
    ----------
    config : Config
        Its ``[sensors]`` is the calibration the measured rates were corrected with (and
        the one the fit is judged against); its ``analysis.latency_s`` puts the readings
        on the pose's clock.
    measured : list of Measured
        The segments of :func:`~gainsched.analysis.compare.compare` (``.measured``).

    Returns
    -------
    GyroCalibration or None
        None when fewer than two flights have a gyro (no held-out check).

    Examples
    --------
    >>> import glob
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> c = gs.compare(cfg, sorted(glob.glob("examples/flights/*.csv")))
    >>> cal = gs.gyro_calibration(cfg, c.measured)
    >>> cal.accepted, bool(np.all(np.abs(cal.scale - 1) < 0.01))  # the example gyro is right
    (False, True)
    """
    flights = _samples(config, measured)
    if len(flights) < 2:
        return None
    y = np.concatenate([f[0] for f in flights])
    x = np.concatenate([f[1] for f in flights])
    est = _fit(y, x)
    floor = np.sqrt(np.mean((y - (x @ est[3].T + est[1])) ** 2, axis=0))
    folds = [_fit(np.concatenate([f[0] for i, f in enumerate(flights) if i != k]),
                  np.concatenate([f[1] for i, f in enumerate(flights) if i != k]))
             for k in range(len(flights))]
    n = len(flights)
    q = float(student_t.ppf(0.975, n - 1))
    ci = [q * np.sqrt((n - 1) / n * np.sum((np.array([f[i] for f in folds]) - est[i]) ** 2,
                                            axis=0))
          for i in range(3)]
    before = np.sqrt(np.mean((y - config.sensors.readings(x)) ** 2, axis=0))
    held = np.concatenate([f[0] - (f[1] @ fk[3].T + fk[1])
                           for f, fk in zip(flights, folds, strict=True)])
    after = np.sqrt(np.mean(held ** 2, axis=0))
    return GyroCalibration(est[0], est[1], est[2], ci[0], ci[1], ci[2], before, after,
                           floor, config.sensors, n, len(y))
