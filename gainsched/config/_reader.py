"""Configuration: TOML in, one frozen dataclass tree out.

``load_config(path)`` is the only way in. Every key is checked at this
boundary (unknown key, wrong type, missing key, impossible value) and a bad
one raises :class:`~gainsched.errors.InputError` naming the file and the
dotted key. Degrees exist only here (keys ending in ``_deg``); the dataclasses
hold SI units.

Besides types and ranges, the checks refuse what would only fail late in a
build: a name that is not a safe file name (:func:`check_name`), grid axes that
collapse in the tables' float32 (:func:`check_float32_axis`), a weight Q that
leaves the azimuth undetectable, a physically absurd vehicle, a control rate
that undersamples the fastest circle (:func:`check_rate`), a build that
would need more memory or CPU time than ``[limits]`` allows
(:func:`gainsched.budget.check_budget`), and a config no build could fly
(:mod:`gainsched.plausible`: gravity, lengths, hover, a flyable circle).
"""

from __future__ import annotations

import difflib
import hashlib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..actuators import MOTOR_ORDERS
from ..budget import check_budget
from ..constants import INTEGRATORS, MAX_XI, N_INPUT, N_STATE, REDUCED_NAMES, XI_DOT_LIMIT
from ..errors import InputError
from ..plausible import G_RANGE, check_circles, check_hover, check_lengths
from ..resources import config_path, reference_configs
from ..textinput import parse_toml, read_text

__all__ = [
    "Config",
    "Vehicle",
    "Tether",
    "Control",
    "Grid",
    "Feasibility",
    "Analysis",
    "Limits",
    "Firmware",
    "EffectSpec",
    "load_config",
    "config_from_text",
    "check_name",
    "N_STATE",
    "N_INPUT",
    "Section",
]


LINK_MODELS = ("rigid", "spring-damper", "sls", "lumped-mass")  # gainsched.model.links
TERMINAL_COSTS = ("periodic", "single-period")

#: ``name``: 1..64 characters of [A-Za-z0-9_.-], the first a letter or a digit (a file name
#: that stays inside the output folder, is never hidden, and maps to a C identifier)
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}")
NAME_RULE = "1-64 characters from A-Z a-z 0-9 _ - . starting with a letter or a digit"
MASS_RANGE = (0.01, 1000.0)  # kg, a plausible vehicle
INERTIA_TRIANGLE_TOL = 1e-6  # relative slack of J1 + J2 >= J3 (a flat plate is the limit)
MAX_SPEED = 100.0  # m/s, tangential COG speed
MAX_RATE_HZ = 1.0e5  # Hz, control rate
#: control periods: the shortest closed-loop time constant bound a config may ask for
MIN_TIME_CONSTANT_STEPS = 10
MIN_STEPS_PER_PERIOD = 32  # control steps over the fastest circle of the grid
#: largest config text, characters: a hand-written config is a few KiB, and the largest
#: grid the default [limits] allow is far below this (parsing 20 MB of TOML takes seconds)
MAX_CONFIG_CHARS = 2**20
_KEY_LINE = re.compile(r"^[ \t]*([A-Za-z0-9_\-]+)[ \t]*=|^[ \t]*\[+[ \t]*([^\]\n]+?)[ \t]*\]",
                       re.M)


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


def _integrators(delta: bool, azimuth: bool) -> tuple[str, ...]:
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
    #: :func:`gainsched.schedule.grid.check_gain_cap`)
    max_gain: float | None = None
    #: rad s; the firmware controller's bound on each integral state, one per entry of
    #: :attr:`integrators` (``int_limit`` in the file: one number for all of them, or a
    #: list); None: sized from the table's gains
    #: (:func:`gainsched.firmware.controller.int_limits_for`). The LQR does not use it.
    int_limit: tuple[float, ...] | None = None

    @property
    def integrators(self) -> tuple[str, ...]:
        """The LQR's integral states in their order (:data:`~gainsched.constants.INTEGRATORS`)."""
        return _integrators(self.integrator, self.azimuth_integral)

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
class Limits:
    """Resource limits of a build (``[limits]``, checked by :func:`gainsched.budget.check_budget`).

    Attributes
    ----------
    max_memory_gib : float, GiB
        Largest memory one build process may need (estimated).
    max_build_cpu_s : float, s
        Largest estimated CPU time of the whole build (summed over workers).
    """

    max_memory_gib: float = 8.0
    max_build_cpu_s: float = 1800.0


