"""Compiled plants for the closed-loop simulator (``gainsched/native/plant.c``).

The simulator needs the model on *one* state four times per control step;
:meth:`gainsched.model.reduced.Model.evaluate` is batched numpy and spends ~0.4 ms per
single-state call in per-operation overhead. ``plant.c`` is the same physics
(paper eqs. 3, 6, 8, corrected eq. 9; the 6x6 solve for ``(delta'', xi'', omega',
f_t)``) for one state in C, plus one RK4 step with the input held. This module
packs a :class:`~gainsched.model.reduced.Model` into the C parameter array and calls the
kernel through ctypes with preallocated buffers.

Supported: the rigid link with the state-only effects ``drag`` (eq. 10),
``rotor_drag``, ``thrust_scale``, ``motor_efficiency``, ``thrust_airspeed``,
``thrust_momentum`` (eq. 29), ``wind`` (the circle's heading gamma is then an argument of
every call), ``thrust_time`` (1 extra state), ``thrust_voltage`` (2 extra states: the
battery model), ``motor_lag`` (4 extra states) and the campaigns' truth outside the
library ``azimuth_thrust_loss`` (:mod:`gainsched.sim._outside`) (:class:`FastPlant`); the
spring-damper link with the same effects, their states after the rigid body's
(:class:`FastMaximal`, the maximal-coordinate model of :mod:`gainsched.model.maximal`).
Anything else (other effects, the SLS and lumped-mass links) uses the
numpy model: :func:`fast_plant` returns None and the caller falls back, as it does when
no C compiler is available or ``GAINSCHED_NATIVE=0`` (:func:`gainsched.native.load`).
"""

from __future__ import annotations

import ctypes
import math

import numpy as np

from ..config import N_STATE, Config
from ..model.effects import (
    CogOffset,
    Drag,
    MotorEfficiency,
    MotorLag,
    RotorDrag,
    ThrustMomentum,
    ThrustPolynomial,
    ThrustScale,
    ThrustTime,
    ThrustVoltage,
    Wind,
)
from ..model.maximal import N_MAXIMAL, MaximalModel
from ..model.reduced import Model
from ..native import load
from ._outside import AzimuthThrustLoss

__all__ = ["FastPlant", "FastMaximal", "fast_plant", "fast_plant_supported",
           "reduced_fast_plant", "SUPPORTED_EFFECTS"]

_LAYOUT = 6  # GS_PLANT_LAYOUT in plant.c
_EFF_STRIDE = 8  # kind, params a..f, first state index (EFF_STRIDE in plant.c)
#: effect class -> (kind code in plant.c, names of the parameters a, b, ..., or a function
#: of the effect giving their values)
_CODES = {
    Drag: (1, ("mu1", "mu2")),
    RotorDrag: (2, ("k_rd",)),
    ThrustScale: (3, ("k_T",)),
    ThrustPolynomial: (4, ("c1", "c2")),
    MotorLag: (5, ("tau",)),
    ThrustMomentum: (6, ("disk_area", "rho_air")),
    MotorEfficiency: (7, ("eta1", "eta2", "eta3", "eta4")),
    ThrustTime: (8, ("rate",)),
    Wind: (9, ("east", "north")),
    # v_ref, exponent, the battery's drain V/(N s) and load drop V/N, tau
    ThrustVoltage: (10, lambda e: [e.v_ref, e.exponent, *e.coefficients(), e.tau]),
    CogOffset: (11, ()),  # geometry: in the head's p_e and the allocation rows
    # a truth outside the library (the campaigns'): depth, xi0 and width in rad
    AzimuthThrustLoss: (12, lambda e: [e.depth, math.radians(e.xi0_deg),
                                       math.radians(e.width_deg)]),
}
#: config effect names the compiled plant implements
SUPPORTED_EFFECTS = frozenset(cls.kind for cls in _CODES)


def fast_plant_supported(config: Config) -> bool:
    """Whether a compiled plant implements ``config``: the rigid or the spring-damper
    link with the supported effects.

    Says nothing about whether a compiler is available (see :func:`fast_plant`).
    """
    return config.tether.link in ("rigid", "spring-damper") and _effects_supported(config)


def _effects_supported(config: Config) -> bool:
    """Whether ``plant.c`` implements every effect of ``config``."""
    return {s.name for s in config.effects} <= SUPPORTED_EFFECTS


