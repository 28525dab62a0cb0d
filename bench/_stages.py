"""The paper build's time by stage, measured in a process pinned like the ``gainsched``
command (:mod:`gainsched.native.reproducible`), on one worker: ``python -m
bench._stages CONFIG`` prints JSON (run by :func:`bench.bench_build.build_stages`).

The stages are the cumulative profile times of the functions that do them (cProfile):
the nominal (``circle_nominal``, the trim and the offsets included), of it the attitude
offsets (``circle_offsets``), the linearisation (``discrete_system``), the Riccati sweeps
(``periodic_lqr`` and the tilt-0 ``dlqr``) and the outputs (``output_set``: HDF5, headers,
the compact table's certificate). Profiling adds its overhead to every stage alike.
"""

from __future__ import annotations

import json
import sys

from gainsched.native.reproducible import pin_environ

pin_environ()  # before numpy, as the command does

import cProfile  # noqa: E402
import importlib  # noqa: E402
import pstats  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

#: stage -> the function whose cumulative time it is (module, name): resolved to its code
#: object, so a function that moves or is renamed fails here instead of reading as 0 s
STAGES = {
    "nominal": ("gainsched.schedule.nominal", "circle_nominal"),
    "offsets": ("gainsched.schedule.nominal", "circle_offsets"),
    "linearisation": ("gainsched.schedule.discrete", "discrete_system"),
    "riccati": ("gainsched.schedule.lqr", "periodic_lqr"),
    "riccati_tilt0": ("gainsched.schedule.lqr", "dlqr"),
    "outputs": ("gainsched.firmware.outputs", "output_set"),
}


def _profile_key(module: str, name: str) -> tuple:
    """cProfile's key ``(file, first line, name)`` of a module's function."""
    code = getattr(importlib.import_module(module), name).__code__
    return code.co_filename, code.co_firstlineno, code.co_name


def main(path: str) -> dict:
    from gainsched.config import load_config
    from gainsched.firmware.outputs import output_set
    from gainsched.schedule.grid import build_grid

    cfg = load_config(path)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    grid = build_grid(cfg, n_jobs=1)
    output_set(cfg, grid, tempfile.mkdtemp())
    prof.disable()
    total = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats  # (file, line, name) -> (cc, nc, tt, ct, callers)
    out = {"total_s": total}
    for stage, where in STAGES.items():
        key = _profile_key(*where)
        out[f"{stage}_s"] = stats[key][3] if key in stats else 0.0
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1])))
