"""The firmware's whole control loop, pose and gyro in, four thrusts out: the Python
reference of ``gainsched_control.c``.

One control step (``gs_ctrl_update``; docs/runtime.md, "The controller"):

1. **Estimator.** The COG position ``p_I``, velocity ``v_I`` and attitude ``q_IB``
   (inertial frame I) are propagated every step with the gyro ``omega_B`` and the
   accelerometer ``f_B`` (specific force at the COG, B)::

       q <- q (x) dq(omega_B dt)                 (third order in |omega dt|)
       a_I = R_IB f_B - g e_z
       p <- p + dt v + dt^2 / 2 a_I,   v <- v + dt a_I

   Without an accelerometer the motion is the circle's at the last estimate: the
   velocity turns by ``theta = (xi' + xi''_ref dt / 2) dt`` about the circle's normal
   ``n`` (the centripetal acceleration, integrated exactly: a constant-speed circle stays
   one, at its speed) and ``a_I = r xi''_ref`` along the circle::

       v <- Rot(theta n) v + dt a_I,   p <- p + int_0^dt Rot(theta n s / dt) v ds + dt^2 / 2 a_I

   A pose
   arrives ``D = round(pose_delay / dt)`` steps after it was taken; it is compared with
   the estimate of that time (a ring buffer of the last ``D + 1`` estimates), and that
   estimate, every later one and the current one are corrected (paper Sec. V.A: the
   inertial measurements compensate the radio link's latency)::

       e_p = p_pose - p[k - D],   e_theta = 2 vec(q_pose (x) q[k - D]^*)     (in I)
       p[k - D + i] += k_pos e_p + i dt (k_vel / T_pose) e_p,   i = 0..D
       v += (k_vel / T_pose) e_p,  q[k - D + i] <- dq(k_att e_theta) (x) q[k - D + i]

2. **Reduced state** (:func:`reduced_from_kinematics`): the attachment point
   ``p_t = p_C - L_e x_B`` in the circle frame ``R_IC = Rz(gamma) Rx(alpha)``, ``delta``,
   ``xi`` and their rates from ``p_t`` and its velocity, the Z-Y-X angles of ``R_CB``,
   ``chi = psi - xi``, the gyro's body rates.

3. **Control.** The lookup with the manoeuvre feed-forward at the reference (``K``,
   ``x_d``, ``u_d``: :func:`~gainsched.firmware.feedforward.feedforward`), the errors
   ``x - x_d`` with the azimuth error unwrapped from the previous step's,
   ``u = u_d - K (x - x_d)``, the clip to ``[thrust_min, thrust_max]``, and the integral
   states integrating their errors unless a motor is clipped (anti-windup), each within
   its own bound ``int_limit[i]`` (sized from the table's gains by default:
   :func:`int_limits_for`).

4. **Status policy** (bits ``CTRL_*`` above the runtime's): an unusable lookup flies the
   last good gains (``CTRL_HELD``); no good gains yet, a bad reference or no estimate:
   the idle thrusts (``CTRL_IDLE``); a rejected pose (``CTRL_BAD_POSE``) is skipped; no
   pose for ``pose_timeout`` (``CTRL_STALE_POSE``) drops the position and velocity
   feedback and freezes the integrators; a bad gyro sample (``CTRL_BAD_IMU``) keeps
   the last good one and drops the rate feedback; an integral state at its bound
   ``int_limit[i]`` sets ``CTRL_INT_LIMIT`` (the error it integrates is more than it can
   hold: the model misses something, or the bound is too tight).

5. **Outputs** (:meth:`ControllerParams.commands_from_thrust`): the thrusts, renumbered
   to the flight stack's motors and, for PX4, as normalised commands through its thrust
   curve (``[firmware] motor_order``, ``command``; docs/runtime.md, "PX4"). By default
   the thrusts of T1..T4 in N.

Its parameters (:class:`ControllerParams`, :func:`controller_params`, from the table
alone) live in :mod:`gainsched.firmware.params` and are re-exported here. This module
computes the step in double precision; tests/firmware/test_controller.py holds
the C controller (compiled for the host, and on the emulated Cortex-M4F) to it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from ..constants import N_STATE
from ..errors import InputError
from ..rotations import matrix_from_quaternion
from ..schedule.onboard import accel_range_for, largest_specific_force, outputs_from_config
from ..schedule.path import AzimuthPath
from .feedforward import FeedForward, feedforward
from .params import (
    INT_LIMIT_NO_GAINS,
    INT_RANGE_FRACTION,
    MAX_INT,
    ControllerParams,
    controller_params,
    int_limits_for,
)
from .runtime import (
    BAD_ARG,
    BAD_INPUT,
    NO_GAINS,
    STATUS_NAMES,
    TILT_LIMIT,
    XI_DERIV_LIMIT,
    XI_LIMIT,
)

__all__ = [
    "ControlOutputs",
    "CTRL_HELD",
    "CTRL_SATURATED",
    "CTRL_BAD_POSE",
    "CTRL_STALE_POSE",
    "CTRL_BAD_IMU",
    "CTRL_IDLE",
    "CTRL_INT_LIMIT",
    "CTRL_STATUS_NAMES",
    "FLAG_POSE",
    "FLAG_ACCEL",
    "FLAG_KINEMATICS",
    "INPUT_COLUMNS",
    "INPUT_SLICES",
    "N_INPUT",
    "MAX_DELAY",
    "MAX_INT",
    "MAX_STATE",
    "INT_RANGE_FRACTION",
    "INT_LIMIT_NO_GAINS",
    "ControllerParams",
    "controller_params",
    "int_limits_for",
    "largest_specific_force",
    "accel_range_for",
    "outputs_from_config",
    "reduced_from_kinematics",
    "Controller",
    "ctrl_status_text",
]

# status bits (gainsched_control.h), above the runtime's 0x01..0x80
CTRL_HELD = 0x0100
CTRL_SATURATED = 0x0200
CTRL_BAD_POSE = 0x0400
CTRL_STALE_POSE = 0x0800
CTRL_BAD_IMU = 0x1000
CTRL_IDLE = 0x2000
CTRL_INT_LIMIT = 0x4000
CTRL_STATUS_NAMES = {
    CTRL_HELD: "HELD",
    CTRL_SATURATED: "SATURATED",
    CTRL_BAD_POSE: "BAD_POSE",
    CTRL_STALE_POSE: "STALE_POSE",
    CTRL_BAD_IMU: "BAD_IMU",
    CTRL_IDLE: "IDLE",
    CTRL_INT_LIMIT: "INT_LIMIT",
}

# input flags
FLAG_POSE = 0x1
FLAG_ACCEL = 0x2
FLAG_KINEMATICS = 0x4

#: one step's inputs as a float32 row (the SIL and PIL drivers' layout): name -> columns
INPUT_COLUMNS = {"flags": 1, "p_I": 3, "q_IB": 4, "v_I": 3, "gyro": 3, "accel": 3,
                 "ref": 5, "alpha": 1, "gamma": 1}
N_INPUT = sum(INPUT_COLUMNS.values())
MAX_DELAY = 32  # GS_CTRL_MAX_DELAY
MAX_STATE = 24  # GS_CTRL_MAX_STATE
POSE_LIMIT = 1.0e3  # m, m/s: a pose component beyond it is rejected (GS_CTRL_POSE_LIMIT)
#: rad: without an accelerometer a turn of the velocity beyond it in one step (an estimate
#: far off any circle) is dropped (GS_C_MAX_TURN)
MAX_TURN = 0.5


def _columns():
    out, i = {}, 0
    for k, n in INPUT_COLUMNS.items():
        out[k] = slice(i, i + n)
        i += n
    return out


#: name -> the slice of an input row that :data:`INPUT_COLUMNS` gives it
INPUT_SLICES = _columns()
_COL = INPUT_SLICES


def ctrl_status_text(status: int) -> str:
    """``"OK"`` or the names of the set runtime and controller bits joined by ``|``."""
    status = int(status)
    names = [n for b, n in {**STATUS_NAMES, **CTRL_STATUS_NAMES}.items() if status & b]
    return "|".join(names) if names else "OK"


def _wrap(a):
    """Angle (rad) wrapped to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def reduced_from_kinematics(p_I, v_I, q_IB, omega_B, alpha, gamma, L_e):
    """Reduced state of COG kinematics on a circle (``gs_reduced_from_kinematics``).

    Parameters
    ----------
    p_I, v_I : ndarray, shape (..., 3), m and m/s
        COG position and velocity in I (origin at the anchor, z up).
    q_IB : ndarray, shape (..., 4)
        Unit attitude quaternion (Hamilton, scalar first, body -> I).
    omega_B : ndarray, shape (..., 3), rad/s
        Body rates.
    alpha, gamma : float, rad
        Circle tilt and heading, ``R_IC = Rz(gamma) Rx(alpha)``.
    L_e : float, m
        Attachment offset behind the COG.

    Returns
    -------
    ndarray, shape (..., 10)
        ``(delta, xi, delta', xi', phi, theta, chi, omega_B)``, rad and rad/s; xi and chi
        in [-pi, pi].
    """
    p_I, v_I, q_IB, omega_B = (np.asarray(a, dtype=float) for a in (p_I, v_I, q_IB, omega_B))
    sa, ca, sg, cg = math.sin(alpha), math.cos(alpha), math.sin(gamma), math.cos(gamma)
    C = np.array([[cg, sg, 0.0], [-sg * ca, cg * ca, sa], [sg * sa, -cg * sa, ca]])  # R_CI
    R = C @ matrix_from_quaternion(q_IB)  # R_CB
    p = p_I @ C.T - L_e * R[..., :, 0]
    w = omega_B
    v = v_I @ C.T - L_e * w[..., 2:3] * R[..., :, 1] + L_e * w[..., 1:2] * R[..., :, 2]
    h2 = p[..., 0] ** 2 + p[..., 1] ** 2
    h = np.sqrt(h2)
    d2 = h2 + p[..., 2] ** 2
    z = np.empty(p.shape[:-1] + (10,))
    z[..., 0] = np.arctan2(h, p[..., 2])
    z[..., 1] = np.arctan2(p[..., 1], p[..., 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        z[..., 2] = np.where(h > 0, (p[..., 2] * (p[..., 0] * v[..., 0] + p[..., 1] * v[..., 1])
                                     / h - h * v[..., 2]) / d2, 0.0)
        z[..., 3] = np.where(h2 > 0, (p[..., 0] * v[..., 1] - p[..., 1] * v[..., 0]) / h2, 0.0)
    z[..., 4] = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    z[..., 5] = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 2, 1], R[..., 2, 2]))
    z[..., 6] = _wrap(np.arctan2(R[..., 1, 0], R[..., 0, 0]) - z[..., 1])
    z[..., 7:10] = w
    return z


