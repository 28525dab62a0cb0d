"""The controller's accuracy by sensor configuration (issue 38; docs/runtime.md,
"Accuracy by sensor configuration"):

    python -m bench.bench_sensors

Firmware mode (the C controller in the loop when a compiler is present, else its Python
reference), the paper table (tables/paper.h5), the design model as plant; poses at
200 Hz (0.5 mm, 0.2 deg) 12 ms late, gyro 0.005 rad/s and accelerometer 0.1 m/s^2 at
1 kHz; 5 s flights from the nominal, seed 1. Per flight and sensor configuration: the
steady azimuth error ``xi - xi_d`` (mean over the last second, rad; positive: ahead)
and the RMS out-of-plane error (mm), printed as the docs' markdown table.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

FLIGHTS = (("level 8 m/s", 0.0, 8.0), ("level 15 m/s", 0.0, 15.0),
           ("40 deg, 8 m/s", 40.0, 8.0), ("40 deg, 15 m/s", 40.0, 15.0))
#: label -> (ideal, accelerometer, latency compensated)
CONFIGS = (("true state (`GS_CTRL_KINEMATICS`)", True, True, True),
           ("accelerometer, `pose_delay` set", False, True, True),
           ("no accelerometer, `pose_delay` set", False, False, True),
           ("accelerometer, `pose_delay` 0", False, True, False),
           ("no accelerometer, `pose_delay` 0", False, False, False))


def main() -> dict:
    from gainsched.config import load_config
    from gainsched.native import find_cc
    from gainsched.schedule.tables import load_table
    from gainsched.sim.loop import Sensing, load_scenario, metrics, runtime_scheduler, simulate

    cfg = load_config(ROOT / "configs/paper.toml")
    table = load_table(ROOT / "tables/paper.h5")
    sched = runtime_scheduler(table, "c" if find_cc() else "python")
    out = {}
    print("| sensors | " + " | ".join(f[0] for f in FLIGHTS) + " |")
    print("| --- |" + " --- |" * len(FLIGHTS))
    for label, ideal, acc, comp in CONFIGS:
        sens = Sensing(ideal, 200.0, 5e-4, np.deg2rad(0.2), 0.005, 0.012, 1, 0.1, comp, acc)
        cells, row = [], {}
        for name, tilt, speed in FLIGHTS:
            scn = dataclasses.replace(load_scenario("horizontal"), speed=speed, duration=5.0,
                                      tilt=np.deg2rad(tilt), initial_error=(), sensing=sens)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the uncompensated latency's warning
                res = simulate(cfg, sched, scn, controller="firmware")
            err = res.z[:, 1] - res.z_d[:, 1]
            lag = float(err[res.t > res.t[-1] - 1.0].mean())
            oop = metrics(res)["rms_out_of_plane_m"]
            row[name] = {"azimuth_error_rad": lag, "rms_out_of_plane_m": oop}
            cells.append(f"{lag:+.4f} rad, {1e3 * oop:.2f} mm")
        out[label] = row
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    return out


if __name__ == "__main__":
    main()
