"""What choosing the grid costs (issue 23): ``gainsched build`` of a config whose speed and
tilt axes are ranges, against the build of the grid it chose given as lists.

    python -m bench.bench_refine [--config CONFIG] [-j 2] [--json out.json]

Default: configs/heavy_auto.toml, and configs/paper.toml with its speed and tilt lists
as ranges over the same spans (the hand-refined lists have 19 x 7 = 133 circles); the
quick mode (:func:`bench.quick`): the paper's ranges only, one run each.

Both builds run as the command a user types, in a fresh process each (worker start-up,
output checks and writing included), the better of two runs each (one if it takes
:data:`bench.LONG_S` or more); the ratio of their
wall times is the figure (target: at most 3). The refinement's counters come from the
table's ``grid_auto`` record: circles solved at breakpoints (each once), how often a
later round reused one, and the cell centres the certificate solved.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from bench import best_of, quick
from gainsched.config import load_config
from gainsched.schedule.tables import load_table

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "heavy_auto.toml"
PAPER = ROOT / "configs" / "paper.toml"
TARGET = 3.0  # auto build / direct build of the chosen grid (issue 23)


def _build(config: Path, out: Path, jobs: int) -> None:
    cmd = [sys.executable, "-m", "gainsched", "build", str(config), "-o", str(out),
           "-j", str(jobs)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    if res.returncode:
        raise RuntimeError(res.stderr.strip().splitlines()[-1])


def measure(config: Path = CONFIG, jobs: int = 2, repeats: int = 2) -> dict:
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        t_auto = best_of(lambda: _build(config, d / "auto", jobs), repeats)[0]
        table = load_table(next((d / "auto").glob("*.h5")))
        listed = d / "listed.toml"
        listed.write_text(table.config_text)  # the chosen axes as lists
        t_list = best_of(lambda: _build(listed, d / "list", jobs), repeats)[0]
    rec = table.grid_auto
    return {
        "config": str(config.relative_to(ROOT)) if config.is_relative_to(ROOT)
        else f"{config.stem} (configs/paper.toml with ranges)" if config.stem == "paper_auto"
        else config.name,
        "jobs": jobs,
        "grid": [rec["speed_count"], rec["tilt_count"]],
        "bound": rec["bound"],
        "max_error": max(rec["gain_error"], rec["thrust_error"], rec["roll_error"]),
        "auto_s": t_auto,
        "listed_s": t_list,
        "ratio": t_auto / t_list,
        "target_ratio": TARGET,
        "circles": rec["circles"],
        "reused": rec["reused"],
        "centres": rec["centres"],
        "centres_final": rec["centres_final"],
        "rounds": rec["rounds"],
    }


def report(r: dict) -> None:
    print(f"choosing the grid of {r['config']} (-j {r['jobs']}): {r['grid'][0]} speeds x "
          f"{r['grid'][1]} tilts for {100 * r['bound']:g} % (met: "
          f"{100 * r['max_error']:.2f} %) in {r['rounds']} rounds")
    print(f"  build with ranges {r['auto_s']:.1f} s, the chosen grid as lists "
          f"{r['listed_s']:.1f} s: x{r['ratio']:.2f} (target <= x{r['target_ratio']:g})")
    print(f"  circles: {r['circles']} breakpoints solved once each, reused {r['reused']} "
          f"times by later rounds; {r['centres']} cell centres "
          f"({r['centres_final']} certify the chosen grid)")


def paper_with_ranges(path: Path) -> Path:
    """configs/paper.toml with its speed and tilt lists as ranges over the same spans
    (the hand-refined 19 x 7 = 133 circles are the comparison)."""
    cfg = load_config(PAPER).with_values({
        "name": "paper_auto",
        "grid.speeds": {"min": 1.3, "max": 15.0, "max_count": 64},
        "grid.tilts_deg": {"min": 0.0, "max": 40.0, "max_count": 40}})
    path.write_text(cfg.text)
    return path


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, help="one config (default: configs/"
                    "heavy_auto.toml and configs/paper.toml with ranges)")
    ap.add_argument("-j", "--jobs", type=int, default=2)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv if argv is not None else [])
    out = {}
    with tempfile.TemporaryDirectory() as d:
        configs = ([args.config.resolve()] if args.config else
                   [paper_with_ranges(Path(d) / "paper_auto.toml")] if quick() else
                   [CONFIG, paper_with_ranges(Path(d) / "paper_auto.toml")])
        for path in configs:
            r = measure(path, args.jobs, repeats=1 if quick() else 2)
            report(r)
            out[path.stem] = r
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
