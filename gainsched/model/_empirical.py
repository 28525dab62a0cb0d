"""The empirical effects (``empirical = True``): laws with no physical model behind them,
which ``gainsched diagnose`` fits only when no physical candidate explains the residual
(docs/model-vs-measurement.md), one per variable where-it-fails locates: a Fourier
series in azimuth, power series in flight time and airspeed, a thrust curve per motor and
a force from a fixed inertial direction. Re-exported by :mod:`.effects` (the registry).
"""

from __future__ import annotations

import math

import numpy as np

from ._base import (
    _EPS2,
    Effect,
    Kinematics,
    Param,
    Refit,
    _FlightTime,
    circle_to_inertial,
    mirrored_motors,
    norm,
    wind_in_circle_frame,
)


def fundamental_azimuth(kin: Kinematics):
    """``(cos xi_f, sin xi_f)`` of the COG's azimuth mapped to the table's stored domain
    (tilt >= 0, positive circulation) by the symmetries S1 and S2 (docs/symmetry.md),
    each shape (...); complex-step safe (no ``arctan2``; the maps are decided on real parts).

    The azimuth is that of the COG in C, ``xi = atan2(p_y, p_x)``; the direction of
    circulation is the sign of ``(p_C x v_C)_z``. S1 (negative tilt) turns it by pi, S2
    (negative circulation) mirrors it to ``pi - xi``: the same maps as
    :func:`gainsched.model.symmetry.fundamental_from_query`, so an effect of ``xi_f``
    keeps both symmetries by construction.
    """
    x, y = kin.p_C[..., 0], kin.p_C[..., 1]
    rho = np.sqrt(x * x + y * y + _EPS2)
    c, s = x / rho, y / rho
    neg_tilt = np.real(np.asarray(kin.alpha)) < 0
    c, s = np.where(neg_tilt, -c, c), np.where(neg_tilt, -s, s)
    backwards = np.real(x * kin.v_C[..., 1] - y * kin.v_C[..., 0]) < 0
    return np.where(backwards, -c, c), s


#: harmonics of :class:`ThrustAzimuth`
AZIMUTH_HARMONICS = 8


class ThrustAzimuth(Effect):
    """Empirical thrust factor in azimuth: every motor's thrust times
    ``1 + a0 + sum_k (a_k cos k xi + b_k sin k xi)``, k = 1..8, with xi the azimuth of
    the COG in C mapped to tilt >= 0 and positive circulation (:func:`fundamental_azimuth`).

    No physical model behind it: a Fourier series for what diagnose finds locked to the
    azimuth when no effect of the library explains it (an own wake, a draft in the hall).
    Identified on the flown circles (one direction, tilts >= 0), it is extended to the
    other quadrants by the table's symmetries.
    """

    kind = "thrust_azimuth"
    params = (
        Param("a0", "-", 0.0, -0.5, 0.5, "mean relative thrust change"),
        *(Param(f"{ab}{k}", "-", 0.0, -0.5, 0.5, f"{'cos' if ab == 'a' else 'sin'} {k} xi "
                "coefficient") for k in range(1, AZIMUTH_HARMONICS + 1) for ab in "ab"),
    )
    empirical = True
    fits = (Refit("thrust_azimuth", tuple(p.name for p in params),
                  "empirical thrust factor, a Fourier series in azimuth",
                  orders=tuple(1 + 2 * k for k in range(1, AZIMUTH_HARMONICS + 1))),)

    def factor(self, kin: Kinematics):
        """The thrust factor, shape (...)."""
        c1, s1 = fundamental_azimuth(kin)
        f = 1.0 + self.a0 + 0 * c1
        c, s = c1, s1
        for k in range(1, AZIMUTH_HARMONICS + 1):
            a, b = self.values[f"a{k}"], self.values[f"b{k}"]
            if a or b:
                f = f + a * c + b * s
            c, s = c * c1 - s * s1, s * c1 + c * s1  # cos, sin of (k + 1) xi
        return f

    def modify_thrust(self, T, kin, x):
        return T * self.factor(kin)[..., None]

    def law(self) -> str:
        xi = np.deg2rad(np.arange(0.0, 360.0, 0.5))
        kin = Kinematics(np.eye(3), np.stack([-np.sin(xi), np.cos(xi), 0 * xi], -1),
                         np.zeros(3), np.stack([np.cos(xi), np.sin(xi), 0 * xi], -1), 0.0)
        d = self.factor(kin) - 1.0
        lo, hi = int(np.argmin(d)), int(np.argmax(d))
        used = [k for k in range(1, AZIMUTH_HARMONICS + 1)
                if self.values[f"a{k}"] or self.values[f"b{k}"]]
        return (f"thrust x (1 + Fourier series in azimuth, {max(used, default=0)} "
                f"harmonics): {d[lo]:+.1%} at {np.rad2deg(xi[lo]):.0f} deg, "
                f"{d[hi]:+.1%} at {np.rad2deg(xi[hi]):.0f} deg, mean {self.a0:+.1%}")


