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
import pstats  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

STAGES = {
    "nominal": ("nominal.py", "circle_nominal"),
    "offsets": ("nominal.py", "circle_offsets"),
    "linearisation": ("grid.py", "discrete_system"),
    "riccati": ("lqr.py", "periodic_lqr"),
    "riccati_tilt0": ("lqr.py", "dlqr"),
    "outputs": ("outputs.py", "output_set"),
}


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
    for stage, (file, name) in STAGES.items():
        out[f"{stage}_s"] = sum(v[3] for (f, _, n), v in stats.items()
                                if n == name and f.endswith(file))
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1])))
