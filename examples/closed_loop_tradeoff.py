"""What bounding the closed-loop modes costs: the paper's weights against a config.

For each config: build its schedule, read the slowest closed-loop time constant and
the largest gain from the table, then fly the standard circles (level at 3, 9 and
15 m/s, 40 deg at 8 m/s; motion-capture noise 0.5 mm / 0.2 deg) and measure the
out-of-plane and along-track RMS and the motor-command noise (RMS of the command's
step-to-step change). Prints a Markdown table and writes it as JSON. Run from the
repository root:

    python examples/closed_loop_tradeoff.py configs/paper.toml configs/recommended.toml

``--speeds 3,9,15 --tilts 0,20,40`` builds a coarser grid (faster; the modes and gains
of the flown circles are the same, the lookups between grid points differ).
"""

import argparse
import dataclasses
import json

import numpy as np

import gainsched as gs
from gainsched.model.reduced import Model
from gainsched.schedule.tables import table_bytes, table_from_bytes

FLIGHTS = (("horizontal", 3.0), ("horizontal", 9.0), ("horizontal", 15.0), ("tilted40", 8.0))


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def measure(cfg, duration=10.0, settle=2.0):
    """The figures of one config: its table's slowest mode and largest gain, and the
    standard flights (after ``settle`` s, past the scenarios' initial offsets)."""
    table = table_from_bytes(table_bytes(cfg, gs.build_grid(cfg), Model(cfg)))
    row = {"config": cfg.name, "slowest_mode_s": float(np.nanmax(table.mode_tau[..., 0])),
           "max_abs_K": float(np.nanmax(np.abs(table.K_full()))), "flights": {}}
    for name, speed in FLIGHTS:
        scn = dataclasses.replace(gs.load_scenario(name), speed=speed, duration=duration)
        res = gs.simulate(cfg, gs.table_scheduler(table), scn)
        late = res.t >= settle
        errors = gs.tracking_errors(res)
        du = np.diff(res.u, axis=0, prepend=res.u[:1])  # the command's step-to-step change
        row["flights"][f"{name} {speed:g} m/s"] = {
            "out_of_plane_rms_mm": 1e3 * _rms(errors["out_of_plane_m"][late]),
            "along_track_rms_mm": 1e3 * _rms(errors["along_track_m"][late]),
            "command_noise_N": _rms(du[late]),
        }
    return row


def markdown(rows) -> str:
    head = ["config", "slowest mode (s)", "max abs K", "flight", "out-of-plane RMS (mm)",
            "along-track RMS (mm)", "command noise (N)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        for k, (flight, f) in enumerate(r["flights"].items()):
            lead = [r["config"], f"{r['slowest_mode_s']:.3g}", f"{r['max_abs_K']:.3g}"] if k == 0 \
                else ["", "", ""]
            lines.append("| " + " | ".join(lead + [flight, f"{f['out_of_plane_rms_mm']:.2f}",
                                                   f"{f['along_track_rms_mm']:.2f}",
                                                   f"{f['command_noise_N']:.4f}"]) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("configs", nargs="+", help="config files (TOML)")
    ap.add_argument("--speeds", help="grid speeds, m/s, comma-separated (default: the config's)")
    ap.add_argument("--tilts", help="grid tilts, deg, comma-separated (default: the config's)")
    ap.add_argument("--json", default="tradeoff.json", help="output JSON file")
    args = ap.parse_args(argv)
    grid = {}
    if args.speeds:
        grid["grid.speeds"] = [float(v) for v in args.speeds.split(",")]
    if args.tilts:
        grid["grid.tilts_deg"] = [float(v) for v in args.tilts.split(",")]
    rows = [measure(gs.load_config(p).with_values(grid) if grid else gs.load_config(p))
            for p in args.configs]
    print(markdown(rows))
    with open(args.json, "w") as f:
        json.dump(rows, f, indent=2, sort_keys=True)


if __name__ == "__main__":
    main()
