"""The sections of a config file, one reader each (``read_vehicle`` for ``[vehicle]``,
...): the keys of the section, their types, ranges and defaults, and the checks
between keys of one section; each returns the section's dataclass
(:mod:`gainsched.config._schema`) in SI units (degrees exist only in the file: keys
ending in ``_deg``). Checks across sections are the reader's
(:func:`gainsched.config._reader._config`).
"""

from __future__ import annotations

import math

import numpy as np

from ..actuators import MOTOR_ORDERS
from ..constants import (
    MARGIN_DELAY_MAX_S,
    MARGIN_GAIN_MAX,
    MAX_XI,
    N_INPUT,
    N_STATE,
    REDUCED_NAMES,
    XI_DOT_LIMIT,
)
from ._checks import Section, check_axis, check_axis_range, check_float32_axis, check_square_weight
from ._schema import (
    COMMANDS,
    FORMATS,
    LINK_MODELS,
    TERMINAL_COSTS,
    Analysis,
    AzimuthRange,
    Control,
    EffectSpec,
    Feasibility,
    Firmware,
    Grid,
    Limits,
    Sensors,
    Tether,
    Vehicle,
    integral_states,
)

MASS_RANGE = (0.01, 1000.0)  # kg, a plausible vehicle
INERTIA_TRIANGLE_TOL = 1e-6  # relative slack of J1 + J2 >= J3 (a flat plate is the limit)
MAX_SPEED = 100.0  # m/s, tangential COG speed
MAX_RATE_HZ = 1.0e5  # Hz, control rate
#: control periods: the shortest closed-loop time constant bound a config may ask for
MIN_TIME_CONSTANT_STEPS = 10


def read_vehicle(sec: Section) -> Vehicle:
    """``[vehicle]`` -> :class:`Vehicle`: mass (kg), inertia (3, 3) kg m^2, motor thrusts (N)."""
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


def read_tether(sec: Section) -> Tether:
    """``[tether]`` -> :class:`Tether`: length and offset (m), the link model's keys."""
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


def read_effects(sec: Section) -> tuple[EffectSpec, ...]:
    """``[effects.NAME]`` tables -> :class:`EffectSpec` tuple, sorted by name (SI)."""
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


def read_control(sec: Section) -> Control:
    """``[control]`` -> :class:`Control`: rate (Hz), Q (n, n), R (4, 4), integrals."""
    rate = sec.number("rate_hz", positive=True)
    if rate > MAX_RATE_HZ:
        raise sec.error("rate_hz", f"must be <= {MAX_RATE_HZ:g} Hz, got {rate:g}")
    integ = sec.boolean("integrator", True)
    az_integ = sec.boolean("azimuth_integral", False)
    integrators = integral_states(integ, az_integ)
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
    margins = sec.boolean("margins", True)
    bounds = _margin_bounds(sec, margins)
    sec.done()
    Q.setflags(write=False)
    R.setflags(write=False)
    return Control(rate, Q, R, integ, term, az_integ, tau_max, max_gain, int_limit, margins,
                   *bounds)


def _margin_bounds(sec: Section, margins: bool) -> tuple[float | None, float | None]:
    """``control.min_gain_margin_db`` (dB) and ``min_delay_margin_ms`` (ms): positive,
    within the margins' search ranges, and only with ``margins = true``."""
    out = []
    for key, limit, unit in (("min_gain_margin_db", 20 * math.log10(MARGIN_GAIN_MAX), "dB"),
                             ("min_delay_margin_ms", 1e3 * MARGIN_DELAY_MAX_S, "ms")):
        if key not in sec.data:
            out.append(None)
            continue
        value = sec.number(key, positive=True)
        if value > limit:
            raise sec.error(key, f"{value:g} {unit} is beyond the margins' search range "
                            f"({limit:g} {unit}; docs/margins.md)")
        if not margins:
            raise sec.error(key, "needs margins = true (the bound is checked on the margins "
                            "the build computes)")
        out.append(value)
    return out[0], out[1]


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


def _axis_or_range(sec: Section, k: str, *, nonneg: bool, positive: bool):
    """A list axis, or a range the build refines: ``(breakpoints or seeds, AxisRange or
    None)``."""
    if isinstance(sec.data.get(k), dict):
        rng = check_axis_range(sec, k)
        if positive and rng.lo <= 0:
            raise sec.error(f"{k}.min", f"must be > 0, got {rng.lo:g}")
        return rng.seeds(), rng
    return check_axis(sec, k, nonneg=nonneg, positive=positive), None


def read_grid(sec: Section, radius: float) -> Grid:
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


def read_firmware(sec: Section) -> Firmware:
    """``[firmware]`` -> :class:`Firmware`: table format, flash budget, outputs."""
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


def read_feasibility(sec: Section) -> Feasibility:
    """``[feasibility]`` -> :class:`Feasibility`: margins (N), offsets (deg in, rad out)."""
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


def read_analysis(sec: Section) -> Analysis:
    """``[analysis]`` -> :class:`Analysis`: the log differentiation window (s) and order."""
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


#: the range of a gyro axis's scale factor and of its bias (rad/s) in ``[sensors]``
GYRO_SCALE_RANGE = (0.5, 2.0)
GYRO_BIAS_MAX = 0.5
#: the largest accelerometer bias in ``[sensors]``, m/s^2
ACCEL_BIAS_MAX = 2.0
#: the largest marker-frame rotation in ``[sensors]``, deg (a rigid body defined on the
#: markers is a degree or two off; more is a wrong body, not a calibration)
MARKER_ROTATION_MAX_DEG = 10.0


def read_sensors(sec: Section) -> Sensors:
    """``[sensors]`` -> :class:`Sensors`: the gyro's scale factors and biases (rad/s) per
    body axis, the marker frame's rotation (deg in the file, rad in :class:`Sensors`), the
    accelerometer's scale factors and biases (m/s^2)."""

    def axes(key, default, lo, hi, unit):
        a = sec.array(key, list(default))
        if a.shape != (3,):
            raise sec.error(key, f"must be 3 numbers (x, y, z), got shape {a.shape}")
        if np.any(a < lo) or np.any(a > hi):
            raise sec.error(key, f"each must be in [{lo:g}, {hi:g}]{unit}, got "
                                 f"{', '.join(f'{x:g}' for x in a)}")
        return tuple(float(x) for x in a)

    scale = axes("gyro_scale", Sensors.gyro_scale, *GYRO_SCALE_RANGE, "")
    bias = axes("gyro_bias", Sensors.gyro_bias, -GYRO_BIAS_MAX, GYRO_BIAS_MAX, " rad/s")
    rot = axes("marker_rotation_deg", (0.0, 0.0, 0.0), -MARKER_ROTATION_MAX_DEG,
               MARKER_ROTATION_MAX_DEG, " deg")
    a_scale = axes("accel_scale", Sensors.accel_scale, *GYRO_SCALE_RANGE, "")
    a_bias = axes("accel_bias", Sensors.accel_bias, -ACCEL_BIAS_MAX, ACCEL_BIAS_MAX, " m/s^2")
    sec.done()
    return Sensors(scale, bias, tuple(float(np.deg2rad(a)) for a in rot), a_scale, a_bias)


def read_limits(sec: Section) -> Limits:
    """``[limits]`` -> :class:`Limits`: memory (GiB) and CPU time (s) of a build."""
    mem = sec.number("max_memory_gib", Limits.max_memory_gib, positive=True)
    cpu = sec.number("max_build_cpu_s", Limits.max_build_cpu_s, positive=True)
    sec.done()
    return Limits(mem, cpu)
