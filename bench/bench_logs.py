"""Reading a PX4 ULog against reading the same flight as the project's CSV (issue 36).

    python -m bench.bench_logs [--minutes 10]   (the quick mode: 2 minutes)

A steady level circle of the paper's vehicle (9 m/s, the attitude of a tethered circle,
the body rates of the turn, constant commands) is written for
``--minutes`` as a PX4 ULog in PX4's conventions and rates (position 100 Hz,
attitude 250 Hz, gyro and accelerometer 1 kHz, ``actuator_motors`` 400 Hz; pyulog's
writer, through the test support's ``write_ulog``) and as the project's CSV at the
pose rate (100 Hz). Timed in the same run: ``read_log`` of the CSV (the baseline, best
of three) and of the ULog through the shipped ``px4`` map, first with an empty cache of
converted logs (pyulog's parse, the conversion, the format's checks; best of three, the
cache off) and then again (the model loop's every later read: the converted columns
from the cache, :mod:`gainsched.analysis.logs._cache`; best of three). Target: the ULog
within 3x of the CSV.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import best_of, quick

REPO = Path(__file__).parents[1]
G = 9.80665
TMAX = 6.0  # N, a motor at full command (the circle needs 1.2 N per motor)


def steady_circle(minutes: float, rate: float = 1000.0):
    """t (s), p_I (m), R_IB, omega_B (rad/s), f_B (m/s^2) of a steady level circle at
    1 kHz: radius 2.6 m, 9 m/s, the attitude of a tethered circle (docs/conventions.md:
    x_B outward along the tether, the thrust axis up holding the weight, the tether
    pulling the vehicle round), as the reader's consistency checks expect."""
    t = np.arange(0.0, 60.0 * minutes, 1.0 / rate)
    r, v = 2.6, 9.0
    w = v / r
    xi = w * t
    p = np.stack([r * np.cos(xi), r * np.sin(xi), np.zeros_like(t)], -1)
    a = -w * w * p
    f_I = a - np.array([0.0, 0.0, -G])  # specific force in I: thrust and tether, per kg
    x_B = p / r  # outward along the tether
    z_B = np.broadcast_to([0.0, 0.0, 1.0], p.shape)
    R = np.stack([x_B, np.cross(z_B, x_B), z_B], -1)  # columns: body axes in I
    omega_B = np.einsum("kji,j->ki", R, [0.0, 0.0, w])
    f_B = np.einsum("kji,kj->ki", R, f_I)
    return t, p, R, omega_B, f_B


