"""Log output: a simulated flight as the flight log a real one would leave, and the
run folder of ``gainsched simulate``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..rotations import (
    matrix_from_quaternion,
    quaternion_from_matrix,
)
from ._metrics import metrics
from ._result import SimResult

__all__ = [
    "log_from_result",
    "write_run",
]


def log_from_result(res: SimResult, *, rate_hz: float | None = None, seed: int | None = None):
    """The flight log a real flight would leave: a simulated flight as a FlightLog.

    In the format of docs/flight-log.md, sampled every ``round(1 / (rate_hz dt))``
    control steps: the motion-capture pose with the scenario's position and attitude
    noise (the attitude of the plant's marker frame, ``res.sensors``), the commanded
    thrusts (the mean over each sample interval, as held since the
    previous sample), the gyro (the mean body rate over the interval centred on the
    sample, read through the plant's gyro calibration ``res.sensors``, with the scenario's
    gyro noise), the accelerometer (the mean specific force
    at the COG over the same interval, with the scenario's accelerometer noise), the
    load-cell tension and the reference azimuth and its rate; the battery voltage when the
    plant has a battery (the mean over the interval centred on the sample, no noise).

    Parameters
    ----------
    res : SimResult
        A simulated flight (:func:`simulate`).
    rate_hz : float, optional
        Sampling rate of the log, Hz; default the scenario's motion-capture rate
        (``scenario.sensing.rate_hz``).
    seed : int, optional
        Seed of the pose, gyro and accelerometer noise; default
        ``scenario.sensing.seed + 1000``.

    Returns
    -------
    FlightLog
        One segment, ``source`` ``"simulation NAME"``, metadata ``alpha_c_deg``,
        ``gamma_c_deg``, ``flight_id`` ``"sim-NAME"`` and ``notes``; the optional columns
        ``omega_B`` (rad/s), ``f_B`` (m/s^2), ``tension`` (N), ``xi_ref`` (rad),
        ``xi_dot_ref`` (rad/s), and ``vbat`` (V) with a battery.
        ``gainsched.analysis.logs.write_log`` writes it.

    Examples
    --------
    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> table = gs.load_table("tables/paper.h5")
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> log = gs.log_from_result(gs.simulate(cfg, gs.table_scheduler(table), scn))
    >>> len(log), round(1 / log.dt_median), log.meta["flight_id"], sorted(log.optional)
    (101, 200, 'sim-horizontal', ['f_B', 'omega_B', 'tension', 'xi_dot_ref', 'xi_ref'])

    The design model explains its own simulated flight down to the measurement noise:

    >>> round(gs.compare(cfg, [log]).normalized_rms(), 1)  # 1: residual = noise
    1.0
    """
    from ..analysis.logs import log_from_arrays
    from ..rotations import Rx, Ry, Rz

    sens = res.scenario.sensing
    rate = sens.rate_hz if rate_hz is None else rate_hz
    dt = res.t[1] - res.t[0]
    every = max(1, int(round(1.0 / (rate * dt))))
    idx = np.arange(0, res.t.size, every)
    rng = np.random.default_rng(sens.seed + 1000 if seed is None else seed)
    p = res.p_I[idx] + sens.position_noise * rng.standard_normal((idx.size, 3))
    rot = sens.attitude_noise * rng.standard_normal((idx.size, 3))
    R = matrix_from_quaternion(res.q_IB[idx]) @ Rz(rot[:, 2]) @ Ry(rot[:, 1]) @ Rx(rot[:, 0])
    q = quaternion_from_matrix(res.sensors.marker_attitude(R))  # the markers' frame
    # thrust "held since the previous sample": the mean of the commands applied over
    # [t_prev, t) (command k acts on [t_k, t_k+1)); the first row has only u[0]
    ends = np.maximum(idx, 1)
    starts = np.maximum(idx - every, 0)
    csum = np.concatenate([np.zeros((1, 4)), np.cumsum(res.u, 0)])
    T = (csum[ends] - csum[starts]) / (ends - starts)[:, None]
    meta = {
        "alpha_c_deg": f"{np.rad2deg(res.scenario.tilt):.12g}",
        "gamma_c_deg": f"{np.rad2deg(res.scenario.gamma):.12g}",
        "flight_id": f"sim-{res.scenario.name}",
        "notes": "simulated by gainsched",
    }
    # the gyro: the mean body rate over the sample interval centred on the sample time (an
    # anti-aliased gyro whose filter delay the driver's time stamps compensate), plus noise
    h = every // 2
    w = res.z[:, 7:10]
    wsum = np.concatenate([np.zeros((1, 3)), np.cumsum(w, 0)])
    lo, hi = np.maximum(idx - h, 0), np.minimum(idx + h + 1, w.shape[0])
    gyro = res.sensors.readings((wsum[hi] - wsum[lo]) / (hi - lo)[:, None])  # its calibration
    gyro = gyro + sens.gyro_noise * rng.standard_normal((idx.size, 3))
    extra = {}
    if res.f_B is not None:  # the accelerometer, anti-aliased the same way, its own noise
        fsum = np.concatenate([np.zeros((1, 3)), np.cumsum(res.f_B, 0)])
        f_B = (fsum[hi] - fsum[lo]) / (hi - lo)[:, None]
        extra["f_B"] = res.sensors.accel_readings(f_B) + sens.accel_noise * np.random.default_rng(
            (sens.seed + 1000 if seed is None else seed) + 7919).standard_normal((idx.size, 3))
    if res.vbat is not None:  # the battery voltage, averaged over the same interval
        vsum = np.concatenate([[0.0], np.cumsum(res.vbat)])
        extra["vbat"] = (vsum[hi] - vsum[lo]) / (hi - lo)
    return log_from_arrays(
        res.t[idx], p, q, T, meta, source=f"simulation {res.scenario.name}",
        omega_B=gyro, tension=res.tension[idx],
        xi_ref=res.z_d[idx, 1], xi_dot_ref=res.z_d[idx, 3], **extra,
    )


def write_run(res: SimResult, out_dir) -> dict:
    """Write log.csv, log.h5, metrics.json and the plots into ``out_dir``; returns the metrics."""
    import json

    from ..analysis.logs import write_log
    from ..publish import write_atomic
    from .plots import plot_result

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log = log_from_result(res)
    write_log(out_dir / "log.csv", log)
    write_log(out_dir / "log.h5", log)
    m = metrics(res)
    m["scenario"] = res.scenario.name
    write_atomic(
        out_dir / "metrics.json", (json.dumps(m, indent=2, sort_keys=True) + "\n").encode()
    )
    plot_result(res, out_dir)
    return m
