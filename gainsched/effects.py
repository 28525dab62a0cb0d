"""Effects: the one place physics is added to the plant (DESIGN.md section 2).

An effect is a small frozen object with named parameters (units, defaults,
bounds). The same objects serve the nominal trim, the linearisation, the
simulators and the model-vs-measurement fits, so adding an effect changes all
of them at once. An effect may

- modify the per-motor thrust (``modify_thrust``: thrust scale, thrust change
  with airspeed, the output of a motor-lag filter),
- add a force at the COG (in C) and a torque (in B) (``wrench``: body drag,
  rotor drag),
- carry extra states (``n_states``, ``state_derivative``: motor lag).

Evaluation order inside the model: commanded thrust -> stateful effects ->
thrust modifiers (config order) -> wrench effects, which see the final thrust.
All hooks broadcast over leading batch dimensions and are complex-step safe.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = [
    "Param",
    "Kinematics",
    "Effect",
    "Drag",
    "RotorDrag",
    "ThrustScale",
    "ThrustPolynomial",
    "MotorLag",
    "EFFECTS",
    "effects_from_specs",
    "norm",
]

_EPS2 = 1e-24  # keeps sqrt differentiable at exactly zero speed; changes values by < 1e-12 m/s


def norm(v):
    """Euclidean norm over the last axis, complex-step safe (no ``abs``)."""
    return np.sqrt(np.sum(v * v, axis=-1) + _EPS2)


@dataclass(frozen=True)
class Param:
    """A physical parameter of an effect: name, unit, default and plausible bounds."""

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    doc: str = ""


@dataclass(frozen=True)
class Kinematics:
    """What an effect may look at (all batched over leading dimensions).

    Attributes
    ----------
    R_CB : ndarray, shape (..., 3, 3)
        Body-to-circle rotation.
    v_C : ndarray, shape (..., 3), m/s
        COG velocity in C (equal to the airspeed: no wind).
    omega_B : ndarray, shape (..., 3), rad/s
    """

    R_CB: np.ndarray
    v_C: np.ndarray
    omega_B: np.ndarray

    @property
    def v_B(self):
        """COG velocity in B, shape (..., 3), m/s."""
        return np.einsum("...ji,...j->...i", self.R_CB, self.v_C)


class Effect:
    """Base class. Subclasses set ``kind``, ``params`` and override hooks."""

    kind: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    n_states: ClassVar[int] = 0
    doc: ClassVar[str] = ""

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

    def state_derivative(self, x, u, kin: Kinematics):
        """Time derivative of the effect's own states, shape (..., n_states)."""
        raise NotImplementedError

    def steady_states(self, T_actual, T_actual_dot):
        """States and command that produce the thrust trajectory ``T_actual`` (nominal use).

        Returns ``(x, u_cmd)``, shapes (..., n_states) and (..., 4).
        """
        raise NotImplementedError

    def mirror(self):
        """How the effect's states map under the direction mirror S2, shape (n_states, n_states)."""
        return np.eye(self.n_states)

    def tangential_drag(self, v):
        """For closed-form nominals: tangential force magnitude D(v) and its first two
        derivatives when the effect is a pure function of the COG velocity directed
        against it; None otherwise (the nominal then comes from the numerical trim)."""
        return None


class Drag(Effect):
    """Body drag at the COG, ``F = -(mu1 |v| + mu2 |v|^2) v/|v|`` (paper eq. 10)."""

    kind = "drag"
    params = (
        Param("mu1", "N s/m", 0.0, 0.0, 10.0, "linear drag coefficient"),
        Param("mu2", "N s^2/m^2", 0.0, 0.0, 1.0, "quadratic drag coefficient"),
    )

    def wrench(self, T, kin):
        speed = norm(kin.v_C)
        F = -(self.mu1 + self.mu2 * speed)[..., None] * kin.v_C
        return F, np.zeros_like(F)

    def tangential_drag(self, v):
        a = np.abs(v)
        return (self.mu1 + self.mu2 * a) * v, self.mu1 + 2 * self.mu2 * a, 2 * self.mu2 * np.sign(v)


class RotorDrag(Effect):
    """Rotor (induced) drag: ``F_B = -k_rd T_C (v_Bx, v_By, 0)``, in the rotor plane,
    proportional to the collective thrust and the in-plane airspeed (blade flapping)."""

    kind = "rotor_drag"
    params = (Param("k_rd", "s/m", 0.0, 0.0, 0.2, "rotor drag per newton of thrust per m/s"),)

    def wrench(self, T, kin):
        T_C = np.sum(T, axis=-1)
        v_B = kin.v_B
        F_B = -self.k_rd * T_C[..., None] * (v_B * np.array([1.0, 1.0, 0.0]))
        F_C = np.einsum("...ij,...j->...i", kin.R_CB, F_B)
        return F_C, np.zeros_like(F_C)


class ThrustScale(Effect):
    """Thrust scale: the real thrust is ``k_T`` times the static-test map (miscalibration)."""

    kind = "thrust_scale"
    params = (Param("k_T", "-", 1.0, 0.5, 1.5, "real / commanded thrust"),)

    def modify_thrust(self, T, kin, x):
        return self.k_T * T


class ThrustPolynomial(Effect):
    """Thrust change with airspeed, polynomial form: ``T *= 1 + c1 |v| + c2 |v|^2``."""

    kind = "thrust_airspeed"
    params = (
        Param("c1", "s/m", 0.0, -0.2, 0.2, "linear coefficient"),
        Param("c2", "s^2/m^2", 0.0, -0.01, 0.01, "quadratic coefficient"),
    )

    def modify_thrust(self, T, kin, x):
        v = norm(kin.v_C)
        return T * (1 + self.c1 * v + self.c2 * v * v)[..., None]


class MotorLag(Effect):
    """First-order motor lag: ``T_actual' = (T_cmd - T_actual) / tau`` (4 states, N)."""

    kind = "motor_lag"
    params = (Param("tau", "s", 0.03, 1e-4, 0.5, "motor time constant"),)
    n_states = 4

    def modify_thrust(self, T, kin, x):
        return x

    def state_derivative(self, x, u, kin):
        return (u - x) / self.tau

    def steady_states(self, T_actual, T_actual_dot):
        return T_actual, T_actual + self.tau * T_actual_dot

    def mirror(self):
        return np.eye(4)[[3, 2, 1, 0]]  # per-motor states swap like the motors


EFFECTS: dict[str, type[Effect]] = {
    cls.kind: cls for cls in (Drag, RotorDrag, ThrustScale, ThrustPolynomial, MotorLag)
}


def effects_from_specs(specs) -> tuple[Effect, ...]:
    """Effect objects from config ``EffectSpec`` entries (stateful effects first)."""
    objs = [EFFECTS[s.name](**s.param_dict()) for s in specs]
    return tuple(sorted(objs, key=lambda e: e.n_states == 0))
