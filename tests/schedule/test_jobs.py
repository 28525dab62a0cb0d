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
from gainsched.schedule.jobs import run_jobs

def job(k, fail):
    time.sleep(0.05)
    if k == fail:
        raise ValueError(f"job {k} failed")
    return k, os.getpid()

fail = int(sys.argv[1])
try:
    out = list(run_jobs([(k, fail) for k in range(12)], 2, None, job))
except ValueError as exc:
    out = str(exc)
print(json.dumps({"same": process_pinned() or not pin_available(), "main": os.getpid(),
                  "out": out}))
"""


def _run(fail: int) -> dict:
    res = subprocess.run([sys.executable, "-c", _SCRIPT, str(fail)], capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_a_pinned_process_works_beside_its_worker_in_order():
    """Issue 39: the command no longer waits about a second for a fresh worker to import
    the schedule: it takes jobs itself. Both processes ran jobs, the results are in
    submission order, and one worker was started for two processes at work."""
    got = _run(fail=-1)
    if not got["same"]:
        pytest.skip("this process did not get the pinned numerics")
    assert [k for k, _ in got["out"]] == list(range(12))
    pids = {pid for _, pid in got["out"]}
    assert got["main"] in pids and len(pids) == 2


@pytest.mark.parametrize("fail", [0, 1, 11], ids=["first", "second", "last"])
def test_an_error_in_any_job_reaches_the_caller(fail):
    """Whichever process runs the failing job (this one takes the first, the worker the
    second), its error is raised to the caller."""
    got = _run(fail)
    assert got["out"] == f"job {fail} failed"
