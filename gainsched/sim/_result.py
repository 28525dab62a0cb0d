"""What a flight leaves: :class:`SimResult`, the per-step histories it is made from
(``_Record``) and the accelerometer of the flown path (:func:`specific_force`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import N_STATE, Config, Sensors
from ..rotations import matrix_from_quaternion
from ._plant import _Plant
from ._scenario import Scenario

__all__ = [
    "SimResult",
    "specific_force",
]


@dataclass(frozen=True)
class SimResult:
    """Time histories of a simulated flight, one sample per control step.

    What :func:`simulate` returns: N samples at the design's control step ``dt`` from
    t = 0, ``round(duration / dt) + 1``, fewer when the tether went slack (the flight
    stops there, ``slack_time``). Reduced states are in the order (delta, xi, delta', xi',
    phi, theta, chi, omega_x, omega_y, omega_z), rad and rad/s (docs/conventions.md), xi
    continuous (a lap adds 2 pi). Motors 1..4 in the X layout.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time of each control step, s.
    z : ndarray, shape (N, 10)
        True reduced state of the plant, rad, rad/s.
    z_hat : ndarray, shape (N, 10)
        The controller's estimate of it (``z`` with ideal sensing), rad, rad/s.
    z_d : ndarray, shape (N, 10)
        Nominal state along the reference path (from the design model, or the table's
        feed-forward with ``controller="firmware"``), rad, rad/s.
    u : ndarray, shape (N, 4)
        Applied (saturated) motor thrust commands, N, held over each step.
    u_d : ndarray, shape (N, 4)
        Nominal (feed-forward) motor thrusts, N.
    tension : ndarray, shape (N,)
        Tether tension of the plant at each step, N (negative: slack).
    p_I : ndarray, shape (N, 3)
        What the motion capture tracks, in the inertial frame (origin at the anchor, z up),
        m: the frame centre (the COG unless ``[effects.cog_offset]`` moves it).
    q_IB : ndarray, shape (N, 4)
        Attitude quaternion (w, x, y, z), Hamilton, body -> inertial.
    saturated : ndarray of bool, shape (N, 4)
        The motor's command was clipped to the plant's ``thrust_min`` or ``thrust_max``.
    status : ndarray of int32, shape (N,)
        Status bits of the gain lookup (:mod:`gainsched.firmware.runtime`: 0 OK,
        ``CLAMPED_SPEED`` 0x01, ``NO_GAINS`` 0x08, ...; ``status_text`` names them).
    slack_time : float or None
        Time the tether went slack and the simulation stopped, s; None: it stayed taut.
    scenario : Scenario
        The flight that was flown.
    r : float
        Nominal COG radius ``rho + L_e`` of the design model, m.
    mass : float
        Mass of the plant, kg.
    g : float
        Gravity of the plant, m/s^2.
    held : ndarray of bool, shape (N,), or None
        The lookup was unusable (``NO_GAINS``, bad input) and the last good gains were
        flown, the firmware's policy.
    tension_d : ndarray, shape (N,), or None
        Tension of the nominal, N.
    min_tension : float
        The design config's tension margin (``[feasibility] min_tension``), N.
    f_B : ndarray, shape (N, 3), or None
        Specific force at the COG in the body frame, ``R_IB^T (a_I + g e_z)``, m/s^2: what
        an ideal accelerometer senses (from second differences of ``p_I``).
    controller_status : ndarray of int32, shape (N,), or None
        ``controller="firmware"``: the controller's whole status, the lookup's bits with
        the ``CTRL_*`` bits of :mod:`gainsched.firmware.controller` (``HELD``,
        ``SATURATED``, ``BAD_POSE``, ``STALE_POSE``, ``BAD_IMU``, ``IDLE``); else None.
    vbat : ndarray, shape (N,), or None
        The battery's terminal voltage, V, when the plant has a battery (an effect whose
        ``log_channel`` is ``"vbat"``: ``[effects.thrust_voltage]``, rigid link); else None.
    sensors : Sensors
        The plant's on-board sensors (its config's ``[sensors]``): what its gyro reads,
        ``gyro_scale * omega + gyro_bias`` (:func:`log_from_result` logs that).
    """

    t: np.ndarray
    z: np.ndarray
    z_hat: np.ndarray
    z_d: np.ndarray
    u: np.ndarray
    u_d: np.ndarray
    tension: np.ndarray
    p_I: np.ndarray
    q_IB: np.ndarray
    saturated: np.ndarray
    status: np.ndarray
    slack_time: float | None
    scenario: Scenario
    r: float
    mass: float
    g: float
    held: np.ndarray | None = None
    tension_d: np.ndarray | None = None
    min_tension: float = 0.0
    f_B: np.ndarray | None = None
    controller_status: np.ndarray | None = None
    vbat: np.ndarray | None = None
    sensors: Sensors = Sensors()


def specific_force(p_I, q_IB, dt: float, g: float) -> np.ndarray:
    """What an accelerometer at the frame centre (the IMU, beside the markers; the COG
    unless ``[effects.cog_offset]`` moves it) senses, ``f_B = R_IB^T (a_I + g e_z)`` (N, 3)
    m/s^2, at the control steps: ``a_I`` from second differences of its positions ``p_I``
    (N, 3) m, which the plant integrates at step ``dt`` s (error O(dt^2); the ends repeat
    their neighbours), ``q_IB`` (N, 4) the attitude, ``g`` m/s^2."""

    a = np.zeros_like(p_I)
    if len(p_I) >= 3:
        a[1:-1] = (p_I[2:] - 2 * p_I[1:-1] + p_I[:-2]) / (dt * dt)
        a[0], a[-1] = a[1], a[-2]
    a[:, 2] += g
    return np.einsum("nji,nj->ni", matrix_from_quaternion(q_IB), a)


class _Record:
    """The per-step histories of a flight, preallocated, and the :class:`SimResult` they
    make: plant states ``X`` (poses are computed after the loop), true and estimated
    reduced states, applied thrusts, tension, saturation, status, held gains."""

    def __init__(self, n_steps: int, x, P: _Plant):
        self.P = P
        self.X = np.empty((n_steps, x.size))
        self.Z = self.X[:, :N_STATE] if P.maximal is None else np.empty((n_steps, N_STATE))
        self.Zh = np.empty((n_steps, N_STATE))
        self.U = np.empty((n_steps, 4))
        self.TEN = np.empty(n_steps)
        self.SAT = np.zeros((n_steps, 4), dtype=bool)
        self.STAT = np.zeros(n_steps, dtype=np.int32)
        self.HELD = np.zeros(n_steps, dtype=bool)
        self.CTRL = None  # the firmware controller's status bits (its loop sets them)

    def result(self, n_done: int, t, z_d, u_d, tension_d, slack_time, scenario, r: float,
               design: Config, plant: Config) -> SimResult:
        """The first ``n_done`` steps as a :class:`SimResult`."""
        sl = slice(0, n_done)
        PI, QI = self.P.poses(self.X[sl], scenario.tilt, scenario.gamma)
        dt = design.control.dt
        return SimResult(t[sl], self.Z[sl].copy(), self.Zh[sl], z_d[sl], self.U[sl], u_d[sl],
                         self.TEN[sl], PI, QI, self.SAT[sl], self.STAT[sl], slack_time,
                         scenario, r, plant.vehicle.mass, plant.g, self.HELD[sl],
                         tension_d[sl], design.feasibility.min_tension,
                         specific_force(PI, QI, dt, plant.g),
                         None if self.CTRL is None else self.CTRL[sl],
                         self.P.battery_voltage(self.X[sl]), plant.sensors)
