"""The path controller's state estimate: the true state, or motion-capture poses
fused with a model prediction (paper Sec. V.A)."""

from __future__ import annotations

import numpy as np

from ..config import N_STATE
from ..model.geometry import pose_angles_from_pose, wrap_angle
from ..rotations import (
    matrix_from_euler_zyx_scalar,
)
from .fastplant import reduced_fast_plant


class _Estimator:
    """Ideal state, or motion-capture pose updates fused with a model prediction.

    Between pose samples the estimate is propagated with the design model and
    the applied input. The effect states of a design model (a motor lag's thrusts) are
    never measured: they are predicted from ``z0``'s (the nominal's) with the design
    model and the applied input, ideal sensing or not (what a firmware can run from its
    own commands), and kept in ``effect_states``; :meth:`estimate` hands out the 10
    reduced states. A pose sample (delayed by the latency) corrects the pose
    states and, through the innovation divided by the sample interval, the
    rates (an alpha-beta correction on top of the model prediction); body rates
    come from the gyro. Delayed samples are compared with the estimate of their
    own time (ring buffer) and the correction is applied now.
    """

    def __init__(self, model, plant, sens, dt, alpha, gamma, z0, rng, sensors=None):
        self.model, self.plant, self.sens, self.dt = model, plant, sens, dt
        # (the plant's sensors, the design's calibration of them) when either is not
        # identity: what the gyro and the markers report, and how it is undone
        self.sensors = (sensors if sensors and not all(g.identity for g in sensors)
                        else None)
        self.alpha, self.gamma, self.rng = alpha, gamma, rng
        self.z = z0.copy()
        self.every = max(1, int(round(1.0 / (sens.rate_hz * dt))))
        self.delay = int(round(sens.latency / dt))
        self.hist: list[np.ndarray] = []
        self.pending: list[tuple[int, np.ndarray]] = []
        self.R_IC = matrix_from_euler_zyx_scalar(alpha, 0.0, gamma)
        # prediction model: the compiled reduced design model when it applies (its
        # numbers to 1e-12), effect states included; an elastic design link predicts
        # with the reduced (rigid) model too
        fast = None if sens.ideal and model.n_z == N_STATE else reduced_fast_plant(model)
        self._f = ((lambda z, u, a: fast.f(z, u, a, gamma)[0]) if fast is not None
                   else (lambda z, u, a: model.f(z, u, a, gamma)))

    @property
    def effect_states(self) -> np.ndarray:
        """The predicted effect states of the design model (none without one)."""
        return self.z[N_STATE:]

    def estimate(self, k, x, z_true):
        if self.sens.ideal:
            self.z[:N_STATE] = z_true  # the effect states stay predicted
            return z_true
        if k % self.every == 0:  # a pose sample taken now, arriving after the latency
            self.pending.append((k + self.delay, self._measure(x, self.z[1])))
        self.hist.append(self.z.copy())
        while self.pending and self.pending[0][0] <= k:
            _, meas = self.pending.pop(0)
            then = self.hist[-1 - self.delay] if len(self.hist) > self.delay else self.z
            innov = meas - then[[0, 1, 4, 5, 6]]
            innov[1] = wrap_angle(innov[1])
            innov[4] = wrap_angle(innov[4])
            T = self.every * self.dt
            self.z[[0, 1, 4, 5, 6]] += 0.5 * innov
            self.z[[2, 3]] += 0.5 * innov[[0, 1]] / T * 0.5
        if len(self.hist) > self.delay + 2:
            self.hist.pop(0)
        z = self.z[:N_STATE].copy()
        noise = self.sens.gyro_noise * self.rng.standard_normal(3)
        if self.sensors is None:
            z[7:10] = z_true[7:10] + noise
        else:  # what the plant's gyro reads, undone by the design's calibration
            z[7:10] = self.sensors[1].body_rates(self.sensors[0].readings(z_true[7:10]) + noise)
        return z

    def _measure(self, x, xi_near):
        """Noisy pose -> (delta, xi, phi, theta, chi), rad, shape (5,).

        True COG position and attitude in I, plus position noise (m) and a small
        attitude perturbation ``R_IB Rz Ry Rx`` (rad), converted back to the reduced
        pose angles (:func:`~gainsched.model.geometry.pose_angles_from_pose`) with xi on
        the branch nearest ``xi_near`` (the estimate: the azimuth is tracked continuously,
        as a firmware must, from what it knows).
        """
        p_I, R_IB = self.plant.pose(x, self.alpha, self.gamma)
        p_I = p_I + self.sens.position_noise * self.rng.standard_normal(3)
        rot = self.sens.attitude_noise * self.rng.standard_normal(3)
        R_IB = R_IB @ matrix_from_euler_zyx_scalar(rot[0], rot[1], rot[2])
        if self.sensors is not None:  # the plant's markers' attitude, turned by the design's
            R_IB = self.sensors[1].body_attitude(self.sensors[0].marker_attitude(R_IB))
        R_CI = self.R_IC.T
        return pose_angles_from_pose(R_CI @ p_I, R_CI @ R_IB, self.model.p_e_frame,
                                     xi_near)[1]

    def predict(self, u):
        if self.sens.ideal and self.z.size == N_STATE:
            return
        self.z = self.z + self.dt * self._f(self.z, u, self.alpha)
