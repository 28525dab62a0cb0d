"""MISRA C:2012 check of the hand-written C (``c/``): cppcheck's MISRA addon, the rule
categories, and the documented deviations. ``make lint`` runs ``python -m
gainsched.firmware.host.misra``; tests/firmware/test_misra.py runs the same
:func:`command` on a copy with a rule broken on purpose.

The pass rule: no finding is left after the deviations (``misra_deviations.txt``, next to
this module), and the deviations name advisory rules only, so a mandatory or required
rule never has a finding. Every deviation has its row, rule, scope and reason, in
docs/runtime.md, "MISRA C:2012 compliance".

cppcheck's addon needs the rule texts (licensed with the MISRA document) only for its
messages: without them it reports rule numbers, and :data:`ADVISORY` and
:data:`MANDATORY` (the categories of MISRA C:2012 Appendix A, with Amendments 1 and 2)
class them; every other rule is required.

Without cppcheck (``make lint`` first tries to install it: ``.ci/install-tools``) the
check is skipped in one line, except in CI (:func:`required_here`), where lint fails in
one line.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

__all__ = ["ADVISORY", "MANDATORY", "SOURCES", "DEVIATIONS", "Finding", "category", "command",
           "deviated_rules", "required_here", "run", "main"]

_HERE = Path(__file__).resolve().parent
#: the shipped C (``gainsched/firmware/c``)
_C = _HERE.parent / "c"
#: the translation units checked (their headers come in through their #includes)
SOURCES = (_C / "gainsched_runtime.c", _C / "gainsched_control.c")
#: the documented deviations, a cppcheck suppressions list (one ``misra-c2012-R.N:*/file``
#: per line, each under a comment saying why)
DEVIATIONS = _HERE / "misra_deviations.txt"

#: advisory rules of MISRA C:2012 (Amendments 1 and 2 included)
ADVISORY = frozenset({
    "1.2", "2.3", "2.4", "2.5", "2.6", "2.7", "4.2", "5.9", "8.7", "8.9", "8.11", "8.13",
    "10.5", "11.4", "11.5", "12.1", "12.3", "12.4", "13.3", "13.4", "15.1", "15.4", "15.5",
    "17.5", "17.8", "18.4", "18.5", "19.2", "20.1", "20.5", "20.10", "21.12"})
#: mandatory rules (no deviation possible)
MANDATORY = frozenset({
    "9.1", "12.5", "13.6", "17.3", "17.4", "17.6", "19.1", "21.13", "21.17", "21.18",
    "21.19", "21.20", "22.2", "22.4", "22.5", "22.6"})

_LINE = re.compile(r"^(?P<file>[^:]+):(?P<line>\d+):(?P<col>\d+): (?P<id>\S+)$")


def category(rule: str) -> str:
    """``"mandatory"``, ``"required"`` or ``"advisory"`` of a rule number such as ``"14.4"``."""
    if rule in MANDATORY:
        return "mandatory"
    return "advisory" if rule in ADVISORY else "required"


class Finding:
    """One cppcheck report: file, line, column and id (``misra-c2012-14.4``, or a cppcheck
    check of its own such as ``syntaxError``)."""

    __slots__ = ("file", "line", "col", "id")

    def __init__(self, file: str, line: int, col: int, id: str):
        self.file, self.line, self.col, self.id = file, line, col, id

    @property
    def rule(self) -> str | None:
        """The MISRA rule number, or None for a report of cppcheck's own."""
        return self.id[len("misra-c2012-"):] if self.id.startswith("misra-c2012-") else None

    @property
    def category(self) -> str:
        return category(self.rule) if self.rule else "cppcheck"

    def __repr__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}: {self.id} ({self.category})"


def deviated_rules(path: Path = DEVIATIONS) -> list[str]:
    """The rule numbers the deviations file suppresses, in its order."""
    rules = []
    for line in Path(path).read_text().splitlines():
        m = re.match(r"^misra-c2012-(\d+\.\d+)\b", line.strip())
        if m and m.group(1) not in rules:
            rules.append(m.group(1))
    return rules