def _within(x, limit) -> bool:
    """x finite and within +-limit (the float32 limit, as the C controller compares)."""
    return bool(np.isfinite(x)) and abs(float(np.float32(x))) <= float(limit)


def _sample_ok(v, limit) -> bool:
    """An IMU sample's three axes finite and within +-limit (float32, as in C)."""
    return all(_within(x, np.float32(limit)) for x in v)


def _finite(a) -> bool:
    return bool(np.all(np.isfinite(a)))


def _pose_ok(p, q, tol) -> bool:
    """A usable pose: position within POSE_LIMIT, quaternion with | |q|^2 - 1 | <= tol."""
    if not all(_within(x, POSE_LIMIT) for x in p) or not _finite(q):
        return False
    n2 = float(q @ q)
    return abs(n2 - 1.0) <= tol


def _rotate_left(a, q):
    """``(1, a) (x) q`` renormalised: a small rotation (half angle a, rad) applied in I."""
    w, x, y, z = q
    out = np.array([w - (a[0] * x + a[1] * y + a[2] * z),
                    x + a[0] * w + (a[1] * z - a[2] * y),
                    y + a[1] * w + (a[2] * x - a[0] * z),
                    z + a[2] * w + (a[0] * y - a[1] * x)])
    return out / np.linalg.norm(out)


