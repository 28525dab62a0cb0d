"""Closed-loop simulation: the scheduled LQR flying the nonlinear tethered vehicle.

The plant is a config of its own (the "truth"): other parameters, other
effects, another link model than the design config the tables came from.
Fixed-step RK4 at the control rate with the input held (zero-order hold),
motor saturation at the plant's thrust limits, and a clean stop when the
tether goes slack. Sensing: ideal state, or motion capture at a fixed rate
with noise and latency, fused with a model prediction in between pose updates
(the paper's scheme, Sec. V.A: pose updates, prediction in between).

Control law (paper Sec. IV): ``u = u_d - K(xi_d, xi_d', alpha) (x - x_d)``
with the 11-entry LQR state x (xi error wrapped to [-pi, pi)), the nominal
(x_d, u_d) of the reference path on the design model, and K from the tables.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import MAX_SPEED, N_STATE, Config, Section
from ..constants import INTEGRATORS, MAX_FLIGHT_S, MAX_FLIGHT_STEPS, MAX_SEED
from ..errors import GainschedWarning, InputError
from ..firmware.feedforward import FeedForward, feedforward
from ..firmware.runtime import BAD_ARG, CLAMPED_SPEED, NO_GAINS, UNUSABLE, status_text
from ..model.geometry import pose_angles_from_pose, pose_from_reduced, wrap_angle
from ..model.maximal import MaximalModel, reduced_from_maximal
from ..model.reduced import Model
from ..model.rotations import (
    R_IC_from_tilt,
    matrix_from_euler_zyx_scalar,
    matrix_from_quaternion,
    quaternion_from_matrix,
    quaternion_from_matrix_scalar,
)
from ..schedule.nominal import circle_offsets, nominal_from_path
from ..schedule.path import AzimuthPath, maneuver_path
from ..textinput import load_toml
from .fastplant import SUPPORTED_EFFECTS, fast_plant

#: the lookup's status bits (SimResult.status) among the firmware controller's
LOOKUP_BITS = 0xFF

__all__ = [
    "Scenario",
    "Sensing",
    "Maneuver",
    "SimResult",
    "SCENARIO_DIR",
    "load_scenario",
    "scenario_from_dict",
    "check_flight_steps",
    "profile_path",
    "simulate",
    "metrics",
    "table_scheduler",
    "c_runtime_scheduler",
    "RUNTIMES",
    "runtime_scheduler",
    "log_from_result",
    "write_run",
]


@dataclass(frozen=True)
class Maneuver:
    """Speed change at ``t_start`` (s) to ``speed`` (m/s) with eq. 20 parameter ``a`` (m/s^2)."""

    t_start: float
    speed: float
    a: float


@dataclass(frozen=True)
class Sensing:
    """Motion capture: rate (Hz), noise std (m, rad), latency (s); ``ideal`` bypasses it."""

    ideal: bool = True
    rate_hz: float = 200.0
    position_noise: float = 0.0
    attitude_noise: float = 0.0
    gyro_noise: float = 0.0
    latency: float = 0.0
    seed: int = 0
    accel_noise: float = 0.0  # m/s^2, the accelerometer's (the log's; the firmware's)
    latency_compensation: bool = True  # the firmware controller knows the latency
    accelerometer: bool = True  # the firmware controller is given the accelerometer


@dataclass(frozen=True)
class Scenario:
    """A flight to simulate: the circle, the speed profile, the duration and the sensing.

    Made by :func:`load_scenario` from a TOML file (``gainsched/sim/scenarios/*.toml``
    shows the keys; angles there in deg, ``*_deg`` keys); here every angle is in rad.
    Frozen: make a variant with :func:`dataclasses.replace`.

    Attributes
    ----------
    name : str
        Name of the flight (the file's ``name``, default the file name without its
        suffix); it names the outputs (the log's ``flight_id`` is ``sim-NAME``).
    tilt : float
        Circle tilt alpha_C, rad, in (-pi/2, pi/2) (``tilt_deg`` in the file).
    speed : float
        Initial tangential COG speed ``v = (rho + L_e) xi_dot``, m/s.
    duration : float
        Flight time, s (> 0): the simulation takes ``round(duration / dt) + 1`` steps of
        the design's control step ``dt``.
    maneuvers : tuple of Maneuver
        Speed changes in time order, none overlapping the previous one: each from its
        ``t_start`` (s) to a new ``speed`` (m/s) along the smooth profile of paper eq. 20
        with parameter ``a`` (m/s^2; peak tangential acceleration ``2 a``). Empty: the
        whole flight at ``speed``.
    gamma : float
        Circle heading gamma_C, rad (``gamma_deg``): turns the tilted circle about the
        vertical, ``R_IC = Rz(gamma_C) Rx(alpha_C)`` (docs/conventions.md).
    sensing : Sensing
        What the controller sees: the true state (``ideal``), or motion capture at
        ``rate_hz`` (Hz) with ``position_noise`` (m), ``attitude_noise`` (rad),
        ``gyro_noise`` (rad/s) and ``latency`` (s), fused with a model prediction (paper
        Sec. V.A); ``accel_noise`` (m/s^2) is that of the logged accelerometer
        (:func:`log_from_result`) and of the firmware controller's; ``seed`` seeds the
        noise. In firmware mode ``latency_compensation = false`` leaves the controller's
        ``pose_delay`` at 0 (with a warning when the poses are late) and
        ``accelerometer = false`` flies it without its accelerometer.
    initial_error : tuple of float
        Offset of the initial state from the nominal, on the first entries of the reduced
        state (delta, xi, delta', xi', phi, theta, chi, omega_x, omega_y, omega_z), rad and
        rad/s; empty: the flight starts on the nominal.
    source : str
        The file the scenario was read from (``""`` when built in Python): errors about
        the scenario name it (:attr:`origin`).

    Examples
    --------
    >>> import dataclasses
    >>> scn = gs.load_scenario("speedup")
    >>> scn.speed, [(m.t_start, m.speed, m.a) for m in scn.maneuvers]
    (2.0, [(0.5, 11.3, 6.25)])
    >>> round(float(np.rad2deg(gs.load_scenario("tilted40").tilt)), 6)
    40.0
    >>> dataclasses.replace(scn, duration=1.0).duration  # a shorter variant
    1.0
    """

    name: str
    tilt: float
    speed: float
    duration: float
    maneuvers: tuple[Maneuver, ...] = ()
    gamma: float = 0.0
    sensing: Sensing = field(default_factory=Sensing)
    initial_error: tuple[float, ...] = ()
    source: str = field(default="", compare=False, repr=False)

    @property
    def origin(self) -> str:
        """What an error about the scenario names: its file, else ``scenario NAME``."""
        return self.source or f"scenario {self.name}"


#: most speed changes of one scenario (each is evaluated over the whole flight)
MAX_MANEUVERS = 100
#: motion-capture rates, Hz: a pose a second is the least a flight of seconds can use;
#: above the fastest control rate a config may set no sample is ever used
SENSING_RATE_HZ = (1.0, 1.0e5)
#: motion-capture latency, s: real systems have milliseconds; a second is far past any
MAX_LATENCY_S = 1.0
#: lengths of ``initial_error``: whole groups of the reduced state (positions, their
#: rates, the attitude, the body rates), never a group cut in two
INITIAL_ERROR_SIZES = (2, 4, 7, 10)


def _speed(sec: Section, k: str) -> float:
    v = sec.number(k)
    if v == 0 or abs(v) > MAX_SPEED:
        raise sec.error(k, f"must be a non-zero speed with |speed| <= {MAX_SPEED:g} m/s "
                        f"(negative: reversed), got {v:g}")
    return v


def check_flight_steps(duration: float, rate_hz: float, source, where: str) -> int:
    """The number of control steps of a flight, ``round(duration * rate_hz) + 1``; raises
    InputError naming ``source`` and ``where`` above :data:`MAX_FLIGHT_STEPS`."""
    n = int(round(duration * rate_hz)) + 1
    if n > MAX_FLIGHT_STEPS:
        raise InputError(source, where, f"{duration:g} s at the {rate_hz:g} Hz control rate is "
                         f"{n:,} steps; a flight may have at most {MAX_FLIGHT_STEPS:,} (about "
                         f"1 GB of history): at most {(MAX_FLIGHT_STEPS - 1) / rate_hz:g} s")
    return n


def scenario_from_dict(d: dict, source="<scenario>") -> Scenario:
    """Validate a scenario table (see ``gainsched/sim/scenarios/*.toml``): every key's type,
    unit and range (the limits above), in one pass, before anything flies."""
    top = Section(str(source), "", d)
    name = top.string("name", Path(str(source)).stem)
    tilt_deg = top.number("tilt_deg", 0.0)
    if not -90 < tilt_deg < 90:
        raise top.error("tilt_deg", "must be in (-90, 90)")
    speed = _speed(top, "speed")
    duration = top.bounded("duration", lo=0.0, lo_open=True, hi=MAX_FLIGHT_S, unit="s")
    gamma = np.deg2rad(top.number("gamma_deg", 0.0))
    raw = top.get("maneuvers", [])
    if not isinstance(raw, list):
        raise top.error("maneuvers", "must be a list of tables")
    if len(raw) > MAX_MANEUVERS:
        raise top.error("maneuvers", f"at most {MAX_MANEUVERS} manoeuvres, got {len(raw)}")
    mans = []
    t_free = 0.0  # end of the previous manoeuvre
    for i in range(len(raw)):
        sec = Section(str(source), f"maneuvers[{i}]", raw[i])
        man = Maneuver(sec.bounded("t_start", lo=0.0, hi=MAX_FLIGHT_S, unit="s"),
                       _speed(sec, "speed"),
                       sec.number("a", positive=True))
        sec.done()
        if man.t_start < t_free:
            raise sec.error("t_start", "manoeuvres must not overlap")
        t_free = man.t_start + abs(man.speed - (mans[-1].speed if mans else speed)) / man.a
        mans.append(man)
    sens = top.sub("sensing", {})
    lo, hi = SENSING_RATE_HZ
    sensing = Sensing(
        sens.boolean("ideal", True),
        sens.bounded("rate_hz", 200.0, lo=lo, hi=hi, unit="Hz"),
        sens.number("position_noise", 0.0, nonneg=True),
        np.deg2rad(sens.number("attitude_noise_deg", 0.0, nonneg=True)),
        sens.number("gyro_noise", 0.0, nonneg=True),
        sens.bounded("latency", 0.0, lo=0.0, hi=MAX_LATENCY_S, unit="s"),
        sens.integer("seed", 0, lo=0, hi=MAX_SEED),
        sens.number("accel_noise", 0.0, nonneg=True),
        sens.boolean("latency_compensation", True),
        sens.boolean("accelerometer", True),
    )
    sens.done()
    init = ()
    if "initial_error" in d:
        a = top.array("initial_error")
        if a.ndim != 1 or a.size not in INITIAL_ERROR_SIZES:
            raise top.error("initial_error", "must be a list of 2 (delta, xi), 4 (+ delta', "
                            "xi'), 7 (+ phi, theta, chi) or 10 (+ omega_x, omega_y, omega_z) "
                            f"numbers, rad and rad/s; got {'x'.join(map(str, a.shape))}")
        init = tuple(float(x) for x in a)
    top.done()
    return Scenario(name, np.deg2rad(tilt_deg), speed, duration, tuple(mans), gamma, sensing, init,
                    source=str(source))


#: The shipped scenarios (package data): horizontal, tilted40, speedup, braking, staircase.
SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"


def load_scenario(path) -> Scenario:
    """Load a scenario: a TOML file, or the name of a shipped one.

    Parameters
    ----------
    path : str or path-like
        A scenario file (``gainsched/sim/scenarios/*.toml`` shows the keys), or the name of
        a shipped scenario (``"horizontal"``, ``"tilted40"``, ``"speedup"``, ``"braking"``,
        ``"staircase"``; a name without a ``.toml`` suffix that is no existing file).

    Returns
    -------
    Scenario
        The validated flight.

    Raises
    ------
    InputError
        The file cannot be read, is larger than 1 MiB, is not UTF-8 TOML (nested at most
        32 deep: :mod:`gainsched.textinput`), or a key is bad or out of its range (the
        message names the file and the key).

    Examples
    --------
    >>> scn = gs.load_scenario("horizontal")
    >>> scn.name, scn.speed, scn.duration
    ('horizontal', 8.0, 5.0)
    """
    p = Path(path)
    if p.suffix != ".toml" and not p.exists():
        p = SCENARIO_DIR / f"{p}.toml"
    return scenario_from_dict(load_toml(p, what="scenario"), p)


def profile_path(scn: Scenario, r: float, t) -> AzimuthPath:
    """The reference azimuth path of a scenario: initial speed plus sequential manoeuvres."""
    t = np.asarray(t, dtype=float)
    v_prev = scn.speed
    xi = scn.speed * t / r
    d = [np.full_like(t, scn.speed / r), np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)]
    for m in scn.maneuvers:
        p = maneuver_path(v_prev, m.speed, m.a, r, t, t_start=m.t_start)
        xi = xi + p.xi - v_prev * t / r  # the manoeuvre's extra displacement
        d[0] = d[0] + p.d[0] - v_prev / r
        for j in (1, 2, 3):
            d[j] = d[j] + p.d[j]
        v_prev = m.speed
    return AzimuthPath(t, xi, tuple(d))


@dataclass(frozen=True)
class SimResult:
    """Time histories of a simulated flight, one sample per control step.

    What :func:`simulate` returns: N samples at the design's control step ``dt`` from
    t = 0, ``round(duration / dt) + 1``, fewer when the tether went slack (the flight
    stops there, ``slack_time``). Reduced states are in the order (delta, xi, delta', xi',
    phi, theta, chi, omega_x, omega_y, omega_z), rad and rad/s (docs/conventions.md), xi
    continuous (a lap adds 2 pi). Motors 1..4 in the X layout.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time of each control step, s.
    z : ndarray, shape (N, 10)
        True reduced state of the plant, rad, rad/s.
    z_hat : ndarray, shape (N, 10)
        The controller's estimate of it (``z`` with ideal sensing), rad, rad/s.
    z_d : ndarray, shape (N, 10)
        Nominal state along the reference path (from the design model, or the table's
        feed-forward with ``controller="firmware"``), rad, rad/s.
    u : ndarray, shape (N, 4)
        Applied (saturated) motor thrust commands, N, held over each step.
    u_d : ndarray, shape (N, 4)
        Nominal (feed-forward) motor thrusts, N.
    tension : ndarray, shape (N,)
        Tether tension of the plant at each step, N (negative: slack).
    p_I : ndarray, shape (N, 3)
        COG position in the inertial frame (origin at the anchor, z up), m.
    q_IB : ndarray, shape (N, 4)
        Attitude quaternion (w, x, y, z), Hamilton, body -> inertial.
    saturated : ndarray of bool, shape (N, 4)
        The motor's command was clipped to the plant's ``thrust_min`` or ``thrust_max``.
    status : ndarray of int32, shape (N,)
        Status bits of the gain lookup (:mod:`gainsched.firmware.runtime`: 0 OK,
        ``CLAMPED_SPEED`` 0x01, ``NO_GAINS`` 0x08, ...; ``status_text`` names them).
    slack_time : float or None
        Time the tether went slack and the simulation stopped, s; None: it stayed taut.
    scenario : Scenario
        The flight that was flown.
    r : float
        Nominal COG radius ``rho + L_e`` of the design model, m.
    mass : float
        Mass of the plant, kg.
    g : float
        Gravity of the plant, m/s^2.
    held : ndarray of bool, shape (N,), or None
        The lookup was unusable (``NO_GAINS``, bad input) and the last good gains were
        flown, the firmware's policy.
    tension_d : ndarray, shape (N,), or None
        Tension of the nominal, N.
    min_tension : float
        The design config's tension margin (``[feasibility] min_tension``), N.
    f_B : ndarray, shape (N, 3), or None
        Specific force at the COG in the body frame, ``R_IB^T (a_I + g e_z)``, m/s^2: what
        an ideal accelerometer senses (from second differences of ``p_I``).
    controller_status : ndarray of int32, shape (N,), or None
        ``controller="firmware"``: the controller's whole status, the lookup's bits with
        the ``CTRL_*`` bits of :mod:`gainsched.firmware.controller` (``HELD``,
        ``SATURATED``, ``BAD_POSE``, ``STALE_POSE``, ``BAD_IMU``, ``IDLE``); else None.
    vbat : ndarray, shape (N,), or None
        The battery's terminal voltage, V, when the plant has a battery (an effect whose
        ``log_channel`` is ``"vbat"``: ``[effects.thrust_voltage]``, rigid link); else None.
    """

    t: np.ndarray
    z: np.ndarray
    z_hat: np.ndarray
    z_d: np.ndarray
    u: np.ndarray
    u_d: np.ndarray
    tension: np.ndarray
    p_I: np.ndarray
    q_IB: np.ndarray
    saturated: np.ndarray
    status: np.ndarray
    slack_time: float | None
    scenario: Scenario
    r: float
    mass: float
    g: float
    held: np.ndarray | None = None
    tension_d: np.ndarray | None = None
    min_tension: float = 0.0
    f_B: np.ndarray | None = None
    controller_status: np.ndarray | None = None
    vbat: np.ndarray | None = None


_FALLBACKS_SEEN: set[str] = set()


def _warn_numpy_plant(cfg: Config) -> None:
    """Say once per reason that the rigid-link plant runs on the numpy model (slower)."""
    missing = sorted(s.name for s in cfg.effects if s.name not in SUPPORTED_EFFECTS)
    why = (f"the compiled plant does not implement the effect(s) {', '.join(missing)}"
           if missing else "the compiled plant is not available (no C compiler, or "
           "GAINSCHED_NATIVE=0)")
    if why in _FALLBACKS_SEEN:
        return
    _FALLBACKS_SEEN.add(why)
    warnings.warn(f"{why}: the simulation runs on the numpy model, about 0.3x real time "
                  f"instead of 80x (gainsched/sim/fastplant.py)", GainschedWarning,
                  stacklevel=3)


class _Plant:
    """Reduced model (rigid link) or maximal model (elastic links) behind one interface.

    The rigid and the spring-damper links run on the compiled plants
    (:mod:`gainsched.sim.fastplant`) when they support the config and a compiler is
    available, else on the numpy models (the reference). The SLS and lumped-mass links
    keep their own path: set ``self.maximal`` (an object with ``f(x, u, alpha, gamma)``
    and ``tension(x, u, alpha, gamma)``) and ``self.fast = None``. ``gamma`` (rad) is the
    circle's heading: with a wind (``[effects.wind]``) it sets the wind's direction in C.
    """

    def __init__(self, cfg: Config, gamma: float = 0.0):
        self.model = Model(cfg)
        self.gamma = float(gamma)  # the circle's heading, rad: the wind's direction in C
        self.maximal = None if cfg.tether.link == "rigid" else MaximalModel(self.model)
        # compiled RK4 of the reduced or the spring-damper maximal model; None: numpy model
        self.fast = fast_plant(cfg)
        if self.maximal is None and self.fast is None:
            _warn_numpy_plant(cfg)

    def initial(self, z0, u0):
        """Plant state from the reduced state ``z0`` (10,) and the thrusts ``u0`` (4,), N:
        stateful effects (motor lag) start in their steady state at ``u0``."""
        if self.maximal is None:
            extra = [e.steady_states(u0, np.zeros(4))[0] for e in self.model.effects
                     if e.n_states]
            return np.concatenate([z0, *extra]) if extra else np.array(z0, dtype=float)
        return self.maximal.from_reduced(z0)  # the elastic link pre-stretched (maximal.py)

    def f(self, x, u, alpha):
        """State derivative and tether tension (N) at one state."""
        g = self.gamma
        if self.fast is not None:
            return self.fast.f(x, u, alpha, g)
        if self.maximal is None:
            ev = self.model.evaluate(x, u, alpha, g)
            return ev.z_dot, ev.tension
        return self.maximal.f(x, u, alpha, g), self.maximal.tension(x, u, alpha, g)

    def step(self, x, u, alpha, dt):
        """One RK4 step of ``dt`` s with ``u`` held: ``(x_next, tension at x in N)``
        (elastic links: RK4 substeps, and a negative tension when slack)."""
        if self.fast is not None:
            return self.fast.rk4_step(x, u, alpha, dt, self.gamma)
        if self.maximal is not None:
            return self.maximal.step(x, u, alpha, dt, self.gamma)
        return _rk4(self.f, x, u, alpha, dt)

    def reduced(self, x, xi_ref):
        if self.maximal is None:
            return x[:N_STATE]
        return reduced_from_maximal(self.model, x, xi_ref)

    def pose(self, x, alpha, gamma):
        """COG position in I (m) and R_IB of one state or a batch of states (..., n_x)."""
        if self.maximal is None:
            p_C, R_CB = pose_from_reduced(x, self.model.rho, self.model.p_e)
        else:
            q = x[..., 6:10]
            p_C = x[..., 0:3]
            R_CB = matrix_from_quaternion(q / np.linalg.norm(q, axis=-1, keepdims=True))
        if np.ndim(x) == 1:  # one state (the pose sensor): scalar math
            R_IC = matrix_from_euler_zyx_scalar(alpha, 0.0, gamma)
        else:
            R_IC = R_IC_from_tilt(alpha, gamma)
        return p_C @ R_IC.T, R_IC @ R_CB

    def sensors(self, x, u, alpha, gamma, accel=True):
        """What the vehicle's sensors see of one state under the thrusts ``u`` (N): the COG
        position ``p_I`` (m) and velocity ``v_I`` (m/s) in I, the attitude ``q_IB``, the body
        rates (rad/s) and the specific force at the COG in B (m/s^2, what an accelerometer
        there senses; None with ``accel=False``, which skips the plant's derivative)."""
        R_IC = matrix_from_euler_zyx_scalar(alpha, 0.0, gamma)
        f_B = None
        if self.maximal is None:
            z_dot = self.f(x, u, alpha)[0] if accel else np.zeros_like(x)
            p_C, v_C, a_C, R_CB = self.model.cog_motion_one(x, z_dot)
            w = x[7:10]
        else:
            p_C, v_C, w = x[0:3], x[3:6], x[10:13]
            R_CB = matrix_from_quaternion(x[6:10] / np.linalg.norm(x[6:10]))
            a_C = self.f(x, u, alpha)[0][3:6] if accel else None
        if accel:
            f_B = R_CB.T @ (a_C - self.model.g_C(alpha))
        return (R_IC @ p_C, R_IC @ v_C, quaternion_from_matrix_scalar(R_IC @ R_CB),
                np.array(w), f_B)

    def battery_voltage(self, X):
        """The battery's terminal voltage (N,), V, along plant states X (N, n_x), or None
        without a battery (an effect whose ``log_channel`` is ``"vbat"``; the maximal
        model carries no effect states)."""
        if self.maximal is not None:
            return None
        i = N_STATE
        for e in self.model.effects:
            if e.log_channel == "vbat":
                return e.voltage(X[:, i:i + e.n_states])
            i += e.n_states
        return None

    def poses(self, X, alpha, gamma):
        """COG positions in I (N, 3), m, and quaternions q_IB (N, 4) of states X (N, n_x)."""
        p_I, R_IB = self.pose(X, alpha, gamma)
        return p_I, quaternion_from_matrix(R_IB)


#: steps per block of gain lookups of a scheduler with ``batch`` (bounds the memory)
_LOOKUP_BLOCK = 1000


def _rk4(f, x, u, alpha, dt):
    k1, ten = f(x, u, alpha)
    k2, _ = f(x + 0.5 * dt * k1, u, alpha)
    k3, _ = f(x + 0.5 * dt * k2, u, alpha)
    k4, _ = f(x + dt * k3, u, alpha)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), ten


class _Record:
    """The per-step histories of a flight, preallocated, and the :class:`SimResult` they
    make: plant states ``X`` (poses are computed after the loop), true and estimated
    reduced states, applied thrusts, tension, saturation, status, held gains."""

    def __init__(self, n_steps: int, x, P: _Plant):
        self.P = P
        self.X = np.empty((n_steps, x.size))
        self.Z = self.X[:, :N_STATE] if P.maximal is None else np.empty((n_steps, N_STATE))
        self.Zh = np.empty((n_steps, N_STATE))
        self.U = np.empty((n_steps, 4))
        self.TEN = np.empty(n_steps)
        self.SAT = np.zeros((n_steps, 4), dtype=bool)
        self.STAT = np.zeros(n_steps, dtype=np.int32)
        self.HELD = np.zeros(n_steps, dtype=bool)
        self.CTRL = None  # the firmware controller's status bits (its loop sets them)

    def result(self, n_done: int, t, z_d, u_d, tension_d, slack_time, scenario, r: float,
               design: Config, plant: Config) -> SimResult:
        """The first ``n_done`` steps as a :class:`SimResult`."""
        sl = slice(0, n_done)
        PI, QI = self.P.poses(self.X[sl], scenario.tilt, scenario.gamma)
        dt = design.control.dt
        return SimResult(t[sl], self.Z[sl].copy(), self.Zh[sl], z_d[sl], self.U[sl], u_d[sl],
                         self.TEN[sl], PI, QI, self.SAT[sl], self.STAT[sl], slack_time,
                         scenario, r, plant.vehicle.mass, plant.g, self.HELD[sl],
                         tension_d[sl], design.feasibility.min_tension,
                         specific_force(PI, QI, dt, plant.g),
                         None if self.CTRL is None else self.CTRL[sl],
                         self.P.battery_voltage(self.X[sl]))


def simulate(design: Config, scheduler, scenario: Scenario, plant: Config | None = None,
             progress=None, controller: str = "path") -> SimResult:
    """Fly a scenario in closed loop: the scheduled LQR on the nonlinear tethered vehicle.

    The control law of paper Sec. IV, ``u = u_d - K(xi_d, xi_d', alpha) (x - x_d)``, at
    the design's control rate: ``x`` is the LQR state (the 10 reduced states, the azimuth
    error from continuous azimuths, plus the integral states of ``[control]`` and the
    design model's effect states, a motor lag's thrusts, which no sensor measures: they
    are predicted from the applied input with the design model, as a firmware can),
    ``(x_d, u_d)`` the nominal of the reference path and ``K`` the scheduled gains,
    looked up at the reference. The plant is integrated by fixed-step RK4 with the input
    held over each step (zero-order hold); the commands saturate at the plant's thrust
    limits; the flight stops cleanly when the tether goes slack.

    Parameters
    ----------
    design : Config
        The model the tables were built from: the nominal ``(x_d, u_d)`` along the
        reference, the control step ``control.dt`` (s), the integral states and the
        tension margin come from it.
    scheduler : callable
        ``scheduler(xi, xi_dot, alpha) -> (K, status)``: the gains ``K``, ndarray of shape
        (4, n) (N per unit of LQR state: rad, rad/s, rad s), and the lookup's status bits
        (int) at the reference azimuth xi (rad), its rate xi_dot (rad/s) and the tilt
        alpha (rad); :func:`table_scheduler`, :func:`runtime_scheduler` or
        :func:`c_runtime_scheduler` make one. It is queried at the reference only, so a
        scheduler may offer ``scheduler.batch(xi, xi_dot, alpha) -> (K (m, 4, n),
        status (m,))`` giving the same numbers for arrays of queries: the gains are then
        looked up in blocks of steps instead of once per step (``table_scheduler``
        does). Where a lookup is unusable (``NO_GAINS``, bad input) the last good gains
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
        (:mod:`gainsched.firmware.controller`, docs/runtime.md): sensors in, thrusts
        out, with only what a firmware has (the table's lookup, the drag-only closed
        form with the table's correction, its own estimator). With
        ``c_runtime_scheduler`` it is the C controller itself, through ctypes (software
        in the loop); with ``table_scheduler`` its Python reference. Ideal sensing gives
        it the true COG kinematics; motion capture gives it the delayed noisy poses,
        the gyro and the accelerometer (the plant's specific force), with its pose
        delay set to the latency unless ``sensing.latency_compensation`` is false.

    Returns
    -------
    SimResult
        Time histories at the control rate from t = 0: ``round(duration / dt) + 1``
        samples, fewer when the tether went slack.

    Raises
    ------
    InputError
        The table has no usable gains where the flight starts (a firmware would refuse
        to engage), or ``controller="firmware"`` with a C runtime whose table carries no
        closed-form constants.
    ValueError
        ``controller`` is neither ``"path"`` nor ``"firmware"``, or ``"firmware"`` with a
        scheduler without ``controller`` and ``feedforward``.

    Notes
    -----
    Sensing (``scenario.sensing``): the true state, or motion-capture pose updates at
    the sensing rate with noise and latency, fused with a prediction of the design
    model between updates, and gyro body rates (paper Sec. V.A). The rigid-link plant
    runs on the compiled kernel when a C compiler is available (the same results as the
    numpy model to rounding, see tests/sim/test_fastplant.py); ``GAINSCHED_NATIVE=0`` forces
    the numpy model (about 0.3x real time instead of 80x).

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
    P = _Plant(plant, scenario.gamma)
    dmodel = Model(design)
    dt = design.control.dt
    n_steps = int(round(scenario.duration / dt)) + 1
    t = np.arange(n_steps) * dt
    alpha = scenario.tilt
    path = profile_path(scenario, dmodel.r, t)
    if controller == "path":
        # a constant-speed circle flies the table's nominal, attitude offsets included
        offsets = (circle_offsets(dmodel, scenario.speed, alpha) if not scenario.maneuvers
                   else None)
        nom = nominal_from_path(dmodel, path, alpha, offsets=offsets)
        z_d, u_d, tension_d = nom.z[:, :N_STATE], nom.u, nom.tension
    elif controller == "firmware":  # no trim of the design model: only what a firmware has
        return _fly_firmware(design, scheduler, scenario, plant, P, path, progress)
    else:
        raise ValueError(f"controller must be 'path' or 'firmware', got {controller!r}")
    u_min, u_max = plant.vehicle.thrust_min, plant.vehicle.thrust_max

    z0 = z_d[0].copy()
    if scenario.initial_error:
        z0[: len(scenario.initial_error)] += np.asarray(scenario.initial_error)
    x = P.initial(z0, u_d[0])
    sens = scenario.sensing
    rng = np.random.default_rng(sens.seed)
    # a design with effect states (motor lag) predicts them too, from the nominal's start
    est = _Estimator(dmodel, P, sens, dt, alpha, scenario.gamma,
                     np.concatenate([z0, nom.z[0, N_STATE:]]), rng)

    rec = _Record(n_steps, x, P)
    X, Z, Zh, U, TEN, SAT, STAT, HELD = (rec.X, rec.Z, rec.Zh, rec.U, rec.TEN, rec.SAT,
                                         rec.STAT, rec.HELD)
    # per-step work kept to a few small numpy calls: bound methods and arrays looked
    # up once, the LQR error vector (11 + zero-padded effect states) reused
    xi_ref, xi_dot_ref = path.xi, path.d[0]
    step, reduced, estimate, predict = P.step, P.reduced, est.estimate, est.predict
    rigid = P.maximal is None
    batch = getattr(scheduler, "batch", None)
    K_blk = S_blk = None
    # integral states of the design (int_delta, int_xi): the errors they integrate
    int_idx = [INTEGRATORS[name] for name in design.control.integrators]
    n_lqr = N_STATE + len(int_idx)
    xerr = np.zeros(n_lqr)
    zx_d = nom.z[:, N_STATE:]  # the nominal's effect states (motor lag: its thrusts)
    n_fx = zx_d.shape[1]
    integ = np.zeros(len(int_idx))
    xi_true = z0[1]  # the plant's azimuth, tracked continuously (elastic links)
    K_good = None  # the last usable gains (held through NO_GAINS / bad lookups)
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
        if batch is None:
            K, status = scheduler(xi_ref[k], xi_dot_ref[k], alpha)
        else:
            j = k % _LOOKUP_BLOCK
            if j == 0:
                blk = slice(k, k + _LOOKUP_BLOCK)
                K_blk, S_blk = batch(xi_ref[blk], xi_dot_ref[blk], alpha)
                S_blk = S_blk.tolist()
            K, status = K_blk[j], S_blk[j]
        if status & UNUSABLE:  # the firmware policy: hold the last good gains
            if K_good is None:
                raise InputError(
                    scenario.origin, "speed",
                    f"the table has no usable gains where the flight starts ({status_text(status)}"
                    f" at speed {xi_dot_ref[k] * dmodel.r:.3g} m/s, tilt "
                    f"{math.degrees(alpha):.3g} deg): a firmware would refuse to engage")
            K, HELD[k] = K_good, True
        else:
            K_good = K
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


def _firmware_controller(scheduler, params):
    """The scheduler's firmware controller with ``params``: the C controller (software in
    the loop) or its Python reference."""
    make = getattr(scheduler, "controller", None)
    if make is None:
        raise ValueError("controller='firmware' needs a scheduler with the table's "
                         "controller (table_scheduler, c_runtime_scheduler or "
                         "runtime_scheduler)")
    return make(params)


def _fly_firmware(design, scheduler, scenario, plant, P, path, progress) -> SimResult:
    """``simulate(..., controller="firmware")``: the firmware's whole loop, sensors in and
    thrusts out (:mod:`gainsched.firmware.controller`), in C through ctypes or its Python
    reference, on the plant ``P``. Ideal sensing gives the controller the true COG
    kinematics (``FLAG_KINEMATICS``); motion capture gives it delayed noisy poses at the
    sensing rate, the gyro and the accelerometer every step."""
    from ..firmware.controller import (
        CTRL_HELD,
        CTRL_SATURATED,
        FLAG_ACCEL,
        FLAG_KINEMATICS,
        FLAG_POSE,
        INPUT_SLICES,
        N_INPUT,
        Controller,
        controller_params,
    )

    dt, alpha, gamma = design.control.dt, scenario.tilt, scenario.gamma
    sens = scenario.sensing
    t = path.t
    n_steps = t.size
    xi_w = wrap_angle(path.xi)
    ref = np.stack([xi_w, *path.d], axis=1)
    ff = scheduler.feedforward(AzimuthPath(t, xi_w, path.d), alpha)
    z_d, u_d, tension_d = ff.x_d.copy(), ff.u_d, ff.tension
    z_d[:, 1] = path.xi  # continuous, as the path controller's
    every = max(1, int(round(1.0 / (sens.rate_hz * dt))))
    delay = int(round(sens.latency / dt))
    params = controller_params(design, getattr(scheduler, "data", None), pose_period=every * dt,
                               pose_delay=delay * dt if sens.latency_compensation else 0.0)
    if not sens.ideal and delay > 0 and params.pose_delay == 0:
        warnings.warn(uncompensated_latency_text(scenario.origin, sens.latency, scenario.speed,
                                                 design.radius),
                      GainschedWarning, stacklevel=3)
    ctl = _firmware_controller(scheduler, params)
    reference = isinstance(ctl, Controller)
    if reference:  # the Python reference takes each step's nominal (gs_lookup_nominal)
        lk = scheduler.batch(xi_w, path.d[0], np.full(n_steps, alpha))[0]
    u_min, u_max = plant.vehicle.thrust_min, plant.vehicle.thrust_max
    z0 = z_d[0].copy()
    z0[1] = path.xi[0]
    if scenario.initial_error:
        z0[: len(scenario.initial_error)] += np.asarray(scenario.initial_error)
    x = P.initial(z0, u_d[0])
    rng = np.random.default_rng(sens.seed)
    col = INPUT_SLICES
    row = np.zeros(N_INPUT)
    row[col["alpha"]], row[col["gamma"]] = alpha, gamma
    u_now = u_d[0]
    if not sens.ideal:
        p_I, v_I, q_IB, _, _ = P.sensors(x, u_now, alpha, gamma)
        ctl.reset(p_I, v_I, q_IB)  # the estimator starts on the true state
    pending: list[tuple[int, np.ndarray, np.ndarray]] = []
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
        p_I, v_I, q_IB, w_B, f_B = P.sensors(x, u_now, alpha, gamma, accel=not sens.ideal)
        if sens.ideal:
            row[0] = FLAG_KINEMATICS
            row[col["p_I"]], row[col["v_I"]], row[col["q_IB"]] = p_I, v_I, q_IB
            row[col["gyro"]] = w_B
        else:
            if k % every == 0:  # a pose taken now arrives after the latency
                p_m = p_I + sens.position_noise * rng.standard_normal(3)
                rot = sens.attitude_noise * rng.standard_normal(3)
                R_m = matrix_from_quaternion(q_IB) @ matrix_from_euler_zyx_scalar(*rot)
                pending.append((k + delay, p_m, quaternion_from_matrix_scalar(R_m)))
            flags = FLAG_ACCEL if sens.accelerometer else 0
            if pending and pending[0][0] <= k:
                _, p_m, q_m = pending.pop(0)
                flags |= FLAG_POSE
                row[col["p_I"]], row[col["q_IB"]] = p_m, q_m
            row[0] = flags
            row[col["gyro"]] = w_B + sens.gyro_noise * rng.standard_normal(3)
            row[col["accel"]] = f_B + sens.accel_noise * rng.standard_normal(3)
        row[col["ref"]] = ref[k]
        if reference:
            out, status, z_hat = ctl.step(row, (lk[k], ff.x_d[k], ff.u_d[k],
                                                int(ff.status[k])))
        else:
            out, status, z_hat = ctl.step(row)
        thrust = out if newtons else params.thrust_from_commands(out)  # mixer and motors
        if k == 0 and status & NO_GAINS:
            raise InputError(
                scenario.origin, "speed",
                f"the table has no usable gains where the flight starts ({status_text(status)}"
                f" at speed {path.d[0][0] * design.radius:.3g} m/s, tilt "
                f"{math.degrees(alpha):.3g} deg): a firmware would refuse to engage")
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


def specific_force(p_I, q_IB, dt: float, g: float) -> np.ndarray:
    """What an accelerometer at the COG senses, ``f_B = R_IB^T (a_I + g e_z)`` (N, 3) m/s^2,
    at the control steps: ``a_I`` from second differences of the COG positions ``p_I``
    (N, 3) m, which the plant integrates at step ``dt`` s (error O(dt^2); the ends repeat
    their neighbours), ``q_IB`` (N, 4) the attitude, ``g`` m/s^2."""
    from ..model.rotations import matrix_from_quaternion

    a = np.zeros_like(p_I)
    if len(p_I) >= 3:
        a[1:-1] = (p_I[2:] - 2 * p_I[1:-1] + p_I[:-2]) / (dt * dt)
        a[0], a[-1] = a[1], a[-2]
    a[:, 2] += g
    return np.einsum("nji,nj->ni", matrix_from_quaternion(q_IB), a)


class _Estimator:
    """Ideal state, or motion-capture pose updates fused with a model prediction.

    Between pose samples the estimate is propagated with the design model and
    the applied input. The effect states of a design model (a motor lag's thrusts) are
    never measured: they are predicted from ``z0``'s (the nominal's) with the design
    model and the applied input, ideal sensing or not (what a firmware can run from its
    own commands), and kept in ``effect_states``; :meth:`estimate` hands out the 10
    reduced states. A pose sample (delayed by the latency) corrects the pose
    states and, through the innovation divided by the sample interval, the
    rates (an alpha-beta correction on top of the model prediction); body rates
    come from the gyro. Delayed samples are compared with the estimate of their
    own time (ring buffer) and the correction is applied now.
    """

    def __init__(self, model, plant, sens, dt, alpha, gamma, z0, rng):
        self.model, self.plant, self.sens, self.dt = model, plant, sens, dt
        self.alpha, self.gamma, self.rng = alpha, gamma, rng
        self.z = z0.copy()
        self.every = max(1, int(round(1.0 / (sens.rate_hz * dt))))
        self.delay = int(round(sens.latency / dt))
        self.hist: list[np.ndarray] = []
        self.pending: list[tuple[int, np.ndarray]] = []
        self.R_IC = matrix_from_euler_zyx_scalar(alpha, 0.0, gamma)
        # prediction model: the compiled reduced design model when it applies (same
        # numbers); an elastic design link predicts with the reduced (rigid) model too
        fast = None
        if not sens.ideal and model.n_z == N_STATE and model.config.tether.link == "rigid":
            fast = fast_plant(model.config)
        self._f = ((lambda z, u, a: fast.f(z, u, a, gamma)[0]) if fast is not None
                   else (lambda z, u, a: model.f(z, u, a, gamma)))

    @property
    def effect_states(self) -> np.ndarray:
        """The predicted effect states of the design model (none without one)."""
        return self.z[N_STATE:]

    def estimate(self, k, x, z_true):
        if self.sens.ideal:
            self.z[:N_STATE] = z_true  # the effect states stay predicted
            return z_true
        if k % self.every == 0:  # a pose sample taken now, arriving after the latency
            self.pending.append((k + self.delay, self._measure(x, self.z[1])))
        self.hist.append(self.z.copy())
        while self.pending and self.pending[0][0] <= k:
            _, meas = self.pending.pop(0)
            then = self.hist[-1 - self.delay] if len(self.hist) > self.delay else self.z
            innov = meas - then[[0, 1, 4, 5, 6]]
            innov[1] = wrap_angle(innov[1])
            innov[4] = wrap_angle(innov[4])
            T = self.every * self.dt
            self.z[[0, 1, 4, 5, 6]] += 0.5 * innov
            self.z[[2, 3]] += 0.5 * innov[[0, 1]] / T * 0.5
        if len(self.hist) > self.delay + 2:
            self.hist.pop(0)
        z = self.z[:N_STATE].copy()
        z[7:10] = z_true[7:10] + self.sens.gyro_noise * self.rng.standard_normal(3)
        return z

    def _measure(self, x, xi_near):
        """Noisy pose -> (delta, xi, phi, theta, chi), rad, shape (5,).

        True COG position and attitude in I, plus position noise (m) and a small
        attitude perturbation ``R_IB Rz Ry Rx`` (rad), converted back to the reduced
        pose angles (:func:`~gainsched.model.geometry.pose_angles_from_pose`) with xi on
        the branch nearest ``xi_near`` (the estimate: the azimuth is tracked continuously,
        as a firmware must, from what it knows).
        """
        p_I, R_IB = self.plant.pose(x, self.alpha, self.gamma)
        p_I = p_I + self.sens.position_noise * self.rng.standard_normal(3)
        rot = self.sens.attitude_noise * self.rng.standard_normal(3)
        R_IB = R_IB @ matrix_from_euler_zyx_scalar(rot[0], rot[1], rot[2])
        R_CI = self.R_IC.T
        return pose_angles_from_pose(R_CI @ p_I, R_CI @ R_IB, self.model.p_e, xi_near)[1]

    def predict(self, u):
        if self.sens.ideal and self.z.size == N_STATE:
            return
        self.z = self.z + self.dt * self._f(self.z, u, self.alpha)


def metrics(res: SimResult) -> dict:
    """Tracking, load and saturation figures of a simulated flight, by name.

    What ``gainsched simulate`` writes to ``metrics.json``: the out-of-plane error (m),
    the along-track error (the azimuth error, rad, and its arc at the COG radius, m)
    with lap slips, the speed tracking error (m/s), the loads, the time spent at the
    edges of the table and the motors' limits.

    Parameters
    ----------
    res : SimResult
        A simulated flight (:func:`simulate`).

    Returns
    -------
    dict
        By name (the unit ends the name; errors are simulated minus nominal):

        - ``duration_s``: time flown, s (less than the scenario's after a slack stop);
        - ``rms_out_of_plane_m``, ``max_out_of_plane_m``: the COG's distance from the
          circle plane, m;
        - ``rms_along_track_m``, ``max_along_track_m``: the azimuth error times the COG
          radius ``r``, m;
        - ``mean_azimuth_error_rad``, ``final_azimuth_error_rad``,
          ``max_azimuth_error_rad`` (of its magnitude): xi - xi_d from continuous
          azimuths (a lap behind is -2 pi), rad;
        - ``lap_slips``: whole laps gained or lost, int;
        - ``rms_speed_error_mps``, ``mean_speed_error_mps``: tangential COG speed
          ``r xi_dot`` minus the nominal's, m/s; ``max_speed_mps``, m/s;
        - ``max_tension_N``: tether tension, N; ``max_g_load``: ``v^2 / (r g)``, the
          centripetal acceleration in g; ``max_tether_accel_g``: tension / (m g);
        - ``saturation_fraction``: share of motor commands clipped at a thrust limit,
          0..1;
        - ``held_gains_s``: time flown on held gains (an unusable lookup), s;
          ``clamped_speed_s``: time the lookup's speed was clamped to the table's range, s;
        - ``min_nominal_tension_N``: lowest tension of the nominal, N (nan if unknown);
          ``below_tension_margin_s``: time the nominal is below the config's
          ``min_tension``, s;
        - ``slack_events``: 1 if the tether went slack, else 0; ``slack_time_s``: when,
          s, or None;
        - ``max_roll_deg``: largest roll angle magnitude, deg.

    Examples
    --------
    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> table = gs.load_table("tables/paper.h5")
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> m = gs.metrics(gs.simulate(cfg, gs.table_scheduler(table), scn))
    >>> print(f"{100 * m['rms_along_track_m']:.1f} cm along track, "
    ...       f"{m['max_tension_N']:.1f} N, {m['max_g_load']:.1f} g, "
    ...       f"roll {m['max_roll_deg']:.0f} deg")
    3.1 cm along track, 20.0 N, 4.1 g, roll 17 deg
    >>> m["lap_slips"], m["saturation_fraction"], m["slack_events"]
    (0, 0.0, 0)
    """
    R_IC = R_IC_from_tilt(res.scenario.tilt, res.scenario.gamma)
    p_C = res.p_I @ R_IC  # rows: R_IC^T p
    out_of_plane = p_C[:, 2]
    v = res.z[:, 3] * res.r
    v_ref = res.z_d[:, 3] * res.r
    accel = res.tension / res.mass  # the tether carries the centripetal load
    xi_err = res.z[:, 1] - res.z_d[:, 1]  # both continuous: a lap behind is -2 pi
    dt = float(res.t[1] - res.t[0]) if res.t.size > 1 else 0.0
    return {
        "duration_s": float(res.t[-1]),
        "rms_out_of_plane_m": float(np.sqrt(np.mean(out_of_plane**2))),
        "max_out_of_plane_m": float(np.abs(out_of_plane).max()),
        "rms_along_track_m": float(res.r * np.sqrt(np.mean(xi_err**2))),
        "max_along_track_m": float(res.r * np.abs(xi_err).max()),
        "mean_azimuth_error_rad": float(np.mean(xi_err)),
        "final_azimuth_error_rad": float(xi_err[-1]),
        "max_azimuth_error_rad": float(np.abs(xi_err).max()),
        "lap_slips": int(np.abs(xi_err).max() // (2 * np.pi)),
        "rms_speed_error_mps": float(np.sqrt(np.mean((v - v_ref) ** 2))),
        "mean_speed_error_mps": float(np.mean(v - v_ref)),
        "max_speed_mps": float(np.abs(v).max()),
        "max_tension_N": float(res.tension.max()),
        "max_g_load": float(np.max(v**2 / res.r) / res.g),
        "max_tether_accel_g": float(accel.max() / res.g),
        "saturation_fraction": float(res.saturated.mean()),
        "held_gains_s": float(np.count_nonzero(res.held) * dt) if res.held is not None else 0.0,
        "clamped_speed_s": float(np.count_nonzero(res.status & CLAMPED_SPEED) * dt),
        "min_nominal_tension_N": (float(res.tension_d.min()) if res.tension_d is not None
                                  else math.nan),
        "below_tension_margin_s": (float(np.count_nonzero(res.tension_d < res.min_tension) * dt)
                                   if res.tension_d is not None else 0.0),
        "slack_events": 0 if res.slack_time is None else 1,
        "slack_time_s": res.slack_time,
        "max_roll_deg": float(np.rad2deg(np.abs(res.z[:, 4]).max())),
    }


def table_scheduler(table):
    """Gain lookup of a table through the Python reference of the C runtime, for simulate.

    The lookup is :class:`~gainsched.firmware.runtime.Interpolator`, the reference
    implementation of the firmware's ``gainsched_runtime.c`` (the same cell, weights,
    mirroring and status bits, in float32), one query per call.

    Parameters
    ----------
    table : Table, RuntimeData or CompactData
        The gain schedule (:func:`~gainsched.schedule.tables.load_table`), its dense
        runtime form (:func:`gainsched.firmware.runtime.runtime_data`) or its compact
        form (:func:`gainsched.firmware.compact.compact_data`, looked up by
        :class:`~gainsched.firmware.compact.CompactInterpolator`).

    Returns
    -------
    callable
        ``lookup(xi, xi_dot, alpha) -> (K, status)``: at the azimuth xi (rad), the azimuth
        rate xi_dot (rad/s) and the tilt alpha (rad), the gains ``K``, ndarray of shape
        (4, n) (N per unit of LQR state: rad, rad/s, rad s), and the status bits (int;
        0: OK, 0x01 ``CLAMPED_SPEED``: outside the table's speeds, ...; see
        :func:`gainsched.firmware.runtime.status_text`). Its attributes:
        ``lookup.batch(xi, xi_dot, alpha) -> (K (m, 4, n), status (m,) int)``, the same
        numbers for arrays of m queries; ``lookup.interp``, the
        :class:`~gainsched.firmware.runtime.Interpolator`;
        ``lookup.feedforward(path, alpha)``, the firmware's nominal along a reference
        (``simulate(..., controller="firmware")``).

    Examples
    --------
    >>> table = gs.load_table("tables/paper.h5")
    >>> lookup = gs.table_scheduler(table)
    >>> K, status = lookup(0.5, 9.0 / 1.6, 0.0)  # 9 m/s on the level circle, r = 1.6 m
    >>> K.shape, status
    ((4, 11), 0)
    >>> K, status = lookup(0.5, 32.0 / 1.6, 0.0)  # 32 m/s: clamped to the fastest speed
    >>> status
    1
    >>> xi = np.linspace(0.0, 2 * np.pi, 5)  # one lap, in one call
    >>> K, status = lookup.batch(xi, np.full(5, 9.0 / 1.6), np.deg2rad(20.0))
    >>> K.shape, status.tolist()
    ((5, 4, 11), [0, 0, 0, 0, 0])
    """
    from ..firmware.compact import CompactData, CompactInterpolator
    from ..firmware.controller import Controller
    from ..firmware.runtime import Interpolator

    interp = CompactInterpolator(table) if isinstance(table, CompactData) else Interpolator(table)
    query = interp.query  # one query per call: the scalar fast path

    def lookup(xi, xi_dot, alpha):
        K, _, _, status = query(xi, xi_dot, alpha)
        return K, status

    def batch(xi, xi_dot, alpha):
        """Arrays of queries (m,) -> K (m, 4, n), status (m,) int: the same numbers."""
        r = interp(xi, xi_dot, alpha)
        return r.K, r.status.astype(int)

    lookup.batch = batch
    lookup.interp = interp
    # the firmware's nominal along a reference (simulate(controller="firmware"))
    lookup.feedforward = lambda path, alpha: feedforward(interp, path, alpha)
    # the firmware's whole loop (simulate(controller="firmware")): the Python reference
    lookup.controller = lambda params: Controller(params, interp)
    lookup.data = interp.data  # the table it flies (controller_params sizes from it)
    return lookup


def c_runtime_scheduler(table, build_dir=None):
    """Gain lookup through the compiled C runtime (the firmware code): (xi, xi_dot, alpha)
    -> (K (4, n) float64 of the runtime's float32 gains, status int).

    The table, ``gainsched_runtime.c`` and the batch shim are compiled for the host with
    :func:`gainsched.firmware.codegen.build_host` into ``build_dir`` (default: a temporary
    directory that lives as long as the returned function) and called through ctypes,
    one query per call with preallocated buffers. Raises RuntimeError without a C
    compiler.

    Parameters
    ----------
    table : Table, RuntimeData or CompactData
        The table, in the format the firmware holds (a loaded table: the dense one).
    build_dir : path, optional
    """
    import ctypes
    import tempfile

    from ..firmware.codegen import CRuntime, build_host, firmware_data

    data = firmware_data(table)
    tmp = None
    if build_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="gainsched-rt-")
        build_dir = tmp.name
    rt = CRuntime(build_host(data, Path(build_dir)), data)
    n = data.dims[3]
    q = np.zeros(3, dtype=np.float32)
    Kb = np.zeros((4, n), dtype=np.float32)
    Ub = np.zeros(4, dtype=np.float32)
    Pb = np.zeros(1, dtype=np.float32)
    Sb = np.zeros(1, dtype=np.int32)
    # our own function object with raw pointers (CRuntime's ndpointer argtypes cost
    # microseconds of checks per call); the pointers stay valid: the buffers live here
    fn = rt.lib[f"{data.name}_lookup_batch"]
    fn.restype = None
    fn.argtypes = [ctypes.c_size_t] + [ctypes.c_void_p] * 5
    ptrs = [b.ctypes.data for b in (q, Kb, Ub, Pb, Sb)]

    def lookup(xi, xi_dot, alpha):
        q[0], q[1], q[2] = xi, xi_dot, alpha
        fn(1, *ptrs)
        return Kb.astype(np.float64), int(Sb[0])

    def nominal(path, alpha):
        """``gs_lookup_nominal`` along a reference: the gains and the firmware's nominal
        (:class:`~gainsched.firmware.feedforward.FeedForward` with ``K``), all from C."""
        ref = np.stack([path.xi, *path.d], axis=1)
        K, U, X, T, S = rt.nominal(ref, alpha)
        if np.any(S & BAD_ARG):
            raise InputError(str(data.name), "vehicle", "the table carries no closed-form "
                             "constants: no manoeuvre feed-forward")
        return FeedForward(X.astype(np.float64), U.astype(np.float64), T.astype(np.float64),
                           S.astype(int), K)

    lookup.feedforward = nominal
    built = {}

    def controller(params):
        """The C controller with ``params`` (gainsched_control.c; compiled once)."""
        from ..firmware.sil import CController, build_controller

        if "lib" not in built:
            built["lib"] = build_controller(data, params, Path(build_dir) / "control")
        return CController(data, params, lib_path=built["lib"])

    lookup.controller = controller
    lookup.data = data  # the table it flies (controller_params sizes from it)
    lookup.runtime = rt  # keeps the library (and the temporary directory) alive
    lookup.build_dir = tmp
    return lookup


#: where the simulator's firmware takes its lookups and feed-forward from
RUNTIMES = ("auto", "c", "python")


def runtime_scheduler(table, runtime: str = "auto"):
    """The gain source of a simulated flight: the compiled C runtime or its Python reference.

    The C runtime flies the very code that goes on the vehicle (``gainsched_runtime.c``
    with the table, compiled for the host); its Python reference mirrors it in float32
    arithmetic and needs no compiler.

    Parameters
    ----------
    table : Table or RuntimeData
        The gain schedule (:func:`~gainsched.schedule.tables.load_table`).
    runtime : {"auto", "c", "python"}, default "auto"
        ``"c"``: the compiled C runtime, the firmware's own code
        (:func:`c_runtime_scheduler`: gains and the firmware's nominal from
        ``gs_lookup_nominal``; compiled for the host, a second or two); ``"python"``: its
        Python reference (:func:`table_scheduler`); ``"auto"``: the C runtime when a C
        compiler is found (``CC``), else the reference.

    Returns
    -------
    callable
        A scheduler for :func:`simulate`, ``(xi, xi_dot, alpha) -> (K (4, n), status)``
        (see :func:`table_scheduler`), with ``feedforward`` for
        ``controller="firmware"``; its ``source`` (str) says which runtime it is:
        ``"C runtime (gs_lookup_nominal)"`` or ``"Python reference of the C runtime"``.

    Raises
    ------
    InputError
        ``runtime`` is not one of :data:`RUNTIMES`, or ``"c"`` without a C compiler.

    Examples
    --------
    A flight on what the firmware has: the table's gains and feed-forward only.

    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> sched = gs.runtime_scheduler(gs.load_table("tables/paper.h5"), "python")
    >>> sched.source
    'Python reference of the C runtime'
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> res = gs.simulate(cfg, sched, scn, controller="firmware")
    >>> int(res.status.max()), bool(res.held.any()), bool(res.saturated.any())
    (0, False, False)
    """
    from ..native import find_cc

    if runtime not in RUNTIMES:
        raise InputError("--runtime", runtime, f"must be one of {', '.join(RUNTIMES)}")
    if runtime == "c" or (runtime == "auto" and find_cc() is not None):
        if find_cc() is None:
            raise InputError("--runtime", "c", "no C compiler found (set CC)")
        sched = c_runtime_scheduler(table)
        sched.source = "C runtime (gs_lookup_nominal)"
    else:
        sched = table_scheduler(table)
        sched.source = "Python reference of the C runtime"
    return sched


def log_from_result(res: SimResult, *, rate_hz: float | None = None, seed: int | None = None):
    """The flight log a real flight would leave: a simulated flight as a FlightLog.

    In the format of docs/flight-log.md, sampled every ``round(1 / (rate_hz dt))``
    control steps: the motion-capture pose with the scenario's position and attitude
    noise, the commanded thrusts (the mean over each sample interval, as held since the
    previous sample), the gyro (the mean body rate over the interval centred on the
    sample, with the scenario's gyro noise), the accelerometer (the mean specific force
    at the COG over the same interval, with the scenario's accelerometer noise), the
    load-cell tension and the reference azimuth and its rate; the battery voltage when the
    plant has a battery (the mean over the interval centred on the sample, no noise).

    Parameters
    ----------
    res : SimResult
        A simulated flight (:func:`simulate`).
    rate_hz : float, optional
        Sampling rate of the log, Hz; default the scenario's motion-capture rate
        (``scenario.sensing.rate_hz``).
    seed : int, optional
        Seed of the pose, gyro and accelerometer noise; default
        ``scenario.sensing.seed + 1000``.

    Returns
    -------
    FlightLog
        One segment, ``source`` ``"simulation NAME"``, metadata ``alpha_c_deg``,
        ``gamma_c_deg``, ``flight_id`` ``"sim-NAME"`` and ``notes``; the optional columns
        ``omega_B`` (rad/s), ``f_B`` (m/s^2), ``tension`` (N), ``xi_ref`` (rad),
        ``xi_dot_ref`` (rad/s), and ``vbat`` (V) with a battery.
        ``gainsched.analysis.logs.write_log`` writes it.

    Examples
    --------
    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> table = gs.load_table("tables/paper.h5")
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> log = gs.log_from_result(gs.simulate(cfg, gs.table_scheduler(table), scn))
    >>> len(log), round(1 / log.dt_median), log.meta["flight_id"], sorted(log.optional)
    (101, 200, 'sim-horizontal', ['f_B', 'omega_B', 'tension', 'xi_dot_ref', 'xi_ref'])

    The design model explains its own simulated flight down to the measurement noise:

    >>> round(gs.compare(cfg, [log]).normalized_rms(), 1)  # 1: residual = noise
    1.0
    """
    from ..analysis.logs import log_from_arrays
    from ..model.rotations import Rx, Ry, Rz, matrix_from_quaternion

    sens = res.scenario.sensing
    rate = sens.rate_hz if rate_hz is None else rate_hz
    dt = res.t[1] - res.t[0]
    every = max(1, int(round(1.0 / (rate * dt))))
    idx = np.arange(0, res.t.size, every)
    rng = np.random.default_rng(sens.seed + 1000 if seed is None else seed)
    p = res.p_I[idx] + sens.position_noise * rng.standard_normal((idx.size, 3))
    rot = sens.attitude_noise * rng.standard_normal((idx.size, 3))
    R = matrix_from_quaternion(res.q_IB[idx]) @ Rz(rot[:, 2]) @ Ry(rot[:, 1]) @ Rx(rot[:, 0])
    q = quaternion_from_matrix(R)
    # thrust "held since the previous sample": the mean of the commands applied over
    # [t_prev, t) (command k acts on [t_k, t_k+1)); the first row has only u[0]
    ends = np.maximum(idx, 1)
    starts = np.maximum(idx - every, 0)
    csum = np.concatenate([np.zeros((1, 4)), np.cumsum(res.u, 0)])
    T = (csum[ends] - csum[starts]) / (ends - starts)[:, None]
    meta = {
        "alpha_c_deg": f"{np.rad2deg(res.scenario.tilt):.12g}",
        "gamma_c_deg": f"{np.rad2deg(res.scenario.gamma):.12g}",
        "flight_id": f"sim-{res.scenario.name}",
        "notes": "simulated by gainsched",
    }
    # the gyro: the mean body rate over the sample interval centred on the sample time (an
    # anti-aliased gyro whose filter delay the driver's time stamps compensate), plus noise
    h = every // 2
    w = res.z[:, 7:10]
    wsum = np.concatenate([np.zeros((1, 3)), np.cumsum(w, 0)])
    lo, hi = np.maximum(idx - h, 0), np.minimum(idx + h + 1, w.shape[0])
    gyro = (wsum[hi] - wsum[lo]) / (hi - lo)[:, None]
    gyro = gyro + sens.gyro_noise * rng.standard_normal((idx.size, 3))
    extra = {}
    if res.f_B is not None:  # the accelerometer, anti-aliased the same way, its own noise
        fsum = np.concatenate([np.zeros((1, 3)), np.cumsum(res.f_B, 0)])
        f_B = (fsum[hi] - fsum[lo]) / (hi - lo)[:, None]
        extra["f_B"] = f_B + sens.accel_noise * np.random.default_rng(
            (sens.seed + 1000 if seed is None else seed) + 7919).standard_normal((idx.size, 3))
    if res.vbat is not None:  # the battery voltage, averaged over the same interval
        vsum = np.concatenate([[0.0], np.cumsum(res.vbat)])
        extra["vbat"] = (vsum[hi] - vsum[lo]) / (hi - lo)
    return log_from_arrays(
        res.t[idx], p, q, T, meta, source=f"simulation {res.scenario.name}",
        omega_B=gyro, tension=res.tension[idx],
        xi_ref=res.z_d[idx, 1], xi_dot_ref=res.z_d[idx, 3], **extra,
    )


def write_run(res: SimResult, out_dir) -> dict:
    """Write log.csv, log.h5, metrics.json and the plots into ``out_dir``; returns the metrics."""
    import json

    from ..analysis.logs import write_log
    from ..publish import write_atomic
    from .plots import plot_result

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log = log_from_result(res)
    write_log(out_dir / "log.csv", log)
    write_log(out_dir / "log.h5", log)
    m = metrics(res)
    m["scenario"] = res.scenario.name
    write_atomic(
        out_dir / "metrics.json", (json.dumps(m, indent=2, sort_keys=True) + "\n").encode()
    )
    plot_result(res, out_dir)
    return m
