"""The config's schema: one frozen dataclass per section of the file, SI units.

:class:`~gainsched.config.Config` holds one of each (it lives with the reader, which
makes it: :meth:`~gainsched.config.Config.with_values` reads its edited text again).
Made by the reader (:mod:`gainsched.config._sections`), never by hand; the defaults here
are the defaults of the optional keys, and the tuples of choices are the values a
string key may take.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import INTEGRATORS, N_STATE

LINK_MODELS = ("rigid", "spring-damper", "sls", "lumped-mass")  # gainsched.model.links
TERMINAL_COSTS = ("periodic", "single-period")


@dataclass(frozen=True)
class Vehicle:
    """Rigid body and rotors.

    Attributes
    ----------
    mass : float, kg
    inertia : ndarray, shape (3, 3), kg m^2
    layout : str, ``"x"``
    arm_length : float, m (COG to rotor hub)
    kappa : float, m (reaction torque per newton of thrust, paper eq. 8)
    thrust_min, thrust_max : float, N per motor
    """

    mass: float
    inertia: np.ndarray
    layout: str
    arm_length: float
    kappa: float
    thrust_min: float
    thrust_max: float


@dataclass(frozen=True)
class Tether:
    """Tether: length rho (m), attachment offset L_e (m) and link model.

    The elastic links (:mod:`gainsched.model.links`) are used by the maximal-coordinate
    simulator only: ``stiffness`` (N/m) and ``damping`` (N s/m) are the
    spring-damper's k and c, the SLS's parallel k_p and c, and the whole chain's
    k and c; ``series_stiffness`` (N/m) is the SLS's series k_s; ``mass`` (kg,
    whole tether) and ``segments`` are the lumped-mass chain's.
    """

    length: float
    attachment_offset: float
    link: str = "rigid"
    stiffness: float = 2.0e4
    damping: float = 50.0
    series_stiffness: float = 5.0e4
    mass: float = 0.01
    segments: int = 4


@dataclass(frozen=True)
class EffectSpec:
    """One ``[effects.NAME]`` table: the effect kind and its parameters (SI)."""

    name: str
    params: tuple[tuple[str, float], ...]

    def param_dict(self) -> dict[str, float]:
        return dict(self.params)


def integral_states(delta: bool, azimuth: bool) -> tuple[str, ...]:
    """The LQR's integral states, in their order, from ``integrator`` (``delta``) and
    ``azimuth_integral`` (``azimuth``)."""
    on = {"int_delta": delta, "int_xi": azimuth}
    return tuple(n for n in INTEGRATORS if on[n])


@dataclass(frozen=True)
class Control:
    """LQR design: control rate (Hz), weights Q (n x n, n = 10 + integrals), R (4x4),
    the integral states, terminal cost."""

    rate_hz: float
    Q: np.ndarray
    R: np.ndarray
    integrator: bool = True
    terminal: str = "periodic"
    azimuth_integral: bool = False
    #: s; every closed-loop mode decays at least this fast (None: no bound; see
    #: :func:`gainsched.schedule.lqr.stability_scale`)
    max_time_constant_s: float | None = None
    #: the largest gain magnitude a build may produce, N per state unit (None: no cap;
    #: :func:`gainsched.schedule.bounds.check_gain_cap`)
    max_gain: float | None = None
    #: rad s; the firmware controller's bound on each integral state, one per entry of
    #: :attr:`integrators` (``int_limit`` in the file: one number for all of them, or a
    #: list); None: sized from the table's gains
    #: (:func:`gainsched.firmware.controller.int_limits_for`). The LQR does not use it.
    int_limit: tuple[float, ...] | None = None
    #: compute the stability margins of every circle's loop at the build
    #: (:mod:`gainsched.schedule.margins`; docs/margins.md)
    margins: bool = True
    #: dB; every loop's gain margins (down and up, all motors and each alone) at least
    #: this far from 0 dB, or the build fails naming the circle (None: no bound;
    #: :func:`gainsched.schedule.bounds.check_margin_bounds`)
    min_gain_margin_db: float | None = None
    #: ms; every loop's delay margin at least this, or the build fails (None: no bound)
    min_delay_margin_ms: float | None = None

    @property
    def integrators(self) -> tuple[str, ...]:
        """The LQR's integral states in their order (:data:`~gainsched.constants.INTEGRATORS`)."""
        return integral_states(self.integrator, self.azimuth_integral)

    @property
    def n_lqr(self) -> int:
        """LQR state dimension without effect states: 10 plus the integrals."""
        return N_STATE + len(self.integrators)

    @property
    def dt(self) -> float:
        """Control period, s."""
        return 1.0 / self.rate_hz


