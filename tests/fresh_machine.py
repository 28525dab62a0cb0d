"""The README's promise on a machine that has only what it asks (issue 58): Python 3.11, a
C compiler and GNU make; no cppcheck, no ARM cross compiler, no QEMU, and no package
manager that could install them.

``python tests/fresh_machine.py`` (``make fresh-machine``) clones HEAD into a temporary
folder and runs the README's commands there, ``make tables`` then ``make test-fast``
(lint included), with those tools hidden from the PATH (:func:`hidden_path`), CI unset
and an empty kernel cache. It passes when both commands pass, the checks that could not
run said so (the MISRA check's line, the processor-in-the-loop skips), and ``git
status`` is clean after them; it ends with the list of what was skipped and why.

tests/test_setup.py runs ``make lint`` the same way on this checkout (the quick part of
the promise, in the suite); this script is the whole of it (a few minutes).
"""

from __future__ import annotations

import fnmatch
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: what a machine with only Python, a C compiler and make lacks: the optional tools, and
#: a usable package manager (with it, ``make lint`` would install cppcheck)
HIDDEN = ("cppcheck*", "arm-none-eabi-*", "qemu-*", "apt-get", "apt", "sudo")
#: a line of each check the hidden tools skip, as the run prints it
SKIP_LINES = {
    "MISRA C:2012 check (cppcheck)": "lint: skipped the MISRA C:2012 check",
    "processor-in-the-loop tests (ARM gcc, QEMU)": "processor-in-the-loop tests skipped",
}


def hidden_path(folder: Path, hide=HIDDEN, path: str | None = None) -> str:
    """A PATH of one folder holding a link to every program of ``path`` (default: this
    process's PATH, first occurrence of a name wins) but those whose names match a pattern
    of ``hide`` (:mod:`fnmatch`): the PATH of a machine without those tools."""
    folder.mkdir(parents=True, exist_ok=True)
    for d in (path if path is not None else os.environ["PATH"]).split(os.pathsep):
        if not d or not os.path.isdir(d):
            continue
        for entry in os.scandir(d):
            name = entry.name
            if any(fnmatch.fnmatch(name, p) for p in hide) or (folder / name).exists():
                continue
            if os.access(entry.path, os.X_OK) and not entry.is_dir():
                (folder / name).symlink_to(entry.path)
    return str(folder)


def fresh_env(tmp: Path) -> dict[str, str]:
    """The environment of the fresh machine: :func:`hidden_path`, CI unset, an empty
    kernel cache in ``tmp``."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("CI", "VIRTUAL_ENV", "PYTHONPATH", "GAINSCHED_INSTALL_TOOLS")}
    env["PATH"] = hidden_path(tmp / "bin")
    env["GAINSCHED_CACHE"] = str(tmp / "cache")
    return env


def _make(target: str, clone: Path, env) -> str:
    """Run ``make TARGET`` in the clone, echoing its output; its text, or exit 1."""
    print(f"fresh-machine: make {target}", flush=True)
    proc = subprocess.Popen(["make", target], cwd=clone, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    out = []
    for line in proc.stdout:
        sys.stdout.write(line)
        out.append(line)
    if proc.wait():
        sys.exit(f"fresh-machine: make {target} failed (exit {proc.returncode})")
    return "".join(out)


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="gainsched-fresh-") as t:
        tmp = Path(t)
        clone = tmp / "clone"
        subprocess.run(["git", "clone", "--quiet", str(REPO), str(clone)], check=True)
        env = fresh_env(tmp)
        for tool in ("cppcheck", "arm-none-eabi-gcc", "qemu-system-arm", "apt-get"):
            found = subprocess.run(["sh", "-c", f"command -v {tool}"], env=env,
                                   capture_output=True, text=True).stdout.strip()
            assert not found, f"{tool} is still on the PATH: {found}"
        _make("tables", clone, env)
        out = _make("test-fast", clone, env)
        status = subprocess.run(["git", "status", "--porcelain"], cwd=clone, text=True,
                                capture_output=True, check=True).stdout
        if status:
            sys.exit(f"fresh-machine: git status is not clean after the commands:\n{status}")
        missing = [what for what, line in SKIP_LINES.items() if line not in out]
        if missing:
            sys.exit(f"fresh-machine: no line says these checks were skipped: {missing}")
        print("\nfresh-machine: make tables and make test-fast passed without "
              f"{', '.join(HIDDEN)}; git status clean. Skipped, and why:")
        lines = [ln.strip() for ln in out.splitlines()
                 if ln.startswith(("lint: skipped", "install-tools:", "SKIPPED"))]
        for ln in dict.fromkeys(re.sub(r"^SKIPPED \[\d+\] ", "SKIPPED ", ln) for ln in lines):
            print(f"  {ln}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
