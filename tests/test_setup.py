"""The README's set-up on a machine with only Python, a C compiler and make (issue 58):
``make lint`` installs cppcheck itself where the package manager is usable, skips the
MISRA check in one line where it is not, and fails in one line in CI.

Each case runs ``make lint`` on this checkout with the tools hidden from the PATH
(:func:`fresh_machine.hidden_path`); ``make fresh-machine`` (tests/fresh_machine.py) is
the whole promise on a fresh clone: ``make tables`` and ``make test-fast``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from fresh_machine import HIDDEN, SKIP_LINES, fresh_env, hidden_path

import gainsched

from support import REPO

MISRA_SKIP = SKIP_LINES["MISRA C:2012 check (cppcheck)"]

#: ``make lint`` checks the checkout in its own venv; a run against an installed wheel
#: (``make test-wheel``) has nothing of the checkout's to lint
checkout_only = pytest.mark.skipif(
    Path(gainsched.__file__).resolve().parents[1] != REPO.resolve(),
    reason="gainsched is not imported from this checkout (an installed wheel): make lint "
           "checks the checkout")
#: this Python is the venv make built from the lock (.ci/constraints.txt)
IN_LOCKED_VENV = Path(sys.prefix).resolve() == (REPO / ".venv").resolve()


def _lint(env):
    return subprocess.run(["make", "--no-print-directory", "lint"], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture
def bare(tmp_path):
    """The environment of a machine without cppcheck, the ARM tools, QEMU and a usable
    package manager (CI unset)."""
    return fresh_env(tmp_path)


def test_the_hidden_path_lacks_the_tools_and_keeps_the_rest(tmp_path):
    """What the other cases rely on: none of the hidden tools on the PATH, make, the C
    compiler and git still there."""
    path = hidden_path(tmp_path / "bin", hide=HIDDEN)
    names = set(os.listdir(path))
    assert {"make", "git", "sh"} <= names and ({"cc", "gcc"} & names)
    assert not [n for n in names if n.startswith(("cppcheck", "arm-none-eabi-", "qemu-"))]
    assert "apt-get" not in names and "sudo" not in names


@checkout_only
def test_lint_without_cppcheck_skips_the_misra_check_saying_so(bare):
    """No cppcheck and no way to install it: lint passes (ruff, the import contracts) and
    says in one line that the MISRA check was skipped, and how to get it."""
    res = _lint(bare)
    assert res.returncode == 0, res.stdout + res.stderr
    out = res.stdout + res.stderr
    skips = [ln for ln in out.splitlines() if MISRA_SKIP in ln]
    assert len(skips) == 1 and "apt-get install cppcheck" in skips[0], out
    assert "install-tools: could not install cppcheck" in out
    assert "Traceback" not in out


@checkout_only
def test_lint_in_ci_without_cppcheck_fails_in_one_line(bare):
    """CI=true (what .ci/run sets): the MISRA check is required, lint fails, one line."""
    res = _lint({**bare, "CI": "true"})
    assert res.returncode != 0
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("lint:")]
    assert len(lines) == 1 and "cppcheck not found" in lines[0], res.stderr
    assert "required in CI" in lines[0]
    assert MISRA_SKIP not in res.stdout + res.stderr
    assert "Traceback" not in res.stdout + res.stderr


@checkout_only
def test_lint_installs_cppcheck_where_the_package_manager_is_usable(tmp_path, bare):
    """A usable apt-get on the PATH (here a stand-in that records its call and fails as an
    offline mirror would): lint's install step asks it for cppcheck, then the check is
    skipped saying so. GAINSCHED_INSTALL_TOOLS=0 asks nothing."""
    bin_dir = tmp_path / "bin"
    calls = tmp_path / "apt-calls"
    (bin_dir / "apt-get").write_text(f'#!/bin/sh\necho "$@" >> {calls}\nexit 100\n')
    (bin_dir / "sudo").write_text('#!/bin/sh\n[ "$1" = -n ] && shift\nexec "$@"\n')
    for f in ("apt-get", "sudo"):
        (bin_dir / f).chmod(0o755)
    res = _lint(bare)
    assert res.returncode == 0, res.stdout + res.stderr
    asked = calls.read_text().splitlines()
    assert asked[0] == "install -y --no-install-recommends cppcheck", asked
    assert "update" in asked, asked  # the retry after refreshing the package lists
    assert MISRA_SKIP in res.stdout + res.stderr
    calls.unlink()
    res = _lint({**bare, "GAINSCHED_INSTALL_TOOLS": "0"})
    assert res.returncode == 0 and not calls.exists()
    assert "GAINSCHED_INSTALL_TOOLS=0" in res.stdout


def test_dependencies_are_ranges_and_the_lock_is_what_runs():
    """Issue 54: the package asks for ranges (a lower and an upper bound, never ``==``:
    a library pinned exactly cannot be installed beside anything else); the tested lock,
    .ci/constraints.txt, pins every one of them (and of the extras make installs) exactly,
    inside its range, and is what this environment runs when it is make's venv (an
    installed wheel beside other versions in the ranges, ``make test-wheel``, is not)."""
    import tomllib
    from importlib.metadata import version

    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    reqs = [Requirement(r) for r in project["dependencies"]]
    installed = reqs + [Requirement(r) for extra in ("dev", "dask")
                        for r in project["optional-dependencies"][extra]]
    for r in reqs + [Requirement(r) for rs in project["optional-dependencies"].values()
                     for r in rs]:
        ops = {s.operator for s in r.specifier}
        assert ops == {">=", "<"}, (r, "a range: a lower and an upper bound")
    lock = {}
    for line in (REPO / ".ci" / "constraints.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, ver = line.partition("==")
            assert ver, f".ci/constraints.txt: {line!r} is not exact"
            lock[canonicalize_name(name)] = ver.strip()
    for r in installed:
        name = canonicalize_name(r.name)
        assert name in lock, f"{r.name} is not in the lock"
        assert r.specifier.contains(lock[name]), (r, lock[name])
        if IN_LOCKED_VENV:
            assert version(r.name) == lock[name], (r.name, version(r.name), lock[name])
