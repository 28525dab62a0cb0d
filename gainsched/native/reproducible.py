"""Reproducible numerics: the same config gives the same table bits on every machine.

A table's floating-point bits depend on more than the config and the code:

- **BLAS threads.** OpenBLAS splits a product differently over 1 and 2 threads
  (the paper table differed by 8e-14 in K between ``-j 1`` and ``-j 2``).
- **BLAS kernel family.** numpy and scipy each ship an OpenBLAS built for every
  x86-64 family and pick the kernels of the CPU at load time: Haswell/Zen (AVX2
  with FMA), SkylakeX (AVX-512), Sandybridge (AVX, no FMA) round differently.
- **numpy's SIMD dispatch.** numpy's ufunc loops (``exp``, ``arctan2``,
  ``power``, ...) have X86_V3 (AVX2) and X86_V4 (AVX-512) versions chosen at
  import; the AVX-512 ones are different algorithms, not only wider.

The first is fixed at run time (:func:`blas_single_thread`). The other two are
chosen when the libraries load, so they are fixed in the environment of the
process before numpy is imported: :data:`PINNED_ENV` selects the Haswell
kernels in both OpenBLAS copies and caps numpy's dispatch at X86_V3. Every
x86-64 CPU with AVX2 and FMA (Intel since Haswell, AMD since Zen: x86-64-v3)
can run exactly that code, and glibc's libm picks its FMA variants on all of
them, so the bits agree across those machines. The compiled kernels
(``c/*.c``) are built with ``-ffp-contract=off`` and give the same bits at
every vector width (tested).

Where the pin applies:

- the ``gainsched`` command pins its own process at start (``__main__``);
- :func:`gainsched.schedule.grid.build_grid` called from a process that is not pinned
  (a notebook, a test) runs the circles in worker processes started with the
  pin (:func:`pinned_executor`);
- Dask workers must be started with :data:`PINNED_ENV`; the cluster check
  refuses others (``docs/distributed.md``).

On a CPU without AVX2/FMA, or with a BLAS that ignores ``OPENBLAS_CORETYPE``,
no pin is possible: builds still run and are deterministic on that machine,
but their bits may differ from other machines (:func:`status` says so).
``GAINSCHED_PIN=0`` turns the pin off (for experiments; tables then follow the
CPU). See ``docs/performance.md``, "Reproducibility".

This module must not import numpy at module level: :func:`pin_environ` has to
run before numpy loads.
"""

from __future__ import annotations

import os
import platform
from collections.abc import MutableMapping
from contextlib import contextmanager

from . import cpu_flags  # no numpy: this module must load before numpy

__all__ = [
    "BLAS_CORETYPE",
    "NUMPY_DISABLED",
    "PINNED_ENV",
    "WORKER_IDLE_S",
    "pin_available",
    "pin_environ",
    "fingerprint",
    "process_pinned",
    "status",
    "blas_single_thread",
    "pinned_executor",
    "children_ignore_sigint",
]

#: the OpenBLAS kernel family every pinned process uses (AVX2 + FMA)
BLAS_CORETYPE = "Haswell"
#: numpy dispatch targets above X86_V3, switched off in pinned processes
NUMPY_DISABLED = ("X86_V4", "AVX512_ICL", "AVX512_SPR")
#: environment of a pinned process (set before numpy and scipy are imported)
PINNED_ENV = {
    "OPENBLAS_CORETYPE": BLAS_CORETYPE,
    "NPY_DISABLE_CPU_FEATURES": " ".join(NUMPY_DISABLED),
}
#: s, how long an idle worker of :func:`pinned_executor` waits for the next job: joblib's
#: own for its loky backend (``idle_worker_timeout``). loky's default of 10 s ended the
#: workers between two builds of one session (a notebook, the test suite), and each
#: build then started its workers again, 1.2 s of imports each (129 worker processes in
#: one run of the suite)
WORKER_IDLE_S = 300
_OFF = "GAINSCHED_PIN"
#: CPU flags (``/proc/cpuinfo``) the pinned code needs
_NEEDS = ("avx2", "fma")


def pin_available() -> bool:
    """Whether this machine can run the pinned code (x86-64 with AVX2 and FMA) and the
    pin is not switched off (``GAINSCHED_PIN=0``)."""
    if os.environ.get(_OFF, "1") == "0":
        return False
    return platform.machine() in ("x86_64", "AMD64") and all(f in cpu_flags() for f in _NEEDS)


def pin_environ(environ: MutableMapping[str, str] | None = None) -> bool:
    """Put :data:`PINNED_ENV` into ``environ`` (default ``os.environ``) if the CPU can run it.

    Takes effect for numpy and scipy only if they are loaded after this call (in
    this process) or in a child started with ``environ``. Returns whether it pinned.
    """
    environ = os.environ if environ is None else environ
    if not pin_available():
        return False
    environ.update(PINNED_ENV)
    return True


