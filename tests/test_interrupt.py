"""A real build interrupted at random moments by SIGINT or SIGKILL (issue 12).

Each trial starts ``gainsched build`` (two worker processes) over a folder that
holds a complete older output set, and signals it at a random moment: SIGINT
to its process group (Ctrl-C in a terminal) or SIGKILL to the command alone
(``kill -9``, the OOM killer). Then:

- no process of the build is left (the workers die with the command);
- no shared-memory file is left in ``/dev/shm``;
- the folder holds the old set or the new set, never a mix, once the next run
  has started (:func:`gainsched.publish.recover` is what it does first), and no
  temp file or stage.

``make interrupt-trials`` runs 60 trials; the suite runs a few
(``GAINSCHED_INTERRUPT_TRIALS``).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gainsched.publish import recover

from support import small_config_text

TRIALS = int(os.environ.get("GAINSCHED_INTERRUPT_TRIALS", "8"))
SET = ("gainsched_control.c", "gainsched_control.h", "gainsched_runtime.c", "gainsched_runtime.h",
       "trial.h5", "trial_control.h", "trial_gains.h")


def _config(n_xi: int) -> str:
    return small_config_text(name="trial", grid__speeds=[4, 6, 9, 12, 15],
                             grid__tilts_deg=[0, 10, 20, 30], grid__azimuth_samples=n_xi)


def _build(cfg: Path, out: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "gainsched", "build", str(cfg), "-o", str(out), "-j", "2"]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)


def _group(pgid: int) -> list[int]:
    """Live (not zombie) processes of a process group."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2 :].split()
            if fields[0] != "Z" and int(fields[2]) == pgid:
                pids.append(int(d.name))
    return pids


def _shm() -> set[str]:
    try:
        return set(os.listdir("/dev/shm"))
    except OSError:
        return set()


def _contents(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="process groups and /proc: Linux")
def test_random_sigint_and_sigkill_leave_old_or_new_set(tmp_path):
    old_cfg, new_cfg = tmp_path / "old.toml", tmp_path / "trial.toml"
    old_cfg.write_text(_config(6))
    new_cfg.write_text(_config(8))
    runs = {}
    for name, cfg in (("old", old_cfg), ("new", new_cfg)):
        t0 = time.perf_counter()
        p = _build(cfg, tmp_path / name)
        assert p.wait(timeout=300) == 0, p.stderr.read().decode()
        runs[name] = (_contents(tmp_path / name), time.perf_counter() - t0)
    (old, _), (new, duration) = runs["old"], runs["new"]
    assert sorted(old) == sorted(new) == sorted(SET) and old != new

    shm_before = _shm()
    pids = []  # the killed commands: what they left in /dev/shm is named after them
    rng = np.random.default_rng(2026)
    outcomes = {"old": 0, "new": 0, "rolled forward": 0}
    for trial in range(TRIALS):
        out = tmp_path / f"trial{trial}"
        out.mkdir()
        for name, data in old.items():
            (out / name).write_bytes(data)
        sig = signal.SIGKILL if trial % 2 == 0 else signal.SIGINT
        p = _build(new_cfg, out)
        pids.append(p.pid)
        # the first quarter is imports; every third trial aims at the end (writing)
        late = trial % 3 == 2
        time.sleep(duration * (rng.uniform(0.85, 1.1) if late else rng.uniform(0.25, 1.0)))
        if sig == signal.SIGINT:
            os.killpg(p.pid, sig)
        else:
            os.kill(p.pid, sig)
        p.wait(timeout=120)
        err = p.stderr.read().decode()
        assert "Traceback" not in err, err
        deadline = time.monotonic() + 20
        while _group(p.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _group(p.pid), f"trial {trial} ({sig.name}): processes left {_group(p.pid)}"
        pending = (out / ".gainsched-publish.json").exists()
        recover(out)  # what the next run in the folder does first
        got = _contents(out)
        assert got in (old, new), f"trial {trial} ({sig.name}): a mixed or partial set"
        outcomes["rolled forward" if pending else ("new" if got == new else "old")] += 1
    # loky names its semaphores and joblib its memmap folders after the creating process;
    # other entries (this test process's own pools, other programs) are not the builds'.
    # A dead build's resource tracker unlinks them when its last worker is gone: wait.
    ours = re.compile(r"[-_](" + "|".join(map(str, pids)) + r")[-_]")
    deadline = time.monotonic() + 15
    while (left := {e for e in _shm() - shm_before if ours.search(e)}) and \
            time.monotonic() < deadline:
        time.sleep(0.2)
    assert not left, f"shared memory left in /dev/shm by killed builds: {sorted(left)}"
    print(f"{TRIALS} trials: {outcomes}")