def power_series(x, coefficients):
    """``sum_k c_k x^k``, k = 0, 1, ..., shape of ``x`` (the empirical series in time and
    airspeed); term by term with the powers built up (complex-step safe)."""
    f, xk = coefficients[0] + 0 * x, 1.0
    for c in coefficients[1:]:
        xk = xk * x
        f = f + c * xk
    return f


#: highest power of the flight time in :class:`ThrustTimeSeries`
TIME_ORDER = 3
#: the time unit of its terms, s (coefficients read as relative change per minute)
TIME_UNIT_S = 60.0


class ThrustTimeSeries(_FlightTime):
    """Empirical thrust factor in flight time: every motor's thrust times
    ``1 + sum_k c_k (t / 60 s)^k``, k = 1..3, with t the flight time (the state of
    :class:`_FlightTime`).

    No physical model behind it: a power series for a residual that drifts with time
    when no effect of the library explains it (a battery whose sag is not linear, a
    motor warming up, a draft that builds up). Diagnose chooses its order held out. A
    table cannot hold it (it changes with time): simulate and diagnose with it.
    """

    kind = "thrust_time_series"
    params = tuple(Param(f"c{k}", "-", 0.0, -2.0, 2.0,
                         f"coefficient of (t / {TIME_UNIT_S:g} s)^{k}")
                   for k in range(1, TIME_ORDER + 1))
    empirical = True
    fits = (Refit("thrust_time_series", tuple(p.name for p in params),
                  "empirical thrust factor, a power series in flight time",
                  orders=tuple(range(1, TIME_ORDER + 1))),)

    def factor(self, t):
        """The thrust factor at flight time ``t`` (s), shape of ``t``."""
        return power_series(np.asarray(t) / TIME_UNIT_S,
                            [1.0, *(self.values[f"c{k}"] for k in range(1, TIME_ORDER + 1))])

    def modify_thrust(self, T, kin, x):
        return T * self.factor(x[..., 0])[..., None]

    def law(self) -> str:
        used = [k for k in range(1, TIME_ORDER + 1) if self.values[f"c{k}"]]
        terms = " ".join(f"{self.values[f'c{k}']:+.3g} (t/min)" + (f"^{k}" if k > 1 else "")
                         for k in used)
        return (f"thrust x (1 {terms}): {self.c1 / TIME_UNIT_S:+.2%} per second at the start "
                f"of a flight, {self.factor(10.0) - 1:+.1%} after 10 s")


