"""Where a build's jobs run: this process, pinned worker processes, both, or Dask.

:func:`run_jobs` yields the results of one job per argument tuple in submission order,
whatever ran them, so a table's bits never depend on the machine, the worker count or
the backend (every job runs on the pinned numerics, :mod:`gainsched.native.reproducible`).

A pinned process with more than one job to share (the ``gainsched`` command) works
beside its workers instead of waiting for them: it has every module loaded, while a
fresh worker spends about a second starting Python and importing the schedule before
its first job (2026-11-27, 2 vCPUs: 1.8 s of a 4.6 s paper build). One thread per
worker hands it the next job as soon as it returns one, so neither side idles while
jobs are left. No library pool lets its caller take jobs from its own queue (joblib's
and concurrent.futures' callers only wait), hence these few lines.
"""

from __future__ import annotations

import importlib
import threading
from collections import deque

from joblib import Parallel, cpu_count, delayed

from ..native.reproducible import (
    children_ignore_sigint,
    pin_available,
    pinned_executor,
    process_pinned,
)

__all__ = ["local_processes", "run_jobs", "start_workers"]


def _dask_active() -> bool:
    """Whether joblib's active backend is Dask (set by ``distributed.executor``)."""
    from joblib.parallel import get_active_backend

    return type(get_active_backend()[0]).__name__.startswith("Dask")


def _same_numerics() -> bool:
    """Whether this process runs what the pinned workers run (pinned, or no pin here)."""
    return process_pinned() or not pin_available()


def local_processes(n_jobs: int, n_args: int | None = None) -> int:
    """Processes (or threads) at work at once for ``n_jobs`` (-1: every core), at most
    ``n_args``."""
    n = n_jobs if n_jobs > 0 else max(1, cpu_count() + 1 + n_jobs)
    return n if n_args is None else min(n, n_args)


def _import(module: str) -> None:
    """A worker's first job from :func:`start_workers`: import ``module``."""
    importlib.import_module(module)


def start_workers(n_jobs: int, module: str) -> None:
    """Start the workers :func:`run_jobs` will use beside this pinned process and have them
    import ``module`` (what their jobs need) now, while this process imports its own:
    both take about a second, and this way they overlap (the ``gainsched`` command calls
    it first thing in a build). Nothing when this process would not work beside workers
    (not pinned, or one job at a time)."""
    n = local_processes(n_jobs)
    if n < 2 or not _same_numerics():
        return
    with children_ignore_sigint():
        pool = pinned_executor(n - 1)
        for _ in range(n - 1):
            pool.submit(_import, module)


def run_jobs(args, n_jobs, backend, job):
    """Run ``job(*a)`` for every tuple ``a`` of ``args`` and yield the results in
    submission order.

    Worker processes on this machine (the default, ``"loky"``) come from
    :func:`~gainsched.native.reproducible.pinned_executor`: started with the pinned
    numerics and ended by the kernel when this process dies, even by SIGKILL. A process
    that does not run the pinned numerics (a notebook, a test) sends every job there,
    also for the ``sequential`` and ``threading`` backends, so that the table bits never
    depend on the calling process; a pinned one (the command) runs them itself when one
    process is to work (``sequential``, ``n_jobs`` 1 or one job), in threads for
    ``threading``, else beside ``n - 1`` workers (:func:`_beside_workers`). joblib runs
    the jobs on Dask.

    Parameters
    ----------
    args : list of tuple
        One argument tuple per job.
    n_jobs : int
        Processes at work at once, this one included when it works (-1: all cores).
    backend : str or None
        joblib backend name (``"loky"``, ``"threading"``, ``"sequential"``, ``"dask"``);
        None: pinned local processes, or Dask when a Dask joblib backend is active.
    job : callable
        Picklable (a module-level function): it travels to the workers.
    """
    if backend == "dask" or (backend is None and _dask_active()):
        yield from Parallel(n_jobs=n_jobs, backend=backend, return_as="generator")(
            delayed(job)(*a) for a in args)
        return
    n = 1 if backend == "sequential" else local_processes(n_jobs, len(args))
    if _same_numerics():
        if backend == "threading" and n > 1:
            yield from Parallel(n_jobs=n, backend="threading", return_as="generator")(
                delayed(job)(*a) for a in args)
        elif n == 1:
            yield from (job(*a) for a in args)
        else:
            yield from _beside_workers(args, n - 1, job)
        return
    with children_ignore_sigint():  # the workers (and loky's tracker) start in here
        pool = pinned_executor(n)
        futures = [pool.submit(job, *a) for a in args]
    try:
        for f in futures:
            yield f.result()
    except BaseException:  # Ctrl-C, an error, a closed generator: stop the workers now
        pool.shutdown(wait=False, kill_workers=True)
        raise


def _beside_workers(args, n_workers, job):
    """:func:`run_jobs` with this process taking jobs from the same queue as
    ``n_workers`` pinned workers (each fed by a thread of this process); the results in
    submission order, each as soon as it and every earlier one are done."""
    queue = deque(enumerate(args))  # popleft is atomic: the threads and this one share it
    done: dict[int, tuple[bool, object]] = {}  # index -> (ok, result or exception)
    ready = threading.Condition()
    stop = threading.Event()
    with children_ignore_sigint():  # the workers start at their first job: in here
        pool = pinned_executor(n_workers)
        first = [(i, pool.submit(job, *a))
                 for i, a in (queue.popleft() for _ in range(min(n_workers, len(args))))]

    def feed(i, future):  # one worker's jobs, one at a time
        while True:
            try:
                out = (True, future.result())
            except BaseException as exc:  # noqa: BLE001 - handed to the caller
                out = (False, exc)
            with ready:
                done[i] = out
                ready.notify()
            if stop.is_set():
                return
            try:
                i, a = queue.popleft()
            except IndexError:
                return
            try:
                future = pool.submit(job, *a)
            except BaseException as exc:  # noqa: BLE001 - the pool shut down under this
                # thread (Ctrl-C or an error in the caller, between the check above and
                # here: nothing to tell), or it broke (handed to the caller)
                if not stop.is_set():
                    with ready:
                        done[i] = (False, exc)
                        ready.notify()
                return

    for i, future in first:
        threading.Thread(target=feed, args=(i, future), daemon=True).start()
    try:
        for k in range(len(args)):
            while k not in done:
                try:
                    i, a = queue.popleft()  # this process's share
                except IndexError:  # nothing left to take: wait for the workers
                    with ready:
                        ready.wait_for(lambda k=k: k in done)
                    continue
                done[i] = (True, job(*a))
            ok, out = done.pop(k)
            if not ok:
                raise out
            yield out
    except BaseException:  # Ctrl-C, an error, a closed generator: stop the workers now
        stop.set()
        queue.clear()
        pool.shutdown(wait=False, kill_workers=True)
        raise