@contextmanager
def _ctrl_c_after():
    """Defer a Ctrl-C (SIGINT) that arrives in the block to its end, where it is raised
    as usual. threadpoolctl finds the loaded libraries through a ctypes callback of
    ``dl_iterate_phdr``; a KeyboardInterrupt raised inside it cannot leave the callback:
    ctypes prints its traceback and carries on, and the Ctrl-C is lost. The handler is
    Python's (it runs in the main thread whichever thread the signal reached), so the
    block only changes anything in the main thread."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending = []
    handler = signal.signal(signal.SIGINT, lambda signum, frame: pending.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, handler)
        if pending:  # delivered to the handler of before (ignored where that ignores it)
            signal.raise_signal(signal.SIGINT)


def _threadpool_info() -> list[dict]:
    """threadpoolctl's ``threadpool_info()``, a Ctrl-C during its scan raised after it."""
    from threadpoolctl import threadpool_info

    with _ctrl_c_after():
        return threadpool_info()


def _threadpool_limits(limits: int):
    """threadpoolctl's ``threadpool_limits(limits, user_api="blas")`` (a context manager
    and a call that limits at once), a Ctrl-C during its scan raised after it."""
    from threadpoolctl import threadpool_limits

    with _ctrl_c_after():
        return threadpool_limits(limits=limits, user_api="blas")


def _blas_libraries() -> list[dict]:
    import numpy  # noqa: F401  (load both OpenBLAS copies before asking threadpoolctl)
    import scipy.linalg  # noqa: F401

    return [i for i in _threadpool_info() if i.get("user_api") == "blas"]


def fingerprint() -> str:
    """What decides the bits of this process's numerics, as one line.

    Example: ``"numpy SIMD X86_V3; BLAS openblas Haswell, openblas Haswell"``.
    """
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    simd = [t for t in __cpu_dispatch__ if __cpu_features__.get(t)]
    blas = [f"{i['internal_api']} {i.get('architecture', '?')}" for i in _blas_libraries()]
    return f"numpy SIMD {' '.join(simd) or 'baseline'}; BLAS {', '.join(blas) or 'none'}"


def process_pinned() -> bool:
    """Whether this process runs the pinned numerics: every OpenBLAS on the Haswell
    kernels and no numpy loop above X86_V3 (checked on the loaded libraries, not on
    the environment)."""
    from numpy._core._multiarray_umath import __cpu_features__

    if any(__cpu_features__.get(t) for t in NUMPY_DISABLED):
        return False
    blas = _blas_libraries()
    return bool(blas) and all(
        i["internal_api"] == "openblas" and i.get("architecture") == BLAS_CORETYPE for i in blas
    )


def status() -> str:
    """One line for reports: whether builds here give the bits of every other machine."""
    if process_pinned():
        return f"pinned ({fingerprint()})"
    if pin_available():
        return f"this process is not pinned ({fingerprint()}); builds run in pinned workers"
    return (f"no pin on this machine ({fingerprint()}): table bits may differ from "
            "other machines (docs/performance.md)")


@contextmanager
def blas_single_thread():
    """Limit every BLAS in this process to one thread for the block (and restore after)."""
    with _threadpool_limits(1):
        yield


def ensure_blas_single_thread() -> None:
    """Limit BLAS to one thread for good in this (worker) process.

    Unlike :func:`blas_single_thread` it never restores, so tasks running on
    concurrent threads of one worker (Dask) cannot undo each other's limit.
    """
    if any(i["num_threads"] != 1 for i in _threadpool_info() if i.get("user_api") == "blas"):
        _threadpool_limits(1)


def pinned_executor(n_workers: int):
    """A loky process pool whose workers start with :data:`PINNED_ENV` (where the CPU can run
    it) and one BLAS thread.

    Workers are reused across calls (loky's reusable executor), idle ones for
    :data:`WORKER_IDLE_S`; they end with this process (see :func:`_worker_init`). What
    the pool leaves in ``/dev/shm`` when the whole process group is killed goes with the
    next run (:mod:`.shm`).
    """
    from joblib.externals.loky import get_reusable_executor

    from . import shm

    shm.claim()  # before the pool makes its semaphores: a later run removes them if killed
    env = dict(PINNED_ENV if pin_available() else {}, OPENBLAS_NUM_THREADS="1",
               OMP_NUM_THREADS="1")
    return get_reusable_executor(max_workers=n_workers, env=env, initializer=_worker_init,
                                 timeout=WORKER_IDLE_S)


@contextmanager
def children_ignore_sigint():
    """Processes started in the block ignore SIGINT for good (Ctrl-C reaches the whole
    foreground process group: the command handles it and ends its workers; a worker
    would only print a traceback). This process keeps its own Ctrl-C: SIGINT is held
    back while the block runs and delivered when it ends. Main thread only."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _worker_init() -> None:
    """Ask Linux to end this worker when its parent dies (SIGKILL included), so a killed
    build leaves no worker behind."""
    if platform.system() != "Linux":
        return
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() == 1:  # the parent died before prctl: nothing to work for
        os._exit(0)
