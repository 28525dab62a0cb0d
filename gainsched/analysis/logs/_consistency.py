"""Consistency of a flight log's channels with each other and with the model
(docs/flight-log.md, "Channels that contradict each other").

A log can pass every rule of the format and still hold a conversion mistake that a
new logging setup makes once: a gyro in deg/s, the reference azimuth in degrees,
thrust in grams, quaternions scalar last, the load cell's sign, the circle plane's
normal upside down, another vehicle's log. The analysis would then fit the model to
nonsense. Each check here compares a channel with what the pose (and, for forces,
the config's vehicle) says it must be, as one ratio, and refuses the log when the
ratio is far from 1, naming the file, the column and the likely cause:

``plane``
    The thrust axis ``z_B`` of the attitude against the declared plane's normal
    ``R_IC (0, 0, 1)``: the model's nominal holds the vehicle up with thrust along
    the normal (``T_C cos(phi) = m g cos(alpha_C)``), so the mean of ``z_B . n`` must
    be positive (0.7 and more on honest flights); a declared ``alpha_c_deg`` of 180 on
    a level flight gives about -1.
``quaternion``
    The body x axis the quaternion gives against the tether direction: ``x_B`` points
    outward along the tether (docs/conventions.md), so the mean of ``x_B . p/|p|``
    over a flight is near 1 (0.9 and more on honest flights); a scalar-last or
    conjugated quaternion read as the format's gives about 0. Tried the other way
    round, the order that does fit names the cause.
``gyro``
    ``p, q, r`` against the body rates derived from consecutive attitudes (the
    rotation ``R_k^T R_{k+m}`` over about 20 ms, the gyro averaged over the same
    interval): the scale ``|w|^2 / (w . w_pose)`` over the axes that move, and the
    sign of each moving axis. deg/s reads as 57.3x.
``thrust``
    The commanded thrust against the force the motion needs, across the plane of the
    tether and the velocity where neither the tether nor the drag pulls:
    ``sum T_i (z_B . n) = m (a - g) . n``, ``n = e x v / |e x v|``, with the config's
    mass (and thrust scale, if the config has one), over the samples with every motor
    on. Grams-force read as newtons give
    102x, mN 1000x, another vehicle what it weighs against this one.
``tension``
    The load cell against the radial equation, the tension the motion needs along the
    tether: ``f_t = sum T_i (z_B . e) + m (g - a) . e``. Negated reads as -1.
``xi_ref``
    The reference azimuth (and its rate ``xi_dot_ref``) against the azimuth flown in
    the declared circle frame: their advances over the flight. Degrees read as 57.3x.
``radius``
    The distance of the positions from the anchor (the inertial origin) against the
    config's tether, ``tether.length + attachment_offset``: the median over the log
    within a factor 1.25 of it, and its 5-95 % spread within 25 % of it. A taut tether
    holds the vehicle on its sphere to millimetres (the stretch of a real one is
    0.3 mm); motion capture of a vehicle that is not tethered, or a map's anchor
    metres off, is neither.

The checks are a few vectorised passes over the arrays (no model evaluation per
sample): a few milliseconds on a 1 kHz log of minutes. Each check runs only when its
figure is well determined (the axis moves, the flight covers an arc, the motion needs
a force of some newtons), so a log that does not tell is not refused. Accelerations and
rates are differences over a few samples, never across a gap.

Where the user knows better (a vehicle that really flies with its x axis across the
tether, a load cell that measures something else), the check is skipped by name:
``read_log(..., trust=("gyro",))``, ``--trust gyro`` on ``compare`` and ``diagnose``,
or the log's metadata ``trust: gyro, tension``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...rotations import matrix_from_quaternion
from ._progress import report

__all__ = ["CHECKS", "RATIO_TOL", "QUAT_ALONG_MIN", "Figures", "figures", "check_log",
           "thrust_units", "trusted"]

#: the checks, by the name ``trust`` takes
CHECKS = ("plane", "quaternion", "gyro", "thrust", "tension", "xi_ref", "radius")
#: a ratio (gyro, thrust, tension, xi_ref) is accepted within [1 / RATIO_TOL, RATIO_TOL]:
#: honest logs stay within 0.87-1.30 (the example flights and the campaigns of every
#: hidden effect: momentum-theory thrust at 15 m/s is the largest), and the mistakes are
#: a factor 2.8 and more away (a vehicle 3x as heavy, deg/s 57.3, gf 102, negated -1)
RATIO_TOL = 2.0
#: the body x axis must point along the tether by at least this mean cosine (honest
#: flights: 0.99 and more; a quaternion in the wrong order: about 0)
QUAT_ALONG_MIN = 0.5
#: the positions' median distance from the anchor must be within this factor of the
#: tether's radius, and their 5-95 % spread within RADIUS_SPREAD of it (honest flights:
#: within 0.1 % and 0.1 %; an anchor a metre off on a 2 m tether: 1.5x)
RADIUS_TOL = 1.25
RADIUS_SPREAD = 0.25
#: the mean of z_B . n (declared plane normal) must be above this (honest: 0.79 and
#: more; the normal upside down: about -0.9)
PLANE_UP_MIN = 0.0
#: an axis "moves" (its gyro scale and sign are checked) above this RMS rate, rad/s
MOVING_RATE = 0.5
#: the xi_ref check needs the flight to cover this much azimuth, rad
MIN_ARC = 1.0
#: the force checks need the motion to ask for this much force on average, N
MIN_FORCE = 0.5
#: the figures are means over a flight: a long log is thinned to about this many
#: samples (windows) per figure, evenly spread, so a check costs the same on any log
MAX_SAMPLES = 20_000
#: windows of the differences, s (rates; accelerations)
RATE_WINDOW_S = 0.02
ACCEL_WINDOW_S = 0.04
_DEG = 180.0 / math.pi
_GF = 1.0 / 9.80665  # a force in kgf over the same force in N
#: a ratio names a unit when it is within this factor of the unit's (honest ratios
#: spread up to 1.3 from 1, and the units' factors are further apart than 1.4^2)
CAUSE_TOL = 1.4
#: known unit factors of a ratio: (factor, cause)
_UNITS = {
    "gyro": ((_DEG, "deg/s"),),
    "thrust": ((1000 * _GF, "grams-force (gf)"), (1000.0, "mN or grams"),
               (_GF, "kgf"), (1 / 1000.0, "kN")),
    "tension": ((_GF, "kgf"), (1000 * _GF, "grams-force (gf)"), (1000.0, "mN")),
    "xi_ref": ((_DEG, "degrees"),),
}


@dataclass(frozen=True)
class Figures:
    """What the checks measured on a log (nan where a check had nothing to measure).

    ``plane_up``: mean ``z_B . n`` of the declared plane; ``x_along``: mean ``x_B .
    p/|p|`` (the quaternion as given); ``gyro_scale``: the gyro over the pose's rates
    (moving axes together), ``gyro_sign``: per axis p, q, r the correlation with the
    pose's rate (nan where the axis does not move); ``thrust_ratio``: commanded over
    needed thrust; ``tension_ratio``: load cell over the radial equation;
    ``xi_ref_ratio``, ``xi_dot_ref_ratio``: reference over flown azimuth advance / rate;
    ``radius_m``: the positions' median distance from the anchor, m, and
    ``radius_range_m`` their 5 and 95 % points.
    """

    plane_up: float = math.nan
    x_along: float = math.nan
    gyro_scale: float = math.nan
    gyro_sign: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    thrust_ratio: float = math.nan
    tension_ratio: float = math.nan
    xi_ref_ratio: float = math.nan
    xi_dot_ref_ratio: float = math.nan
    radius_m: float = math.nan
    radius_range_m: tuple[float, float] = (math.nan, math.nan)


def trusted(meta: dict, trust=()) -> frozenset[str]:
    """The checks to skip: ``trust`` (names of :data:`CHECKS`) and the log's metadata
    ``trust`` (comma- or space-separated); an unknown name is an error."""
    names = [str(n).strip() for n in trust]
    names += [n for n in str(meta.get("trust", "")).replace(",", " ").split() if n]
    for n in names:
        if n not in CHECKS:
            raise ValueError(n)
    return frozenset(names)


# --------------------------------------------------------------------------- geometry


def _plane_normal(alpha_deg: float, gamma_deg: float) -> np.ndarray:
    """``R_IC (0, 0, 1)`` with ``R_IC = Rz(gamma_C) Rx(alpha_C)`` (docs/conventions.md)."""
    a, g = math.radians(alpha_deg), math.radians(gamma_deg)
    return np.array([math.sin(a) * math.sin(g), -math.sin(a) * math.cos(g), math.cos(a)])


def _plane_angles(n) -> tuple[float, float]:
    """``(alpha_c, gamma_c)`` in deg of a plane's unit normal ``n`` (``n[2] >= 0``): the
    inverse of :func:`_plane_normal`; gamma_c 0 for a level plane."""
    alpha = math.degrees(math.acos(min(1.0, float(n[2]))))
    gamma = math.degrees(math.atan2(float(n[0]), -float(n[1]))) if alpha > 1e-9 else 0.0
    return alpha, gamma


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _windows(t: np.ndarray, m: int, gap_factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Start indices k of the windows (k, k + m) that hold no gap, and their lengths, s."""
    n = t.shape[0]
    if n <= m:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    dt = np.diff(t)
    med = float(np.median(dt))
    gap = np.concatenate([[0], np.cumsum(dt > gap_factor * med)])
    k = np.flatnonzero(gap[m:] == gap[:-m])
    return k, t[k + m] - t[k]