def _params(model: Model, maximal: MaximalModel | None = None) -> np.ndarray:
    """The ``plant.c`` parameter array of a model (layout in plant.c), float64; with
    ``maximal`` (spring-damper link) its link constants, state size and the effect
    states' indices after its rigid-body states."""
    alloc = np.asarray(model.alloc, dtype=float)
    n_x = model.n_z if maximal is None else maximal.n_x
    link = [0.0, 0.0] if maximal is None else [maximal.link_model.k, maximal.link_model.c]
    J_inv = np.linalg.inv(model.J) if maximal is None else maximal.J_inv
    head = [_LAYOUT, n_x, model.m, model.rho, *model.p_e, model.g]
    eff = []
    i = N_STATE if maximal is None else N_MAXIMAL
    for e in model.effects:
        code, names = _CODES[type(e)]
        vals = ([float(v) for v in names(e)] if callable(names)
                else [float(e.values[n]) for n in names])
        vals += [0.0] * (_EFF_STRIDE - 2 - len(vals))
        eff.append([code, *vals, i])
        i += e.n_states
    p = np.concatenate(
        [
            np.asarray(head, dtype=float),
            np.asarray(model.J, dtype=float).reshape(9),
            alloc[1:].reshape(12),
            link,
            np.asarray(J_inv, dtype=float).reshape(9),
            [len(eff)],
            np.asarray(eff, dtype=float).reshape(-1),
        ]
    )
    return np.ascontiguousarray(p)


class FastPlant:
    """The reduced model of ``config`` (rigid link) evaluated by ``plant.c``.

    Same interface as the simulator's plant: :meth:`f` and :meth:`rk4_step`. Not
    thread-safe (the instance owns its scratch buffers); make one per thread.

    Parameters
    ----------
    config : Config
        Must satisfy :func:`fast_plant_supported`.
    lib : ctypes.CDLL
        The loaded ``plant`` kernel (``gainsched.native.load("plant")``).
    model : Model, optional
        The reduced model to evaluate (default ``Model(config)``, which needs the rigid
        link): given, the config's link does not matter (:func:`reduced_fast_plant`).
    """

    def __init__(self, config: Config, lib: ctypes.CDLL, model: Model | None = None):
        if not _effects_supported(config) or (model is None and config.tether.link != "rigid"):
            raise ValueError(f"{config.source}: not supported by the compiled plant")
        model = Model(config) if model is None else model
        if int(lib.gs_plant_layout()) != _LAYOUT:
            raise RuntimeError("plant.c parameter layout does not match fastplant.py")
        if model.n_z > int(lib.gs_plant_max_states()):
            raise ValueError(f"{model.n_z} states: more than plant.c holds")
        self.model = model
        self.n_z = model.n_z
        self._p = _params(model)
        # Preallocated buffers, their addresses taken once and passed as c_void_p ints:
        # measured per RK4 call (paper config, one core), c_void_p ints ~5.7 us,
        # POINTER(c_double) from ``ndarray.ctypes.data_as`` ~7.5 us, ndpointer argtypes
        # with fresh output arrays ~31 us (its per-call array checks dominate).
        self._x = np.zeros(self.n_z)
        self._u = np.zeros(4)
        self._out = np.zeros(self.n_z)
        self._ten = np.zeros(1)
        self._T = np.zeros(4)
        bufs = (self._p, self._x, self._u, self._out, self._ten, self._T)
        self._pp, self._px, self._pu, self._pout, self._pten, self._pT = (
            a.ctypes.data for a in bufs
        )
        # private function objects: the argtypes are ours, not shared with other users
        vp, dbl = ctypes.c_void_p, ctypes.c_double
        self._eval = lib["gs_plant_eval"]
        self._eval.argtypes = [vp, vp, vp, dbl, dbl, vp, vp, vp]
        self._eval.restype = ctypes.c_int
        self._rk4 = lib["gs_plant_rk4"]
        self._rk4.argtypes = [vp, vp, vp, dbl, dbl, dbl, vp, vp]
        self._rk4.restype = ctypes.c_int
        self._lib = lib

    def evaluate(self, z, u, alpha, gamma=0.0):
        """``(z_dot (n_z,), tension N, T (4,) N)`` at one state, as ``Model.evaluate``."""
        self._x[:] = z
        self._u[:] = u
        if self._eval(self._pp, self._px, self._pu, alpha, gamma, self._pout, self._pten,
                      self._pT):
            raise np.linalg.LinAlgError("singular model matrix")
        return self._out.copy(), float(self._ten[0]), self._T.copy()

    def f(self, x, u, alpha, gamma=0.0):
        """State derivative (n_z,) and tether tension (float, N) at one state.

        Parameters
        ----------
        x : array (n_z,) reduced state (rad, rad/s) and effect states
        u : array (4,) commanded motor thrusts, N
        alpha : float, rad, tilt of the circle plane
        gamma : float, rad, heading of the circle plane (matters with a wind only)
        """
        self._x[:] = x
        self._u[:] = u
        if self._eval(self._pp, self._px, self._pu, alpha, gamma, self._pout, self._pten,
                      None):
            raise np.linalg.LinAlgError("singular model matrix")
        return self._out.copy(), float(self._ten[0])

    def rk4_step(self, x, u, alpha, dt, gamma=0.0):
        """One RK4 step of ``dt`` s with ``u`` held: ``(x_next (n_z,), tension at x, N)``.

        Same operations as ``gainsched.sim._plant._rk4`` with the numpy model; ``gamma``
        (rad) is the circle's heading (matters with a wind only).
        """
        self._x[:] = x
        self._u[:] = u
        rc = self._rk4(self._pp, self._px, self._pu, alpha, gamma, dt, self._pout, self._pten)
        if rc:
            raise np.linalg.LinAlgError("singular model matrix")
        return self._out.copy(), float(self._ten[0])