def command(sources=SOURCES, deviations: Path | None = DEVIATIONS, cppcheck: str = "cppcheck"
            ) -> list[str]:
    """The cppcheck command line: C99, the MISRA addon, the sources' folder on the include
    path, the deviations as a suppressions list (None: every finding)."""
    sources = [Path(s) for s in sources]
    cmd = [cppcheck, "--std=c99", "--addon=misra", "--quiet", "--error-exitcode=2",
           "--template={file}:{line}:{column}: {id}"]
    cmd += sorted({f"-I{s.parent}" for s in sources})
    if deviations is not None:
        cmd.append(f"--suppressions-list={deviations}")
    return cmd + [str(s) for s in sources]


def run(sources=SOURCES, deviations: Path | None = DEVIATIONS) -> list[Finding]:
    """Run :func:`command`; the findings left (cppcheck's own errors included). Raises
    FileNotFoundError without cppcheck, RuntimeError when cppcheck fails without a
    finding to show for it."""
    exe = shutil.which("cppcheck")
    if exe is None:
        raise FileNotFoundError("cppcheck")
    res = subprocess.run(command(sources, deviations, exe), capture_output=True, text=True)
    findings, other = [], []
    for line in res.stderr.splitlines():
        m = _LINE.match(line.strip())
        if m:
            findings.append(Finding(m["file"], int(m["line"]), int(m["col"]), m["id"]))
        elif line.strip():
            other.append(line)
    if res.returncode not in (0, 2) or (res.returncode == 2 and not findings):
        raise RuntimeError(f"cppcheck failed ({res.returncode}):\n" + "\n".join(other))
    return findings


def _check_deviations(path: Path = DEVIATIONS) -> list[str]:
    """Problems of the deviations file: a rule that is not advisory may not be deviated."""
    return [f"{path.name}: rule {r} is {category(r)}: it may not be deviated, fix the code"
            for r in deviated_rules(path) if category(r) != "advisory"]


def required_here(environ=None) -> bool:
    """Whether the MISRA check must run here: in CI (``CI`` set to anything but ``""``,
    ``0``, ``false`` or ``no``, as CI services and ``.ci/run`` set it). Elsewhere a machine
    without cppcheck skips it, saying so (README, Set-up)."""
    value = (os.environ if environ is None else environ).get("CI", "")
    return value.strip().lower() not in ("", "0", "false", "no")


def _missing_text(required: bool) -> str:
    """The one line of a lint run without cppcheck: a failure in CI, a skip elsewhere."""
    what = "the MISRA C:2012 check of gainsched/firmware/c"
    get = ("Debian: apt-get install cppcheck, or `bash .ci/install-tools lint` as root, "
           "then `make lint`")
    if required:
        return f"lint: cppcheck not found: {what} is required in CI (CI is set) ({get})"
    return f"lint: skipped {what}: cppcheck not found ({get})"


def main(argv=None) -> int:
    """``make lint``'s MISRA step (``python -m gainsched.firmware.host.misra [SOURCE.c ...]``,
    default :data:`SOURCES`): 0 when clean, 1 with the findings. Without cppcheck: one
    line, and 0 (the check skipped) or, where it is required (:func:`required_here`), 1."""
    argv = sys.argv[1:] if argv is None else list(argv)
    sources = tuple(Path(a) for a in argv) or SOURCES
    exe = shutil.which("cppcheck")
    if exe is None:
        required = required_here()
        print(_missing_text(required), file=sys.stderr if required else sys.stdout)
        return 1 if required else 0
    problems = _check_deviations()
    findings = run(sources)
    for f in findings:
        print(repr(f), file=sys.stderr)
    for p in problems:
        print(p, file=sys.stderr)
    version = subprocess.run([exe, "--version"], capture_output=True, text=True).stdout.strip()
    names = ", ".join(s.name for s in sources)
    if findings or problems:
        counts = {}
        for f in findings:
            counts[f.category] = counts.get(f.category, 0) + 1
        print(f"lint: MISRA C:2012 ({version}): {len(findings)} findings in {names} "
              f"({', '.join(f'{n} {c}' for c, n in sorted(counts.items()))}); deviations: "
              f"{DEVIATIONS.name}, docs/runtime.md", file=sys.stderr)
        return 1
    print(f"lint: MISRA C:2012 ({version}): {names}: no findings "
          f"({len(deviated_rules())} advisory rules deviated, docs/runtime.md)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
