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
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ._vec import dot, mtv, mv
from .momentum import induced_velocity
from .rotations import up_C_from_tilt

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
    "norm",
]

_EPS2 = 1e-24  # keeps sqrt differentiable at exactly zero speed; changes values by < 1e-12 m/s


#: the build's reason for refusing an effect of flight time (``Effect.time_varying``)
_TIME_REFUSAL = "changes with flight time, which a table (periodic in the azimuth) cannot hold"


def norm(v):
    """Euclidean norm over the last axis, complex-step safe (no ``abs``)."""
    return np.sqrt(dot(v, v) + _EPS2)


@dataclass(frozen=True)
class Param:
    """A physical parameter of an effect.

    Attributes
    ----------
    name, unit : str
    default : float
        Value when a config leaves it out.
    lower, upper : float
        The range a config may set (checked when it is loaded).
    doc : str
    fit : (float, float) or None
        The plausible range ``gainsched diagnose`` searches when it fits the parameter
        to flight logs (an estimate pinned to its edge is implausible); None: the
        config range.
    scale : {"lin", "log"}
        How a 1-D search samples the fit range.
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    doc: str = ""
    fit: tuple[float, float] | None = None
    scale: str = "lin"

    @property
    def fit_range(self) -> tuple[float, float]:
        """``fit`` or the config range."""
        return self.fit if self.fit is not None else (self.lower, self.upper)


@dataclass(frozen=True)
class Refit:
    """One way ``gainsched diagnose`` may fit an effect to flight logs (one candidate).

    Attributes
    ----------
    name : str
        Candidate name (unique over all effects).
    params : tuple of str
        The effect's parameters the candidate fits; the others keep their values.
    doc : str
        One line for the report.
    search : str or None
        The parameter found by a bounded 1-D search (nonlinear, e.g. a time constant);
        the others by least squares at each search value.
    affine : bool
        Whether the residual is affine in the least-squares parameters (one step is
        exact); False: a few Gauss-Newton steps.
    orders : tuple of int
        Nested fits of the first ``n`` parameters for each ``n`` (a series truncated at
        several orders); diagnose keeps the one with the best held-out score after a
        BIC penalty per parameter. Empty: all ``params``.
    contains : tuple of str
        Candidates of other effects whose every model is one of this candidate's
        (``thrust_scale`` in ``motor_efficiency``: four equal efficiencies). Diagnose
        then prefers the smaller one unless this one fits clearly better (the parsimony
        of nested fits), and does not call them twins.
    """

    name: str
    params: tuple[str, ...]
    doc: str
    search: str | None = None
    affine: bool = True
    orders: tuple[int, ...] = ()
    contains: tuple[str, ...] = ()


def wind_in_circle_frame(wind_I, alpha, gamma=0.0):
    """The air velocity ``wind_I`` (..., 3), m/s, in I expressed in C:
    ``R_IC^T wind_I`` with ``R_IC = Rz(gamma) Rx(alpha)`` (docs/conventions.md), shape
    broadcast of ``wind_I`` (..., 3) and ``alpha``, ``gamma`` (...) + (3,), m/s.

    Complex-step safe (``wind_I`` may be complex; the angles are taken as given)."""
    w = np.asarray(wind_I)
    a, g = np.asarray(alpha), np.asarray(gamma)
    ca, sa, cg, sg = np.cos(a), np.sin(a), np.cos(g), np.sin(g)
    wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
    u0 = cg * wx + sg * wy  # Rz(gamma)^T w
    u1 = cg * wy - sg * wx
    return np.stack(np.broadcast_arrays(u0, ca * u1 + sa * wz, ca * wz - sa * u1), -1)


def circle_to_inertial(v_C, alpha, gamma=0.0):
    """``R_IC v_C`` with ``R_IC = Rz(gamma) Rx(alpha)`` (docs/conventions.md): a vector
    ``v_C`` (..., 3) of C expressed in I, shape the broadcast with ``alpha``, ``gamma``
    (...) + (3,); the inverse of :func:`wind_in_circle_frame`. Complex-step safe."""
    v = np.asarray(v_C)
    a, g = np.asarray(alpha), np.asarray(gamma)
    ca, sa, cg, sg = np.cos(a), np.sin(a), np.cos(g), np.sin(g)
    t1 = ca * v[..., 1] - sa * v[..., 2]  # Rx(alpha) v
    t2 = sa * v[..., 1] + ca * v[..., 2]
    return np.stack(np.broadcast_arrays(cg * v[..., 0] - sg * t1, sg * v[..., 0] + cg * t1,
                                        t2), -1)


@dataclass(frozen=True)
class Kinematics:
    """What an effect may look at (all batched over leading dimensions).

    Attributes
    ----------
    R_CB : ndarray, shape (..., 3, 3)
        Body-to-circle rotation.
    v_C : ndarray, shape (..., 3), m/s
        COG velocity in C relative to the ground (the anchor). Effects of the airspeed
        use :attr:`v_air_C`, which equals it when there is no wind.
    omega_B : ndarray, shape (..., 3), rad/s
        Body rates.
    p_C : ndarray, shape (..., 3), m
        COG position in C (the tether anchor at the origin).
    alpha : float or ndarray, shape (...), rad
        Tilt of the circle plane: C is turned by ``alpha`` about the inertial x axis
        (paper eq. 1).
    gamma : float or ndarray, shape (...), rad
        Heading of the circle plane, ``R_IC = Rz(gamma) Rx(alpha)`` (docs/conventions.md).
        It enters the physics through the wind only (an inertial direction).
    wind_I : ndarray, shape (3,) or (..., 3), m/s, or None
        Velocity of the air in I (x east, y north, z up), from the model's effects
        (:meth:`Effect.air_velocity`); None: still air.
    """

    R_CB: np.ndarray
    v_C: np.ndarray
    omega_B: np.ndarray
    p_C: np.ndarray
    alpha: float | np.ndarray
    gamma: float | np.ndarray = 0.0
    wind_I: np.ndarray | None = None

    @property
    def v_B(self):
        """COG velocity in B relative to the ground, shape (..., 3), m/s."""
        return mtv(self.R_CB, self.v_C)

    @property
    def wind_C(self):
        """The air velocity in C, ``R_IC^T wind_I``, shape (..., 3), m/s (zeros: still air)."""
        if self.wind_I is None:
            return np.zeros(3)
        return wind_in_circle_frame(self.wind_I, self.alpha, self.gamma)

    @property
    def v_air_C(self):
        """COG velocity relative to the air in C, ``v_C - wind_C``, shape (..., 3), m/s:
        what every airspeed-dependent effect sees. Still air: ``v_C`` itself (bit for bit)."""
        if self.wind_I is None:
            return self.v_C
        return self.v_C - self.wind_C

    @property
    def v_air_B(self):
        """COG velocity relative to the air in B, shape (..., 3), m/s (still air: :attr:`v_B`)."""
        if self.wind_I is None:
            return self.v_B
        return mtv(self.R_CB, self.v_air_C)

    @property
    def up_C(self):
        """The inertial up direction ``R_IC^T (0, 0, 1) = (0, sin alpha, cos alpha)`` in C,
        shape (..., 3) (broadcast against the batch of ``alpha``)."""
        return up_C_from_tilt(self.alpha)

    @property
    def height(self):
        """COG height above the anchor, ``(R_IC p_C)_z``, shape (...), m."""
        return dot(self.p_C, self.up_C)


class Effect:
    """Base class. Subclasses set ``kind``, ``params`` and override hooks."""

    kind: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    n_states: ClassVar[int] = 0
    doc: ClassVar[str] = ""
    #: how ``gainsched diagnose`` fits the effect; empty: see :meth:`refits`
    fits: ClassVar[tuple[Refit, ...]] = ()
    #: an empirical law (no physical model behind it): diagnose fits it only when no
    #: physical candidate explains the residual, and reports its law (:meth:`law`)
    empirical: ClassVar[bool] = False
    #: the effect changes with flight time (its states are not the motion's): a table,
    #: which is periodic in the azimuth, cannot hold it (the build refuses it)
    time_varying: ClassVar[bool] = False
    #: why a gain table cannot hold the effect (it breaks what the table relies on: the
    #: periodicity in azimuth, the symmetries S1 and S2, no heading axis), one clause for
    #: the build's refusal; empty: a table can hold it (:meth:`refusal`)
    table_refusal: ClassVar[str] = ""
    #: the flight-log column (a key of ``FlightLog.optional``, e.g. ``"vbat"``) whose
    #: samples give the effect's states in a log (:meth:`states_from_log`) instead of an
    #: integration of :meth:`state_derivative` from the commands; empty: none. A log
    #: without it cannot be compared with a model that has the effect, and diagnose does
    #: not offer the effect's candidates for it
    log_channel: ClassVar[str] = ""

    @classmethod
    def refusal(cls) -> str:
        """Why no table can hold this effect (``table_refusal``; for an effect that is
        only marked ``time_varying``, the flight-time reason), or "" when one can."""
        if cls.table_refusal or not cls.time_varying:
            return cls.table_refusal
        return _TIME_REFUSAL

    @classmethod
    def refits(cls) -> tuple[Refit, ...]:
        """The diagnose candidates of this effect: ``fits``, or one candidate named after
        the effect that fits every parameter with no affine assumption (a bounded 1-D
        search when there is one parameter, Gauss-Newton steps otherwise).

        When ``fits`` fit the parameters one at a time, a joint candidate named after the
        effect follows them: every parameter any of them fits, together (drag: mu1 and
        mu2 at once, as the paper's Fig. 6 fit), affine when they all are and none
        searches. An effect whose parameters are all wrong is then one candidate, not
        several that each explain part of it.
        """
        if cls.fits:
            names = tuple(dict.fromkeys(n for r in cls.fits for n in r.params))
            if len(names) < 2 or any(set(r.params) == set(names) for r in cls.fits):
                return cls.fits
            affine = all(r.affine and r.search is None for r in cls.fits)
            doc = f"{cls.kind.replace('_', ' ')}: {', '.join(names)} fitted together"
            return (*cls.fits, Refit(cls.kind, names, doc, affine=affine))
        line = (cls.__doc__ or cls.kind).strip().splitlines()[0]
        names = tuple(p.name for p in cls.params)
        return (Refit(cls.kind, names, line, search=names[0] if len(names) == 1 else None,
                      affine=False),)

    def __init__(self, **values: float):
        names = {p.name for p in self.params}
        unknown = set(values) - names
        if unknown:
            raise TypeError(f"{self.kind}: unknown parameter(s) {sorted(unknown)}")
        vals = {p.name: float(values.get(p.name, p.default)) for p in self.params}
        object.__setattr__(self, "values", vals)

    def __getattr__(self, name):
        try:
            return self.__dict__["values"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name, value):
        raise AttributeError("effects are immutable; use replace()")

    def replace(self, **values: float) -> Effect:
        """A copy with some parameters changed."""
        return type(self)(**{**self.values, **values})

    def __repr__(self):
        inner = ", ".join(f"{k}={v:g}" for k, v in self.values.items())
        return f"{type(self).__name__}({inner})"

    def __eq__(self, other):
        return type(self) is type(other) and self.values == other.values

    def __hash__(self):
        return hash((type(self), tuple(self.values.items())))

    # ---- hooks (defaults: no contribution) ----
    def modify_thrust(self, T, kin: Kinematics, x):
        """Per-motor thrust after this effect, shape (..., 4), N. ``x``: own states."""
        return T

    def wrench(self, T, kin: Kinematics):
        """(force at the COG in C, shape (..., 3), N; torque in B, shape (..., 3), N m) or None."""
        return None

    def air_velocity(self):
        """The velocity of the air in I this effect sets, shape (3,), m/s, or None (the
        model sums them into :attr:`Kinematics.wind_I`)."""
        return None

    def state_derivative(self, x, u, kin: Kinematics):
        """Time derivative of the effect's own states, shape (..., n_states)."""
        raise NotImplementedError

    def steady_states(self, T_actual, T_actual_dot):
        """States and command that produce the thrust trajectory ``T_actual`` (nominal use).

        Returns ``(x, u_cmd)``, shapes (..., n_states) and (..., 4).
        """
        raise NotImplementedError

    def states_from_held_commands(self, t, T_cmd):
        """The effect's states along a log whose commands ``T_cmd`` (N, 4), N, are held
        over each sample interval ``t`` (N,), s, started in steady state: shape
        (N, n_states), or None when the effect has no exact form (the caller then
        integrates :meth:`state_derivative`)."""
        return None

    def states_from_log(self, values):
        """The effect's states along a log from the samples ``values`` (N, ...) of its
        ``log_channel``: shape (N, n_states). Only for effects with a ``log_channel``."""
        raise NotImplementedError

    def mirror(self):
        """How the effect's states map under the direction mirror S2, shape (n_states, n_states)."""
        return np.eye(self.n_states)

    def law(self) -> str:
        """The effect's law in words with its numbers (reports of empirical effects)."""
        return repr(self)

    def implausible(self, airspeed_range) -> str:
        """Why no real vehicle has the effect at these parameters over the flown
        ``airspeed_range`` (``(lo, hi)``, m/s), in words; empty when it may. Diagnose
        refuses a fit that is implausible whatever its score."""
        return ""

    def drag_coefficients(self):
        """``(mu1, mu2)`` when the effect is a pure COG-velocity drag
        ``F = -(mu1 + mu2 |v|) v`` (N s/m, N s^2/m^2), else None.

        The closed-form nominal (paper eqs. 15-18) and the firmware's compiled
        feed-forward cover such effects exactly; for any other effect the nominal comes
        from the numerical trim and reaches the firmware through the table.
        """
        return None


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
    direction mirror S2 (the mirrored vehicle swaps motors 1 <-> 4 and 2 <-> 3;
    docs/symmetry.md): simulate and diagnose with them, build tables without them.
    """

    kind = "motor_efficiency"
    params = tuple(Param(f"eta{i}", "-", 1.0, 0.3, 1.5, f"motor {i}: real / commanded thrust",
                         fit=(0.5, 1.3)) for i in range(1, 5))
    fits = (Refit("motor_efficiency", tuple(f"eta{i}" for i in range(1, 5)),
                  "one efficiency per motor: thrust and reaction torque (the body torques "
                  "tell the motors apart)", contains=("thrust_scale",)),)

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


class _FlightTime(Effect):
    """An effect whose one state is the flight time (``t' = 1``, from 0 at the start of a
    simulated flight; in a flight log the log's time axis, ``t`` of
    ``gainsched-flightlog/1``). The thrust then changes with time, so a table cannot
    hold it (``time_varying``: the build refuses it)."""

    n_states = 1
    time_varying = True
    table_refusal = _TIME_REFUSAL

    def state_derivative(self, x, u, kin):
        return np.ones_like(x)

    def steady_states(self, T_actual, T_actual_dot):
        return np.zeros((*np.shape(T_actual)[:-1], 1)), T_actual  # at t = 0: no change

    def states_from_held_commands(self, t, T_cmd):
        return np.asarray(t, dtype=float)[:, None]

    def mirror(self):
        return np.eye(1)


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
    motor. Unequal motors break the direction mirror S2 (docs/symmetry.md): the build
    refuses it; simulate and diagnose with it.
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


EFFECTS: dict[str, type[Effect]] = {
    cls.kind: cls
    for cls in (Drag, RotorDrag, ThrustScale, MotorEfficiency, ThrustTime, ThrustVoltage,
                ThrustPolynomial, ThrustMomentum, MotorLag, ThrustAzimuth, ThrustTimeSeries,
                ThrustMotorCurve, Wind, ForceAirspeed, ForceHorizontal)
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


def effects_from_specs(specs) -> tuple[Effect, ...]:
    """Effect objects from config ``EffectSpec`` entries (stateful effects first)."""
    objs = [EFFECTS[s.name](**s.param_dict()) for s in specs]
    return tuple(sorted(objs, key=lambda e: e.n_states == 0))