class FastMaximal:
    """The maximal-coordinate model of ``config`` with its spring-damper link
    (:class:`gainsched.model.maximal.MaximalModel`) evaluated by ``plant.c``.

    The simulator's plant interface, as :class:`FastPlant`: :meth:`f` and
    :meth:`rk4_step` (with the RK4 substeps of :meth:`MaximalModel.substeps`). Not
    thread-safe; make one per thread.

    Parameters
    ----------
    config : Config
        Spring-damper link; must satisfy :func:`fast_plant_supported`.
    lib : ctypes.CDLL
        The loaded ``plant`` kernel.
    """

    def __init__(self, config: Config, lib: ctypes.CDLL):
        if config.tether.link != "spring-damper" or not fast_plant_supported(config):
            raise ValueError(f"{config.source}: not supported by the compiled maximal plant")
        if int(lib.gs_plant_layout()) != _LAYOUT:
            raise RuntimeError("plant.c parameter layout does not match fastplant.py")
        self.maximal = MaximalModel(Model(config))
        self.n_x = self.maximal.n_x
        if self.n_x > int(lib.gs_plant_max_states()):
            raise ValueError(f"{self.n_x} states: more than plant.c holds")
        self._p = _params(self.maximal.model, self.maximal)
        self._x = np.zeros(self.n_x)
        self._u = np.zeros(4)
        self._out = np.zeros(self.n_x)
        self._ten = np.zeros(1)
        bufs = (self._p, self._x, self._u, self._out, self._ten)
        self._pp, self._px, self._pu, self._pout, self._pten = (a.ctypes.data for a in bufs)
        vp, dbl = ctypes.c_void_p, ctypes.c_double
        self._eval = lib["gs_maximal_eval"]
        self._eval.argtypes = [vp, vp, vp, dbl, dbl, vp, vp]
        self._eval.restype = ctypes.c_int
        self._rk4 = lib["gs_maximal_rk4"]
        self._rk4.argtypes = [vp, vp, vp, dbl, dbl, dbl, ctypes.c_int, vp, vp]
        self._rk4.restype = ctypes.c_int
        self._substeps: dict[float, int] = {}
        self._lib = lib

    def f(self, x, u, alpha, gamma=0.0):
        """State derivative (n_x,) and tether tension (float, N, >= 0) at one state, as
        ``MaximalModel.f`` and ``MaximalModel.tension``."""
        self._x[:] = x
        self._u[:] = u
        self._eval(self._pp, self._px, self._pu, alpha, gamma, self._pout, self._pten)
        return self._out.copy(), max(0.0, float(self._ten[0]))

    def rk4_step(self, x, u, alpha, dt, gamma=0.0):
        """Advance by ``dt`` s with ``u`` held, as ``MaximalModel.step``: ``(x_next (n_x,),
        signed tension at x, N)`` (negative: slack, the push the link would need)."""
        n = self._substeps.get(dt)
        if n is None:
            n = self._substeps[dt] = self.maximal.substeps(dt)
        self._x[:] = x
        self._u[:] = u
        self._rk4(self._pp, self._px, self._pu, alpha, gamma, dt, n, self._pout, self._pten)
        return self._out.copy(), float(self._ten[0])


def reduced_fast_plant(model: Model) -> FastPlant | None:
    """The compiled form of a reduced model, whatever its config's link (a design model
    predicts with the reduced, rigid-link physics: the state estimator), or None: an
    effect ``plant.c`` lacks, more states than it holds, no compiler, or
    ``GAINSCHED_NATIVE=0``. Its derivatives equal ``model.f``'s to 1e-12 of their
    largest entry (tests/sim/test_fastplant.py) at about 1 % of the cost (2.3 against
    225 us a state with a motor lag and momentum theory)."""
    lib = load("plant") if _effects_supported(model.config) else None
    if lib is None or model.n_z > int(lib.gs_plant_max_states()):
        return None
    return FastPlant(model.config, lib, model=model)


def fast_plant(config: Config) -> FastPlant | FastMaximal | None:
    """The compiled plant for ``config``, or None: unsupported config, no compiler, or
    ``GAINSCHED_NATIVE=0`` (the caller then uses the numpy model)."""
    if not fast_plant_supported(config):
        return None
    lib = load("plant")
    if lib is None:
        return None
    if config.tether.link == "spring-damper":
        return FastMaximal(config, lib)
    return FastPlant(config, lib)