def _thin(k: np.ndarray) -> np.ndarray:
    """Every s-th of the indices ``k``: at most about MAX_SAMPLES of them."""
    return k[:: max(1, -(-k.shape[0] // MAX_SAMPLES))]


def _lag(t: np.ndarray, seconds: float) -> int:
    dt = float(np.median(np.diff(t))) if t.shape[0] > 1 else 1.0
    return max(1, int(round(seconds / dt)))


def _accelerations(t, p, gap_factor):
    """Centre indices c and the accelerations (c, 3) from second differences over
    about ACCEL_WINDOW_S, and the velocities there (central differences)."""
    m = _lag(t, ACCEL_WINDOW_S / 2)
    k, _ = _windows(t, 2 * m, gap_factor)
    k = _thin(k)
    if k.size == 0:
        return k, np.zeros((0, 3)), np.zeros((0, 3))
    c = k + m
    h1 = (t[c] - t[k])[:, None]
    h2 = (t[c + m] - t[c])[:, None]
    v1 = (p[c] - p[k]) / h1
    v2 = (p[c + m] - p[c]) / h2
    a = 2 * (v2 - v1) / (h1 + h2)
    v = (p[c + m] - p[k]) / (h1 + h2)
    return c, a, v


def _ratio(num: float, den: float) -> float:
    return num / den if den > 0 else math.nan


# --------------------------------------------------------------------------- figures


def figures(t, p_I, q, T_cmd, optional: dict, meta: dict, *, mass: float | None = None,
            g: float = 9.81, thrust_scale: float = 1.0, gap_factor: float = 1.5) -> Figures:
    """Measure the figures of every check on a whole file's arrays (see the module doc).

    ``mass`` (kg), ``g`` (m/s^2) and ``thrust_scale`` come from the config of the
    analysis; without a mass the force checks (thrust, tension) are not measured.
    """
    t = np.asarray(t, float)
    p = np.asarray(p_I, float)
    n = t.shape[0]
    out: dict = {}
    if n < 3:
        return Figures()
    q = np.asarray(q, float)
    sel = _thin(np.arange(n))
    R = matrix_from_quaternion(q[sel])
    x_B, z_B = R[:, :, 0], R[:, :, 2]
    alpha = math.radians(float(meta["alpha_c_deg"]))
    gamma = math.radians(float(meta["gamma_c_deg"]))
    normal = np.array([math.sin(alpha) * math.sin(gamma), -math.sin(alpha) * math.cos(gamma),
                       math.cos(alpha)])
    out["plane_up"] = float(np.mean(z_B @ normal))

    radius = np.linalg.norm(p[sel], axis=-1)
    out["radius_m"] = float(np.median(radius))
    out["radius_range_m"] = tuple(float(v) for v in np.percentile(radius, [5.0, 95.0]))
    far = radius > 0.5 * float(np.median(radius))
    if np.count_nonzero(far) >= 3:
        e = p[sel][far] / radius[far, None]
        out["x_along"] = float(np.mean(np.einsum("ki,ki->k", x_B[far], e)))
    if optional.get("omega_B") is not None:
        out.update(_gyro_figures(t, q, np.asarray(optional["omega_B"], float), gap_factor))
    if mass is not None:
        out.update(_force_figures(t, p, q, T_cmd, optional.get("tension"), mass, g,
                                  thrust_scale, gap_factor))
    out.update(_reference_figures(t, p, optional, alpha, gamma, gap_factor))
    return Figures(**out)


def _gyro_figures(t, q, w, gap_factor: float) -> dict:
    """``gyro_sign`` and ``gyro_scale``: the gyro ``w`` (n, 3) rad/s against the rates of
    the attitude, R_k^T R_{k+m} over :data:`RATE_WINDOW_S`."""
    out: dict = {}
    m = _lag(t, RATE_WINDOW_S)
    k, h = _windows(t, m, gap_factor)
    if k.size <= 10:
        return out
    bad = ~np.all(np.isfinite(w), -1)
    wz = np.where(bad[:, None], 0.0, w)
    # trapezoid integral of the gyro, so the window mean is a difference
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(
        0.5 * (wz[1:] + wz[:-1]) * np.diff(t)[:, None], 0)])
    nbad = np.concatenate([[0], np.cumsum(bad)])
    ok = (nbad[k + m + 1] - nbad[k]) == 0
    k, h = _thin(k[ok]), h[ok]
    h = t[k + m] - t[k]
    if k.size <= 10:
        return out
    mean_w = (cum[k + m] - cum[k]) / h[:, None]
    dR = np.einsum("kji,kjl->kil", matrix_from_quaternion(q[k]),
                   matrix_from_quaternion(q[k + m]))
    vee = np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0],
                    dR[:, 1, 0] - dR[:, 0, 1]], -1) / 2
    s = np.linalg.norm(vee, axis=-1)
    cos = np.clip((np.trace(dR, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    ang = np.arctan2(s, cos)
    factor = np.where(s > 1e-12, ang / np.where(s > 1e-12, s, 1.0), 1.0)
    pose_w = vee * (factor / h)[:, None]
    moving = np.sqrt(np.mean(pose_w**2, 0)) > MOVING_RATE
    sign = [math.nan] * 3
    for j in np.flatnonzero(moving):
        a, b = mean_w[:, j], pose_w[:, j]
        den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
        sign[j] = float(np.sum(a * b)) / den if den > 0 else 0.0
    out["gyro_sign"] = tuple(sign)
    if np.any(moving):
        a, b = mean_w[:, moving], pose_w[:, moving]
        # |w|^2 / (w . w_pose): the pose's rates are the noisy ones, and noise
        # in the regressor would bias w . w_pose / |w_pose|^2 towards zero
        out["gyro_scale"] = _ratio(float(np.sum(a * a)), abs(float(np.sum(a * b))))
    return out


def _force_figures(t, p, q, T_cmd, tension, mass: float, g: float, thrust_scale: float,
                   gap_factor: float) -> dict:
    """``thrust_ratio`` and ``tension_ratio``: the forces the motion needs (thrust across
    the tether-velocity plane; tension along the tether), from second differences of the
    positions, against the logged thrusts and load cell."""
    out: dict = {}
    c, a, v = _accelerations(t, p, gap_factor)
    if c.size <= 10:
        return out
    e = _unit(p[c])
    z_c = matrix_from_quaternion(q[c])[:, :, 2]
    T_c = np.asarray(T_cmd, float)[c]
    thrust = thrust_scale * np.sum(T_c, -1)
    hold = a - np.array([0.0, 0.0, -g])  # what thrust and tether must supply, /m
    nrm = np.cross(e, v)
    # moving across the tether (m/s), every motor on (a motor at exactly zero is
    # off: the reader's other rules, and compare, deal with those stretches)
    good = (np.linalg.norm(nrm, axis=-1) > 0.5) & np.all(T_c != 0, -1)
    if np.count_nonzero(good) > 10:
        nn = _unit(nrm[good])
        nn *= np.where(nn[:, 2] < 0, -1.0, 1.0)[:, None]
        need = mass * np.einsum("ki,ki->k", hold[good], nn)
        have = thrust[good] * np.einsum("ki,ki->k", z_c[good], nn)
        if float(np.mean(need)) > MIN_FORCE:
            out["thrust_ratio"] = float(np.sum(have) / np.sum(need))
    if tension is not None:
        f = np.asarray(tension, float)[c]
        fin = np.isfinite(f)
        f_need = (thrust * np.einsum("ki,ki->k", z_c, e)
                  - mass * np.einsum("ki,ki->k", hold, e))[fin]
        if fin.sum() > 10 and float(np.mean(f_need)) > MIN_FORCE:
            out["tension_ratio"] = float(np.sum(f[fin]) / np.sum(f_need))
    return out


def _reference_figures(t, p, optional: dict, alpha: float, gamma: float,
                       gap_factor: float) -> dict:
    """``xi_ref_ratio`` and ``xi_dot_ref_ratio``: the reference azimuth (and its rate)
    against the azimuth flown in the declared circle frame (tilt ``alpha``, heading
    ``gamma``, rad)."""
    out: dict = {}
    xi_ref = optional.get("xi_ref")
    xi_dot_ref = optional.get("xi_dot_ref")
    if xi_ref is None and xi_dot_ref is None:
        return out
    ca, sa, cg, sg = math.cos(alpha), math.sin(alpha), math.cos(gamma), math.sin(gamma)
    x_c = cg * p[:, 0] + sg * p[:, 1]
    y_c = ca * (-sg * p[:, 0] + cg * p[:, 1]) + sa * p[:, 2]
    xi = np.arctan2(y_c, x_c)
    k, h = _windows(t, 1, gap_factor)
    dxi = (np.diff(xi)[k] + np.pi) % (2 * np.pi) - np.pi
    if xi_ref is not None:
        r = np.asarray(xi_ref, float)
        dr = (np.diff(r)[k] + np.pi) % (2 * np.pi) - np.pi  # a wrapped xi_ref too
        fin = np.isfinite(dr)
        arc = float(np.sum(dxi[fin]))
        if abs(arc) > MIN_ARC:
            out["xi_ref_ratio"] = float(np.sum(dr[fin])) / arc
    if xi_dot_ref is not None:
        rd = np.asarray(xi_dot_ref, float)
        mid = 0.5 * (rd[k] + rd[k + 1])
        fin = np.isfinite(mid)
        arc = float(np.sum(dxi[fin]))
        if abs(arc) > MIN_ARC:
            out["xi_dot_ref_ratio"] = float(np.sum(mid[fin] * h[fin])) / arc
    return out


# --------------------------------------------------------------------------- the checks


def _cause(check: str, ratio: float) -> str | None:
    for factor, name in _UNITS.get(check, ()):
        if 1 / CAUSE_TOL < ratio / factor < CAUSE_TOL:
            return name
    return None


def _off(ratio: float) -> bool:
    return math.isfinite(ratio) and not (1 / RATIO_TOL <= ratio <= RATIO_TOL)


def _x(ratio: float) -> str:
    digits = 2 if abs(ratio) < 10 else 1 if abs(ratio) < 100 else 0
    return f"{ratio:.{digits}f}x"


def check_log(path, t, p_I, q, T_cmd, optional: dict, meta: dict, *, config=None,
              trust=(), gap_factor: float = 1.5) -> Figures:
    """Refuse a log whose channels contradict each other or the model (module doc).

    ``config``: the analysis config (its vehicle mass, g, thrust scale), for the force
    checks; ``trust``: names of :data:`CHECKS` to skip (with the log's metadata
    ``trust``). Returns the :class:`Figures`; raises :class:`InputError` naming ``path``,
    the column or key and the likely cause.
    """
    try:
        skip = trusted(meta, trust)
    except ValueError as exc:
        raise InputError(path, "metadata trust" if "trust" in meta else "trust",
                         f"unknown check {str(exc)!r} (known: {', '.join(CHECKS)})") from None
    kw = {}
    if config is not None:
        kw = {"mass": config.vehicle.mass, "g": config.g,
              "thrust_scale": _thrust_scale(config)}
    report("check channels")
    fig = figures(t, p_I, q, T_cmd, optional, meta, gap_factor=gap_factor, **kw)

    def fail(check, where, message):
        raise InputError(path, where, f"{message} (if the log is right: --trust {check}, "
                         "docs/flight-log.md)")

    if "radius" not in skip and config is not None:  # first: off the sphere, all else fails
        _check_radius(fig, config, fail)
    if "quaternion" not in skip and fig.x_along < QUAT_ALONG_MIN:
        where = "columns qw, qx, qy, qz"
        qa = np.asarray(q, float)
        alts = {"scalar-last (x, y, z, w)": qa[:, [3, 0, 1, 2]],
                "inertial -> body (conjugated)": qa * np.array([1.0, -1, -1, -1])}
        for name, alt in alts.items():
            f2 = figures(t, p_I, alt, T_cmd, {}, meta, gap_factor=gap_factor)
            if f2.x_along >= QUAT_ALONG_MIN:
                fail("quaternion", where,
                     f"look {name}: read so, the body x axis points along the tether (mean "
                     f"cosine {f2.x_along:.2f}); read as the format's (w, x, y, z), body -> "
                     f"inertial, it does not ({fig.x_along:.2f})")
        fail("quaternion", where,
             f"the body x axis they give points along the tether by a mean cosine of "
             f"{fig.x_along:.2f} (x_B points outward along the tether): are they (w, x, y, "
             "z), Hamilton, body -> inertial?")
    if "plane" not in skip and fig.plane_up < PLANE_UP_MIN:
        alpha, gamma = float(meta["alpha_c_deg"]), float(meta["gamma_c_deg"])
        a2, g2 = _plane_angles(-_plane_normal(alpha, gamma))
        g2 += 0.0  # no "-0"
        same = f"alpha_c_deg = {a2:.6g}" + (f", gamma_c_deg = {g2:.6g}" if a2 > 1e-6 else
                                            ", gamma_c_deg = 0")
        fail("plane", "metadata alpha_c_deg",
             f"the declared plane's normal (alpha_c_deg = {alpha:g}, gamma_c_deg = {gamma:g}) "
             f"points away from the thrust (mean z_B . n = {fig.plane_up:.2f}): the normal is "
             f"upside down; the same plane with the normal on the thrust's side is {same}")
    if "gyro" not in skip:
        if _off(fig.gyro_scale):
            cause = _cause("gyro", fig.gyro_scale)
            what = f"look like {cause}" if cause else "do not match the attitude"
            fail("gyro", "columns p, q, r",
                 f"{what}: {_x(fig.gyro_scale)} the rates from the pose")
        for j, name in enumerate("pqr"):
            if fig.gyro_sign[j] < -0.5:
                fail("gyro", f"column {name}",
                     f"turns against the attitude (correlation {fig.gyro_sign[j]:.2f} with the "
                     "rate from the pose): sign flipped (FRD body axes read as FLU?)")
    if "thrust" not in skip and _off(fig.thrust_ratio):
        cause = _cause("thrust", fig.thrust_ratio)
        if fig.thrust_ratio < 0:
            cause = "negated (thrust along -z_B, NED/FRD?)"
        m = config.vehicle.mass
        fail("thrust", "columns T1, T2, T3, T4",
             (f"look {cause}: " if fig.thrust_ratio < 0 else
              f"look like {cause}: " if cause else "")
             + f"{_x(fig.thrust_ratio)} the thrust the motion needs with vehicle.mass = "
             f"{m:g} kg of {config.source}"
             + ("" if cause else ": a log of another vehicle, or thrust in other units?"))
    if "tension" not in skip and math.isfinite(fig.tension_ratio):
        r = fig.tension_ratio
        if -RATIO_TOL <= r <= -1 / RATIO_TOL:
            fail("tension", "column tension",
                 f"looks negated: {_x(r)} the tension the radial equation gives (the load cell "
                 "must read the pull, positive)")
        if _off(r):
            cause = _cause("tension", r)
            fail("tension", "column tension",
                 (f"looks like {cause}: " if cause else "")
                 + f"{_x(r)} the tension the radial equation gives with vehicle.mass = "
                 f"{config.vehicle.mass:g} kg of {config.source}")
    if "xi_ref" not in skip:
        for col, r in (("xi_ref", fig.xi_ref_ratio), ("xi_dot_ref", fig.xi_dot_ref_ratio)):
            if _off(r):
                cause = _cause("xi_ref", r)
                what = (f"looks like {cause}" if cause else
                        "runs against the flown azimuth" if r < 0 else "does not match the "
                        "flown azimuth")
                flown = "azimuth" if col == "xi_ref" else "azimuth rate"
                fail("xi_ref", f"column {col}",
                     f"{what}: {_x(r)} the {flown} flown in the declared circle plane")
    return fig


def _check_radius(fig: Figures, config, fail) -> None:
    """The ``radius`` check: the positions on the sphere the config's tether holds."""
    r = config.tether.length + config.tether.attachment_offset
    lo, hi = fig.radius_range_m
    if not (r / RADIUS_TOL <= fig.radius_m <= r * RADIUS_TOL) or hi - lo > RADIUS_SPREAD * r:
        fail("radius", "columns x, y, z",
             f"the positions are {fig.radius_m:.3g} m from the anchor (5-95 %: {lo:.3g}-"
             f"{hi:.3g} m), where the tether holds the vehicle {r:g} m from it "
             f"(tether.length + attachment_offset of {config.source}): not a tethered "
             "flight of this vehicle, or the anchor (the origin) is elsewhere")


def thrust_units(path, arrays: dict, optional: dict, meta: dict, *, config=None, trust=(),
                 gap_factor: float = 1.5) -> None:
    """For thrust beyond the format's range (|T| > 1e3 N): raise the ``thrust`` check's
    error when the ratio to the needed thrust names a unit (mN, gf: the range error
    would hide the cause); return otherwise (the caller raises the range error)."""
    if config is None:
        return
    try:
        if "thrust" in trusted(meta, trust):
            return
    except ValueError:
        return
    with np.errstate(all="ignore"):
        fig = figures(arrays["t"], arrays["p_I"], arrays["q"], arrays["T_cmd"], {}, meta,
                      mass=config.vehicle.mass, g=config.g,
                      thrust_scale=_thrust_scale(config), gap_factor=gap_factor)
    if _off(fig.thrust_ratio) and _cause("thrust", fig.thrust_ratio):
        check_log(path, arrays["t"], arrays["p_I"], arrays["q"], arrays["T_cmd"], {}, meta,
                  config=config, trust=[c for c in CHECKS if c != "thrust"],
                  gap_factor=gap_factor)


def _thrust_scale(config) -> float:
    for spec in config.effects:
        if spec.name == "thrust_scale":
            return float(spec.param_dict().get("k_T", 1.0))
    return 1.0