@dataclass(frozen=True)
class Config:
    """A validated config: every parameter of a build, in SI units, from one TOML file.

    Made by :func:`load_config` or :func:`config_from_text`, never by hand: those check
    every key. Frozen; :meth:`with_values` makes a validated variant. Each section of the
    file is a frozen dataclass of its own (:class:`Vehicle`, :class:`Tether`, ...); keys
    ending in ``_deg`` are held in rad under the name without the suffix.

    Attributes
    ----------
    name : str
        The ``name`` key (default: the config file's stem): the stem of the output files
        (``NAME.h5``, ``NAME_gains.h``) and the prefix of the C symbols
        (:func:`check_name`).
    vehicle : Vehicle
        ``[vehicle]``: mass (kg), inertia (3, 3) kg m^2, motor layout (``"x"``), arm
        length (m), reaction torque per newton of thrust ``kappa`` (m, paper eq. 8), and
        the thrust range of each motor ``thrust_min``, ``thrust_max`` (N).
    tether : Tether
        ``[tether]``: length ``rho`` (m), attachment offset ``L_e`` (m, behind the COG),
        and the link model with its stiffness (N/m), damping (N s/m), mass (kg) and
        segments; the schedule treats the tether as rigid, the elastic links are used by
        the maximal-coordinate simulator only.
    effects : tuple of EffectSpec
        The ``[effects.NAME]`` tables, sorted by name: each model effect (e.g. ``drag``,
        paper eq. 10) and its parameters in SI; empty when the file has none.
    g : float
        ``[environment] g``: gravitational acceleration, m/s^2.
    control : Control
        ``[control]``: control rate ``rate_hz`` (Hz; period ``dt``, s), the LQR weights
        ``Q`` (n, n) over the LQR state (n = 10 + integral states, 11 for
        configs/paper.toml; paper eq. 24) and ``R`` (4, 4) over the motor thrusts, the
        integral states (``integrator``: delta, paper Sec. IV.B; ``azimuth_integral``:
        xi), the terminal cost (``"periodic"`` or ``"single-period"``) and the firmware's
        bounds on the integral states (``int_limit``, rad s; default: sized from the
        table's gains).
    grid : Grid
        ``[grid]``: the schedule's axes: tangential COG speeds ``speeds`` (n_v,) m/s,
        circle tilts ``tilts`` (n_a,) rad (``tilts_deg`` in the file, starting at 0), and
        ``azimuth_samples`` (n_xi, even) per circle.
    feasibility : Feasibility
        ``[feasibility]`` (defaults when absent): the tension margin and thrust margin
        (N) every nominal keeps, and whether it may use pitch and yaw offsets.
    source : str
        Where the config came from: the file path, or the ``source`` given to
        :func:`config_from_text` (``"<string>"`` by default); errors about it name it.
    text : str
        The TOML text as read (newlines normalised to ``\\n``): :attr:`sha256` hashes it
        and every table built from it embeds it (``config_text``).
    analysis : Analysis
        ``[analysis]`` (defaults when absent): how flight logs are differentiated and
        aligned for model versus measurement (:func:`gainsched.compare`).
    limits : Limits
        ``[limits]`` (defaults when absent): the memory (GiB) and CPU time (s) a build
        may need (:func:`gainsched.budget.check_budget`).
    firmware : Firmware
        ``[firmware]`` (defaults when absent): the table format the C header carries and
        the flash budget.
    radius : float
        Property: nominal COG circle radius ``r = rho + L_e``, m.
    sha256 : str
        Property: SHA-256 of :attr:`text` (hex), stored in the tables and C headers.

    See Also
    --------
    load_config : Load and validate a config file.
    config_from_text : Parse and validate config text.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cfg.vehicle.mass, cfg.tether.length, cfg.radius            # kg, m, m
    (0.5, 1.5, 1.6)
    >>> cfg.control.Q.shape, cfg.control.integrators, cfg.control.dt  # dt in s
    ((11, 11), ('int_delta',), 0.001)
    >>> [e.name for e in cfg.effects]
    ['drag']
    >>> cfg.grid.speeds.size, np.rad2deg(cfg.grid.tilts).round(1).tolist()
    (19, [0.0, 10.0, 20.0, 28.0, 34.0, 37.0, 40.0])

    A heavier vehicle, validated again (the text and hash follow the change):

    >>> heavy = cfg.with_values({"vehicle.mass": 0.55})
    >>> heavy.vehicle.mass, heavy.sha256 == cfg.sha256
    (0.55, False)
    """

    name: str
    vehicle: Vehicle
    tether: Tether
    effects: tuple[EffectSpec, ...]
    g: float
    control: Control
    grid: Grid
    feasibility: Feasibility
    source: str = "<string>"
    text: str = field(default="", repr=False)
    analysis: Analysis = field(default_factory=Analysis)
    limits: Limits = field(default_factory=Limits)
    firmware: Firmware = field(default_factory=Firmware)

    def __repr__(self) -> str:
        """One line: the name, the source, the vehicle and tether at a glance, the effects,
        the grid and the text's hash (the full values: the attributes, or ``text``)."""
        g = self.grid
        grid = ("axes chosen by the build" if g.auto else
                f"{g.speeds.size} speeds x {g.tilts.size} tilts x {g.azimuth_samples} azimuths")
        effects = ", ".join(e.name for e in self.effects) or "none"
        return (f"Config({self.name!r}, source={self.source!r}, mass {self.vehicle.mass:g} kg, "
                f"tether {self.tether.length:g} m {self.tether.link}, effects {effects}, "
                f"{grid}, sha256 {self.sha256[:12]})")

    @property
    def sha256(self) -> str:
        """SHA-256 of the config text (hex)."""
        return hashlib.sha256(self.text.encode()).hexdigest()

    @property
    def radius(self) -> float:
        """Nominal COG radius r = rho + L_e, m."""
        return self.tether.length + self.tether.attachment_offset

    def with_values(self, values: dict, source: str | None = None) -> Config:
        """A variant with some keys changed: the config text edited as a TOML document
        (comments kept, floats in full precision; :func:`gainsched.configedit.set_values`)
        and validated again, so ``text`` and ``sha256`` describe the variant.

        Parameters
        ----------
        values : dict
            Dotted key -> value, e.g. ``{"vehicle.mass": 0.55, "grid.azimuth_samples": 72}``.
        source : str, optional
            Where errors point (default: this config's source).

        Example
        -------
        >>> cfg = load_config("configs/paper.toml")              # doctest: +SKIP
        >>> cfg.with_values({"vehicle.mass": 0.55}).vehicle.mass  # doctest: +SKIP
        0.55
        """
        from ..configedit import set_values

        return config_from_text(set_values(self.text, values),
                                self.source if source is None else source)


# --------------------------------------------------------------------------- checks