class ThrustMotorCurve(Effect):
    """Empirical thrust curve per motor: motor ``i`` gives ``1 + a_i + b_i T_i`` times
    its commanded thrust ``T_i`` (N), and its reaction torque with it.

    No physical model behind it: each motor's static-test map corrected by a line in its
    own thrust, for a body-torque residual that follows one motor when no effect of the
    library explains it. Its first order (``a_i`` only) is one constant factor per
    motor. Unequal motors break the direction mirror S2: the mirror image of the vehicle
    swaps them (:meth:`mirror_values`; docs/symmetry.md).
    """

    kind = "thrust_motor"
    params = (*(Param(f"a{i}", "-", 0.0, -0.5, 0.5, f"motor {i}: relative thrust change")
                for i in range(1, 5)),
              *(Param(f"b{i}", "1/N", 0.0, -0.1, 0.1,
                      f"motor {i}: relative thrust change per N of its thrust")
                for i in range(1, 5)))
    empirical = True
    fits = (Refit("thrust_motor", tuple(p.name for p in params),
                  "empirical thrust curve per motor, 1 + a_i + b_i T_i", orders=(4, 8),
                  contains=("motor_efficiency", "thrust_scale")),)

    def mirror_values(self) -> dict[str, float]:
        return mirrored_motors(self.values, "a", "b")

    def modify_thrust(self, T, kin, x):
        a = np.array([self.values[f"a{i}"] for i in range(1, 5)])
        b = np.array([self.values[f"b{i}"] for i in range(1, 5)])
        return T * (1.0 + a + b * T)

    def law(self) -> str:
        a = np.array([self.values[f"a{i}"] for i in range(1, 5)])
        b = np.array([self.values[f"b{i}"] for i in range(1, 5)])
        i = int(np.argmax(np.abs(a - np.median(a))))
        others = ", ".join(f"motor {k + 1} {a[k]:+.1%}" for k in range(4) if k != i)
        slope = (f"; per N of its thrust: {', '.join(f'{v:+.2%}' for v in b)}"
                 if np.any(b) else "")
        return f"motor {i + 1} thrust {a[i]:+.1%} ({others}){slope}"


#: the airspeed unit of the empirical forces' speed terms (:class:`ForceAirspeed`,
#: :class:`ForceHorizontal`), m/s (the coefficients read as newtons at that airspeed)
FORCE_SPEED_UNIT = 10.0
#: highest power of the airspeed in :class:`ForceAirspeed`
AIRSPEED_ORDER = 3


class ForceAirspeed(Effect):
    """Empirical force against the air velocity: ``F = -(sum_k f_k s^k) u``, k = 0..3, N,
    with ``s = |v_air| / 10 m/s`` and ``u`` the unit vector of the air velocity.

    No physical model behind it: a power series in the airspeed for a residual along the
    track that grows with speed when no effect of the library explains it (a body whose
    drag is not the paper's law, eq. 10, a fairing, a payload). Its terms k = 1, 2 are
    the paper's drag, ``f1 = 10 m/s mu1``, ``f2 = (10 m/s)^2 mu2``. Diagnose chooses its
    order held out. It depends on the airspeed alone, so it keeps the table's symmetries
    and a table can hold it.
    """

    kind = "force_airspeed"
    params = tuple(Param(f"f{k}", "N", 0.0, -20.0, 20.0,
                         f"force against the air velocity per (airspeed / "
                         f"{FORCE_SPEED_UNIT:g} m/s)^{k}")
                   for k in range(AIRSPEED_ORDER + 1))
    empirical = True
    fits = (Refit("force_airspeed", tuple(p.name for p in params),
                  "empirical force against the air velocity, a power series in airspeed",
                  orders=tuple(range(1, AIRSPEED_ORDER + 2))),)

    def magnitude(self, speed):
        """The force's size at airspeed ``speed`` (m/s), N, shape of ``speed``."""
        return power_series(np.asarray(speed) / FORCE_SPEED_UNIT,
                            [self.values[f"f{k}"] for k in range(AIRSPEED_ORDER + 1)])

    def wrench(self, T, kin):
        v = kin.v_air_C
        speed = norm(v)
        F = -(self.magnitude(speed) / speed)[..., None] * v
        return F, np.zeros_like(F)

    def law(self) -> str:
        used = [k for k in range(AIRSPEED_ORDER + 1) if self.values[f"f{k}"]]
        terms = " ".join(f"{self.values[f'f{k}']:+.3g}" + ("" if k == 0 else " s" if k == 1
                                                           else f" s^{k}") for k in used)
        return (f"force against the air velocity ({terms}) N, s = airspeed / "
                f"{FORCE_SPEED_UNIT:g} m/s: {self.magnitude(5.0):.3g} N at 5 m/s, "
                f"{self.magnitude(15.0):.3g} N at 15 m/s")


_EN = {"e": "east", "n": "north"}


