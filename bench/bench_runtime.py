"""Runtime benchmarks: C lookup time and instruction count, Python reference throughput.

    python -m bench.bench_runtime [--table tables/paper.h5] [--json out.json]

- C: the runtime and the table compiled for the host (``-O2`` and ``-O3``), timed
  over pseudo-random queries through one ctypes call per pass (ns per lookup,
  best of several passes), for two query sets: *flight* (inside the table, all
  corners feasible: the normal case at 1 kHz) and *mixed* (every symmetry branch,
  clamped, infeasible and invalid queries).
- Instructions per lookup: valgrind callgrind, counting only inside ``gs_lookup``
  (``--toggle-collect``), if valgrind is installed.
- The manoeuvre feed-forward (``gs_lookup_nominal``: the lookup plus the drag-only
  closed form at an accelerating reference, corrected by the table) on the same
  queries, ns and instructions, printed as a ratio to the plain lookup measured in
  the same run.
- Python: vectorised reference lookups per second (100k-query batches).
- Formats: the compact table (Fourier series per circle, docs/runtime.md) against the
  dense one: host ns per flight lookup (-O2) as a ratio, and the instructions a lookup
  executes on the emulated Cortex-M4F (QEMU mps2-an386, ``-Os``, when
  ``arm-none-eabi-gcc`` and ``qemu-system-arm`` are installed) for interior,
  symmetry-mapped and NaN queries.

Targets (issue 4): under 1 us and under 1000 instructions per C lookup on x86.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gainsched import native
from gainsched.firmware.compact import compact_data
from gainsched.firmware.host.lookup import CRuntime, build_host
from gainsched.firmware.host.pil import build_pil, instructions_per_lookup, pil_tools
from gainsched.firmware.runtime import Interpolator, runtime_data
from gainsched.schedule.tables import load_table

REPO = Path(__file__).parents[1]


def query_sets(data, interp, m=100_000, seed=0):
    """``{"flight": q, "mixed": q}``, float32 arrays (m, 3)."""
    rng = np.random.default_rng(seed)
    vmax, amax = float(data.xi_dot[-1]), float(data.tilt[-1])
    mixed = np.stack(
        [
            rng.uniform(-7, 7, m),
            rng.choice([-1, 1], m) * rng.uniform(0, 1.1 * vmax, m),
            rng.choice([-1, 1], m) * rng.uniform(0, 1.1 * amax, m),
        ],
        1,
    ).astype(np.float32)
    mixed[rng.random(m) < 0.02, 1] = np.nan
    cand = np.stack(
        [
            rng.uniform(-np.pi, np.pi, 4 * m),
            rng.choice([-1, 1], 4 * m) * rng.uniform(float(data.xi_dot[0]), vmax, 4 * m),
            rng.choice([-1, 1], 4 * m) * rng.uniform(0, amax, 4 * m),
        ],
        1,
    ).astype(np.float32)
    st = interp(cand[:, 0], cand[:, 1], cand[:, 2]).status
    flight = cand[st == 0][:m]
    return {"flight": np.ascontiguousarray(flight), "mixed": mixed}


def time_c(lib: CRuntime, q, reps=5, passes=7, nominal=False) -> float:
    """Best ns per lookup over ``passes`` of ``reps`` sweeps (``nominal``: with the
    manoeuvre feed-forward, ``gs_lookup_nominal``)."""
    lib.bench(q[:1000], 1, nominal=nominal)  # warm up
    best = np.inf
    for _ in range(passes):
        t0 = time.perf_counter()
        lib.bench(q, reps, nominal=nominal)
        best = min(best, (time.perf_counter() - t0) / (reps * len(q)))
    return best * 1e9


def callgrind_instructions(exe: Path, q, workdir: Path, nominal=False) -> float | None:
    """Instructions per call (callgrind, only inside gs_lookup, or gs_lookup_nominal)."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        return None
    qf = workdir / "queries.bin"
    qf.write_bytes(np.ascontiguousarray(q, dtype=np.float32).tobytes())
    res = subprocess.run(
        [valgrind, "--tool=callgrind", "--callgrind-out-file=/dev/null",
         f"--toggle-collect={'gs_lookup_nominal' if nominal else 'gs_lookup'}", str(exe),
         "benchn" if nominal else "benchq", str(qf), "1"],
        capture_output=True, text=True,
    )
    m = re.search(r"Collected\s*:\s*(\d+)", res.stderr)
    return int(m.group(1)) / len(q) if m else None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", type=Path, default=REPO / "tables" / "paper.h5")
    ap.add_argument("--json", type=Path, help="also write the figures as JSON")
    ap.add_argument("--queries", type=int, default=100_000)
    args = ap.parse_args(argv)
    table = load_table(args.table)
    data = runtime_data(table)
    interp = Interpolator(data)
    sets = query_sets(data, interp, args.queries)
    out = {"table": str(args.table), "queries": args.queries, "c": {}, "python": {}}
    if native.find_cc() is None:
        print("no C compiler: C benchmarks skipped")
    else:
        with tempfile.TemporaryDirectory() as tmp:
            for opt in ("-O2", "-O3"):
                wd = Path(tmp) / opt.strip("-")
                lib = CRuntime(build_host(data, wd, opt=opt), data)
                exe = build_host(data, wd, opt=opt, shared=False)
                for name, q in sets.items():
                    cg_q = q[:20_000]
                    out["c"][f"{opt} {name}"] = {
                        "ns_per_lookup": round(time_c(lib, q), 1),
                        "instructions_per_lookup": callgrind_instructions(exe, cg_q, wd),
                    }
                    out["c"][f"{opt} {name} +nominal"] = {
                        "ns_per_lookup": round(time_c(lib, q, nominal=True), 1),
                        "instructions_per_lookup": callgrind_instructions(exe, cg_q, wd,
                                                                          nominal=True),
                    }
    for name, q in sets.items():
        interp(q[:1000, 0], q[:1000, 1], q[:1000, 2])
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            interp(q[:, 0], q[:, 1], q[:, 2])
            best = min(best, time.perf_counter() - t0)
        out["python"][name] = {"lookups_per_s": round(len(q) / best)}
    print(f"runtime benchmarks, table {args.table} ({args.queries} queries per set)")
    for key, r in out["c"].items():
        ins = r["instructions_per_lookup"]
        ins_s = f"{ins:7.0f} instructions" if ins is not None else "  (no valgrind)"
        print(f"  C {key:19s} {r['ns_per_lookup']:7.1f} ns/lookup  {ins_s}")
    out["nominal_ratio"] = {}
    for key, r in out["c"].items():
        if key.endswith(" +nominal"):
            base = out["c"][key.removesuffix(" +nominal")]
            ratio = {"ns": r["ns_per_lookup"] / base["ns_per_lookup"]}
            if r["instructions_per_lookup"] and base["instructions_per_lookup"]:
                ratio["instructions"] = (r["instructions_per_lookup"]
                                         / base["instructions_per_lookup"])
            out["nominal_ratio"][key.removesuffix(" +nominal")] = ratio
            ins = f", instructions x{ratio['instructions']:.2f}" if "instructions" in ratio else ""
            print(f"  feed-forward / lookup {key.removesuffix(' +nominal'):10s} "
                  f"ns x{ratio['ns']:.2f}{ins}")
    for key, r in out["python"].items():
        print(f"  Python {key:7s} {r['lookups_per_s'] / 1e3:8.0f} k lookups/s (vectorised)")
    c = out["c"].get("-O2 flight")
    if c:
        ok = c["ns_per_lookup"] < 1000 and (c["instructions_per_lookup"] or 0) < 1000
        print(f"  target (< 1 us and < 1000 instructions, -O2 flight): {'met' if ok else 'MISSED'}")
    out["formats"] = formats(data, sets["flight"])
    if args.json:
        args.json.write_text(json.dumps(out, indent=2) + "\n")
    return 0