def _numeric_list(v) -> bool:
    """A (nested) list whose leaves are all ints or floats (TOML booleans and strings are not)."""
    return isinstance(v, list) and all(
        (isinstance(x, int | float) and not isinstance(x, bool)) or _numeric_list(x) for x in v
    )


#: how alike a written key and a known one must be to be named as its likely meaning
#: (difflib's ratio: ``arm_lenght`` and ``arm_length`` 0.9, ``mass`` and ``max`` 0.57)
_TYPO_CUTOFF = 0.8


class Section:
    """A TOML table being consumed: tracks which keys were read, to reject unknown ones."""

    def __init__(self, source: str, prefix: str, data):
        if not isinstance(data, dict):
            raise InputError(source, prefix, "must be a table")
        self.source, self.prefix, self.data = source, prefix, data
        self.used: set[str] = set()

    def key(self, k: str) -> str:
        return f"{self.prefix}.{k}" if self.prefix else k

    def error(self, k: str, msg: str) -> InputError:
        return InputError(self.source, self.key(k), msg)

    def get(self, k: str, default=...):
        self.used.add(k)
        if k not in self.data:
            if default is ...:
                # a misspelt key reads as a missing one: name the key that was written
                typo = difflib.get_close_matches(k, [d for d in self.data if d not in self.used],
                                                 n=1, cutoff=_TYPO_CUTOFF)
                if typo:
                    raise self.error(typo[0], f"unknown key (did you mean {k}?)")
                raise self.error(k, "missing required key")
            return default
        return self.data[k]

    def number(self, k, default=..., *, positive=False, nonneg=False) -> float:
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.error(k, f"must be a number, got {type(v).__name__}")
        try:
            v = float(v)
        except OverflowError:  # an integer beyond the floats (TOML integers are unbounded)
            raise self.error(k, "must be finite") from None
        if not math.isfinite(v):
            raise self.error(k, "must be finite")
        if positive and v <= 0:
            raise self.error(k, f"must be > 0, got {v:g}")
        if nonneg and v < 0:
            raise self.error(k, f"must be >= 0, got {v:g}")
        return v

    def bounded(self, k, default=..., *, lo: float, hi: float, unit: str,
                lo_open: bool = False) -> float:
        """A finite number in ``[lo, hi]`` (``lo_open``: ``(lo, hi]``); the message gives
        the range and the unit."""
        v = self.number(k, default)
        if (v <= lo if lo_open else v < lo) or v > hi:
            raise self.error(k, f"must be in {'(' if lo_open else '['}{lo:g}, {hi:g}] {unit}, "
                             f"got {v:g}")
        return v

    def integer(self, k, default=..., *, lo: int, hi: int, what: str = "") -> int:
        """An integer (not a float, not a boolean) in ``[lo, hi]``."""
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            shown = repr(v) if isinstance(v, int | float | bool) else type(v).__name__
            raise self.error(k, f"must be an integer in [{lo}, {hi}]{what}, got {shown}")
        return v

    def string(self, k, default=..., choices=None) -> str:
        v = self.get(k, default)
        if not isinstance(v, str):
            raise self.error(k, f"must be a string, got {type(v).__name__}")
        if choices is not None and v not in choices:
            raise self.error(k, f"must be one of {', '.join(choices)}; got {v!r}")
        return v

    def boolean(self, k, default=...) -> bool:
        v = self.get(k, default)
        if not isinstance(v, bool):
            raise self.error(k, f"must be true or false, got {type(v).__name__}")
        return v

    def array(self, k, default=...) -> np.ndarray:
        v = self.get(k, default)
        if not _numeric_list(v):
            raise self.error(k, "must be a list of numbers (or a list of rows)")
        try:
            a = np.array(v, dtype=float)
        except (TypeError, ValueError, OverflowError):  # ragged rows, integers beyond floats
            raise self.error(k, "must be a list of numbers (or a list of rows)") from None
        if not np.all(np.isfinite(a)):
            raise self.error(k, "entries must be finite")
        return a

    def sub(self, k, default=...) -> Section:
        return Section(self.source, self.key(k), self.get(k, default))

    def done(self):
        extra = sorted(set(self.data) - self.used)
        if extra:
            near = difflib.get_close_matches(extra[0], sorted(self.used), n=1,
                                             cutoff=_TYPO_CUTOFF)
            raise self.error(extra[0], "unknown key" + (f" (did you mean {near[0]}?)"
                                                        if near else ""))


def check_square_weight(sec: Section, k: str, n: int, *, definite: bool,
                        names: tuple[str, ...] = ()) -> np.ndarray:
    """Q or R: n diagonal entries or an n x n symmetric matrix; PSD (Q) or PD (R).
    ``names`` (n entries) are quoted when the size is wrong."""
    a = sec.array(k)
    order = f" ({', '.join(names)})" if names else ""
    if a.ndim == 1:
        if a.shape != (n,):
            raise sec.error(k, f"must have {n} diagonal entries{order} or be {n}x{n}, "
                            f"got {a.size}")
        a = np.diag(a)
    elif a.shape != (n, n):
        raise sec.error(k, f"must be {n}x{n}, got {'x'.join(map(str, a.shape))}")
    if not np.allclose(a, a.T, rtol=0, atol=1e-12 * max(1.0, np.abs(a).max())):
        raise sec.error(k, "must be symmetric")
    lam = np.linalg.eigvalsh(a).min()
    tol = 1e-12 * max(1.0, np.abs(a).max())
    if definite and lam <= tol:
        raise sec.error(k, f"must be positive definite (smallest eigenvalue {lam:.3g})")
    if not definite and lam < -tol:
        raise sec.error(k, f"must be positive semidefinite (smallest eigenvalue {lam:.3g})")
    return a


