"""The controller's parameters (``gs_ctrl_params``): what the controller knows of the
vehicle, the loop and the sensors, from the table it flies.

:func:`controller_params` takes them from the table's firmware record (computed by the
build from its config, docs/table-format.md) and sizes the integral states' bounds from
its gains (:func:`int_limits_for`); :class:`ControllerParams` holds them in
``gs_ctrl_params`` order and turns thrusts into the flight stack's outputs. The control
step itself is :mod:`gainsched.firmware.controller`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..actuators import command_from_thrust, thrust_from_command
from ..constants import N_STATE
from ..errors import InputError

__all__ = [
    "MAX_INT",
    "INT_RANGE_FRACTION",
    "INT_LIMIT_NO_GAINS",
    "ControllerParams",
    "controller_params",
    "int_limits_for",
]

MAX_INT = 2  # GS_CTRL_MAX_INT: integral states a gs_ctrl holds
#: the share of a motor's range (thrust_max - thrust_min) one integral term may command
#: at its bound, at the table's largest gain (:func:`int_limits_for`)
INT_RANGE_FRACTION = 1.0
#: rad s: the bound of an integral state the rule cannot size, no gain of it at any
#: feasible point (a table without one: its controller never engages), where the bound
#: does not act on the command (the former single default, :func:`int_limits_for`)
INT_LIMIT_NO_GAINS = 0.5


#: | |q_MB|^2 - 1 | a controller accepts (gs_ctrl_init: GS_BAD_ARG beyond)
Q_MB_TOLERANCE = 1e-4


@dataclass(frozen=True)
class ControllerParams:
    """What the controller knows of the vehicle, the loop and the sensors (``gs_ctrl_params``,
    the same fields in the same order).

    Attributes
    ----------
    dt : float, s
        Control step.
    rho : float, m
        Tether length.
    L_e : float, m
        Attachment offset behind the COG.
    thrust_min, thrust_max : float, N
        Each motor's range: the clip.
    thrust_idle : float, N
        Each motor's thrust while the controller is idle (``CTRL_IDLE``).
    int_limit : tuple of float, rad s
        The bound on each integral state (anti-windup), one per entry of ``int_of``
        (``gs_ctrl_params.int_limit[GS_CTRL_MAX_INT]``), rounded to float32 as C holds
        them; each finite and > 0 (the controllers refuse others). A single number is
        taken for every integral state. :func:`controller_params` sizes them
        from the table's gains (:func:`int_limits_for`).
    int_of : tuple of int
        The reduced state each integral state integrates (0: delta, 1: xi), in the LQR
        state's order.
    pose_delay : float, s
        Age of a pose when it arrives (rounded to control steps, at most ``MAX_DELAY``).
    pose_timeout : float, s
        No accepted pose for longer than this: ``CTRL_STALE_POSE``.
    quat_tolerance : float
        A pose quaternion with ``| |q|^2 - 1 |`` above this is rejected.
    gyro_range : float, rad/s
        A gyro axis beyond it is saturated.
    gyro_scale, gyro_bias : tuple of 3 float (-, rad/s)
        The gyro's calibration (``[sensors]`` of the config): each axis reads
        ``gyro_scale * omega + gyro_bias``; the controller uses
        ``(reading - gyro_bias) / gyro_scale`` (float32, as in C), as the log reader does.
    accel_scale, accel_bias : tuple of 3 float (-, m/s^2)
        The accelerometer's calibration (``[sensors]``): the controller uses
        ``(reading - accel_bias) / accel_scale``, as the log reader does.
    q_MB : tuple of 4 float
        The body frame in the motion capture's marker frame, a unit quaternion (w, x, y,
        z; ``[sensors] marker_rotation_deg``): each pose's ``q_IM`` becomes the body's
        ``q_IB = q_IM (x) q_MB``, as the log reader turns it.
    accel_range : float, m/s^2
        The accelerometer's range: an axis beyond it is a bad sample (``CTRL_BAD_IMU``).
        :func:`controller_params` sizes it from the config's grid
        (:func:`accel_range_for`); the 16 g here is the floor.
    k_pos, k_vel, k_att : float
        The estimator's corrections per pose: position ``k_pos e_p``, velocity
        ``k_vel e_p / pose_period``, attitude ``k_att e_theta``.
    pose_period : float, s
        Interval between poses.
    motor_slot : tuple of 4 int
        The output slot (0-based) of the tool's motors T1..T4: ``(0, 1, 2, 3)`` the tool's
        numbering, ``(2, 1, 3, 0)`` PX4's quad-X (:mod:`gainsched.actuators`).
    normalized : bool
        Outputs are normalised commands through the thrust curve, not thrusts in N.
    thr_mdl_fac : float
        The thrust curve's quadratic part (PX4's ``THR_MDL_FAC``), 0..1.
    thrust_full : float, N
        Thrust at full command (normalised outputs).
    n_lag : int
        0, or 4 when the LQR state ends with the 4 thrusts of a motor lag (a table built
        with ``[effects.motor_lag]``): no sensor measures them, so the controller
        predicts their error from its own commands (:attr:`lag_keep`).
    lag_keep : float
        ``exp(-dt / tau)`` of that motor lag (tau, s): each step the predicted thrust
        error ``e_T`` (N, thrust minus the nominal's) becomes ``lag_keep e_T + (1 -
        lag_keep) (u - u_d)``, the lag's exact step with the applied command held,
        relative to the nominal's.
    """

    dt: float
    rho: float
    L_e: float
    thrust_min: float
    thrust_max: float
    thrust_idle: float
    int_limit: tuple[float, ...]
    int_of: tuple[int, ...]
    pose_delay: float = 0.0
    pose_timeout: float = 0.05
    quat_tolerance: float = 0.01
    gyro_range: float = 34.9  # 2000 deg/s
    gyro_scale: tuple[float, ...] = (1.0, 1.0, 1.0)
    gyro_bias: tuple[float, ...] = (0.0, 0.0, 0.0)
    accel_scale: tuple[float, ...] = (1.0, 1.0, 1.0)
    accel_bias: tuple[float, ...] = (0.0, 0.0, 0.0)
    q_MB: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0)
    accel_range: float = 156.9  # 16 g
    k_pos: float = 0.3
    k_vel: float = 0.04
    k_att: float = 0.15
    pose_period: float = 0.005
    motor_slot: tuple[int, ...] = (0, 1, 2, 3)
    normalized: bool = False
    thr_mdl_fac: float = 0.0
    thrust_full: float = 0.0
    n_lag: int = 0
    lag_keep: float = 0.0

    def __post_init__(self):
        lim = self.int_limit
        lim = (lim,) * len(self.int_of) if np.ndim(lim) == 0 else tuple(lim)
        if len(self.int_of) > MAX_INT or len(lim) != len(self.int_of):
            raise ValueError(f"int_limit: {len(lim)} bounds for {len(self.int_of)} integral "
                             f"states (at most {MAX_INT})")
        # float32, as gs_ctrl_params holds them: the same clamp and status in C and here
        object.__setattr__(self, "int_limit", tuple(float(np.float32(v)) for v in lim))
        if self.n_lag not in (0, 4) or not 0.0 <= self.lag_keep < 1.0:
            raise ValueError(f"n_lag {self.n_lag}, lag_keep {self.lag_keep}: a motor lag's "
                             "4 thrusts with 0 <= lag_keep < 1, or none")
        object.__setattr__(self, "lag_keep", float(np.float32(self.lag_keep)))
        for name in ("gyro_scale", "gyro_bias", "accel_scale", "accel_bias"):
            v = tuple(float(np.float32(x)) for x in getattr(self, name))
            if len(v) != 3 or not all(math.isfinite(x) for x in v):
                raise ValueError(f"{name}: 3 finite numbers (x, y, z), got {v}")
            object.__setattr__(self, name, v)
        for name in ("gyro_scale", "accel_scale"):
            if not all(x > 0 for x in getattr(self, name)):
                raise ValueError(f"{name}: each > 0, got {getattr(self, name)}")
        q = tuple(float(np.float32(x)) for x in self.q_MB)
        if len(q) != 4 or not all(math.isfinite(x) for x in q) or \
                abs(sum(x * x for x in q) - 1.0) > Q_MB_TOLERANCE:
            raise ValueError(f"q_MB: a unit quaternion (w, x, y, z), got {q}")
        object.__setattr__(self, "q_MB", q)

    @property
    def delay_steps(self) -> int:
        """The pose delay in control steps, as the C controller rounds it (float32)."""
        return int(np.float32(self.pose_delay) / np.float32(self.dt) + np.float32(0.5))

    @property
    def timeout_steps(self) -> int:
        """The pose timeout in control steps (float32, as in C)."""
        return int(np.float32(self.pose_timeout) / np.float32(self.dt) + np.float32(0.5))

    def c_array(self) -> np.ndarray:
        """:meth:`c_fields` flattened to float32 (the integers as floats): what the SIL
        and PIL drivers read into a ``gs_ctrl_params``."""
        return np.array([float(x) for _, _, v in self.c_fields() for x in np.ravel(v)],
                        dtype=np.float32)

    def c_fields(self) -> list[tuple[str, str, float | int | tuple[int, ...]]]:
        """The ``gs_ctrl_params`` fields in its order: ``(name, C type, value)``, the type
        ``"float"``, ``"float[n]"``, ``"uint32_t"`` or ``"uint32_t[n]"`` (``int_limit`` is
        padded to ``MAX_INT`` with 0, ``int_of`` is ``n_int`` and the array padded to
        ``MAX_INT``)."""
        out = []
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "int_limit":
                out.append(("int_limit", f"float[{MAX_INT}]",
                            tuple(float(x) for x in v) + (0.0,) * (MAX_INT - len(v))))
            elif f.name == "int_of":
                out += [("n_int", "uint32_t", len(v)),
                        ("int_of", f"uint32_t[{MAX_INT}]", tuple(v) + (0,) * (MAX_INT - len(v)))]
            elif f.type == "float":
                out.append((f.name, "float", float(v)))
            elif f.type in ("bool", "int"):
                out.append((f.name, "uint32_t", int(v)))
            elif f.type == "tuple[float, ...]":
                out.append((f.name, f"float[{len(v)}]", tuple(float(x) for x in v)))
            else:  # tuple[int, ...]
                out.append((f.name, f"uint32_t[{len(v)}]", tuple(int(i) for i in v)))
        return out

    def commands_from_thrust(self, thrust) -> np.ndarray:
        """The controller's outputs of thrusts: renumbered by :attr:`motor_slot` and, when
        :attr:`normalized`, through the thrust curve (``gs_ctrl_commands``).

        Parameters
        ----------
        thrust : array_like, shape (..., 4), N
            Thrusts of the tool's motors T1..T4.

        Returns
        -------
        ndarray, shape (..., 4)
            The outputs in slot order: N, or commands in 0..1.

        Examples
        --------
        >>> p = controller_params(gs.load_table("tables/paper.h5"), motor_slot=(2, 1, 3, 0))
        >>> p.commands_from_thrust([1.0, 2.0, 3.0, 4.0]).tolist()
        [4.0, 2.0, 1.0, 3.0]
        """
        t = np.asarray(thrust, dtype=float)
        c = command_from_thrust(t, self.thr_mdl_fac, self.thrust_full) if self.normalized else t
        out = np.empty_like(c)
        out[..., list(self.motor_slot)] = c
        return out

    def thrust_from_commands(self, commands) -> np.ndarray:
        """The thrusts of the controller's outputs: the inverse of
        :meth:`commands_from_thrust` (what the flight stack's mixer and motors do).

        Parameters
        ----------
        commands : array_like, shape (..., 4)
            Outputs in slot order: N, or commands in 0..1 when :attr:`normalized`.

        Returns
        -------
        ndarray, shape (..., 4), N
            Thrusts of the tool's motors T1..T4.

        Examples
        --------
        >>> p = controller_params(gs.load_table("tables/paper.h5"), motor_slot=(2, 1, 3, 0))
        >>> p.thrust_from_commands([4.0, 2.0, 1.0, 3.0]).tolist()
        [1.0, 2.0, 3.0, 4.0]
        """
        c = np.asarray(commands, dtype=float)[..., list(self.motor_slot)]
        if self.normalized:
            return thrust_from_command(c, self.thr_mdl_fac, self.thrust_full)
        return c


def _dense_data(table):
    """The dense float32 form (RuntimeData) of a table, a RuntimeData, a CompactData (the
    dense form it was made from) or a lookup holding one (``.data``)."""
    from .compact import CompactData
    from .runtime import RuntimeData, runtime_data

    if isinstance(table, CompactData):
        return table.base
    if isinstance(table, RuntimeData):
        return table
    if hasattr(table, "data"):  # an Interpolator, a CompactInterpolator, a scheduler
        return _dense_data(table.data)
    return runtime_data(table)


def int_limits_for(table, thrust_min: float, thrust_max: float, n_int: int,
                   fraction: float = INT_RANGE_FRACTION) -> tuple[float, ...]:
    """The default bound of each integral state (rad s), sized from the table's gains:
    at its bound, the integral term ``K[j, 10 + i] x_i`` alone commands at most
    ``fraction`` of a motor's range, on every motor j at every operating point of the
    table (integrator clamping to the actuator range, with the scheduled gains)::

        k_i     = max over the feasible points and the motors of |K[:, 10 + i]|   (N / rad s)
        limit_i = fraction * (thrust_max - thrust_min) / k_i                       (rad s)

    With the default ``fraction = 1`` an integral at its bound asks, by its own term, for
    a whole motor range where its gain is largest (less elsewhere): beyond that it cannot
    be holding a model error the motors can follow, it is winding up, and
    ``CTRL_INT_LIMIT`` says so. Two integral states whose gains differ 20x get bounds
    that differ 20x: each one's largest command is the same share of the motors. (The
    integral's command is not the thrust it moves: in a steady state the proportional
    terms balance most of it. On configs/recommended.toml's level table at 12 m/s, a
    plant with rotor drag and motor lag holds int_delta at 0.069 rad s, a 1.3 N command,
    with no motor clipped: a bound sized from the thrust reserve above the
    nominal, 0.5 x 1.88 N / 35 N per rad s = 0.027 rad s, would hold it at its bound, 6
    cm out of the circle's plane.) The conditional integration (no integration while a
    motor is clipped) stays the anti-windup; this bound is what the integral may hold.

    The gains are the runtime's float32 data (the same bits in C), the bounds rounded
    to float32, as ``gs_ctrl_params`` holds them: a table, its RuntimeData and its
    CompactData give the same bounds. An integral state with no gain at any feasible
    point (in a table without a feasible point, whose controller never engages: every
    lookup is ``NO_GAINS``) gets :data:`INT_LIMIT_NO_GAINS`: its bound does not act on
    the command.

    Parameters
    ----------
    table : Table, RuntimeData, CompactData or Interpolator
        The table the controller flies.
    thrust_min, thrust_max : float, N
        Each motor's range (the controller's clip: ``vehicle.thrust_min``, ``thrust_max``).
    n_int : int
        The integral states (the table's LQR state has them after the 10 reduced ones).
    fraction : float
        The share of the motor range an integral term may command, in (0, 1].

    Returns
    -------
    tuple of float, rad s
        One bound per integral state, in the LQR state's order.

    Raises
    ------
    InputError
        The table's LQR state has no room for ``n_int`` integral states.

    Examples
    --------
    >>> lim = int_limits_for(gs.load_table("tables/paper.h5"), 0.1, 3.5, 1)  # int_delta
    >>> [round(v, 2) for v in lim]   # 3.4 N / 0.818 N per rad s
    [4.15]
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction must be in (0, 1], got {fraction!r}")
    if not thrust_max > thrust_min:
        raise ValueError(f"no motor range: thrust_min {thrust_min!r}, thrust_max {thrust_max!r}")
    d = _dense_data(table)
    n_a, n_v, n_xi, n = d.dims
    if N_STATE + n_int > n:
        raise InputError(d.name, "n_state", f"{n} states hold no {n_int} integral states")
    ok = d.mask == 0  # feasible, with gains (n_a, n_v, n_xi)
    K = np.empty((n_a, n_v, n_xi, 4, n))
    K[0] = np.asarray(d.K_tilt0, dtype=float).reshape(n_v, d.n_xi_tilt0, 4, n)
    K[1:] = np.asarray(d.K, dtype=float)
    span = fraction * (float(thrust_max) - float(thrust_min))
    out = []
    for i in range(n_int):
        k = float(np.max(np.abs(K[..., N_STATE + i][ok]), initial=0.0))
        out.append(float(np.float32(span / k if k > 0.0 else INT_LIMIT_NO_GAINS)))
    return tuple(out)


def controller_params(table, **overrides) -> ControllerParams:
    """The controller's parameters of the table it flies: the design parameters the
    table carries (its firmware record, computed at the build from its config: the loop,
    the vehicle and the motors, the outputs, the accelerometer range sized from the grid,
    the motor lag; :func:`~gainsched.schedule.onboard.controller_from_config`), the
    integral states' bounds (``[control] int_limit``, else sized from the table's gains:
    :func:`int_limits_for`), plus the sensing fields (defaults of
    :class:`ControllerParams`, or ``overrides``).

    Parameters
    ----------
    table : Table, RuntimeData, CompactData or Interpolator
        The table the controller flies (a lookup holding one: ``.data``).
    **overrides
        Sensing: ``pose_delay``, ``pose_timeout``, ``quat_tolerance``, ``gyro_range``,
        ``accel_range``, ``k_pos``, ``k_vel``, ``k_att``, ``pose_period``,
        ``thrust_idle``, ``int_limit`` (rad s: one number for every integral state, or
        one per state); and outputs replacing the table's (``export-c --motor-order``,
        ...): ``motor_slot``, ``normalized``, ``thr_mdl_fac``, ``thrust_full``.

    Returns
    -------
    ControllerParams

    Raises
    ------
    TypeError
        An unknown field.
    InputError
        The table carries no controller parameters (a RuntimeData made by hand).

    Examples
    --------
    >>> p = controller_params(gs.load_table("tables/paper.h5"), pose_delay=0.012)
    >>> p.dt, p.rho, p.int_of, p.delay_steps, [round(v, 2) for v in p.int_limit]
    (0.001, 1.5, (0,), 12, [4.15])
    """
    d = _dense_data(table)
    names = {f.name for f in fields(ControllerParams)} - {
        "dt", "rho", "L_e", "thrust_min", "thrust_max", "int_of", "n_lag", "lag_keep"}
    for k in overrides:
        if k not in names:
            raise TypeError(f"controller_params() got an unexpected field {k!r}")
    if d.controller is None:
        raise InputError(d.name, "firmware/controller", "the table carries no controller "
                         "parameters; rebuild it (gainsched build CONFIG)")
    rec = dict(d.controller)
    int_of = tuple(int(i) for i in rec["int_of"])
    limit = overrides.pop("int_limit", rec["int_limit"])
    if limit is None and int_of:
        limit = int_limits_for(d, rec["thrust_min"], rec["thrust_max"], len(int_of))
    out = {**rec, "int_limit": () if limit is None else limit, "int_of": int_of, **overrides}
    out.update(motor_slot=tuple(int(i) for i in out["motor_slot"]),
               normalized=bool(out["normalized"]), n_lag=int(out["n_lag"]))
    return ControllerParams(**out)
