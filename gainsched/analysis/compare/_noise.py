"""The noise floor: the residual that measurement noise of the estimated level alone
produces (the noise added once more and pushed through the same pipeline).
"""

from __future__ import annotations

import math

import numpy as np

from ...config import Config
from ...model.reduced import Model
from ...rotations import (
    matrix_from_quaternion,
)
from ..logs import FlightLog
from ._measured import (
    Measured,
    _accelerometer,
    _gyro,
    _raw_channels,
    _reconstruct,
    _smoothed,
)
from ._predict import predict
from ._residual import _residual


def _noisy(log: FlightLog, meas: Measured, config: Config, rng, rng_gyro=None,
           rng_accel=None) -> Measured:
    """The same segment with motion-capture noise of the estimated level added once more:
    position noise (std from the tether-distance channel, where attitude noise does not
    enter to first order) and attitude noise (std from the roll and pitch channels); and
    gyro and accelerometer noise of their estimated levels when they are used (from
    ``rng_gyro`` and ``rng_accel``, their own streams, so that the pose's noise does not
    depend on which sensors are used)."""
    an = config.analysis
    sp = meas.raw_sigma["d"]
    sa = 0.5 * (meas.raw_sigma["phi"] + meas.raw_sigma["theta"])
    n = len(log)
    rot = sa * rng.standard_normal((n, 3))
    from ...rotations import Rx, Ry, Rz

    R_IB = matrix_from_quaternion(log.q) @ Rz(rot[:, 2]) @ Ry(rot[:, 1]) @ Rx(rot[:, 0])
    raw = _raw_channels(log, meas.L_e, config.sensors,
                        log.p_I + sp * rng.standard_normal((n, 3)), R_IB)
    dt = meas.dt
    ch, ch1, ch2 = _smoothed(raw, meas.window, an.savgol_order, dt)
    z, acc, p, v, a, R, w_dot, e, axes = _reconstruct(ch, ch1, ch2, meas.p_e)
    gyro, gyro_dot = None, None
    if meas.gyro is not None:  # the gyro's own noise, once more
        g_sig = np.array([meas.raw_sigma[k] for k in ("p", "q", "r")])
        gyro, gyro_dot = _gyro(log, an, meas.window, dt, config.sensors,
                               g_sig * (rng_gyro or rng).standard_normal((n, 3)))
    accel = None
    if meas.accel is not None:  # the accelerometer's own noise, once more
        a_sig = np.array([meas.raw_sigma[k] for k in ("ax", "ay", "az")])
        accel = _accelerometer(log, an, config.sensors,
                               a_sig * (rng_accel or rng).standard_normal((n, 3)))
    return Measured(meas.name, meas.source, meas.alpha, meas.gamma, meas.t, meas.t_flight,
                    meas.window, meas.order, z, acc, ch[0], ch1[0], p, v, a, R, w_dot, e, axes,
                    meas.T_cmd, meas.tension, meas.raw_sigma, meas.L_e, meas.p_e, gyro=gyro,
                    gyro_dot=gyro_dot, accel=accel, gravity_C=meas.gravity_C,
                    vbat=meas.vbat)


def noise_floor(config: Config, measured, segs, *, effects=None, latency=None,
                seed: int = 0) -> tuple[dict, dict]:
    """RMS change of each residual axis when measurement noise of the estimated level is
    added once more (motion capture on the raw pose channels, the gyro's on the gyro, the
    accelerometer's on the accelerometer): the residual the noise alone explains.

    Returns ``(floors, pose_floors)``: the floor per axis, and for the axes measured with
    an on-board sensor (rotational: gyro; translational: accelerometer) the floor they
    would have from the pose alone (twice differentiated): what the sensor saves.
    """
    model = Model(config, effects)
    rng, rng_gyro, rng_accel = (np.random.default_rng(seed + i) for i in range(3))
    acc: dict = {}
    pose: dict = {}

    def add(store, ax, d):
        s, k = store.get(ax, (0.0, 0))
        store[ax] = (s + float(np.sum(d * d)), k + d.size)

    for m, s in zip(measured, segs, strict=True):
        p0 = predict(model, m, latency=latency)
        r0 = _residual(model, m, p0)
        mn = _noisy(s, m, config, rng, rng_gyro, rng_accel)
        p1 = predict(model, mn, latency=latency)
        r1 = _residual(model, mn, p1)
        for ax in r0.residual:
            add(acc, ax, r1.residual[ax] - r0.residual[ax])
        c = m.core
        if m.gyro_dot is not None:
            for j, ax in enumerate(("roll", "pitch", "yaw")):
                add(pose, ax, (mn.omega_dot[c, j] - p1.omega_dot_pose[c, j])
                    - (m.omega_dot[c, j] - p0.omega_dot_pose[c, j]))
        if m.accel is not None:
            d1 = np.einsum("nij,nj->ni", mn.axes[c], mn.a[c]) - p1.acc[c]
            d0 = np.einsum("nij,nj->ni", m.axes[c], m.a[c]) - p0.acc[c]
            for j, ax in enumerate(("tangential", "normal", "radial")):
                if ax in r0.residual:
                    add(pose, ax, d1[:, j] - d0[:, j])
    rms = lambda store: {ax: math.sqrt(s / k) for ax, (s, k) in store.items()}  # noqa: E731
    return rms(acc), rms(pose)
