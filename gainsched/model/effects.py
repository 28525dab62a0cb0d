"""Effects: the one place physics is added to the plant (docs/architecture.md).

An effect is a small frozen object with named parameters (units, defaults,
bounds). The same objects serve the nominal trim, the linearisation, the
simulators and the model-vs-measurement fits, so adding an effect changes all
of them at once. An effect may

- modify the per-motor thrust (``modify_thrust``: thrust scale, thrust change
  with airspeed, the output of a motor-lag filter),
- add a force at the COG (in C) and a torque (in B) (``wrench``: body drag,
  rotor drag),
- carry extra states (``n_states``, ``state_derivative``: motor lag),
- move the air (``air_velocity``: a steady wind); every airspeed-dependent effect
  sees the COG velocity relative to the air, :attr:`Kinematics.v_air_C`,
- take its states from a flight log's column (``log_channel``, ``states_from_log``:
  the battery voltage ``vbat`` of :class:`ThrustVoltage`) where a simulation integrates
  them.

Evaluation order inside the model: commanded thrust -> stateful effects ->
thrust modifiers (config order) -> wrench effects, which see the final thrust.
All hooks broadcast over leading batch dimensions and are complex-step safe.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from .._vec import mv
from ._base import (
    Effect,
    Kinematics,
    Param,
    Refit,
    _FlightTime,
    circle_to_inertial,
    mirrored_motors,
    norm,
    tether_stretch_of,
    wind_in_circle_frame,
)
from ._empirical import (
    AIRSPEED_ORDER,
    AZIMUTH_HARMONICS,
    FORCE_SPEED_UNIT,
    STRETCH_FALL_TOL_M,
    TENSION_ORDER,
    TENSION_UNIT_N,
    TIME_ORDER,
    TIME_UNIT_S,
    ForceAirspeed,
    ForceHorizontal,
    TetherStretchSeries,
    ThrustAzimuth,
    ThrustMotorCurve,
    ThrustTimeSeries,
    fundamental_azimuth,
    power_series,  # noqa: F401  (the series helper, importable here as before)
)
from .momentum import induced_velocity

__all__ = [
    "Param",
    "Refit",
    "Kinematics",
    "Effect",
    "Drag",
    "polynomial_drag",
    "RotorDrag",
    "ThrustScale",
    "MotorEfficiency",
    "ThrustTime",
    "ThrustVoltage",
    "ThrustPolynomial",
    "ThrustMomentum",
    "MotorLag",
    "CogOffset",
    "ThrustAzimuth",
    "ThrustTimeSeries",
    "ThrustMotorCurve",
    "TIME_ORDER",
    "TIME_UNIT_S",
    "Wind",
    "ForceHorizontal",
    "ForceAirspeed",
    "FORCE_SPEED_UNIT",
    "AIRSPEED_ORDER",
    "TetherStretchSeries",
    "TENSION_UNIT_N",
    "TENSION_ORDER",
    "STRETCH_FALL_TOL_M",
    "tether_stretch_of",
    "wind_in_circle_frame",
    "circle_to_inertial",
    "fundamental_azimuth",
    "AZIMUTH_HARMONICS",
    "EFFECTS",
    "registered_effect",
    "registered_effects",
    "registered_effects_context",
    "BUILTIN_KINDS",
    "effects_from_specs",
    "air_velocity",
    "cog_offset",
    "norm",
]

def polynomial_drag(mu1: float, mu2: float):
    """The tangential drag of ``F = -(mu1 + mu2 |v|) v`` (paper eq. 10) for the closed form.

    Returns ``D(v) -> (D, dD/dv, d2D/dv2)``, N, N s/m, N s^2/m^2, for the signed speed
    ``v`` (m/s, any shape).
    """

    def D(v):
        a = np.abs(v)
        return (mu1 + mu2 * a) * v, mu1 + 2 * mu2 * a, 2 * mu2 * np.sign(v)

    return D



class Drag(Effect):
    """Body drag at the COG, ``F = -(mu1 |v| + mu2 |v|^2) v/|v|`` (paper eq. 10)."""

    kind = "drag"
    params = (
        Param("mu1", "N s/m", 0.0, 0.0, 10.0, "linear drag coefficient", fit=(0.0, 2.0)),
        Param("mu2", "N s^2/m^2", 0.0, 0.0, 1.0, "quadratic drag coefficient", fit=(0.0, 0.05)),
    )
    fits = (
        Refit("drag_linear", ("mu1",), "linear body drag mu1 |v| (paper eq. 10)"),
        Refit("drag_quadratic", ("mu2",), "quadratic body drag mu2 |v|^2 (paper eq. 10)"),
        Refit("drag", ("mu1", "mu2"), "body drag, mu1 and mu2 together (paper eq. 10, the "
              "joint fit of Fig. 6)"),
    )

    def wrench(self, T, kin):
        v = kin.v_air_C
        speed = norm(v)
        F = -(self.mu1 + self.mu2 * speed)[..., None] * v
        return F, np.zeros_like(F)

    def drag_coefficients(self):
        return float(self.mu1), float(self.mu2)


class RotorDrag(Effect):
    """Rotor (induced) drag: ``F_B = -k_rd T_C (v_Bx, v_By, 0)``, in the rotor plane,
    proportional to the collective thrust and the in-plane airspeed (blade flapping)."""

    kind = "rotor_drag"
    params = (Param("k_rd", "s/m", 0.0, 0.0, 0.2, "rotor drag per newton of thrust per m/s"),)
    fits = (Refit("rotor_drag", ("k_rd",),
                  "rotor drag: thrust x in-plane airspeed (with its normal-axis signature)"),)

    def wrench(self, T, kin):
        T_C = T.sum(-1)
        v_B = kin.v_air_B
        F_B = -self.k_rd * T_C[..., None] * (v_B * np.array([1.0, 1.0, 0.0]))
        F_C = mv(kin.R_CB, F_B)
        return F_C, np.zeros_like(F_C)


class ThrustScale(Effect):
    """Thrust scale: the real thrust is ``k_T`` times the static-test map (miscalibration)."""

    kind = "thrust_scale"
    params = (Param("k_T", "-", 1.0, 0.5, 1.5, "real / commanded thrust"),)
    fits = (Refit("thrust_scale", ("k_T",),
                  "thrust scale: the static-test map is off by a factor"),)

    def modify_thrust(self, T, kin, x):
        return self.k_T * T


class MotorEfficiency(Effect):
    """One efficiency per motor: motor ``i`` gives ``eta_i`` times its commanded thrust,
    and its reaction torque with it (``kappa eta_i T_i``: the same rotor at another
    operating point; a damaged or worn propeller, a weak ESC or motor).

    ``thrust_scale`` is the case of four equal efficiencies. Unequal ones break the
    direction mirror S2 (the mirror image of the vehicle swaps motors 1 <-> 4 and
    2 <-> 3; docs/symmetry.md): its reversed circles are the image's forward ones
    (:meth:`mirror_values`).
    """

    kind = "motor_efficiency"
    params = tuple(Param(f"eta{i}", "-", 1.0, 0.3, 1.5, f"motor {i}: real / commanded thrust",
                         fit=(0.5, 1.3)) for i in range(1, 5))
    fits = (Refit("motor_efficiency", tuple(f"eta{i}" for i in range(1, 5)),
                  "one efficiency per motor: thrust and reaction torque (the body torques "
                  "tell the motors apart)", contains=("thrust_scale",)),)

    def mirror_values(self) -> dict[str, float]:
        return mirrored_motors(self.values, "eta")

    def factors(self) -> np.ndarray:
        """``(eta1, eta2, eta3, eta4)``, shape (4,)."""
        return np.array([self.values[f"eta{i}"] for i in range(1, 5)])

    def modify_thrust(self, T, kin, x):
        return T * self.factors()

    def law(self) -> str:
        eta = self.factors()
        i = int(np.argmax(np.abs(eta - np.median(eta))))
        others = ", ".join(f"motor {k + 1} {eta[k] - 1:+.1%}" for k in range(4) if k != i)
        return (f"motor {i + 1} gives {eta[i] - 1:+.1%} thrust and reaction torque "
                f"({others})")


class Wind(Effect):
    """A steady, uniform wind: the air moves at ``(east, north, 0)`` m/s in I (ENU, the
    axes of docs/conventions.md and the flight logs), and every airspeed-dependent effect
    (``drag``, ``rotor_drag``, ``thrust_airspeed``, ``thrust_momentum``) sees the COG
    velocity relative to the air, ``v_C - R_IC^T wind_I`` (:attr:`Kinematics.v_air_C`),
    instead of the ground velocity.

    The wind has no force of its own: alone (no drag in the model) it changes nothing.
    It is tied to an inertial direction, so the circle's heading ``gamma_C`` matters,
    the tilt-sign and direction symmetries of the table (S1, S2; docs/symmetry.md) do
    not hold, and the table has no heading axis: simulate and diagnose with it, build
    tables without it. A flight log's ``gamma_c_deg`` (docs/flight-log.md) turns the
    wind into each flight's circle frame. The paper's drag (eq. 10) and thrust change
    (eq. 29) are laws of the airspeed, which its indoor flights equate with the ground
    speed; M. Tognon and A. Franchi, "Theory and Applications for Control of Aerial
    Robots in Physical Interaction Through Tethers", Springer, 2021, sec. 3.3.1, name
    strong wind as where drag and blade flapping must be considered.
    """

    kind = "wind"
    params = (
        Param("east", "m/s", 0.0, -15.0, 15.0, "wind velocity towards east (x of I)",
              fit=(-10.0, 10.0)),
        Param("north", "m/s", 0.0, -15.0, 15.0, "wind velocity towards north (y of I)",
              fit=(-10.0, 10.0)),
    )
    table_refusal = ("blows from an inertial direction, which breaks the tilt-sign and "
                     "direction symmetries (S1, S2) the table's query maps rely on, and a "
                     "table has no heading axis")
    fits = (Refit("wind", ("east", "north"), "steady wind: the airspeed is the ground "
                  "velocity minus the wind (needs drag or another airspeed effect)",
                  affine=False),)

    def air_velocity(self):
        return np.array([self.east, self.north, 0.0])

    def law(self) -> str:
        speed = math.hypot(self.east, self.north)
        # the direction the wind comes from, clockwise from north (meteorological)
        frm = math.degrees(math.atan2(-self.east, -self.north)) % 360.0
        return (f"wind {speed:.3g} m/s from {frm:.0f} deg (east {self.east:+.3g}, "
                f"north {self.north:+.3g} m/s)")


class ThrustTime(_FlightTime):
    """Thrust that declines with flight time: ``T *= 1 - rate t`` (the battery sagging
    while it discharges: the commands are mapped to thrust at a fresh battery's voltage).

    The flight time is the effect's one state (:class:`_FlightTime`): start the log when
    the battery is connected, or when it was charged. The thrust changes with time, so a
    table cannot hold it: simulate and diagnose with it, build tables without it (or with
    a battery of a known state).
    """

    kind = "thrust_time"
    params = (Param("rate", "1/s", 0.0, -0.05, 0.05, "relative thrust loss per second",
                    fit=(-0.02, 0.02)),)
    fits = (Refit("thrust_time", ("rate",), "thrust that declines with flight time "
                  "(battery sag)"),)

    def modify_thrust(self, T, kin, x):
        return T * (1.0 - self.rate * x[..., 0:1])

    def law(self) -> str:
        return f"thrust {-self.rate:+.2%} per second of flight ({-60 * self.rate:+.1%} per minute)"


class ThrustVoltage(Effect):
    """Thrust that follows the battery voltage: ``T *= (vbat / v_ref)^exponent``.

    The firmware maps a commanded thrust to a throttle (the ESC's duty cycle) with a map
    measured at the battery voltage ``v_ref``. At a fixed duty cycle the motor sees
    ``duty x vbat``, its speed follows that voltage (a DC motor's speed is proportional to
    its voltage less the resistive drop), and a rotor's thrust goes with the square of
    its speed (``T = c_T rho n^2 D^4``): so the thrust at a fixed command scales as
    ``(vbat / v_ref)^2`` for an ESC without voltage compensation, and less (exponent
    towards 0) where the firmware scales the throttle with the voltage. References: J. G.
    Leishman, "Principles of Helicopter Aerodynamics", 2nd ed., Cambridge University
    Press, 2006, ch. 2 (the thrust coefficient: thrust ~ the square of the rotor speed);
    R. W. Beard and T. W. McLain, "Small Unmanned Aircraft: Theory and Practice",
    Princeton University Press, 2012 (the propeller and DC-motor model: thrust from the
    motor's speed, which its voltage sets); M. Tognon and A. Franchi, "Theory and
    Applications for Control of Aerial Robots in Physical Interaction Through Tethers",
    Springer, 2021 (the thruster model of the tethered vehicle, thrust ~ the square of
    the rotor speed).

    The effect's states are the battery's (2 states, V): its open-circuit voltage and
    the voltage dropped inside it under load; the terminal voltage ``vbat`` is their
    difference. In a flight log they are the logged ``vbat`` column (``log_channel``:
    states ``(vbat, 0)``, latency-delayed like the commands): a log without it cannot be
    compared with a model that has the effect, and diagnose offers the candidate only
    for logs that have it. In simulation a battery model produces them (the other
    parameters; a log's vbat replaces them): the open-circuit voltage falls linearly
    from ``v_full`` to ``v_empty`` over the charge ``capacity``, and the drop follows
    ``resistance x current`` with the time constant ``tau`` (a Thevenin equivalent
    circuit with one RC branch that lumps the ohmic and the fast polarisation drop: G.
    L. Plett, "Battery Management Systems, Vol. I: Battery Modeling", Artech House,
    2015, ch. 2), with a current stated linear in the commanded thrust (``current`` A
    per N; the electrical power of a rotor grows as ``T^1.5`` by momentum theory, close
    to linear over a flight's narrow range of thrust):

        q_oc' = -current sum(T_cmd) (v_full - v_empty) / capacity
        drop' = (resistance current sum(T_cmd) - drop) / tau,   vbat = q_oc - drop

    The voltage changes with the battery's charge and load, not with the motion: a
    table cannot hold it (the build refuses it); simulate and diagnose with it.
    """

    kind = "thrust_voltage"
    params = (
        Param("v_ref", "V", 11.1, 1.0, 100.0, "battery voltage at which the thrust map "
              "(command -> throttle) was measured", fit=(3.0, 60.0)),
        Param("exponent", "-", 2.0, -1.0, 4.0, "thrust ~ voltage^exponent at a fixed "
              "command (2: an ESC without voltage compensation; 0: full compensation)",
              fit=(0.0, 4.0)),
        Param("v_full", "V", 12.6, 1.0, 100.0, "simulation: open-circuit voltage at the "
              "start of a flight (3S LiPo full: 12.6 V)"),
        Param("v_empty", "V", 10.5, 0.5, 100.0, "simulation: open-circuit voltage with the "
              "capacity used (linear in between)"),
        Param("capacity", "A h", 1.3, 1e-4, 100.0, "simulation: charge from v_full to "
              "v_empty"),
        Param("resistance", "ohm", 0.05, 0.0, 2.0, "simulation: internal resistance"),
        Param("current", "A/N", 1.2, 0.0, 50.0, "simulation: battery current per newton "
              "of commanded collective thrust"),
        Param("tau", "s", 0.05, 1e-3, 10.0, "simulation: time constant of the drop under "
              "load"),
    )
    n_states = 2
    time_varying = True
    table_refusal = ("changes with the battery's charge and load (its states are the "
                     "battery's, not the motion's), which a table cannot hold")
    log_channel = "vbat"
    fits = (Refit("thrust_voltage", ("exponent", "v_ref"), "thrust that follows the logged "
                  "battery voltage, (vbat / v_ref)^exponent", affine=False),)

    def factor(self, vbat):
        """The thrust factor ``(vbat / v_ref)^exponent`` at the battery voltage ``vbat``
        (V), shape of ``vbat``; 0 at a voltage of 0 or less (a dead battery gives no
        thrust). Complex-step safe (decided on the real part)."""
        v = np.asarray(vbat)
        up = np.real(v) > 0
        return np.where(up, (np.where(up, v, self.v_ref) / self.v_ref) ** self.exponent, 0.0)

    @staticmethod
    def voltage(x):
        """The battery's terminal voltage (V) of the states ``x`` (..., 2), shape (...)."""
        return x[..., 0] - x[..., 1]

    def coefficients(self) -> tuple[float, float]:
        """``(drain, load)``: the open-circuit voltage's fall per second per newton of
        commanded thrust, V/(N s), and the drop per newton, V/N, of the battery model."""
        drain = self.current * (self.v_full - self.v_empty) / (3600.0 * self.capacity)
        return drain, self.resistance * self.current

    def modify_thrust(self, T, kin, x):
        return T * self.factor(self.voltage(x))[..., None]

    def state_derivative(self, x, u, kin):
        drain, load = self.coefficients()
        s = np.sum(u, -1)
        return np.stack(np.broadcast_arrays(-drain * s, (load * s - x[..., 1]) / self.tau), -1)

    def steady_states(self, T_actual, T_actual_dot):
        # a full battery, its drop settled at the command that gives T_actual
        _, load = self.coefficients()
        T = np.asarray(T_actual, dtype=float)
        u = T
        for _ in range(20):  # u = T / factor(v_full - load sum(u)): a contraction
            drop = load * np.sum(u, -1)
            u = T / self.factor(self.v_full - drop)[..., None]
        drop = load * np.sum(u, -1)
        return np.stack(np.broadcast_arrays(self.v_full + 0 * drop, drop), -1), u

    def states_from_log(self, values):
        v = np.asarray(values, dtype=float)
        return np.stack([v, np.zeros_like(v)], -1)

    def mirror(self):
        return np.eye(2)

    def law(self) -> str:
        return (f"thrust x (vbat / {self.v_ref:.3g} V)^{self.exponent:.2f}: "
                f"{self.factor(0.95 * self.v_ref) - 1:+.1%} at 5 % below {self.v_ref:.3g} V")


#: how far a thrust curve of :class:`ThrustPolynomial` may turn back inside the flown
#: airspeeds (relative thrust) before it is no rotor's
NONMONOTONE_TOL = 0.02


class ThrustPolynomial(Effect):
    """Thrust change with airspeed, polynomial form: ``T *= 1 + c1 |v| + c2 |v|^2``."""

    kind = "thrust_airspeed"
    params = (
        Param("c1", "s/m", 0.0, -0.2, 0.2, "linear coefficient", fit=(-0.1, 0.1)),
        Param("c2", "s^2/m^2", 0.0, -0.01, 0.01, "quadratic coefficient", fit=(-0.005, 0.005)),
    )
    fits = (Refit("thrust_airspeed", ("c1", "c2"),
                  "thrust change with airspeed, polynomial 1 + c1 v + c2 v^2"),)

    def modify_thrust(self, T, kin, x):
        v = norm(kin.v_air_C)
        return T * (1 + self.c1 * v + self.c2 * v * v)[..., None]

    def implausible(self, airspeed_range) -> str:
        # A rotor's thrust at a fixed command changes monotonically with the airspeed
        # over a flight's range (momentum theory, paper eq. 29: the induced velocity
        # falls as the inflow grows); a curve that falls and rises again by more than
        # NONMONOTONE_TOL inside the flown range is a fit to something else.
        lo, hi = airspeed_range
        if self.c2 == 0.0:
            return ""
        v0 = -self.c1 / (2.0 * self.c2)
        if not lo < v0 < hi:
            return ""
        f = 1.0 + self.c1 * np.array([lo, v0, hi]) + self.c2 * np.array([lo, v0, hi]) ** 2
        back = min(abs(f[0] - f[1]), abs(f[2] - f[1]))
        if back <= NONMONOTONE_TOL:
            return ""
        turn = "falls" if self.c2 > 0 else "rises"
        return (f"thrust_airspeed {turn} to {f[1] - 1:+.1%} at {v0:.1f} m/s and turns back by "
                f"{back:.1%} inside the flown {lo:.1f}-{hi:.1f} m/s (no rotor's thrust "
                "curve turns)")


class ThrustMomentum(Effect):
    """Thrust change with airspeed from momentum theory (paper eq. 29, after its ref. [4]).

    A rotor run at the power of its static test (thrust ``T_h`` = the commanded
    thrust, hover induced velocity ``v_h = sqrt(T_h / (2 rho_air A))``) that moves
    through the air with the COG velocity ``v_B`` (relative to the air:
    :attr:`Kinematics.v_air_B`) produces

        T / T_h = v_h / (v_i + v_z),   v_i^2 ((v_i + v_z)^2 + v_xy^2) = v_h^4

    with ``v_z = v_B . z_B`` the airspeed along the rotor axis (the paper's
    ``-v_inf sin(beta)``: positive when the rotor plane meets the air from above,
    which costs thrust) and ``v_xy`` the in-plane airspeed. ``disk_area = 0``
    switches the effect off (``T = T_h``). Momentum theory fails where the inflow
    ``v_i + v_z`` through the disk vanishes (vortex ring, windmill: hard braking with
    the rotor plane tilted back); there the inflow is floored smoothly at half its
    hover value, so the thrust gain stays below 2 (< 0.05% change where ``v_i + v_z >=
    0.8 v_h``).
    """

    kind = "thrust_momentum"
    params = (
        Param("disk_area", "m^2", 0.0, 0.0, 0.1, "rotor disk area per rotor (0: off)",
              fit=(1e-5, 0.1), scale="log"),
        Param("rho_air", "kg/m^3", 1.225, 0.5, 1.5, "air density"),
    )
    fits = (Refit("thrust_momentum", ("disk_area",),
                  "thrust change with airspeed by momentum theory (paper eq. 29)",
                  search="disk_area", affine=False),)

    def ratio(self, T, v_B):
        """``T / T_h`` per motor, shape (..., 4), for thrusts T (..., 4) N and v_B (..., 3) m/s."""
        if self.disk_area == 0:
            return np.ones_like(T)
        vh2 = np.sqrt(T * T + 1e-12) / (2 * self.rho_air * self.disk_area)  # T > 0, smooth
        vz = v_B[..., 2:3]
        vxy2 = (v_B[..., 0:1] ** 2 + v_B[..., 1:2] ** 2)
        vh = np.sqrt(vh2)
        # root of g(v) = v^2 ((v + vz)^2 + vxy^2) - vh^4 in the bracket [0, vh + max(0, -vz)]
        # (g < 0 at 0, >= 0 at the top): Newton, bisection where a step leaves the bracket
        # (vortex-ring states)
        v = induced_velocity(vh, vz, vxy2)
        lam = v + vz  # inflow through the disk
        lam0, eps = 0.5 * vh, 0.02 * vh  # smooth max(lam, lam0), complex-step safe
        lam = 0.5 * (lam + lam0 + np.sqrt((lam - lam0) ** 2 + eps * eps))
        return vh / lam

    def modify_thrust(self, T, kin, x):
        return T * self.ratio(T, kin.v_air_B)


class MotorLag(Effect):
    """First-order motor lag: ``T_actual' = (T_cmd - T_actual) / tau`` (4 states, N)."""

    kind = "motor_lag"
    params = (Param("tau", "s", 0.03, 1e-4, 0.5, "motor time constant", fit=(0.001, 0.2),
                    scale="log"),)
    n_states = 4
    fits = (Refit("motor_lag", ("tau",), "first-order motor lag (adds states)", search="tau",
                  affine=False),)

    def modify_thrust(self, T, kin, x):
        return x

    def state_derivative(self, x, u, kin):
        return (u - x) / self.tau

    def steady_states(self, T_actual, T_actual_dot):
        return T_actual, T_actual + self.tau * T_actual_dot

    def mirror(self):
        return np.eye(4)[[3, 2, 1, 0]]  # per-motor states swap like the motors

    def states_from_held_commands(self, t, T_cmd):
        # exact zero-order hold: x_k = a x_{k-1} + (1 - a) T_k, a = exp(-dt / tau)
        from scipy.signal import lfilter

        a = math.exp(-float(np.median(np.diff(t))) / self.tau)
        return lfilter([1 - a], [1, -a], T_cmd, axis=0, zi=(a * T_cmd[0])[None, :])[0]


class CogOffset(Effect):
    """The centre of mass off the frame centre, ``(x, y, z)`` m in B.

    The COG sits there from the point the arms, the tether's attachment point and the
    motion capture's markers are measured from (a battery slid a few millimetres, a
    camera on one side).

    It is geometry, not a force: the model measures every lever from the COG, so the
    rotor hubs sit at ``L_i - d`` and the attachment point at ``p_e - d`` (paper eqs. 6,
    8: the thrust rolls and pitches the vehicle by ``-d x T``, the tether yaws and
    pitches it by ``-(p_e - d) x f_t e``), and the pose the motion capture tracks is the
    frame centre, ``p_q - R_CB d`` (:class:`~gainsched.model.reduced.Model`,
    ``cog_offset``), as does the IMU (its specific force is the frame centre's: the log
    reader adds the lever ``R_CB (omega' x d + omega x (omega x d))``). The other effects'
    forces act at the COG. A lateral offset ``y`` breaks the direction mirror S2: the
    mirror image of the vehicle has its COG on the other side (:meth:`mirror_values`;
    docs/symmetry.md).
    """

    kind = "cog_offset"
    params = tuple(Param(a, "m", 0.0, -0.05, 0.05,
                         f"centre of mass from the frame centre along the body {a} axis",
                         fit=(-0.02, 0.02)) for a in "xyz")
    fits = (Refit("cog_offset", ("x", "y", "z"), "centre of mass off the frame centre (the "
                  "thrust's and the tether's levers; the markers and the IMU at the frame "
                  "centre)", affine=False),)

    def offset(self) -> np.ndarray:
        """``d = (x, y, z)``, shape (3,), m: the COG in B from the frame centre."""
        return np.array([self.x, self.y, self.z], dtype=float)

    def mirror_values(self) -> dict[str, float]:
        return {"x": self.x, "y": -self.y, "z": self.z}

    def law(self) -> str:
        d = self.offset() * 1e3
        return f"centre of mass ({d[0]:+.2f}, {d[1]:+.2f}, {d[2]:+.2f}) mm from the frame centre"


EFFECTS: dict[str, type[Effect]] = {
    cls.kind: cls
    for cls in (Drag, RotorDrag, ThrustScale, MotorEfficiency, ThrustTime, ThrustVoltage,
                ThrustPolynomial, ThrustMomentum, MotorLag, ThrustAzimuth, ThrustTimeSeries,
                ThrustMotorCurve, Wind, ForceAirspeed, ForceHorizontal, TetherStretchSeries,
                CogOffset)
}


#: the kinds that ship with the package (the rest of EFFECTS came from registered_effect)
BUILTIN_KINDS = frozenset(EFFECTS)


def registered_effects(kinds=None) -> tuple[type[Effect], ...]:
    """The effect classes registered in this process with :func:`registered_effect` (not
    built in), optionally only those of ``kinds``: what a worker process needs to be
    told to build the same model (its own registry has the built-in ones only)."""
    return tuple(cls for kind, cls in EFFECTS.items()
                 if kind not in BUILTIN_KINDS and (kinds is None or kind in kinds))


@contextlib.contextmanager
def registered_effects_context(classes):
    """Register every class of ``classes`` for the block (see :func:`registered_effect`)."""
    with contextlib.ExitStack() as stack:
        for cls in classes:
            stack.enter_context(registered_effect(cls))
        yield


@contextlib.contextmanager
def registered_effect(cls: type[Effect]):
    """Make a user-defined effect class nameable in configs (``[effects.<kind>]``) for the
    block: the config checks, the model, the simulator and the analysis then use it
    like a built-in one.

    Example
    -------
    >>> class Wake(Effect):                            # doctest: +SKIP
    ...     kind = "wake"
    ...     params = (Param("depth", "-", 0.0, 0.0, 0.5, "relative thrust loss"),)
    >>> with registered_effect(Wake):                  # doctest: +SKIP
    ...     cfg = load_config("vehicle_with_wake.toml")
    """
    if cls.kind in EFFECTS and EFFECTS[cls.kind] is not cls:
        raise ValueError(f"an effect named {cls.kind!r} exists already")
    had = cls.kind in EFFECTS
    EFFECTS[cls.kind] = cls
    try:
        yield cls
    finally:
        if not had:
            EFFECTS.pop(cls.kind, None)


def air_velocity(effects):
    """The velocity of the air in I, shape (3,), m/s, that ``effects`` set together (the sum
    of their :meth:`Effect.air_velocity`), or None when none of them moves the air (still
    air: every effect then sees the ground velocity, bit for bit)."""
    parts = [w for w in (e.air_velocity() for e in effects) if w is not None]
    if not parts:
        return None
    w = np.sum(parts, axis=0).astype(float)
    w.setflags(write=False)
    return w


def cog_offset(effects) -> np.ndarray:
    """The centre of mass in B from the frame centre, shape (3,), m, that ``effects`` set
    (:class:`CogOffset`; zeros without one: the COG is the frame centre)."""
    d = np.zeros(3)
    for e in effects:
        if isinstance(e, CogOffset):
            d = d + e.offset()
    d.setflags(write=False)
    return d


def effects_from_specs(specs) -> tuple[Effect, ...]:
    """Effect objects from config ``EffectSpec`` entries (stateful effects first)."""
    objs = [EFFECTS[s.name](**s.param_dict()) for s in specs]
    return tuple(sorted(objs, key=lambda e: e.n_states == 0))
