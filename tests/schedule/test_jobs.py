"""Where a build's jobs run (gainsched.schedule.jobs): a pinned process (the command) works
beside its workers, the results come back in submission order, and an error in any job
reaches the caller."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

#: a pinned process running 12 jobs on 2 (itself and one worker); the job is defined in
#: __main__, so loky sends it to the worker by value
_SCRIPT = """
from gainsched.native.reproducible import pin_environ
pin_environ()
import json, os, sys, time
from gainsched.native.reproducible import process_pinned, pin_available
from gainsched.schedule.jobs import run_jobs, start_workers

def job(k, fail):
    time.sleep(0.05)
    if k == fail:
        raise ValueError(f"job {k} failed")
    return k, os.getpid(), "gainsched.schedule.grid" in sys.modules

fail, n_args, warm = (int(a) for a in sys.argv[1:])
if warm:
    start_workers(2, "gainsched.schedule.grid")
try:
    out = list(run_jobs([(k, fail) for k in range(n_args)], 2, None, job))
except ValueError as exc:
    out = str(exc)
print(json.dumps({"same": process_pinned() or not pin_available(), "main": os.getpid(),
                  "out": out}))
"""


def _run(fail: int, n_args: int = 12, warm: bool = False) -> dict:
    res = subprocess.run([sys.executable, "-c", _SCRIPT, str(fail), str(n_args), str(int(warm))],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    if not got["same"]:
        pytest.skip("this process did not get the pinned numerics")
    return got


def test_a_pinned_process_works_beside_its_worker_in_order():
    """Issue 39: the command no longer waits about a second for a fresh worker to import
    the schedule: it takes jobs itself. Both processes ran jobs, the results are in
    submission order, and one worker was started for two processes at work."""
    got = _run(fail=-1)
    assert [k for k, _, _ in got["out"]] == list(range(12))
    pids = {pid for _, pid, _ in got["out"]}
    assert got["main"] in pids and len(pids) == 2


def test_one_job_runs_in_this_process():
    """One circle to solve: no worker is waited for (the old pool started one)."""
    got = _run(fail=-1, n_args=1)
    assert [pid for _, pid, _ in got["out"]] == [got["main"]]


@pytest.mark.parametrize("warm", [False, True], ids=["cold", "started"])
def test_started_workers_have_the_schedule_imported(warm):
    """start_workers (called as a build begins) has the worker import the schedule while
    this process imports its own; run_jobs then uses that worker. The job itself imports
    nothing: a cold worker does not have the schedule (the control)."""
    got = _run(fail=-1, warm=warm)
    in_worker = [grid for _, pid, grid in got["out"] if pid != got["main"]]
    assert in_worker and all(g is warm for g in in_worker)


@pytest.mark.parametrize("fail", [0, 1, 11], ids=["first", "second", "last"])
def test_an_error_in_any_job_reaches_the_caller(fail):
    """Whichever process runs the failing job (this one takes the first, the worker the
    second), its error is raised to the caller."""
    got = _run(fail)
    assert got["out"] == f"job {fail} failed"


#: fault injection: the worker's feeder thread submits its next job just as the caller
#: fails and shuts the pool down (the pool's submit waits for the shutdown, then raises
#: what loky raises there); the caller's error must be the only thing that shows
_SHUTDOWN_RACE = """
from gainsched.native.reproducible import pin_environ
pin_environ()
import json, threading, time
import gainsched.schedule.jobs as jobs
from joblib.externals.loky.process_executor import ShutdownExecutorError

real = jobs.pinned_executor

feeding = threading.Event()

class Pool:
    def __init__(self, n):
        self.pool, self.calls, self.down = real(n), 0, threading.Event()
    def submit(self, *args, **kwargs):
        self.calls += 1
        if self.calls > 1:  # the feeder's next job: lands after the caller's shutdown
            feeding.set()
            self.down.wait(10)
            raise ShutdownExecutorError("cannot schedule new futures after shutdown")
        return self.pool.submit(abs, *args[1:])  # the worker's job: picklable (job is not)
    def shutdown(self, **kwargs):
        self.down.set()
        self.pool.shutdown(**kwargs)

jobs.pinned_executor = Pool

def job(k):  # job 1 (this process's) fails once the feeder is submitting its next
    # (it holds an Event, which cloudpickle cannot send: the workers get abs instead)
    if k == 1:
        feeding.wait(30)
        raise ValueError("job 1 failed")
    return k

try:
    list(jobs._beside_workers([(k,) for k in range(6)], 1, job))
except ValueError as exc:
    time.sleep(0.5)  # the feeder thread's turn
    print(json.dumps(str(exc)))
"""


def test_a_feeder_that_meets_the_shut_down_pool_stops_quietly():
    """CI's random interrupt trials once printed a feeder thread's ShutdownExecutorError
    after "gainsched: interrupted": the thread submitted its next job after the caller
    had shut the pool down. It now stops without a word; the caller's error is what
    shows."""
    res = subprocess.run([sys.executable, "-c", _SHUTDOWN_RACE], capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0 and json.loads(res.stdout) == "job 1 failed", res.stderr
    assert "Traceback" not in res.stderr and "Exception in thread" not in res.stderr, \
        res.stderr


def test_idle_workers_wait_for_the_next_build_as_joblibs_do():
    """The pool keeps an idle worker WORKER_IDLE_S, 300 s as joblib's loky backend keeps
    it (``idle_worker_timeout``): with loky's own default of 10 s, every build of a
    session after a pause started and imported its workers again (1.2 s each)."""
    from gainsched.native.reproducible import WORKER_IDLE_S, pinned_executor

    assert WORKER_IDLE_S == 300
    assert pinned_executor(1)._timeout == WORKER_IDLE_S