def check_axis(sec: Section, k: str, *, nonneg: bool, positive: bool) -> np.ndarray:
    a = sec.array(k)
    if a.ndim != 1 or a.size == 0:
        raise sec.error(k, "must be a non-empty list of numbers")
    if np.any(np.diff(a) <= 0):
        raise sec.error(k, "must be strictly increasing")
    if positive and a[0] <= 0:
        raise sec.error(k, f"must be > 0, got {a[0]:g}")
    if nonneg and a[0] < 0:
        raise sec.error(k, f"must be >= 0 (negative values come from the symmetry), got {a[0]:g}")
    return a


def check_float32_axis(sec: Section, k: str, values: np.ndarray, what: str) -> None:
    """The tables store axes as float32: ``values`` must stay finite and strictly increasing.

    ``values`` is the axis as stored (e.g. speeds / r for ``xi_dot``, rad for tilts);
    ``what`` names it in the message. Raises InputError naming ``k``.
    """
    with np.errstate(over="ignore"):
        f = values.astype(np.float32)
    if not np.all(np.isfinite(f)):
        raise sec.error(k, f"{what} overflows float32 (the C tables store float32)")
    same = np.flatnonzero(np.diff(f) <= 0)
    if same.size:
        i = int(same[0])
        raise sec.error(
            k,
            f"entries {i + 1} and {i + 2} are equal in float32 ({what} {float(values[i])!r} "
            f"and {float(values[i + 1])!r}; the C tables store float32): space them further "
            "apart",
        )


def check_name(source, name: str, *, from_file: bool = False) -> str:
    """``name``: the output file stem (``OUT/NAME.h5``, ``OUT/NAME_gains.h``) and the C prefix.

    Rule: 1-64 characters from ``A-Z a-z 0-9 _ - .``, the first a letter or a digit (so
    it stays inside the output folder, is never a hidden file, and
    :func:`gainsched.firmware.runtime.c_identifier` maps it to a C identifier). With
    ``from_file`` the name is the default taken from the config file's name, and the
    message says to set ``name``. Raises InputError naming the key ``name``.
    """
    if NAME_RE.fullmatch(name):
        return name
    shown = name if len(name) <= 80 else name[:77] + "..."
    if from_file:
        fix = re.sub(r"[^A-Za-z0-9_.\-]", "_", name).lstrip("._-")[:64] or "config"
        raise InputError(
            source,
            "name",
            f"not set, and the default from the file name {shown!r} is not a valid name "
            f"({NAME_RULE}); set name = {fix!r} in the file",
        )
    raise InputError(
        source,
        "name",
        f"must be {NAME_RULE} (it names the output files NAME.h5, NAME_gains.h and "
        f"the C symbols); got {shown!r}",
    )


def _vehicle(sec: Section) -> Vehicle:
    mass = sec.number("mass", positive=True)
    if not MASS_RANGE[0] <= mass <= MASS_RANGE[1]:
        raise sec.error(
            "mass", f"must be in [{MASS_RANGE[0]:g}, {MASS_RANGE[1]:g}] kg, got {mass:g}"
        )
    J = sec.array("inertia")
    if J.shape == (3,):
        J = np.diag(J)
    elif J.shape != (3, 3):
        raise sec.error("inertia", "must be [Jxx, Jyy, Jzz] or a 3x3 matrix")
    if not np.allclose(J, J.T, rtol=0, atol=1e-15):
        raise sec.error("inertia", "must be symmetric")
    lam = np.linalg.eigvalsh(J)  # ascending principal moments
    if lam[0] <= 0:
        raise sec.error("inertia", "must be positive definite")
    if lam[0] + lam[1] < lam[2] * (1 - INERTIA_TRIANGLE_TOL):
        # every rigid body has J1 + J2 >= J3 (equality: a flat plate)
        raise sec.error(
            "inertia",
            f"principal moments {lam[0]:.4g}, {lam[1]:.4g}, {lam[2]:.4g} kg m^2 violate the "
            f"triangle inequality J1 + J2 >= J3 of every rigid body",
        )
    if J[0, 1] != 0 or J[1, 2] != 0:
        # The direction symmetry S2 (mirror about the body x-z plane) needs it.
        raise sec.error("inertia", "Jxy and Jyz must be 0 (the vehicle is mirror-symmetric in y)")
    layout = sec.string("layout", "x", choices=("x",))
    arm = sec.number("arm_length", positive=True)
    kappa = sec.number("kappa", positive=True)
    tmin = sec.number("thrust_min", nonneg=True)
    tmax = sec.number("thrust_max", positive=True)
    if tmin >= tmax:
        raise sec.error("thrust_min", f"must be < thrust_max ({tmin:g} >= {tmax:g})")
    sec.done()
    J.setflags(write=False)
    return Vehicle(mass, J, layout, arm, kappa, tmin, tmax)


