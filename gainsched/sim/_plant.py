"""The plant: the reduced (rigid link) or maximal (elastic links) model behind one
interface, compiled when it can be, integrated by fixed-step RK4, and its sensors."""

from __future__ import annotations

import warnings

import numpy as np

from ..config import N_STATE, Config
from ..errors import GainschedWarning
from ..model.geometry import pose_from_reduced
from ..model.maximal import N_MAXIMAL, MaximalModel, reduced_from_maximal
from ..model.reduced import Model
from ..rotations import (
    R_IC_from_tilt,
    matrix_entries_from_quaternion,
    matrix_from_euler_zyx_scalar,
    matrix_from_quaternion,
    quaternion_from_matrix,
    quaternion_from_matrix_scalar,
)
from .fastplant import SUPPORTED_EFFECTS, fast_plant


def _mv(r, v):
    """The rows ``r`` (3 lists of 3 floats) times ``v`` (3 floats): a list of 3."""
    return [r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
            r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
            r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2]]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _minus(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def _plus(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def _warn_numpy_plant(cfg: Config) -> None:
    """Say that the rigid-link plant runs on the numpy model (slower), and why: once per
    reason and caller, as Python's warning filters show a warning by default (a process
    that flies many flights is told once, with no state kept here)."""
    missing = sorted(s.name for s in cfg.effects if s.name not in SUPPORTED_EFFECTS)
    why = (f"the compiled plant does not implement the effect(s) {', '.join(missing)}"
           if missing else "the compiled plant is not available (no C compiler, or "
           "GAINSCHED_NATIVE=0)")
    warnings.warn(f"{why}: the simulation runs on the numpy model, about 0.3x real time "
                  f"instead of 80x (gainsched/sim/fastplant.py)", GainschedWarning,
                  stacklevel=3)


class _Plant:
    """Reduced model (rigid link) or maximal model (elastic links) behind one interface.

    The rigid and the spring-damper links run on the compiled plants
    (:mod:`gainsched.sim.fastplant`) when they support the config and a compiler is
    available, else on the numpy models (the reference). The SLS and lumped-mass links
    keep their own path: set ``self.maximal`` (an object with ``f(x, u, alpha, gamma)``
    and ``tension(x, u, alpha, gamma)``) and ``self.fast = None``. ``gamma`` (rad) is the
    circle's heading: with a wind (``[effects.wind]``) it sets the wind's direction in C.
    """

    def __init__(self, cfg: Config, gamma: float = 0.0):
        self.model = Model(cfg)
        self.gamma = float(gamma)  # the circle's heading, rad: the wind's direction in C
        self.maximal = None if cfg.tether.link == "rigid" else MaximalModel(self.model)
        # compiled RK4 of the reduced or the spring-damper maximal model; None: numpy model
        self.fast = fast_plant(cfg)
        if self.maximal is None and self.fast is None:
            _warn_numpy_plant(cfg)
        # the frame centre from the COG, floats (None: the same point), and the circle
        # frame of the last sensors' call (:meth:`_frame`)
        d = self.model.cog_offset
        self.cog_offset = d.tolist() if d.any() else None
        self._frame_of = None

    def initial(self, z0, u0):
        """Plant state from the reduced state ``z0`` (10,) and the thrusts ``u0`` (4,), N:
        stateful effects (motor lag) start in their steady state at ``u0``."""
        if self.maximal is None:
            return np.concatenate([z0, self.model.steady_effect_states(u0)])
        # the elastic link pre-stretched (maximal.py), the effect states at rest at u0
        return self.maximal.from_reduced(z0[:N_STATE], u=u0)

    def f(self, x, u, alpha):
        """State derivative and tether tension (N) at one state."""
        g = self.gamma
        if self.fast is not None:
            return self.fast.f(x, u, alpha, g)
        if self.maximal is None:
            ev = self.model.evaluate(x, u, alpha, g)
            return ev.z_dot, ev.tension
        return self.maximal.f(x, u, alpha, g), self.maximal.tension(x, u, alpha, g)

    def step(self, x, u, alpha, dt):
        """One RK4 step of ``dt`` s with ``u`` held: ``(x_next, tension at x in N)``
        (elastic links: RK4 substeps, and a negative tension when slack)."""
        if self.fast is not None:
            return self.fast.rk4_step(x, u, alpha, dt, self.gamma)
        if self.maximal is not None:
            return self.maximal.step(x, u, alpha, dt, self.gamma)
        return _rk4(self.f, x, u, alpha, dt)

    def reduced(self, x, xi_ref):
        if self.maximal is None:
            return x[:N_STATE]
        return reduced_from_maximal(self.model, x, xi_ref)

    def pose(self, x, alpha, gamma):
        """What the motion capture tracks of one state or a batch of states (..., n_x):
        the frame centre's position in I (m; the COG unless ``[effects.cog_offset]`` puts
        it elsewhere) and R_IB."""
        if self.maximal is None:
            p_C, R_CB = pose_from_reduced(x, self.model.rho, self.model.p_e_frame)
        else:
            q = x[..., 6:10]
            R_CB = matrix_from_quaternion(q / np.linalg.norm(q, axis=-1, keepdims=True))
            p_C = x[..., 0:3] - self._cog_offset_C(R_CB)
        if np.ndim(x) == 1:  # one state (the pose sensor): scalar math
            R_IC = matrix_from_euler_zyx_scalar(alpha, 0.0, gamma)
        else:
            R_IC = R_IC_from_tilt(alpha, gamma)
        return p_C @ R_IC.T, R_IC @ R_CB

    def _cog_offset_C(self, R_CB):
        """``R_CB d``, shape (..., 3), m: the COG from the frame centre in C."""
        return np.einsum("...ij,j->...i", R_CB, self.model.cog_offset)

    def sensors(self, x, u, alpha, gamma, accel=True):
        """What the vehicle's sensors see of one state under the thrusts ``u`` (N): the frame
        centre's position ``p_I`` (m) and velocity ``v_I`` (m/s) in I (the COG's unless
        ``[effects.cog_offset]`` moves it), the attitude ``q_IB``, the body
        rates (rad/s) and the specific force at the frame centre in B (m/s^2, what the IMU
        there senses; None with ``accel=False``, which skips the plant's derivative).
        Scalar math (Python floats): it runs at every step of a flight, where numpy's
        small operations cost three times as much."""
        if self.maximal is None:
            z_dot = self.f(x, u, alpha)[0] if accel else np.zeros_like(x)
            p, v, a, r = self.model.cog_motion_floats(x, z_dot)
            w, w_dot = x[7:10].tolist(), z_dot[7:10].tolist()
        else:
            p, v, w = x[0:3].tolist(), x[3:6].tolist(), x[10:13].tolist()
            q = x[6:10] / np.linalg.norm(x[6:10])
            e = matrix_entries_from_quaternion(*q.tolist())
            r = [list(e[0:3]), list(e[3:6]), list(e[6:9])]
            x_dot = self.f(x, u, alpha)[0] if accel else None
            a, w_dot = (None, None) if x_dot is None else (x_dot[3:6].tolist(),
                                                           x_dot[10:13].tolist())
        if self.cog_offset is not None:  # the markers and the IMU sit at the frame centre
            d = self.cog_offset
            w_d = _cross(w, d)
            p, v = _minus(p, _mv(r, d)), _minus(v, _mv(r, w_d))
            if accel:
                a = _minus(a, _mv(r, _plus(_cross(w_dot, d), _cross(w, w_d))))
        R_IC, g_C = self._frame(alpha, gamma)
        f_B = None
        if accel:  # R_CB^T (a - g_C)
            f = _minus(a, g_C)
            f_B = np.array([r[0][j] * f[0] + r[1][j] * f[1] + r[2][j] * f[2] for j in range(3)])
        R_IB = [[R_IC[i][0] * r[0][j] + R_IC[i][1] * r[1][j] + R_IC[i][2] * r[2][j]
                 for j in range(3)] for i in range(3)]
        return (np.array(_mv(R_IC, p)), np.array(_mv(R_IC, v)),
                quaternion_from_matrix_scalar(R_IB), np.array(w), f_B)

    def _frame(self, alpha, gamma):
        """``R_IC`` as its rows (floats) and gravity in C (floats) of the circle ``(alpha,
        gamma)``, rad: made once per circle, not at every step."""
        key = (float(alpha), float(gamma))
        if self._frame_of is None or self._frame_of[0] != key:
            self._frame_of = (key, matrix_from_euler_zyx_scalar(key[0], 0.0, key[1]).tolist(),
                              self.model.g_C(key[0]).tolist())
        return self._frame_of[1:]

    def battery_voltage(self, X):
        """The battery's terminal voltage (N,), V, along plant states X (N, n_x), or None
        without a battery (an effect whose ``log_channel`` is ``"vbat"``)."""
        i = N_STATE if self.maximal is None else N_MAXIMAL
        for e in self.model.effects:
            if e.log_channel == "vbat":
                return e.voltage(X[:, i:i + e.n_states])
            i += e.n_states
        return None

    def poses(self, X, alpha, gamma):
        """COG positions in I (N, 3), m, and quaternions q_IB (N, 4) of states X (N, n_x)."""
        p_I, R_IB = self.pose(X, alpha, gamma)
        return p_I, quaternion_from_matrix(R_IB)

def _rk4(f, x, u, alpha, dt):
    k1, ten = f(x, u, alpha)
    k2, _ = f(x + 0.5 * dt * k1, u, alpha)
    k3, _ = f(x + 0.5 * dt * k2, u, alpha)
    k4, _ = f(x + dt * k3, u, alpha)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), ten


class DelayedCommands:
    """A plant whose thrusts act ``steps`` control steps after they are commanded: the
    extra loop delay of the delay margin (docs/margins.md), flown.

    Each step applies ``(1 - f) u_{k-d} + f u_{k-d-1}`` (``steps = d + f``), held over the
    step, the commands before the first one being the first one: the discrete delay the
    margins are computed for. Everything else is the wrapped plant's.
    """

    def __init__(self, plant, steps: float):
        self.plant = plant
        self.d = int(np.floor(steps))
        self.f = float(steps) - self.d
        self.past = None  # u_k, u_{k-1}, .., u_{k-d-1}

    def __getattr__(self, name):
        return getattr(self.plant, name)

    def step(self, x, u, alpha, dt):
        u = np.array(u, dtype=float)
        if self.past is None:
            self.past = [u] * (self.d + 2)
        self.past = [u, *self.past[:-1]]
        applied = (1.0 - self.f) * self.past[self.d] + self.f * self.past[self.d + 1]
        return self.plant.step(x, applied, alpha, dt)
