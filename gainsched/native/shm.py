"""What killed builds leave in ``/dev/shm``, removed by the next run.

A build's worker pool (loky, :func:`~gainsched.native.reproducible.pinned_executor`)
makes POSIX named semaphores, ``/dev/shm/sem.loky-PID-XXXXXXXX`` (``PID``: the
process that made them), and joblib may make memmap folders
``/dev/shm/joblib_memmapping_folder_PID_...``. loky's resource tracker removes them
when the build ends, even when the command alone is killed; but ``kill -9`` of the
whole process group (a terminal closed, a CI job cancelled, ``timeout -s KILL``)
kills the tracker with it, and nothing removes them again until a reboot.

So a process marks itself before it makes a pool: ``/dev/shm/gainsched-run-PID.json``
holds its pid, the start time of that pid (``/proc/PID/stat``: a later process that
reuses the pid is not it), its pid namespace and the boot. Every later run (every
``gainsched`` command as it starts, whether it makes a pool or not, and a library call
before its own pool starts) looks at the marks: a mark whose process is gone (no process
with that pid and start time in this namespace and boot) has its entries removed,
then the mark. A mark of a live process (a concurrent build) is left alone, and so
is a mark of another pid namespace sharing this ``/dev/shm`` (its processes cannot
be seen from here), and every entry no mark names (other programs'). A run that
ends normally removes its own mark.

Linux only (``/proc``, ``/dev/shm``); elsewhere both functions do nothing.
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
from pathlib import Path

__all__ = ["SHM", "claim", "sweep"]

#: where POSIX named semaphores and joblib's memmaps live
SHM = Path("/dev/shm")
_MARK = "gainsched-run-"
_claimed: int | None = None  # the pid whose mark this process wrote


def _start_time(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot), or None: no such
    process, or a zombie (dead, its entries no longer in use)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (OSError, ValueError):
        return None
    fields = stat[stat.rindex(")") + 2:].split()
    return None if fields[0] in ("Z", "X") else fields[19]


def _here() -> dict[str, str]:
    """This process's pid namespace and boot (what makes a pid mean this process)."""
    try:
        ns = os.readlink("/proc/self/ns/pid")
    except OSError:
        ns = ""
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        boot = ""
    return {"ns": ns, "boot": boot}


def _usable() -> bool:
    return SHM.is_dir() and os.access(SHM, os.W_OK) and Path("/proc/self/stat").exists()


def _entries(pid: int) -> list[Path]:
    """What a process ``pid`` of gainsched makes in :data:`SHM`."""
    return [*SHM.glob(f"sem.loky-{pid}-*"), *SHM.glob(f"joblib_memmapping_folder_{pid}_*")]


def _remove(path: Path) -> None:
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    except OSError:  # another user's (the sticky /dev/shm), or removed meanwhile
        pass


def sweep() -> list[Path]:
    """Remove the entries (and the marks) of gainsched runs that are gone.

    Returns
    -------
    list of Path
        What was removed (the marks included).
    """
    if not _usable():
        return []
    here, removed = _here(), []
    for mark in SHM.glob(_MARK + "*.json"):
        try:
            pid = int(mark.name[len(_MARK):-len(".json")])
        except ValueError:
            continue  # not a name this module writes
        try:
            entry = json.loads(mark.read_text())
            start, ns, boot = str(entry["start"]), str(entry["ns"]), str(entry["boot"])
        except (OSError, ValueError, KeyError, TypeError):
            # a mark cut short by a kill while it was written: judge by the pid alone
            start, ns, boot = None, here["ns"], here["boot"]
        if boot == here["boot"]:
            if ns != here["ns"]:
                continue  # a process of another pid namespace: not ours to judge
            now = _start_time(pid)
            if now is not None and (start is None or now == start):
                continue  # alive: a concurrent run (or, unknown start, maybe it)
        # gone (or a mark from before a reboot: every pid of it is gone)
        for path in _entries(pid):
            _remove(path)
            removed.append(path)
        _remove(mark)
        removed.append(mark)
    return removed


def _release(pid: int) -> None:
    if os.getpid() == pid:  # not in a forked child, which inherits atexit
        (SHM / f"{_MARK}{pid}.json").unlink(missing_ok=True)


def claim() -> None:
    """Before this process makes a worker pool: :func:`sweep` the runs that are gone,
    then mark this process (once; the mark goes when the process ends normally)."""
    global _claimed
    if not _usable():
        return
    sweep()
    pid = os.getpid()
    if _claimed == pid:
        return
    start = _start_time(pid)
    if start is None:
        return
    text = json.dumps({"pid": pid, "start": start, **_here()})
    mark = SHM / f"{_MARK}{pid}.json"
    try:
        with open(mark, "w") as f:  # a few bytes: one write
            f.write(text)
    except OSError:
        return
    _claimed = pid
    atexit.register(_release, pid)