def _tether(sec: Section) -> Tether:
    length = sec.number("length", positive=True)
    off = sec.number("attachment_offset", nonneg=True)
    if off >= length:
        raise sec.error("attachment_offset", f"must be < tether length ({off:g} >= {length:g})")
    link = sec.string("link", "rigid", choices=LINK_MODELS)
    stiffness = sec.number("stiffness", Tether.stiffness, positive=True)
    damping = sec.number("damping", Tether.damping, nonneg=True)
    own = {"series_stiffness": "sls", "mass": "lumped-mass", "segments": "lumped-mass"}
    for k, user in own.items():
        if k in sec.data and link != user:
            raise sec.error(k, f'only used by link = "{user}" (link is "{link}")')
    k_s = sec.number("series_stiffness", Tether.series_stiffness, positive=True)
    mass = sec.number("mass", Tether.mass, nonneg=True)
    n = sec.get("segments", Tether.segments)
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 100:
        raise sec.error("segments", f"must be an integer in [1, 100], got {n!r}")
    if link == "sls" and damping <= 0:
        raise sec.error("damping", "must be > 0 for the sls link (creep time damping / stiffness)")
    if link == "lumped-mass" and n > 1 and mass <= 0:
        raise sec.error("mass", "must be > 0 for a chain of more than one segment")
    sec.done()
    return Tether(length, off, link, stiffness, damping, k_s, mass, n)


def _effects(sec: Section) -> tuple[EffectSpec, ...]:
    from ..model.effects import EFFECTS  # the registry; imported here to avoid a cycle

    out = []
    for name in sorted(sec.data):
        sub = sec.sub(name)
        if name not in EFFECTS:
            raise sec.error(name, f"unknown effect (known: {', '.join(sorted(EFFECTS))})")
        cls = EFFECTS[name]
        vals = []
        for p in cls.params:
            v = sub.number(p.name, p.default)
            if not (p.lower <= v <= p.upper):
                raise sub.error(
                    p.name, f"must be in [{p.lower:g}, {p.upper:g}] {p.unit}, got {v:g}"
                )
            vals.append((p.name, v))
        sub.done()
        out.append(EffectSpec(name, tuple(vals)))
    return tuple(out)


def _control(sec: Section) -> Control:
    rate = sec.number("rate_hz", positive=True)
    if rate > MAX_RATE_HZ:
        raise sec.error("rate_hz", f"must be <= {MAX_RATE_HZ:g} Hz, got {rate:g}")
    integ = sec.boolean("integrator", True)
    az_integ = sec.boolean("azimuth_integral", False)
    integrators = _integrators(integ, az_integ)
    Q = check_square_weight(sec, "Q", N_STATE + len(integrators), definite=False,
                            names=REDUCED_NAMES + integrators)
    if not np.any(Q):
        raise sec.error("Q", "must not be all zero (the LQR would have nothing to regulate)")
    if Q[1, 1] <= 0:
        # xi enters no dynamics (rotation about the anchor), so it is an exact integrator
        # (eigenvalue 1 on every circle): unweighted it is undetectable and the Riccati
        # equation has no stabilising solution
        raise sec.error(
            "Q", "the xi entry (index 1, azimuth) must be > 0: an unweighted azimuth is "
            "undetectable and the LQR has no stabilising solution"
        )
    R = check_square_weight(sec, "R", N_INPUT, definite=True)
    # The table serves reversed circles through the direction mirror S2, exact only if
    # the weights are invariant under it (docs/symmetry.md).
    from ..model.symmetry import P_U, lqr_state_signs

    signs = lqr_state_signs(integrators)
    if not np.array_equal(Q * np.outer(signs, signs), Q):
        raise sec.error(
            "Q",
            "must not couple states the direction mirror flips (xi, xi', "
            "phi, chi, omega_x, omega_z, int_xi) with states it keeps (docs/symmetry.md)",
        )
    if not np.array_equal(P_U @ R @ P_U, R):
        raise sec.error("R", "must be invariant under the motor swap 1<->4, 2<->3 "
                        "(R11 = R44, R22 = R33; docs/symmetry.md)")
    term = sec.string("terminal", "periodic", choices=TERMINAL_COSTS)
    tau_max = None
    if "max_time_constant_s" in sec.data:
        tau_max = sec.number("max_time_constant_s", positive=True)
        if tau_max < MIN_TIME_CONSTANT_STEPS / rate:
            raise sec.error("max_time_constant_s", f"must be at least {MIN_TIME_CONSTANT_STEPS} "
                            f"control periods ({MIN_TIME_CONSTANT_STEPS / rate:g} s at "
                            f"{rate:g} Hz), got {tau_max:g}")
        if term != "periodic":
            raise sec.error("max_time_constant_s", "needs terminal = \"periodic\" (a "
                            "one-period horizon guarantees no decay rate)")
    max_gain = None
    if "max_gain" in sec.data:
        max_gain = sec.number("max_gain", positive=True)
    int_limit = _int_limit(sec, integrators) if "int_limit" in sec.data else None
    sec.done()
    Q.setflags(write=False)
    R.setflags(write=False)
    return Control(rate, Q, R, integ, term, az_integ, tau_max, max_gain, int_limit)


def _int_limit(sec: Section, integrators: tuple[str, ...]) -> tuple[float, ...]:
    """``control.int_limit``: one positive number (rad s) for every integral state, or a
    list of one per integral state in their order."""
    if not integrators:
        raise sec.error("int_limit", "there is no integral state to bound (integrator = "
                        "false, azimuth_integral = false)")
    if isinstance(sec.data["int_limit"], list):
        a = sec.array("int_limit")
        if a.shape != (len(integrators),):
            raise sec.error("int_limit", f"must be one number or {len(integrators)} "
                            f"({', '.join(integrators)}), got {a.size}")
        if np.any(a <= 0):
            raise sec.error("int_limit", "entries must be > 0")
        return tuple(float(v) for v in a)
    return (sec.number("int_limit", positive=True),) * len(integrators)


#: most breakpoints an automatic axis may be given (``max_count``)
MAX_AUTO_COUNT = 1024