class ForceHorizontal(Effect):
    """Empirical horizontal force at the COG fixed in I:
    ``F_I = (e0 + e1 s, n0 + n1 s, 0) + s (u . (e2, n2, 0)) u`` N, (east, north, up),
    with ``s = |v_air| / 10 m/s`` the airspeed in units of 10 m/s and ``u`` the unit
    vector of the air velocity, turned into each flight's circle frame by
    ``R_IC = Rz(gamma) Rx(alpha)`` (docs/conventions.md).

    No physical model behind it: a push from one inertial direction that may grow with
    speed, for a residual locked to the inertial azimuth when no effect of the library
    explains it (a wind, a draft in the hall, a tether that drags sideways). On a level
    circle it is the first harmonic of the along-track and radial residual in the
    inertial azimuth; on tilted circles it has the direction the flights share. Diagnose
    chooses its order held out: a constant force, one growing with speed, and one along
    the velocity that grows with its component along ``(e2, n2)`` (what a drag
    quadratic in the airspeed adds in a wind, to first order in the wind). Like
    the wind it comes from an inertial direction, so no table can hold it (no heading
    axis; the symmetries S1 and S2 break): simulate and diagnose with it.
    """

    kind = "force_horizontal"
    params = (
        Param("e0", "N", 0.0, -20.0, 20.0, "force towards east"),
        Param("n0", "N", 0.0, -20.0, 20.0, "force towards north"),
        Param("e1", "N", 0.0, -20.0, 20.0,
              f"force towards east per {FORCE_SPEED_UNIT:g} m/s of airspeed"),
        Param("n1", "N", 0.0, -20.0, 20.0,
              f"force towards north per {FORCE_SPEED_UNIT:g} m/s of airspeed"),
        Param("e2", "N", 0.0, -20.0, 20.0, f"force along the velocity per "
              f"{FORCE_SPEED_UNIT:g} m/s of airspeed, per unit of its east component"),
        Param("n2", "N", 0.0, -20.0, 20.0, f"force along the velocity per "
              f"{FORCE_SPEED_UNIT:g} m/s of airspeed, per unit of its north component"),
        Param("d0", "N", 0.0, -20.0, 20.0, "force against the air velocity, whatever its "
              "direction"),
        *(Param(f"q{a}{b}", "N", 0.0, -20.0, 20.0, f"force towards {_EN[a]} per unit of the "
                f"air velocity's {_EN[b]} direction component") for a in "en" for b in "en"),
    )
    empirical = True
    table_refusal = ("comes from an inertial direction, which breaks the tilt-sign and "
                     "direction symmetries (S1, S2) the table's query maps rely on, and a "
                     "table has no heading axis")
    fits = (Refit("force_horizontal", tuple(p.name for p in params),
                  "empirical horizontal force from a fixed inertial direction",
                  orders=(2, 4, 6, 7, 11)),)

    def force_I(self, kin: Kinematics):
        """The force in I, shape (..., 3), N."""
        v = kin.v_air_C
        speed = norm(v)
        s = speed / FORCE_SPEED_UNIT
        u = circle_to_inertial(v / speed[..., None], kin.alpha, kin.gamma)  # direction in I
        ue, un = u[..., 0], u[..., 1]
        along = s * (self.e2 * ue + self.n2 * un) - self.d0
        east = self.e0 + self.e1 * s + self.qee * ue + self.qen * un + along * ue
        north = self.n0 + self.n1 * s + self.qne * ue + self.qnn * un + along * un
        return np.stack(np.broadcast_arrays(east, north, along * u[..., 2]), -1)

    def wrench(self, T, kin):
        F = wind_in_circle_frame(self.force_I(kin), kin.alpha, kin.gamma)
        return F, np.zeros_like(F)

    def law(self) -> str:
        def towards(e, n):
            return (f"{math.hypot(e, n):.3g} N towards "
                    f"{math.degrees(math.atan2(e, n)) % 360.0:.0f} deg")
        grow = (f", growing by {towards(self.e1, self.n1)} per {FORCE_SPEED_UNIT:g} m/s"
                if self.e1 or self.n1 else "")
        return f"horizontal force {towards(self.e0, self.n0)} (from north, clockwise){grow}"