def write_logs(folder: Path, minutes: float) -> tuple[Path, Path]:
    sys.path.insert(0, str(REPO / "tests"))
    from gainsched.analysis.logs import write_log
    from gainsched.rotations import quaternion_from_matrix

    from support import write_ulog

    t, p, R, w, f = steady_circle(minutes)
    ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    frd = np.diag([1.0, -1.0, -1.0])
    us = np.round((t + 20.0) * 1e6).astype(np.uint64)
    ip, ia = slice(0, None, 10), slice(0, None, 4)
    p_ned, q = p @ ned.T, quaternion_from_matrix(ned @ R @ frd)
    tm = np.arange(0.0, t[-1], 0.0025)
    thrust = 0.25 * 0.5 * G  # N per motor: the weight m g / 4 (the tether pulls it round)
    ulg = folder / "circle.ulg"
    write_ulog(ulg, {
        "vehicle_local_position": {"timestamp": us[ip], **{a: p_ned[ip, j]
                                                            for j, a in enumerate("xyz")}},
        "vehicle_attitude": {"timestamp": us[ia], **{f"q[{j}]": q[ia, j] for j in range(4)}},
        "vehicle_angular_velocity": {"timestamp": us, **{f"xyz[{j}]": (w @ frd)[:, j]
                                                         for j in range(3)}},
        "sensor_combined": {"timestamp": us, **{f"accelerometer_m_s2[{j}]": (f @ frd)[:, j]
                                                for j in range(3)}},
        "actuator_motors": {"timestamp": np.round((tm + 20.0) * 1e6).astype(np.uint64),
                            **{f"control[{j}]": np.full(tm.size, thrust / TMAX)
                               for j in range(4)}},
    }, {"THR_MDL_FAC": 0.0})
    csv = folder / "circle.csv"
    q_I = quaternion_from_matrix(R[ip])
    cols = {"t": t[ip] + 20.0, **{a: p[ip, j] for j, a in enumerate("xyz")},
            **{n: q_I[:, j] for j, n in enumerate(("qw", "qx", "qy", "qz"))},
            **{f"T{j}": np.full(q_I.shape[0], thrust) for j in range(1, 5)},
            **{n: w[ip, j] for j, n in enumerate("pqr")},
            **{n: f[ip, j] for j, n in enumerate(("ax", "ay", "az"))}}
    write_log(csv, cols, {"alpha_c_deg": "0", "gamma_c_deg": "0"})
    return ulg, csv


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=2.0 if quick() else 10.0)
    args = ap.parse_args(argv)
    from gainsched.analysis.logs import read_log

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        ulg, csv = write_logs(Path(tmp), args.minutes)
        made = time.perf_counter() - t0
        t_csv = best_of(lambda: read_log(csv), 3)[0]
        old = {k: os.environ.get(k) for k in ("GAINSCHED_CACHE", "GAINSCHED_LOG_CACHE")}
        try:
            os.environ["GAINSCHED_LOG_CACHE"] = "0"
            t_cold = best_of(lambda: read_log(ulg, channel_map="px4", thrust_max=TMAX), 3)[0]
            os.environ["GAINSCHED_LOG_CACHE"] = "1"
            os.environ["GAINSCHED_CACHE"] = str(Path(tmp) / "cache")
            (log,) = read_log(ulg, channel_map="px4", thrust_max=TMAX)  # fills the cache
            t_warm = best_of(lambda: read_log(ulg, channel_map="px4", thrust_max=TMAX), 3)[0]
        finally:
            for k, v in old.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        sizes = ulg.stat().st_size, csv.stat().st_size
        t_checks = best_of(lambda: _checks_at_1khz(log, args.minutes), 3)[0]
    cold, warm = t_cold / t_csv, t_warm / t_csv
    print(f"{args.minutes:g} min: ULog {sizes[0] / 2**20:.1f} MiB (1 kHz IMU), CSV "
          f"{sizes[1] / 2**20:.1f} MiB (100 Hz) [written in {made:.1f} s]")
    print(f"read_log: CSV {t_csv:.2f} s; ULog {t_cold:.2f} s first (ratio {cold:.2f}), "
          f"{t_warm:.2f} s again from the cache (ratio {warm:.2f}); {len(log)} pose "
          "samples; target <= 3")
    print(f"the consistency checks and figures of the flight at 1 kHz: {t_checks:.2f} s "
          f"(ratio {t_checks / t_csv:.2f} to the CSV's read at 100 Hz; vectorised: target "
          "<= 3)")
    return {"minutes": args.minutes, "csv_s": t_csv, "ulog_first_s": t_cold,
            "ulog_again_s": t_warm, "ratio_first": cold, "ratio_again": warm,
            "ulog_bytes": sizes[0], "csv_bytes": sizes[1], "checks_1khz_s": t_checks,
            "ratio_checks": t_checks / t_csv}


def _checks_at_1khz(log, minutes: float) -> None:
    """The reader's consistency checks and the figures they judge
    (:func:`gainsched.analysis.logs.check_log`, :func:`~gainsched.analysis.logs.figures`)
    on ``log``'s flight repeated at 1 kHz for ``minutes`` (its jumps are gaps)."""
    from gainsched.analysis.logs import CHECKS, check_log, figures

    n = int(60_000 * minutes)
    k = np.arange(n) % len(log)
    t = np.arange(n) * 1e-3
    opt = {key: v[k] for key, v in log.optional.items()}
    check_log("long.csv", t, log.p_I[k], log.q[k], log.T_cmd[k], opt, log.meta, trust=CHECKS)
    figures(t, log.p_I[k], log.q[k], log.T_cmd[k], opt, log.meta, mass=0.5)

if __name__ == "__main__":
    main()
