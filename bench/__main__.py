"""Benchmark entry point: ``python -m bench [--quick] [NAME ...]`` (``make bench``, ``make
bench-quick``).

Runs every ``bench/bench_*.py`` module present (sorted by name), or those whose names
contain one of the NAMEs, calling its ``main()``; ``--quick``: the quick mode
(:func:`bench.quick`). A module's ``main()`` prints its own figures and may return a
JSON-serialisable dict, which is collected under its name into
``bench/results.json`` (the quick mode: ``bench/results-quick.json``; or the path in
the environment variable ``BENCH_OUT``), with the run's wall time.
A failing module is recorded with its error and the run continues; the exit
code is 1 if any module failed.

Figures are compared only with baselines measured in the same run; there are
no absolute pass/fail timings.
"""

from __future__ import annotations

import importlib
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

import numpy as np

from bench import QUICK_ENV, quick

HERE = Path(__file__).resolve().parent


def discover() -> list[str]:
    """Module names ``bench.bench_*`` for the files present in bench/."""
    return [f"bench.{p.stem}" for p in sorted(HERE.glob("bench_*.py"))]


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, float | int | str | bool) or x is None:
        return x
    return repr(x)


def environment() -> dict:
    import scipy

    from gainsched import __version__

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "gainsched": __version__,
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
    }


def main(argv=None) -> int:
    argv = list(argv or [])
    if "--quick" in argv:  # in the environment: the modules' subprocesses see it too
        argv.remove("--quick")
        os.environ[QUICK_ENV] = "1"
    names = discover()
    if argv:  # optional filter: python -m bench build runtime
        names = [n for n in names if any(a in n for a in argv)]
    # the modules' main() read their own options from sys.argv when run alone (python -m
    # bench.bench_controller --table T): run from here, they get none of these
    sys.argv[1:] = []
    out = Path(os.environ.get("BENCH_OUT", HERE / ("results-quick.json" if quick()
                                                   else "results.json")))
    results = {"environment": environment(), "quick": quick(), "modules": {}}
    t_run = time.perf_counter()
    failed = False
    for name in names:
        print(f"== {name}")
        t0 = time.perf_counter()
        entry = {}
        try:
            mod = importlib.import_module(name)
            entry["result"] = _jsonable(mod.main())
            entry["status"] = "ok"
        except Exception as exc:  # record and go on with the other modules
            failed = True
            traceback.print_exc()
            entry["status"] = "error"
            entry["error"] = f"{type(exc).__name__}: {exc}"
        entry["wall_s"] = round(time.perf_counter() - t0, 3)
        results["modules"][name.removeprefix("bench.")] = entry
        print(f"== {name}: {entry['status']} ({entry['wall_s']:.1f} s)\n")
    if not names:
        print("no bench/bench_*.py modules found")
    results["wall_s"] = round(time.perf_counter() - t_run, 1)
    print(f"{'quick' if quick() else 'full'} run: {results['wall_s']:.0f} s")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