def formats(dense, flight) -> dict:
    """Compact against dense: host ns ratio and emulated Cortex-M4F instructions."""
    forms = {"dense": dense, "compact": compact_data(dense)}
    out = {"bytes": {k: f.nbytes() for k, f in forms.items()}}
    print(f"  formats: table data dense {out['bytes']['dense']:,} B, compact "
          f"{out['bytes']['compact']:,} B")
    if native.find_cc() is not None:
        with tempfile.TemporaryDirectory() as tmp:
            ns = {k: time_c(CRuntime(build_host(f, Path(tmp) / k), f), flight)
                  for k, f in forms.items()}
        out["host_ns"] = ns
        print(f"  host -O2 flight lookup: compact {ns['compact']:.0f} ns, dense "
              f"{ns['dense']:.0f} ns: compact/dense x{ns['compact'] / ns['dense']:.2f}")
    if pil_tools() is None:
        print("  Cortex-M4F instruction counts skipped: arm-none-eabi-gcc or qemu-system-arm "
              "not found (Debian: gcc-arm-none-eabi, qemu-system-arm)")
        return out
    q = flight[:200]
    kinds = {"interior": (q[:, 0], q[:, 1], q[:, 2]),
             "symmetry-mapped": (q[:, 0], -q[:, 1], -q[:, 2]),
             "NaN": (np.full(len(q), np.nan, np.float32), q[:, 1], q[:, 2])}
    out["m4f_instructions"] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k, f in forms.items():
            elf = build_pil(f, Path(tmp) / k, opt="-Os")
            counts = {kind: instructions_per_lookup(elf, *qs, dense.dims[3])
                      for kind, qs in kinds.items()}
            out["m4f_instructions"][k] = counts
            print(f"  Cortex-M4F -Os (QEMU {k:7s}): "
                  + ", ".join(f"{kind} {n:,.0f}" for kind, n in counts.items())
                  + " instructions per lookup")
    return out


if __name__ == "__main__":
    sys.exit(main())