class ControlOutputs(NamedTuple):
    """What a controller step gives (:meth:`Controller.step`; the C one's on the host
    and on the emulated target, :mod:`gainsched.firmware.host`): one step's, or with a
    leading axis of m steps a recorded sequence's (``run``)."""

    #: (4,) or (m, 4): the motor outputs T1..T4 (thrusts, N, or normalized commands)
    out: np.ndarray
    #: int or (m,) int: the status bits (the lookup's and the ``CTRL_*`` ones)
    status: int | np.ndarray
    #: (10,) or (m, 10): the reduced state estimate the step used
    z: np.ndarray


class Controller:
    """The Python reference of ``gs_ctrl`` (double precision): :meth:`step` is
    ``gs_ctrl_update``.

    Parameters
    ----------
    params : ControllerParams
        The loop, the vehicle and the sensing (:func:`controller_params`).
    lookup : Interpolator or CompactInterpolator
        The table's lookup (the runtime's Python reference), whose data carry the
        closed-form constants of the feed-forward.
    n_state : int
        The table's LQR state dimension.
    g : float, m/s^2
        Gravity (the table's ``gs_vehicle.g``).

    Examples
    --------
    >>> from gainsched.firmware.runtime import Interpolator, runtime_data
    >>> table = gs.load_table("tables/paper.h5")
    >>> params = controller_params(gs.load_config("configs/paper.toml"), table)
    >>> ctl = Controller(params, Interpolator(runtime_data(table)))
    >>> row = np.zeros(N_INPUT)  # nothing measured yet: idle
    >>> thrust, status, _ = ctl.step(row, ctl.nominal_row(0.0, 5.0, 0, 0, 0, 0.0))
    >>> thrust.tolist(), ctrl_status_text(status)  # thrust_idle = thrust_min
    ([0.1, 0.1, 0.1, 0.1], 'IDLE')
    """

    def __init__(self, params: ControllerParams, lookup):
        d = lookup.data
        if d.vehicle is None:
            raise InputError(d.name, "vehicle", "the table carries no closed-form constants: "
                             "the controller has no feed-forward")
        n = int(d.state_sign.size)
        if n > MAX_STATE or N_STATE + len(params.int_of) > n:
            raise InputError(d.name, "n_state", f"{n} states: the controller holds "
                             f"{N_STATE + len(params.int_of)} to {MAX_STATE}")
        if params.n_lag and N_STATE + len(params.int_of) + params.n_lag != n:
            raise InputError(d.name, "n_state", f"{n} states do not end with the "
                             f"{params.n_lag} motor-lag thrusts of the params (n_lag)")
        if not all(math.isfinite(v) and v > 0.0 for v in params.int_limit):
            raise InputError("controller", "int_limit", f"{params.int_limit}: each bound "
                             "must be finite and > 0 (gs_ctrl_init: GS_BAD_ARG)")
        if params.delay_steps > MAX_DELAY:
            raise InputError("controller", "pose_delay", f"{params.pose_delay} s is more "
                             f"than {MAX_DELAY} control steps")
        self.params, self.lookup, self.n = params, lookup, n
        self.g = float(d.vehicle[1])
        self.D = params.delay_steps
        self.timeout = params.timeout_steps
        self.hist_p = np.zeros((MAX_DELAY + 1, 3))
        self.hist_q = np.zeros((MAX_DELAY + 1, 4))
        self.head = 0
        self.v = np.zeros(3)
        self.gyro = self.gyro_prev = np.zeros(3)
        self._gyro_scale = np.array(params.gyro_scale)
        self._gyro_bias = np.array(params.gyro_bias)
        self._accel_scale = np.array(params.accel_scale)
        self._accel_bias = np.array(params.accel_bias)
        self.accel = self.accel_prev = np.zeros(3)
        self.fresh = False
        self.have_fix = self.have_gains = self.have_az = False
        self.since_pose = 0
        self.az_err = 0.0
        self.integ = np.zeros(len(params.int_of))
        self.lag_err = np.zeros(params.n_lag)  # predicted motor-lag thrusts - nominal, N
        self.z = np.zeros(N_STATE)
        self.K_good = np.zeros((4, n))

    # ------------------------------------------------------------------ the nominal
    def nominal(self, ref, alpha) -> FeedForward:
        """The lookup with the feed-forward along rows of references (m, 5) at one tilt:
        what ``gs_lookup_nominal`` gives each step (xi wrapped as the controller does)."""
        ref = np.atleast_2d(np.asarray(ref, dtype=float))
        with np.errstate(invalid="ignore"):
            xi = np.where(np.abs(ref[:, 0]) <= 1e4, _wrap(ref[:, 0]), ref[:, 0])
        path = AzimuthPath(np.zeros(len(ref)), xi, tuple(ref[:, i] for i in range(1, 5)))
        with np.errstate(invalid="ignore", over="ignore"):
            ff = feedforward(self.lookup, path, float(alpha))
            # gs_lookup_nominal refuses non-finite or out-of-limit derivatives
            d = ref[:, 2:5]
            bad = ~np.all(np.isfinite(d) & (np.abs(d.astype(np.float32)) <= XI_DERIV_LIMIT), 1)
        return dataclasses.replace(ff, status=np.where(bad, BAD_INPUT, ff.status))

    def nominal_row(self, xi, xi_dot, xi_ddot, xi_dddot, xi_ddddot, alpha):
        """One step's nominal ``(K (4, n), x_d (10,), u_d (4,), status)``."""
        ff = self.nominal([[xi, xi_dot, xi_ddot, xi_dddot, xi_ddddot]], alpha)
        K = self.lookup(np.array([_wrap(xi)]), np.array([xi_dot]),
                        np.array([float(alpha)])).K[0].astype(float)
        return K, ff.x_d[0], ff.u_d[0], int(ff.status[0])

    # ------------------------------------------------------------------ the estimator
    def reset(self, p_I, v_I, q_IB):
        """Start the estimator at a known state (``gs_ctrl_reset``)."""
        q = np.asarray(q_IB, dtype=float)
        self._start(np.asarray(p_I, float), np.asarray(v_I, float), q / np.linalg.norm(q))

    def _start(self, p, v, q):
        self.hist_p[:] = p
        self.hist_q[:] = q / np.linalg.norm(q)
        self.v = np.array(v, dtype=float)
        self.head = 0
        self.have_fix = True
        self.fresh = True
        self.since_pose = 0

    def _imu(self, row, flags):
        pr = self.params
        st = 0
        self.gyro_prev, self.accel_prev = self.gyro, self.accel
        gyro = row[_COL["gyro"]]
        gyro_bad = not _sample_ok(gyro, pr.gyro_range)
        if gyro_bad:
            st |= CTRL_BAD_IMU
        else:
            # the gyro's calibration undone, as the C controller and the log reader do
            self.gyro = (gyro - self._gyro_bias) / self._gyro_scale
        if flags & FLAG_ACCEL:
            f = row[_COL["accel"]]
            if not _sample_ok(f, pr.accel_range):
                st |= CTRL_BAD_IMU
            else:
                self.accel = (f - self._accel_bias) / self._accel_scale
        return st, gyro_bad

    def _acceleration(self, flags, ref, alpha, gamma):
        """The step's acceleration ``a_I`` and the velocity's turn ``w_I`` (rad, I): with
        the accelerometer the measured one and no turn; without one the circle's turn
        ``(xi' + xi''_ref dt / 2) dt`` about its normal (the centripetal acceleration,
        exactly) and ``r xi''_ref`` along the circle (``gs_c_acceleration``)."""
        if flags & FLAG_ACCEL:
            m = 0.5 * (self.accel_prev + self.accel)
            t = 0.25 * self.params.dt * (self.gyro_prev + self.gyro)  # half the step's turn
            f = m + np.cross(t, m)  # in the step's middle attitude
            a = matrix_from_quaternion(self.hist_q[self.head]) @ f
            a[2] -= self.g
            return a, np.zeros(3)
        dt = self.params.dt
        r = self.params.rho + self.params.L_e
        xd = self.z[3]
        xdd = ref[2] if _within(ref[2], XI_DERIV_LIMIT) else 0.0
        alpha = alpha if _within(alpha, TILT_LIMIT) else 0.0
        gamma = gamma if _within(gamma, XI_LIMIT) else 0.0
        sx, cx = math.sin(self.z[1]), math.cos(self.z[1])
        sa, ca, sg, cg = math.sin(alpha), math.cos(alpha), math.sin(gamma), math.cos(gamma)
        a0, a1 = -r * xdd * sx, r * xdd * cx
        a = np.array([cg * a0 - sg * ca * a1, sg * a0 + cg * ca * a1, sa * a1])
        th = (xd + 0.5 * dt * xdd) * dt
        if not _within(th, MAX_TURN):
            th = 0.0
        return a, th * np.array([sg * sa, -cg * sa, ca])

    def _propagate(self, a, w):
        dt = self.params.dt
        p, q = self.hist_p[self.head], self.hist_q[self.head]
        t = 0.5 * (self.gyro_prev + self.gyro) * dt
        tt = float(t @ t)
        dw, ds = 1 - tt / 8, 0.5 - tt / 48
        d = np.array([dw, *(ds * t)])
        w_, x, y, z = q
        qn = np.array([w_ * d[0] - x * d[1] - y * d[2] - z * d[3],
                       w_ * d[1] + x * d[0] + y * d[3] - z * d[2],
                       w_ * d[2] - x * d[3] + y * d[0] + z * d[1],
                       w_ * d[3] + x * d[2] - y * d[1] + z * d[0]])
        nxt = (self.head + 1) % (MAX_DELAY + 1)
        self.hist_q[nxt] = qn / np.linalg.norm(qn)
        # the velocity turned by w exactly (a constant-speed circle stays one):
        # Rot(w) v = v + S w x v - Cc perp, int_0^dt Rot v = dt (v + Cc w x v - Ss perp)
        th2 = float(w @ w)
        th = math.sqrt(th2)
        if th > 0.0:
            S, Cc, Ss = (math.sin(th) / th, 2 * math.sin(th / 2) ** 2 / th2,
                         (th - math.sin(th)) / (th2 * th))
        else:
            S, Cc, Ss = 1.0, 0.5, 1.0 / 6.0
        wxv = np.cross(w, self.v)
        perp = th2 * self.v - float(w @ self.v) * w
        self.hist_p[nxt] = p + dt * (self.v + Cc * wxv - Ss * perp) + 0.5 * dt * dt * a
        self.v = self.v + S * wxv - Cc * perp + dt * a
        self.head = nxt

    def _correct(self, p_m, q_m):
        pr = self.params
        j0 = (self.head - self.D) % (MAX_DELAY + 1)
        e = p_m - self.hist_p[j0]
        dp, dv = pr.k_pos * e, (pr.k_vel / pr.pose_period) * e
        qh = self.hist_q[j0]
        # q_e = q_m (x) conj(q_h)
        w1, x1, y1, z1 = q_m
        w2, x2, y2, z2 = qh
        qe = np.array([w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2,
                       -w1 * x2 + x1 * w2 - y1 * z2 + z1 * y2,
                       -w1 * y2 + x1 * z2 + y1 * w2 - z1 * x2,
                       -w1 * z2 - x1 * y2 + y1 * x2 + z1 * w2])
        a = pr.k_att * (-1.0 if qe[0] < 0 else 1.0) * qe[1:]
        for i in range(self.D + 1):
            k = (j0 + i) % (MAX_DELAY + 1)
            self.hist_p[k] += dp + i * pr.dt * dv
            self.hist_q[k] = _rotate_left(a, self.hist_q[k])
        self.v = self.v + dv

    def _estimate(self, row, flags, ref, alpha, gamma):
        pr = self.params
        st, gyro_bad = self._imu(row, flags)
        pose_ok = False
        if flags & FLAG_POSE:
            pose_ok = _pose_ok(row[_COL["p_I"]], row[_COL["q_IB"]].astype(float),
                               pr.quat_tolerance)
            if not pose_ok:
                st |= CTRL_BAD_POSE
        if self.have_fix and not self.fresh:
            self._propagate(*self._acceleration(flags, ref, alpha, gamma))
        self.fresh = False
        if pose_ok:
            w1, x1, y1, z1 = row[_COL["q_IB"]].astype(float)
            w2, x2, y2, z2 = self.params.q_MB  # the markers' attitude to the body's
            q = np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                          w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                          w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                          w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])
            q = q / np.linalg.norm(q)
            p = row[_COL["p_I"]].astype(float)
            if self.have_fix:
                self._correct(p, q)
            else:
                self._start(p, np.zeros(3), q)
            self.since_pose = 0
        else:
            self.since_pose += 1
        if self.since_pose > self.timeout:
            st |= CTRL_STALE_POSE
        if self.have_fix and not (_finite(self.hist_p[self.head]) and _finite(self.v)
                                  and _finite(self.hist_q[self.head])):
            self.have_fix = False
        return st, gyro_bad

    # ------------------------------------------------------------------ one step
    def step(self, row, nominal):
        """One control step (``gs_ctrl_update``).

        Parameters
        ----------
        row : ndarray, shape (N_INPUT,)
            The step's inputs (:data:`INPUT_COLUMNS`).
        nominal : tuple
            ``(K (4, n), x_d (10,), u_d (4,), status)`` of the lookup with the
            feed-forward at the row's reference (:meth:`nominal_row`, or one row of
            :meth:`nominal` with the lookup's gains).

        Returns
        -------
        ControlOutputs
            ``out`` (4,): the motor outputs (:meth:`ControllerParams.commands_from_thrust`:
            by default the thrusts of T1..T4, N); ``status`` int; ``z`` (10,): the reduced
            state estimate the step used.
        """
        pr = self.params
        row = np.asarray(row, dtype=float)
        flags = int(row[0])
        ref = row[_COL["ref"]]
        alpha, gamma = float(row[_COL["alpha"]][0]), float(row[_COL["gamma"]][0])
        gyro_bad = False
        if flags & FLAG_KINEMATICS:
            st, gyro_bad = self._imu(row, flags)
            p, v, q = (row[_COL[k]].astype(float) for k in ("p_I", "v_I", "q_IB"))
            if not (_pose_ok(p, q, pr.quat_tolerance) and _pose_ok(v, q, pr.quat_tolerance)):
                st |= CTRL_BAD_POSE
                self.since_pose += 1
                if self.since_pose > self.timeout:
                    st |= CTRL_STALE_POSE
            else:
                self.hist_p[self.head] = p
                self.hist_q[self.head] = q / np.linalg.norm(q)
                self.v = v
                self.have_fix = True
                self.since_pose = 0
            circle = _within(alpha, TILT_LIMIT) and _within(gamma, XI_LIMIT)
            if self.have_fix and not st & CTRL_BAD_POSE and circle:
                self._reduced(alpha, gamma)
        else:
            st, gyro_bad = self._estimate(row, flags, ref, alpha, gamma)
            if self.have_fix and _within(alpha, TILT_LIMIT) and _within(gamma, XI_LIMIT):
                self._reduced(alpha, gamma)
        u, st, z = self._control(nominal, st, gyro_bad, gamma)
        return ControlOutputs(pr.commands_from_thrust(u), st, z)

    def _reduced(self, alpha, gamma):
        self.z = reduced_from_kinematics(self.hist_p[self.head], self.v, self.hist_q[self.head],
                                         self.gyro, alpha, gamma, self.params.L_e)

    def _control(self, nominal, st, gyro_bad, gamma):
        pr = self.params
        K, x_d, u_d, status = nominal
        status = int(status) | (0 if _within(gamma, XI_LIMIT) else BAD_INPUT)
        st |= status
        idle = np.full(4, pr.thrust_idle)
        if status & (BAD_INPUT | BAD_ARG):
            return idle, st | CTRL_IDLE, self.z.copy()
        if status & NO_GAINS:
            if not self.have_gains:
                return idle, st | CTRL_IDLE, self.z.copy()
            st |= CTRL_HELD
        else:
            self.K_good = np.asarray(K, dtype=float).reshape(4, self.n)
            self.have_gains = True
        if not self.have_fix:
            return idle, st | CTRL_IDLE, self.z.copy()
        e = np.zeros(self.n)
        e[:N_STATE] = self.z - x_d
        raw = self.z[1] - x_d[1]
        ez = self.az_err + _wrap(raw - self.az_err) if self.have_az else _wrap(raw)
        e[1] = self.az_err = ez
        self.have_az = True
        e[4], e[6] = _wrap(e[4]), _wrap(e[6])
        if st & CTRL_STALE_POSE:
            e[0:4] = 0.0
        if gyro_bad:
            e[7:10] = 0.0
        m = len(pr.int_of)
        e[N_STATE:N_STATE + m] = self.integ
        e[N_STATE + m:N_STATE + m + pr.n_lag] = self.lag_err
        u = u_d - self.K_good @ e
        if not _finite(u):
            return idle, st | CTRL_IDLE, self.z.copy()
        clipped = bool(np.any((u < pr.thrust_min) | (u > pr.thrust_max)))
        u = np.clip(u, pr.thrust_min, pr.thrust_max)
        if pr.n_lag:  # the lag's exact step with this command held, relative to the nominal
            self.lag_err = pr.lag_keep * self.lag_err + (1.0 - pr.lag_keep) * (u - u_d)
        if clipped:
            st |= CTRL_SATURATED
        elif not st & CTRL_STALE_POSE:
            for i, j in enumerate(pr.int_of):
                lim = pr.int_limit[i]
                self.integ[i] = min(max(self.integ[i] + pr.dt * e[j], -lim), lim)
        if any(abs(v) >= lim for v, lim in zip(self.integ[:m], pr.int_limit, strict=True)):
            st |= CTRL_INT_LIMIT
        return u, st, self.z.copy()

    def run(self, rows) -> ControlOutputs:
        """Run a recorded input sequence (m, N_INPUT) at one tilt: ``out`` (m, 4; thrusts
        by default, :meth:`step`), ``status`` (m,) and the state estimates ``z`` (m, 10)
        of every step."""
        rows = np.asarray(rows, dtype=float)
        m = len(rows)
        ref = rows[:, _COL["ref"]]
        alpha = rows[:, _COL["alpha"]][:, 0]
        with np.errstate(invalid="ignore"):
            xi = np.where(np.abs(ref[:, 0]) <= 1e4, _wrap(ref[:, 0]), ref[:, 0])
        K = np.zeros((m, 4, self.n))
        x_d, u_d, status = np.zeros((m, N_STATE)), np.zeros((m, 4)), np.zeros(m, dtype=int)
        keys = alpha.astype(np.float32).view(np.int32)  # one nominal per tilt (NaN too)
        for key in np.unique(keys):
            sel = keys == key
            a = float(alpha[sel][0])
            ff = self.nominal(ref[sel], a)
            with np.errstate(invalid="ignore", over="ignore"):
                K[sel] = self.lookup(xi[sel], ref[sel, 1], np.full(sel.sum(), a)).K
            x_d[sel], u_d[sel], status[sel] = ff.x_d, ff.u_d, ff.status
        T = np.empty((m, 4))
        S = np.empty(m, dtype=np.int64)
        Z = np.empty((m, N_STATE))
        for k, row in enumerate(rows):
            T[k], S[k], Z[k] = self.step(row, (K[k], x_d[k], u_d[k], int(status[k])))
        return ControlOutputs(T, S, Z)