#: points an automatic axis starts from (its ends and the middle; docs/grid.md)
AUTO_SEED_COUNT = 3


@dataclass(frozen=True)
class AxisRange:
    """An axis the build chooses (``{min = .., max = .., max_count = ..}`` in ``[grid]``):
    breakpoints in ``[lo, hi]`` in the file's unit (m/s for speeds, deg for tilts), refined
    by :func:`gainsched.schedule.refine.refine_grid` until the cell midpoints meet
    ``grid.max_interpolation_error``, at most ``max_count`` of them (docs/grid.md)."""

    lo: float
    hi: float
    max_count: int

    def seeds(self) -> np.ndarray:
        """The breakpoints refinement starts from: the ends and the middle."""
        return np.linspace(self.lo, self.hi, min(AUTO_SEED_COUNT, self.max_count))

    def spec(self) -> str:
        """The range as written in a config: ``{min = 3, max = 20, max_count = 40}``."""
        return f"{{min = {self.lo!r}, max = {self.hi!r}, max_count = {self.max_count}}}"


@dataclass(frozen=True)
class AzimuthRange:
    """Azimuth samples the build chooses (``azimuth_samples = {min = .., max = ..}``): the
    smallest of ``lo, 2 lo, 4 lo, ...`` up to ``hi`` whose interpolation along the
    azimuth meets half of ``grid.max_interpolation_error`` at every cell centre
    (:func:`gainsched.schedule.refine.refine_grid`, docs/grid.md)."""

    lo: int
    hi: int

    def spec(self) -> str:
        """The range as written in a config: ``{min = 12, max = 96}``."""
        return f"{{min = {self.lo}, max = {self.hi}}}"


@dataclass(frozen=True)
class Grid:
    """Schedule grid: tangential COG speeds (m/s), tilts (rad), azimuth samples, and the
    interpolation error the table must meet at its cell midpoints (relative gain error,
    a fraction; ``max_interpolation_error`` in percent in the file, default 2).

    An axis given as a range (``speeds_auto``, ``tilts_auto``: :class:`AxisRange`, m/s
    and deg) is chosen by the build; ``speeds`` / ``tilts`` then hold its seeds
    (:meth:`AxisRange.seeds`) until :func:`gainsched.schedule.refine.refine_grid` returns
    the config with the chosen breakpoints."""

    speeds: np.ndarray
    tilts: np.ndarray
    azimuth_samples: int
    max_interpolation_error: float = 0.02
    speeds_auto: AxisRange | None = None
    tilts_auto: AxisRange | None = None
    azimuth_auto: AzimuthRange | None = None

    @property
    def auto(self) -> bool:
        """Whether the build chooses an axis (a range in ``[grid]``)."""
        return any(x is not None for x in (self.speeds_auto, self.tilts_auto,
                                           self.azimuth_auto))

    @property
    def auto_key(self) -> str | None:
        """The first key the build chooses (``grid.speeds``, ...), None for lists."""
        for key, x in (("speeds", self.speeds_auto), ("tilts_deg", self.tilts_auto),
                       ("azimuth_samples", self.azimuth_auto)):
            if x is not None:
                return f"grid.{key}"
        return None


#: table formats the firmware can be given (``[firmware] format``)
FORMATS = ("dense", "compact")
#: what the generated controller outputs (``[firmware] command``): thrusts in N, or
#: normalised commands through PX4's thrust curve (:mod:`gainsched.actuators`)
COMMANDS = ("thrust", "normalized")


