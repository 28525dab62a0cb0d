"""The suite's size, to show that a change keeps it: ``make test-count``.

Prints the tests pytest collects and the assertions written in the test files: ``assert``
statements plus assertion calls (``np.testing.assert_*``, ``pytest.raises``,
``pytest.warns``, ``pytest.approx``), counted on the syntax tree. With a git revision
(``python tests/tally.py HEAD~3``) it counts the assertions of that revision's files.
"""

from __future__ import annotations

import ast
import subprocess
import sys

_CALLS = ("raises", "warns", "approx")


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], capture_output=True, text=True, check=True).stdout


def assertion_counts(rev: str | None = None) -> tuple[int, int, int]:
    """(test files, assert statements, assertion calls) in tests/ of ``rev`` (None: the
    work tree, untracked files included)."""
    if rev is None:
        files = _git("ls-files", "-co", "--exclude-standard", "tests").split()
    else:
        files = _git("ls-tree", "-r", "--name-only", rev, "tests").split()
    files = [f for f in files if f.endswith(".py")]
    statements = calls = 0
    for f in files:
        text = _git("show", f"{rev}:{f}") if rev else open(f, encoding="utf-8").read()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.Assert):
                statements += 1
            elif isinstance(node, ast.Call):
                fn = node.func
                name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", "")
                calls += name.startswith("assert_") or name in _CALLS
    return len(files), statements, calls


def main(argv: list[str]) -> None:
    rev = argv[0] if argv else None
    n_files, statements, calls = assertion_counts(rev)
    print(f"{rev or 'work tree'}: {n_files} test-suite files, {statements} assert statements, "
          f"{calls} assertion calls, {statements + calls} assertions in all")
    if rev is None:
        out = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                              "-p", "no:cacheprovider"], capture_output=True, text=True)
        print(out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    main(sys.argv[1:])
