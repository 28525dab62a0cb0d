"""Elastic tether link models for the maximal-coordinate simulator.

Reference ("the chapter" below): M. Tognon and A. Franchi, "Theory and
Applications for Control of Aerial Robots in Physical Interaction Through
Tethers", Springer, 2021, ch. 3 "Model of the Robotic Elements", sec. 3.1.
The tether is a cable-like link (the chapter's category (a)): it carries tension
only. When its internal force would be compressive the link is *slack*
(``f_L = 0``) and the two ends move independently; a link model reports that
state (``slack``) and never pushes. The anchor is the origin of the circle
frame C; the vehicle end is the attachment point ``p_t`` (m, in C) with velocity
``v_t`` (m/s). ``rho`` (m) is the unstretched length, ``s = |p_t| - rho`` the
elongation, ``s' = n . v_t`` its rate, ``n = p_t / |p_t|``.

- :class:`SpringDamper` (Kelvin-Voigt): ``f = max(0, k s + c s')``.
- :class:`StandardLinearSolid` (SLS, Zener; the chapter's refs [5-7]): a spring
  ``k_s`` in series with the parallel of a spring ``k_p`` and a damper ``c``.
  With the elongation ``s_p`` (m) of the parallel element as the link state::

      f    = max(0, k_s (s - s_p))          (series spring; slack when s < s_p)
      s_p' = (f - k_p s_p) / c              (parallel element carries the same f)

  Instantaneous stiffness ``k_s``, static stiffness ``k_s k_p / (k_s + k_p)``;
  as ``k_s -> inf`` it becomes the Kelvin-Voigt spring-damper ``(k_p, c)``.
- :class:`LumpedMassChain` (finite-element approximation, the chapter's refs [7-9]):
  ``N`` segments of rest length ``rho / N``, each a tension-only spring-damper
  with ``N k`` and ``N c`` (so the whole chain stretched uniformly has stiffness
  ``k`` and damping ``c``), joined at ``N - 1`` point masses ``m_t / N`` under
  gravity. The half-segment masses at the two ends belong to the anchor and to
  the vehicle; the vehicle's is neglected (keeps the vehicle parameters, and
  ``N = 1`` *is* the spring-damper). State: node positions then velocities,
  ``(P_1..P_{N-1}, V_1..V_{N-1})`` in C, shape (..., 6 (N - 1)).

Every model has the same interface: ``n_states``; ``evaluate(p_t, v_t, s, g_C)``
-> :class:`LinkOutput` (force on the vehicle, tension, slack, state rate);
``stretch(f)`` and ``initial(p_t, v_t, f)`` for a start in static equilibrium
at tension ``f``; ``energy`` (stored elastic energy plus the nodes' kinetic and
gravitational energy) and ``power_loss`` (W, >= 0) with
``d(energy)/dt = f s' - power_loss`` (chain: power delivered at the vehicle
end); ``max_rate()`` (1/s) bounds the fastest link eigenvalue for step-size
choice. All broadcast over leading batch dimensions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._vec import broadcast, dot

__all__ = [
    "LinkOutput",
    "SpringDamper",
    "StandardLinearSolid",
    "LumpedMassChain",
    "ELASTIC_LINKS",
    "link_from_tether",
]

#: config ``tether.link`` values served by this module (``"rigid"`` is in ``maximal``)
ELASTIC_LINKS = ("spring-damper", "sls", "lumped-mass")


@dataclass(frozen=True)
class LinkOutput:
    """What a link model gives the rigid body (batch shape ``S``).

    Attributes
    ----------
    force : ndarray (*S, 3), N
        Force of the link on the vehicle at the attachment point, in C.
    tension : ndarray (*S,), N
        Tension at the vehicle end (what a load cell there reads), >= 0.
    slack : ndarray (*S,), bool
        Some part of the link carries no tension (its force law came out <= 0).
    state_dot : ndarray (*S, n_states)
        Rate of the link's own states.
    margin : ndarray (*S,), N
        The smallest force-law value over the link's parts before the tension-only
        clip (``<= 0`` exactly when ``slack``: minus the push the link would need).
    """

    force: np.ndarray
    tension: np.ndarray
    slack: np.ndarray
    state_dot: np.ndarray
    margin: np.ndarray


def _radial(p_t, v_t, rho):
    dist = np.sqrt(dot(p_t, p_t))
    n = p_t / dist[..., None]
    return n, dist - rho, dot(n, v_t)


@dataclass(frozen=True)
class SpringDamper:
    """Tension-only Kelvin-Voigt link: ``f = max(0, k s + c s')``.

    rho : m rest length; k : N/m stiffness; c : N s/m damping.
    """

    rho: float
    k: float
    c: float
    kind = "spring-damper"
    n_states = 0

    def evaluate(self, p_t, v_t, s, g_C) -> LinkOutput:
        n, stretch, rate = _radial(p_t, v_t, self.rho)
        raw = self.k * stretch + self.c * rate
        f = np.maximum(0.0, raw)
        return LinkOutput(-f[..., None] * n, f, raw <= 0, np.zeros(f.shape + (0,)), raw)

    def stretch(self, f):
        """Static elongation (m) at tension f (N)."""
        return np.asarray(f, dtype=float) / self.k

    def initial(self, p_t, v_t, f):
        return np.zeros(np.shape(p_t)[:-1] + (0,))

    def energy(self, p_t, v_t, s, g_C):
        _, stretch, _ = _radial(p_t, v_t, self.rho)
        return 0.5 * self.k * np.maximum(stretch, 0.0) ** 2

    def power_loss(self, p_t, v_t, s, g_C):
        _, stretch, rate = _radial(p_t, v_t, self.rho)
        f = np.maximum(0.0, self.k * stretch + self.c * rate)
        return (f - self.k * np.maximum(stretch, 0.0)) * rate

    def max_rate(self, vehicle_mass: float) -> float:
        """|eigenvalue| bound (1/s) of the vehicle bouncing on the link."""
        m = vehicle_mass
        return math.sqrt(self.k / m) + self.c / m


@dataclass(frozen=True)
class StandardLinearSolid:
    """Tension-only SLS link: spring ``k_s`` in series with ``(k_p || c)``; state ``s_p`` (m).

    rho : m rest length; k_s : N/m series stiffness; k_p : N/m parallel stiffness;
    c : N s/m parallel damping (> 0).
    """

    rho: float
    k_s: float
    k_p: float
    c: float
    kind = "sls"
    n_states = 1

    def __post_init__(self):
        if not (self.k_s > 0 and self.k_p > 0 and self.c > 0):
            raise ValueError("the SLS link needs k_s > 0, k_p > 0 and c > 0")

    def evaluate(self, p_t, v_t, s, g_C) -> LinkOutput:
        n, stretch, _ = _radial(p_t, v_t, self.rho)
        s_p = s[..., 0]
        raw = self.k_s * (stretch - s_p)
        f = np.maximum(0.0, raw)
        s_p_dot = (f - self.k_p * s_p) / self.c
        return LinkOutput(-f[..., None] * n, f, raw <= 0, s_p_dot[..., None], raw)

    def stretch(self, f):
        """Static elongation (m) at tension f (N): the two springs in series."""
        return np.asarray(f, dtype=float) * (1.0 / self.k_s + 1.0 / self.k_p)

    def initial(self, p_t, v_t, f):
        """The parallel element relaxed at tension f: ``s_p = f / k_p``, shape (..., 1)."""
        f = np.broadcast_to(np.asarray(f, dtype=float), np.shape(p_t)[:-1])
        return (f / self.k_p)[..., None]

    def energy(self, p_t, v_t, s, g_C):
        _, stretch, _ = _radial(p_t, v_t, self.rho)
        s_p = s[..., 0]
        return 0.5 * self.k_s * np.maximum(stretch - s_p, 0.0) ** 2 + 0.5 * self.k_p * s_p**2

    def power_loss(self, p_t, v_t, s, g_C):
        s_p_dot = self.evaluate(p_t, v_t, s, g_C).state_dot[..., 0]
        return self.c * s_p_dot**2

    def max_rate(self, vehicle_mass: float) -> float:
        """|eigenvalue| bound (1/s): vehicle on the series spring plus the internal relaxation."""
        return math.sqrt(self.k_s / vehicle_mass) + (self.k_s + self.k_p) / self.c


@dataclass(frozen=True)
class LumpedMassChain:
    """Chain of ``segments`` tension-only spring-dampers with point masses between them.

    rho : m rest length; k : N/m and c : N s/m of the whole tether (segment values
    ``N k``, ``N c``); mass : kg of the whole tether (``mass / N`` per interior node);
    segments : N >= 1.
    """

    rho: float
    k: float
    c: float
    mass: float
    segments: int
    kind = "lumped-mass"

    def __post_init__(self):
        if self.segments < 1 or int(self.segments) != self.segments:
            raise ValueError(f"segments must be an integer >= 1, got {self.segments}")
        if self.segments > 1 and not self.mass > 0:
            raise ValueError("a chain of more than one segment needs a tether mass > 0")

    @property
    def n_nodes(self) -> int:
        return int(self.segments) - 1

    @property
    def n_states(self) -> int:
        return 6 * self.n_nodes

    @property
    def node_mass(self) -> float:
        return self.mass / self.segments

    def _segments(self, p_t, v_t, s):
        """Segment vectors, lengths, unit vectors, length rates and raw forces, anchor first.

        Returns P (*S, N+1, 3) node positions incl. anchor and p_t, and per segment
        (*S, N): length l, unit u (*S, N, 3), rate l', raw force law ``N k (l - l0) + N c l'``.
        """
        N, nn = int(self.segments), self.n_nodes
        S = np.broadcast_shapes(np.shape(p_t)[:-1], np.shape(v_t)[:-1], np.shape(s)[:-1])
        nodes = np.asarray(s, dtype=float).reshape(np.shape(s)[:-1] + (2, nn, 3))
        zero = np.zeros(S + (1, 3))
        P = np.concatenate([zero, broadcast(nodes[..., 0, :, :], S + (nn, 3)),
                            broadcast(p_t, S + (3,))[..., None, :]], -2)
        V = np.concatenate([zero, broadcast(nodes[..., 1, :, :], S + (nn, 3)),
                            broadcast(v_t, S + (3,))[..., None, :]], -2)
        d = np.diff(P, axis=-2)
        length = np.sqrt(dot(d, d))
        u = d / length[..., None]
        rate = dot(u, np.diff(V, axis=-2))
        raw = N * self.k * (length - self.rho / N) + N * self.c * rate
        return P, V, length, u, rate, raw

    def evaluate(self, p_t, v_t, s, g_C) -> LinkOutput:
        P, V, _, u, _, raw = self._segments(p_t, v_t, s)
        f = np.maximum(0.0, raw)
        fu = f[..., None] * u  # pull of segment j on its inner end (node j-1) is +fu_j
        if self.n_nodes:
            acc = (fu[..., 1:, :] - fu[..., :-1, :]) / self.node_mass
            acc = acc + np.asarray(g_C)[..., None, :]
        else:
            acc = np.zeros(fu.shape[:-2] + (0, 3))
        state_dot = np.concatenate([V[..., 1:-1, :], acc], -2)
        state_dot = state_dot.reshape(state_dot.shape[:-2] + (self.n_states,))
        margin = np.min(raw, axis=-1)
        return LinkOutput(-fu[..., -1, :], f[..., -1], margin <= 0, state_dot, margin)

    def tensions(self, p_t, v_t, s):
        """Tension of every segment, anchor end first, shape (..., N), N."""
        return np.maximum(0.0, self._segments(p_t, v_t, s)[-1])

    def stretch(self, f):
        """Static elongation (m) at tension f (N), gravity on the nodes neglected."""
        return np.asarray(f, dtype=float) / self.k

    def initial(self, p_t, v_t, f):
        """Nodes evenly on the straight line anchor -> p_t, moving with it as a rigid rod
        (``P_j = j/N p_t``, ``V_j = j/N v_t``): uniform stretch, tension f in every segment."""
        N = int(self.segments)
        frac = (np.arange(1, N) / N)[:, None]
        P = frac * np.asarray(p_t)[..., None, :]
        V = frac * np.asarray(v_t)[..., None, :]
        out = np.concatenate([P, V], -2)
        return out.reshape(out.shape[:-2] + (self.n_states,))

    def energy(self, p_t, v_t, s, g_C):
        P, V, length, _, _, _ = self._segments(p_t, v_t, s)
        N = int(self.segments)
        elastic = 0.5 * N * self.k * np.sum(np.maximum(length - self.rho / N, 0.0) ** 2, -1)
        inner_P, inner_V = P[..., 1:-1, :], V[..., 1:-1, :]
        kinetic = 0.5 * self.node_mass * np.sum(inner_V * inner_V, (-2, -1))
        potential = -self.node_mass * np.sum(inner_P * np.asarray(g_C)[..., None, :], (-2, -1))
        return elastic + kinetic + potential

    def power_loss(self, p_t, v_t, s, g_C):
        _, _, length, _, rate, raw = self._segments(p_t, v_t, s)
        N = int(self.segments)
        f = np.maximum(0.0, raw)
        return np.sum((f - N * self.k * np.maximum(length - self.rho / N, 0.0)) * rate, -1)

    def max_rate(self, vehicle_mass: float) -> float:
        """|eigenvalue| bound (1/s): a node between two segments (Gershgorin), or the vehicle."""
        N = int(self.segments)
        if self.n_nodes == 0:
            return SpringDamper(self.rho, self.k, self.c).max_rate(vehicle_mass)
        mu = self.node_mass
        return 2.0 * math.sqrt(N * self.k / mu) + 4.0 * N * self.c / mu


def link_from_tether(tether):
    """The elastic link model a :class:`gainsched.config.Tether` asks for (None if rigid)."""
    if tether.link == "rigid":
        return None
    if tether.link == "spring-damper":
        return SpringDamper(tether.length, tether.stiffness, tether.damping)
    if tether.link == "sls":
        return StandardLinearSolid(
            tether.length, tether.series_stiffness, tether.stiffness, tether.damping
        )
    if tether.link == "lumped-mass":
        return LumpedMassChain(
            tether.length, tether.stiffness, tether.damping, tether.mass, tether.segments
        )
    raise ValueError(f"unknown link model {tether.link!r}")
