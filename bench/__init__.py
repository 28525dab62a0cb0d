"""The benchmarks: ``python -m bench`` (``make bench``), ``python -m bench --quick``
(``make bench-quick``).

The quick mode is for the slices of work: the figures a change moves (the kernels, the
paper build and its margins' ratio, the effects on the cut grid, the model loop on
shorter logs), each from fewer repeats. The full mode adds the growth sweeps, the whole
paper grid's and the automatic grid's effect builds, and takes the ratios from more
rounds. The mode travels in the environment (:data:`QUICK_ENV`), so the benchmarks'
own subprocesses see it.

Every module times with :func:`best_of` (repeated calls) and :func:`interleaved` (cases
in turn), here once.
"""

from __future__ import annotations

import os
import time

#: the environment variable that selects the quick mode ("1")
QUICK_ENV = "BENCH_QUICK"


def quick() -> bool:
    """True in the quick mode (``python -m bench --quick``, or ``BENCH_QUICK=1``).

    Examples
    --------
    >>> import os
    >>> os.environ.get(QUICK_ENV) == "1" and quick() or not quick()
    True
    """
    return os.environ.get(QUICK_ENV) == "1"


#: s: a call this long is timed once (a slow spell of a shared machine is a smaller part of
#: it, and a second call would cost what the short cases' repeats cost together: the
#: paper grid at 16 kHz, a chosen grid's build)
LONG_S = 5.0


def best_of(fn, repeat, long_s=LONG_S):
    """Minimum wall time (s) of ``repeat`` calls of ``fn`` (one if the first took
    ``long_s`` or more: :data:`LONG_S`, or ``inf`` for a figure others are measured
    against) and the last call's result.

    Examples
    --------
    >>> t, out = best_of(lambda: sum(range(1000)), 3)
    >>> out == 499500 and 0.0 < t < LONG_S
    True
    """
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        if best >= long_s:
            break
    return best, out


#: s: a round of the interleaved cases this long is the last (a slow spell is a smaller
#: part of it; the whole paper grid's round takes 40 s)
LONG_ROUND_S = 20.0


def interleaved(cases, repeat):
    """``{name: (best wall time s, last result)}`` of the calls ``cases`` (name ->
    function), ``repeat`` rounds of one call each in turn (or fewer: a round of
    :data:`LONG_ROUND_S` or more is the last): a slow spell of a shared machine lands on
    every case alike, not on one case's repeats."""
    best = dict.fromkeys(cases, float("inf"))
    last = {}
    for _ in range(repeat):
        t_round = time.perf_counter()
        for name, fn in cases.items():
            t0 = time.perf_counter()
            last[name] = fn()
            best[name] = min(best[name], time.perf_counter() - t0)
        if time.perf_counter() - t_round >= LONG_ROUND_S:
            break
    return {name: (best[name], last[name]) for name in cases}