#: the tension unit of :class:`TetherStretchSeries`' terms, N (its coefficients read as
#: metres of stretch at that tension)
TENSION_UNIT_N = 10.0
#: highest power of the tension in :class:`TetherStretchSeries`
TENSION_ORDER = 3
#: how far (m) a stretch law may fall as the tension rises inside the flown tensions
#: before it is no tether's (at least; 5 % of its rise over them when that is more):
#: about the motion-capture noise of one position sample
STRETCH_FALL_TOL_M = 5e-4


class TetherStretchSeries(Effect):
    """Empirical tether stretch in tension: the tether is longer than its ``[tether]
    length`` by ``sum_k s_k (f / 10 N)^k`` m, k = 1..3, with f the tether tension (the
    load cell's, or the radial equation's without one), on top of the stretch of the
    ``[tether] link``.

    No physical model behind it: a power series for a stretch residual that follows the
    tension when no effect of the library explains it: a tether whose stretch is not
    linear (a braided line that takes up its slack and stiffens, an elastomer that
    softens), a knot or a spring in the line. Its first term is the static part of the
    linear elasticity, ``s1 = 10 N / k``: it contains the ``tether_elasticity`` candidate
    (``Refit.contains``; exactly at no damping, and to within the damping's lag of c / k
    otherwise), so diagnose prefers the physical elasticity when it fits about as well.
    Diagnose chooses its order held out. A stretch law is monotone: one that
    falls as the tension rises over the flown tensions (by more than
    :data:`STRETCH_FALL_TOL_M`, or 5 % of its rise) is no tether's and is refused.

    It changes no force or torque of the model, only the predicted anchor-attachment
    distance (the comparison's stretch axis), and a function of the tension is the same
    in every quadrant (S1, S2 hold): a table can hold it, as it holds the elastic links,
    built on the rigid tether of paper Sec. II. The simulator's plant flies the
    ``[tether] link``; this law is not flown.
    """

    kind = "tether_stretch"
    params = tuple(Param(f"s{k}", "m", 0.0, -0.5, 0.5,
                         f"stretch per (tension / {TENSION_UNIT_N:g} N)^{k}", fit=(-0.1, 0.1))
                   for k in range(1, TENSION_ORDER + 1))
    empirical = True
    stretch_only = True
    fits = (Refit("tether_stretch", tuple(p.name for p in params),
                  "empirical tether stretch, a power series in tension",
                  orders=tuple(range(1, TENSION_ORDER + 1)),
                  contains=("tether_elasticity",)),)

    def stretch(self, tension):
        f = np.asarray(tension)
        f = np.where(np.real(f) > 0, f, 0.0)  # a slack tether does not stretch
        return power_series(f / TENSION_UNIT_N,
                            [0.0, *(self.values[f"s{k}"] for k in range(1, TENSION_ORDER + 1))])

    def drag_coefficients(self):
        # no force at all: the zero drag, so the closed-form nominal (and the firmware's
        # compiled feed-forward) still covers a model with it, the same bits as without
        return 0.0, 0.0

    def implausible_tension(self, tension_range) -> str:
        lo, hi = (max(float(x), 0.0) for x in tension_range)
        f = np.linspace(lo, hi, 129)
        s = self.stretch(f)
        fall = np.maximum.accumulate(s) - s  # how far it has fallen below its running peak
        k = int(np.argmax(fall))
        tol = max(STRETCH_FALL_TOL_M, 0.05 * float(np.ptp(s)))
        if fall[k] <= tol:
            return ""
        return (f"tether_stretch falls by {1e3 * fall[k]:.2g} mm as the tension rises to "
                f"{f[k]:.1f} N inside the flown {lo:.1f}-{hi:.1f} N (no tether shortens when "
                "pulled harder)")

    def law(self) -> str:
        used = [k for k in range(1, TENSION_ORDER + 1) if self.values[f"s{k}"]]
        terms = " ".join(f"{1e3 * self.values[f's{k}']:+.3g} (f/{TENSION_UNIT_N:g} N)"
                         + (f"^{k}" if k > 1 else "") for k in used)
        at = ", ".join(f"{1e3 * float(self.stretch(f)):.3g} mm at {f:g} N" for f in (10.0, 40.0))
        return f"tether stretch ({terms or '0'}) mm, f the tension: {at}"