def check_axis_range(sec: Section, k: str) -> AxisRange:
    """``grid.<k> = {min = .., max = .., max_count = ..}``: finite ends ``min < max`` and an
    integer ``2 <= max_count <= MAX_AUTO_COUNT``; errors name ``grid.<k>.<field>``."""
    sub = sec.sub(k)
    lo, hi = sub.number("min"), sub.number("max")
    n = sub.get("max_count")
    if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= MAX_AUTO_COUNT:
        raise sub.error("max_count", f"must be an integer in [2, {MAX_AUTO_COUNT}], got {n!r}")
    if not lo < hi:
        raise sub.error("max", f"must be > min ({lo:g}), got {hi:g}")
    sub.done()
    return AxisRange(lo, hi, n)


def _axis_or_range(sec: Section, k: str, *, nonneg: bool, positive: bool):
    """A list axis, or a range the build refines: ``(breakpoints or seeds, AxisRange or
    None)``."""
    if isinstance(sec.data.get(k), dict):
        rng = check_axis_range(sec, k)
        if positive and rng.lo <= 0:
            raise sec.error(f"{k}.min", f"must be > 0, got {rng.lo:g}")
        return rng.seeds(), rng
    return check_axis(sec, k, nonneg=nonneg, positive=positive), None


def _grid(sec: Section, radius: float) -> Grid:
    """``[grid]``; ``radius`` (m, rho + L_e) gives the azimuth-rate axis speeds / radius."""

    speeds, speeds_auto = _axis_or_range(sec, "speeds", nonneg=False, positive=True)
    k_lo, k_hi = ("speeds.min", "speeds.max") if speeds_auto else ("speeds", "speeds")
    if speeds[-1] > MAX_SPEED:
        raise sec.error(k_hi, f"must be <= {MAX_SPEED:g} m/s, got {speeds[-1]:g}")
    xi_dot = speeds / radius
    if xi_dot[-1] > XI_DOT_LIMIT:
        raise sec.error(
            k_hi,
            f"{speeds[-1]:g} m/s on a {radius:g} m circle is an azimuth rate of "
            f"{xi_dot[-1]:.4g} rad/s, above the runtime's limit {float(XI_DOT_LIMIT):g} rad/s",
        )
    check_float32_axis(sec, "speeds", speeds, "speeds (m/s)")
    check_float32_axis(sec, "speeds", xi_dot, "azimuth rates speed / (rho + L_e) (rad/s)")
    tilts_deg, tilts_auto = _axis_or_range(sec, "tilts_deg", nonneg=True, positive=False)
    k_lo, k_hi = ("tilts_deg.min", "tilts_deg.max") if tilts_auto else ("tilts_deg",) * 2
    if tilts_deg[0] != 0:
        raise sec.error(
            k_lo,
            f"must start at 0 (negative tilts come from symmetry), got {tilts_deg[0]:g}",
        )
    if tilts_deg[-1] >= 90:
        raise sec.error(k_hi, f"must be < 90, got {tilts_deg[-1]:g}")
    tilts = np.deg2rad(tilts_deg)
    check_float32_axis(sec, "tilts_deg", tilts, "tilts (rad)")
    azimuth_auto = None
    if isinstance(sec.data.get("azimuth_samples"), dict):
        sub = sec.sub("azimuth_samples")
        lo, hi = _azimuth_count(sub, "min"), _azimuth_count(sub, "max")
        if hi < lo:
            raise sub.error("max", f"must be >= min ({lo}), got {hi}")
        sub.done()
        azimuth_auto = AzimuthRange(lo, hi)
        n = lo
    else:
        n = _azimuth_count(sec, "azimuth_samples")
    err = sec.number("max_interpolation_error", 100 * Grid.max_interpolation_error,
                     positive=True)
    if err >= 100:
        raise sec.error("max_interpolation_error", f"must be < 100 (percent), got {err:g}")
    sec.done()
    for a in (speeds, tilts):
        a.setflags(write=False)
    return Grid(speeds, tilts, n, err / 100, speeds_auto, tilts_auto, azimuth_auto)


def _azimuth_count(sec: Section, k: str) -> int:
    """An azimuth sample count: an even integer in [4, MAX_XI]."""
    n = sec.get(k)
    if isinstance(n, bool) or not isinstance(n, int):
        raise sec.error(k, f"must be an integer, got {type(n).__name__}")
    if n < 4 or n % 2 or n > MAX_XI:
        raise sec.error(k, f"must be an even integer in [4, {MAX_XI}], got {n}")
    return n


def _firmware(sec: Section) -> Firmware:
    fmt = sec.string("format", Firmware.format, choices=FORMATS)
    err = sec.number("azimuth_error", 100 * Firmware.azimuth_error, positive=True)
    if err >= 100:
        raise sec.error("azimuth_error", f"must be < 100 (percent), got {err:g}")
    budget = None
    if "max_table_bytes" in sec.data:
        budget = sec.get("max_table_bytes")
        if isinstance(budget, bool) or not isinstance(budget, int) or budget < 1:
            raise sec.error("max_table_bytes", f"must be a positive integer, got {budget!r}")
    order = sec.string("motor_order", Firmware.motor_order, choices=tuple(MOTOR_ORDERS))
    command = sec.string("command", Firmware.command, choices=COMMANDS)
    for k in ("thr_mdl_fac", "thrust_max_N"):
        if k in sec.data and command != "normalized":
            raise sec.error(k, 'applies to normalised outputs only: set command = "normalized"')
    fac = sec.number("thr_mdl_fac", Firmware.thr_mdl_fac, nonneg=True)
    if fac > 1:
        raise sec.error("thr_mdl_fac", f"must be in 0..1, got {fac:g}")
    full = sec.number("thrust_max_N", positive=True) if "thrust_max_N" in sec.data else None
    sec.done()
    return Firmware(fmt, err / 100, budget, order, command, fac, full)