@dataclass(frozen=True)
class Firmware:
    """What the build writes for the flight firmware (``[firmware]``, docs/runtime.md).

    Attributes
    ----------
    format : {"dense", "compact"}
        ``"dense"``: values at every azimuth sample, interpolated linearly; ``"compact"``:
        per circle, Fourier series in the azimuth, certified at the cell midpoints
        against ``grid.max_interpolation_error`` by the build.
    azimuth_error : float
        The compact format's bound on each circle's series at its azimuth samples,
        relative (a fraction; ``azimuth_error`` in percent in the file, default 1).
    max_table_bytes : int or None
        Flash budget: the build fails when the table data exceed it (None: no budget).
    motor_order : {"gainsched", "px4"}
        The numbering of the generated controller's outputs
        (:data:`gainsched.actuators.MOTOR_ORDERS`; docs/runtime.md, "PX4").
    command : {"thrust", "normalized"}
        Its outputs: thrusts in N, or commands in 0..1 through the thrust curve.
    thr_mdl_fac : float
        The thrust curve's quadratic part (PX4's ``THR_MDL_FAC``), 0..1.
    thrust_full : float or None, N
        Thrust at full command (``thrust_max_N`` in the file; None: ``vehicle.thrust_max``).
    """

    format: str = "dense"
    azimuth_error: float = 0.01
    max_table_bytes: int | None = None
    motor_order: str = "gainsched"
    command: str = "thrust"
    thr_mdl_fac: float = 0.0
    thrust_full: float | None = None


@dataclass(frozen=True)
class Feasibility:
    """Margins and the nominal's freedom.

    Attributes
    ----------
    min_tension : float, N
        The tether must stay at least this taut.
    thrust_margin : float, N
        Distance every nominal motor thrust keeps inside ``[thrust_min, thrust_max]``.
    attitude_offsets : {"zero", "free"}
        ``"zero"``: the nominal keeps ``theta = chi = 0`` (paper eqs. 15-18). ``"free"``:
        where that nominal needs a motor outside its range, pitch and yaw offsets of least
        mean square let the tether carry part of the torque
        (:mod:`gainsched.schedule.offsets`); elsewhere the nominal is the same.
    max_attitude_offset : float, rad
        Largest ``|theta|``, ``|chi|`` a free-offset nominal may use
        (``max_attitude_offset_deg`` in the file).
    """

    min_tension: float = 0.5
    thrust_margin: float = 0.0
    attitude_offsets: str = "zero"
    max_attitude_offset: float = float(np.deg2rad(10.0))


@dataclass(frozen=True)
class Analysis:
    """Model versus measurement (``[analysis]``, :mod:`gainsched.analysis.compare`).

    Attributes
    ----------
    savgol_window_s : float, s
        Savitzky-Golay window for differentiating the pose (rounded to an odd
        number of samples at the log's rate).
    savgol_order : int
        Polynomial order of the Savitzky-Golay fit (2..6; >= 2 for accelerations).
    latency_s : float, s
        Measurement latency: the logged pose lags the logged thrust commands (and the
        on-board sensors: load cell, gyro) by this.
    use_gyro : bool
        Take the body angular accelerations from the logged gyro (``p, q, r``: one
        differentiation) instead of the twice-differentiated attitude, when a log has it.
    use_accelerometer : bool
        Take the COG accelerations from the logged accelerometer (``ax, ay, az``: the
        specific force rotated by the pose's attitude, plus gravity) instead of the
        twice-differentiated position, when a log has it.
    """

    savgol_window_s: float = 0.1
    savgol_order: int = 3
    latency_s: float = 0.0
    use_gyro: bool = True
    use_accelerometer: bool = True


