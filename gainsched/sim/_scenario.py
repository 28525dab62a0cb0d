"""Scenarios: the flight to simulate (circle, speed profile, duration, sensing),
its validation from TOML and its reference azimuth path."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import MAX_SPEED, Section
from ..constants import MAX_FLIGHT_S, MAX_FLIGHT_STEPS, MAX_SEED
from ..errors import InputError
from ..schedule.path import AzimuthPath, maneuver_path
from ..textinput import load_toml

__all__ = [
    "Maneuver",
    "Sine",
    "MAX_TONES",
    "scenario_text",
    "Sensing",
    "Scenario",
    "MAX_MANEUVERS",
    "SENSING_RATE_HZ",
    "MAX_LATENCY_S",
    "INITIAL_ERROR_SIZES",
    "SCENARIO_DIR",
    "load_scenario",
    "scenario_from_dict",
    "check_flight_steps",
    "profile_path",
]


@dataclass(frozen=True)
class Maneuver:
    """Speed change at ``t_start`` (s) to ``speed`` (m/s) with eq. 20 parameter ``a`` (m/s^2)."""

    t_start: float
    speed: float
    a: float


@dataclass(frozen=True)
class Sine:
    """One tone of a speed excitation: ``amplitude`` (m/s) ``sin(2 pi frequency t +
    phase)``, frequency in Hz, phase in rad, t from the flight's start."""

    amplitude: float
    frequency: float
    phase: float = 0.0


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
    excitation : tuple of Sine
        A multisine added to the along-track speed over the whole flight (identification
        flights, ``gainsched plan``): the speed is ``speed + sum A sin(2 pi f t + phi)``
        (``[[excitation]]`` tables of ``amplitude_mps``, ``frequency_hz``, ``phase_deg``).
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
    excitation: tuple[Sine, ...] = ()

    @property
    def origin(self) -> str:
        """What an error about the scenario names: its file, else ``scenario NAME``."""
        return self.source or f"scenario {self.name}"


#: most speed changes of one scenario (each is evaluated over the whole flight)
MAX_MANEUVERS = 100
#: most tones of a speed excitation, and their frequencies, Hz (above 5 Hz the loop does
#: not follow a reference: the closed loop's bandwidth is a few Hz)
MAX_TONES = 16
TONE_HZ = (0.01, 5.0)
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
    tones = _excitation(top, source)
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
                    source=str(source), excitation=tones)


def _excitation(top: Section, source) -> tuple[Sine, ...]:
    """The ``[[excitation]]`` tones of a scenario table."""
    raw = top.get("excitation", [])
    if not isinstance(raw, list):
        raise top.error("excitation", "must be a list of tables")
    if len(raw) > MAX_TONES:
        raise top.error("excitation", f"at most {MAX_TONES} tones, got {len(raw)}")
    tones = []
    for i in range(len(raw)):
        sec = Section(str(source), f"excitation[{i}]", raw[i])
        tones.append(Sine(sec.number("amplitude_mps", positive=True),
                          sec.bounded("frequency_hz", lo=TONE_HZ[0], hi=TONE_HZ[1], unit="Hz"),
                          np.deg2rad(sec.number("phase_deg", 0.0))))
        sec.done()
    return tuple(tones)


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
    """The reference azimuth path of a scenario: initial speed plus sequential manoeuvres,
    plus its speed excitation."""
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
    for tone in scn.excitation:  # v += A sin(w t + phi): xi and its four derivatives
        w = 2 * np.pi * tone.frequency
        ph = w * t + tone.phase
        amp = tone.amplitude / r
        xi = xi - amp / w * (np.cos(ph) - np.cos(tone.phase))
        d[0] = d[0] + amp * np.sin(ph)
        d[1] = d[1] + amp * w * np.cos(ph)
        d[2] = d[2] - amp * w**2 * np.sin(ph)
        d[3] = d[3] - amp * w**3 * np.cos(ph)
    return AzimuthPath(t, xi, tuple(d))


def scenario_text(scn: Scenario) -> str:
    """The TOML of a scenario, as :func:`load_scenario` reads it back (the same flight:
    angles in deg, the sensing's keys; ``initial_error`` when set)."""
    g = lambda x: repr(float(x))  # noqa: E731  (round-trips exactly)
    out = [f"name = {scn.name!r}".replace("'", '"'), f"tilt_deg = {g(np.rad2deg(scn.tilt))}",
           f"gamma_deg = {g(np.rad2deg(scn.gamma))}", f"speed = {g(scn.speed)}",
           f"duration = {g(scn.duration)}"]
    if scn.initial_error:
        out.append(f"initial_error = [{', '.join(g(x) for x in scn.initial_error)}]")
    for m in scn.maneuvers:
        out += ["", "[[maneuvers]]", f"t_start = {g(m.t_start)}", f"speed = {g(m.speed)}",
                f"a = {g(m.a)}"]
    for tone in scn.excitation:
        out += ["", "[[excitation]]", f"amplitude_mps = {g(tone.amplitude)}",
                f"frequency_hz = {g(tone.frequency)}",
                f"phase_deg = {g(np.rad2deg(tone.phase))}"]
    s = scn.sensing
    out += ["", "[sensing]", f"ideal = {str(s.ideal).lower()}", f"rate_hz = {g(s.rate_hz)}",
            f"position_noise = {g(s.position_noise)}",
            f"attitude_noise_deg = {g(np.rad2deg(s.attitude_noise))}",
            f"gyro_noise = {g(s.gyro_noise)}", f"latency = {g(s.latency)}",
            f"seed = {int(s.seed)}", f"accel_noise = {g(s.accel_noise)}",
            f"latency_compensation = {str(s.latency_compensation).lower()}",
            f"accelerometer = {str(s.accelerometer).lower()}"]
    return "\n".join(out) + "\n"