def _check_commands(source, firmware: Firmware, vehicle: Vehicle) -> None:
    """Normalised outputs must cover the motors' range (``vehicle.thrust_min >= 0``
    already): ``vehicle.thrust_max <= firmware.thrust_max_N``, the thrust at full command."""
    if firmware.command != "normalized":
        return
    if firmware.thrust_full is not None and firmware.thrust_full < vehicle.thrust_max:
        raise InputError(source, "firmware.thrust_max_N",
                         f"{firmware.thrust_full:g} N at full command is below "
                         f"vehicle.thrust_max = {vehicle.thrust_max:g} N: the controller's "
                         "range would need commands above 1")


def check_rate(source, control: Control, grid: Grid, radius: float) -> None:
    """The control rate must resolve the fastest circle: at least ``MIN_STEPS_PER_PERIOD``
    steps over its period T = 2 pi r / v (r = rho + L_e, m; v the largest grid speed, m/s).
    Raises InputError naming ``control.rate_hz``."""
    v = float(grid.speeds[-1])
    T = 2 * math.pi * radius / v
    steps = 2 * round(T * control.rate_hz / 2)
    if steps < MIN_STEPS_PER_PERIOD:
        need = MIN_STEPS_PER_PERIOD / T
        raise InputError(
            source,
            "control.rate_hz",
            f"{control.rate_hz:g} Hz gives {steps} steps over the fastest circle "
            f"({v:g} m/s, period {T:.3g} s); needs >= {MIN_STEPS_PER_PERIOD}, i.e. "
            f"rate_hz >= {need:.3g}",
        )


def _feasibility(sec: Section) -> Feasibility:
    bound_deg = sec.number("max_attitude_offset_deg",
                           float(np.rad2deg(Feasibility.max_attitude_offset)), positive=True)
    if bound_deg > 45:
        raise sec.error("max_attitude_offset_deg", f"must be <= 45 deg, got {bound_deg:g}")
    f = Feasibility(
        sec.number("min_tension", Feasibility.min_tension, nonneg=True),
        sec.number("thrust_margin", Feasibility.thrust_margin, nonneg=True),
        sec.string("attitude_offsets", Feasibility.attitude_offsets, ("zero", "free")),
        float(np.deg2rad(bound_deg)),
    )
    sec.done()
    return f


def _analysis(sec: Section) -> Analysis:
    window = sec.number("savgol_window_s", Analysis.savgol_window_s, positive=True)
    if window > 10:
        raise sec.error("savgol_window_s", f"must be <= 10 s, got {window:g}")
    order = sec.get("savgol_order", Analysis.savgol_order)
    if isinstance(order, bool) or not isinstance(order, int):
        raise sec.error("savgol_order", f"must be an integer, got {type(order).__name__}")
    if not 2 <= order <= 6:
        raise sec.error("savgol_order", f"must be in 2..6 (accelerations need >= 2), got {order}")
    latency = sec.number("latency_s", Analysis.latency_s, nonneg=True)
    if latency >= 1:
        raise sec.error("latency_s", f"must be < 1 s, got {latency:g}")
    gyro = sec.boolean("use_gyro", Analysis.use_gyro)
    accel = sec.boolean("use_accelerometer", Analysis.use_accelerometer)
    sec.done()
    return Analysis(window, order, latency, gyro, accel)


def _limits(sec: Section) -> Limits:
    mem = sec.number("max_memory_gib", Limits.max_memory_gib, positive=True)
    cpu = sec.number("max_build_cpu_s", Limits.max_build_cpu_s, positive=True)
    sec.done()
    return Limits(mem, cpu)


SCHEMA = "gainsched-config/1"


def config_from_text(text: str, source: str = "<string>") -> Config:
    """Parse and validate config TOML text held in a string, as load_config does a file.

    The same checks as :func:`load_config`, for text that is not (yet) a file: a
    config generated in a script, a variant, or the ``config_text`` a table embeds.

    Parameters
    ----------
    text : str
        Config TOML text (schema ``gainsched-config/1``; configs/paper.toml shows every
        section), at most 1 MiB.
    source : str or path-like, optional
        Where the text came from (default ``"<string>"``): every error names it, and
        without a ``name`` key the config's name is its stem. For a config file name
        (``*.toml``) that default must pass :func:`check_name` too; other sources
        (``"<string>"``, a table's embedded text) keep their stem unchecked: nothing is
        written under such a name unless the config comes through :func:`load_config`.

    Returns
    -------
    Config
        The validated config, in SI units; ``text`` is ``text`` and ``source`` is
        ``str(source)``.

    Raises
    ------
    InputError
        The text is not TOML, a key is unknown or missing, a value has the wrong type
        or an impossible value, or the build would exceed ``[limits]``; the message
        names ``source`` and the dotted key (e.g. ``vehicle.mass``).

    See Also
    --------
    load_config : The same for a file.
    Config.with_values : A variant of a loaded config with some keys changed.

    Examples
    --------
    >>> from pathlib import Path
    >>> text = Path("configs/paper.toml").read_text()
    >>> cfg = gs.config_from_text(text, "variant.toml")
    >>> cfg.name, cfg.source, cfg.vehicle.thrust_max                # thrust in N
    ('paper', 'variant.toml', 3.5)

    A bad value is refused, naming the source and the key:

    >>> gs.config_from_text(text.replace("mass = 0.5 ", "mass = -0.5 "), "variant.toml")
    Traceback (most recent call last):
        ...
    gainsched.errors.InputError: variant.toml: vehicle.mass: must be > 0, got -0.5
    """
    return _config(text, str(source), Path(str(source)).suffix.lower() == ".toml")