@dataclass(frozen=True)
class Sensors:
    """The on-board sensors' calibration (``[sensors]``): each gyro axis reads
    ``gyro_scale * omega + gyro_bias`` for a body rate ``omega`` (the accelerometer
    likewise), and the motion capture reports the markers' attitude, turned from the
    body's. The log reader (:func:`gainsched.compare`) and the firmware controller undo
    it, ``omega = (reading - gyro_bias) / gyro_scale``, before using a reading;
    ``diagnose`` estimates it against the motion capture
    (:func:`gainsched.analysis.diagnose.sensor_calibration`).

    Attributes
    ----------
    gyro_scale : tuple of 3 float
        Scale factor of the gyro's x, y, z axes (body frame B), in [0.5, 2].
    gyro_bias : tuple of 3 float, rad/s
        Bias of the gyro's x, y, z axes, each within +-0.5 rad/s.
    marker_rotation : tuple of 3 float, rad
        The body frame B relative to the motion capture's marker frame M (the rigid body
        defined on the markers, a degree or two off the vehicle's axes), as Z-Y-X Euler
        angles (roll, pitch, yaw; ``marker_rotation_deg`` in the file, each within +-10
        deg): ``R_MB = Rz(yaw) Ry(pitch) Rx(roll)``, and the body's attitude is
        ``R_IB = R_IM R_MB`` for the pose's ``R_IM``.
    accel_scale : tuple of 3 float
        Scale factor of the accelerometer's x, y, z axes, in [0.5, 2]: each reads
        ``accel_scale * f + accel_bias`` for a specific force ``f`` (m/s^2).
    accel_bias : tuple of 3 float, m/s^2
        Bias of the accelerometer's axes, each within +-2 m/s^2.
    """

    gyro_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    marker_rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def identity(self) -> bool:
        """True when the gyro and the accelerometer read as they are (scale 1, bias 0)
        and the markers' frame is the body's."""
        return self == Sensors()

    @property
    def gyro_identity(self) -> bool:
        """True when the gyro reads the body rates as they are (scale 1, bias 0)."""
        return self.gyro_scale == (1.0, 1.0, 1.0) and self.gyro_bias == (0.0, 0.0, 0.0)

    @property
    def accel_identity(self) -> bool:
        """True when the accelerometer reads the specific force as it is."""
        return self.accel_scale == (1.0, 1.0, 1.0) and self.accel_bias == (0.0, 0.0, 0.0)

    def accel_readings(self, f):
        """The accelerometer's readings (..., 3), m/s^2, of specific forces ``f``."""
        return np.asarray(f, dtype=float) * np.array(self.accel_scale) + np.array(
            self.accel_bias)

    def specific_force(self, reading):
        """The specific forces (..., 3), m/s^2, of accelerometer readings ``reading``:
        ``(reading - accel_bias) / accel_scale``."""
        return (np.asarray(reading, dtype=float) - np.array(self.accel_bias)) / np.array(
            self.accel_scale)

    @property
    def R_MB(self) -> np.ndarray:
        """``R_MB``, (3, 3): body-frame vectors in the marker frame."""
        from ..rotations import matrix_from_euler_zyx_scalar

        return matrix_from_euler_zyx_scalar(*self.marker_rotation)

    def body_attitude(self, R_IM):
        """The body's attitudes ``R_IB = R_IM R_MB`` (..., 3, 3) of the poses' ``R_IM``
        (..., 3, 3)."""
        return np.asarray(R_IM, dtype=float) @ self.R_MB

    def marker_attitude(self, R_IB):
        """What the motion capture reports, ``R_IM = R_IB R_MB^T`` (..., 3, 3), of the
        body's attitudes ``R_IB`` (..., 3, 3)."""
        return np.asarray(R_IB, dtype=float) @ self.R_MB.T

    def body_rates(self, reading):
        """The body rates (..., 3), rad/s, of gyro readings ``reading`` (..., 3), rad/s:
        ``(reading - gyro_bias) / gyro_scale``.

        Examples
        --------
        >>> Sensors((1.02, 1.0, 1.0), (0.01, 0.0, 0.0)).body_rates(np.array([1.03, 2, 3]))
        array([1., 2., 3.])
        """
        return (np.asarray(reading, dtype=float) - np.array(self.gyro_bias)) / np.array(
            self.gyro_scale)

    def readings(self, omega):
        """The gyro readings (..., 3), rad/s, of body rates ``omega`` (..., 3), rad/s."""
        return np.asarray(omega, dtype=float) * np.array(self.gyro_scale) + np.array(
            self.gyro_bias)


@dataclass(frozen=True)
class Limits:
    """Resource limits of a build (``[limits]``, checked by :func:`gainsched.config.check_budget`).

    Attributes
    ----------
    max_memory_gib : float, GiB
        Largest memory one build process may need (estimated).
    max_build_cpu_s : float, s
        Largest estimated CPU time of the whole build (summed over workers).
    """

    max_memory_gib: float = 8.0
    max_build_cpu_s: float = 1800.0
