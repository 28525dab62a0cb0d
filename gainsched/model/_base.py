"""What an effect is (docs/architecture.md): its parameters (:class:`Param`), the ways
diagnose may fit it (:class:`Refit`), what it may look at (:class:`Kinematics`) and its
hooks (:class:`Effect`), the base of every effect of :mod:`.effects` and
:mod:`._empirical`; with the frame maps of the wind (:func:`wind_in_circle_frame`,
:func:`circle_to_inertial`) and the base of the effects of flight time
(:class:`_FlightTime`). Re-exported by :mod:`.effects`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .._vec import dot, mtv
from ..rotations import up_C_from_tilt

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


#: the motor (0-based) whose place each motor takes under the direction mirror S2: the
#: mirror image of motor 1 (+,+) sits at motor 4 (+,-), of 2 at 3 (docs/symmetry.md)
MIRROR_MOTOR = (3, 2, 1, 0)


def mirrored_motors(values: dict, *prefixes: str) -> dict[str, float]:
    """``values`` on the mirror image of the vehicle for per-motor parameters named
    ``<prefix>1`` .. ``<prefix>4``: each takes the value of the motor the mirror puts in
    its place (:data:`MIRROR_MOTOR`); other parameters are kept.

    Examples
    --------
    >>> mirrored_motors({"eta1": 0.9, "eta2": 1.0, "eta3": 1.0, "eta4": 1.1}, "eta")
    {'eta1': 1.1, 'eta2': 1.0, 'eta3': 1.0, 'eta4': 0.9}
    """
    out = dict(values)
    for prefix in prefixes:
        for i, j in enumerate(MIRROR_MOTOR):
            out[f"{prefix}{i + 1}"] = values[f"{prefix}{j + 1}"]
    return out


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
    #: the effect acts on the tether's stretch alone (:meth:`stretch`; no thrust, force,
    #: torque or state): a diagnose fit of it re-evaluates the stretch axis only
    stretch_only: ClassVar[bool] = False

    @classmethod
    def refusal(cls) -> str:
        """Why no table can hold this effect (``table_refusal``; for an effect that is
        only marked ``time_varying``, the flight-time reason), or "" when one can."""
        if cls.table_refusal or not cls.time_varying:
            return cls.table_refusal
        return _TIME_REFUSAL

    def mirror_values(self) -> dict[str, float]:
        """The parameters of this effect on the direction mirror's image of the vehicle
        (S2, docs/symmetry.md: reflected across the body x-z plane, motors relabelled
        1 <-> 4, 2 <-> 3): its own values for an effect the mirror keeps; a per-motor
        parameter swaps with the mirrored motor's, a lateral offset changes sign. A
        vehicle whose image differs from itself needs both flight directions in its table
        (:meth:`mirror_image`)."""
        return dict(self.values)

    def mirror_image(self) -> Effect:
        """This effect on the mirror image of the vehicle (:meth:`mirror_values`); equal
        to ``self`` when the mirror keeps it."""
        return type(self)(**self.mirror_values())

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

    def stretch(self, tension):
        """The tether stretch this effect adds at the tether tension ``tension`` (..., N):
        m, shape of ``tension``; None when it does not stretch the tether (every effect
        but an empirical stretch law). It changes no force of the model: the comparison's
        stretch axis (measured anchor-attachment distance minus the tether's length)
        sees it, on top of the ``[tether] link``'s stretch."""
        return None

    def implausible_tension(self, tension_range) -> str:
        """Why no real tether has the effect at these parameters over the flown
        ``tension_range`` (``(lo, hi)``, N), in words; empty when it may (diagnose refuses
        a fit that is implausible whatever its score, as for :meth:`implausible`)."""
        return ""

    def drag_coefficients(self):
        """``(mu1, mu2)`` when the effect is a pure COG-velocity drag
        ``F = -(mu1 + mu2 |v|) v`` (N s/m, N s^2/m^2), else None.

        The closed-form nominal (paper eqs. 15-18) and the firmware's compiled
        feed-forward cover such effects exactly; for any other effect the nominal comes
        from the numerical trim and reaches the firmware through the table.
        """
        return None


def tether_stretch_of(effects, tension):
    """The tether stretch that ``effects`` add together at the tension ``tension`` (..., N)
    (the sum of their :meth:`Effect.stretch`): m, shape of ``tension``, or None when none
    of them stretches the tether."""
    parts = [s for s in (e.stretch(tension) for e in effects) if s is not None]
    return None if not parts else sum(parts[1:], parts[0])


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