def _largest_key(text: str) -> tuple[str, int]:
    """The dotted key whose value takes the most characters of ``text`` (a TOML file) and
    that number: a cheap scan of the ``key =`` and ``[table]`` lines, no parsing."""
    best, size, table, key, start = "", -1, "", "", 0
    for m in _KEY_LINE.finditer(text):
        if key and m.start() - start > size:
            best, size = key, m.start() - start
        if m.group(2) is not None:
            table, key = m.group(2).strip(), ""
        else:
            key, start = (f"{table}.{m.group(1)}" if table else m.group(1)), m.start()
    if key and len(text) - start > size:
        best, size = key, len(text) - start
    return best, max(size, 0)


def _check_size(source: str, text: str) -> None:
    if len(text) > MAX_CONFIG_CHARS:
        key, size = _largest_key(text)
        raise InputError(
            source,
            key,
            f"the config is {len(text) / 2**20:.3g} MiB ({size / 2**20:.3g} MiB in this key); "
            f"a config may have at most {MAX_CONFIG_CHARS // 2**20} MiB (a grid this large "
            "could not be built anyway)",
        )


def _config(text: str, source: str, check_default_name: bool) -> Config:
    _check_size(source, text)
    data = parse_toml(text, source)
    top = Section(source, "", data)
    schema = top.string("schema", SCHEMA)
    if schema != SCHEMA:
        raise top.error("schema", f"must be {SCHEMA!r}, got {schema!r}")
    if "name" in data:
        name = check_name(source, top.string("name"))
    else:
        name = top.string("name", Path(source).stem)
        if check_default_name:
            check_name(source, name, from_file=True)
    vehicle = _vehicle(top.sub("vehicle"))
    tether = _tether(top.sub("tether"))
    check_lengths(source, vehicle.arm_length, tether.length)
    effects = _effects(top.sub("effects", {}))
    env = top.sub("environment")
    g = env.bounded("g", lo=G_RANGE[0], hi=G_RANGE[1], unit="m/s^2")
    env.done()
    check_hover(source, vehicle.mass, vehicle.thrust_max, g)
    control = _control(top.sub("control"))
    radius = tether.length + tether.attachment_offset
    grid = _grid(top.sub("grid"), radius)
    check_rate(source, control, grid, radius)
    feas = _feasibility(top.sub("feasibility", {}))
    analysis = _analysis(top.sub("analysis", {}))
    limits = _limits(top.sub("limits", {}))
    firmware = _firmware(top.sub("firmware", {}))
    _check_commands(source, firmware, vehicle)
    if feas.thrust_margin * 2 >= vehicle.thrust_max - vehicle.thrust_min:
        raise InputError(source, "feasibility.thrust_margin", "leaves no usable thrust range")
    top.done()
    cfg = Config(name, vehicle, tether, effects, g, control, grid, feas, source, text,
                 analysis=analysis, limits=limits, firmware=firmware)
    check_budget(cfg, source)
    check_circles(cfg, source)  # after the budget: the grid is of a size a build takes
    return cfg


def load_config(path) -> Config:
    """Load and validate a config file (TOML, UTF-8): every key checked, SI units out.

    Every key is checked here (unknown, missing, wrong type, impossible value), and
    whatever would only fail late in a build (a control rate that undersamples the
    fastest circle, a grid that collapses in float32, a build above ``[limits]``); see
    the module docstring. Degrees exist only in the file (keys ending in ``_deg``).

    Parameters
    ----------
    path : str or path-like
        The config file, e.g. ``"configs/paper.toml"``, or the bare name of a config the
        package ships (``"paper"``: :func:`gainsched.resources.reference_configs`; a file
        of that name in the current folder comes first). It must be UTF-8 (a leading
        UTF-8 byte-order mark is accepted; UTF-16, UTF-32 and other encodings are
        refused naming the file), at most 1 MiB. Without a ``name`` key the config's
        name is the file's stem, which must pass :func:`check_name`.

    Returns
    -------
    Config
        The validated config, in SI units, with ``source`` the path and ``text`` the
        file's text (newlines normalised).

    Raises
    ------
    InputError
        The file cannot be read or is not UTF-8 TOML, a key is unknown or missing, a
        value has the wrong type or an impossible value, or the build would exceed
        ``[limits]``; the message names the file and the dotted key.

    See Also
    --------
    config_from_text : The same for text in memory.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cfg.name, cfg.vehicle.mass, cfg.control.rate_hz              # kg, Hz
    ('paper', 0.5, 1000.0)
    >>> cfg.grid.speeds[[0, -1]].tolist(), round(float(cfg.grid.tilts[-1]), 3)  # m/s, rad
    ([1.3, 15.0], 0.698)
    >>> gs.load_config("paper").text == cfg.text                     # the shipped copy
    True
    >>> gs.load_config("configs/missing.toml")
    Traceback (most recent call last):
        ...
    gainsched.errors.InputError: configs/missing.toml: cannot read (No such file or directory)
    """
    p = config_path(path)
    hint = ""
    if len(p.parts) == 1 and not p.suffix:  # a bare name: perhaps a shipped config
        hint = f"; the shipped configs are {', '.join(reference_configs())}"
    # up to 64 MiB is read so that _check_size can name the key that makes a config too
    # long (a list of a million speeds is 20 MiB); a longer file is refused unread
    text = read_text(p, what="config", limit=64 * MAX_CONFIG_CHARS,
                     allowed=f"{MAX_CONFIG_CHARS // 2**20} MiB", hint=hint)
    return _config(text, str(p), True)
