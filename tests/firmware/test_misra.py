"""MISRA C:2012 of the hand-written C (issue 40): `make lint`'s check
(gainsched/firmware/host/misra.py, cppcheck's MISRA addon) passes on the sources, fails on a
copy with a required rule broken on purpose, and deviates advisory rules only, each with
its row in docs/runtime.md."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from gainsched.firmware.host import misra

from support import REPO

C_DIR = Path(misra.__file__).parents[1] / "c"


def test_rule_categories():
    """The required rules issue 40 names, an advisory and a mandatory one."""
    for rule in ("14.4", "10.3", "10.8", "15.7", "14.1", "8.14"):
        assert misra.category(rule) == "required"
    assert misra.category("15.5") == "advisory"
    assert misra.category("9.1") == "mandatory"


def test_deviations_are_advisory_and_documented():
    """Every deviated rule is advisory and has its row (rule, scope, reason) in the
    compliance table of docs/runtime.md, and the table lists nothing else."""
    rules = misra.deviated_rules()
    assert rules and all(misra.category(r) == "advisory" for r in rules)
    doc = (REPO / "docs" / "runtime.md").read_text()
    table = doc.split("## MISRA C:2012 compliance", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| (\d+\.\d+) \| (\w+) \| ([^|]+) \| ([^|]+) \|$", table, re.M)
    assert sorted(r[0] for r in rows) == sorted(rules)
    assert all(cat == "advisory" and scope.strip() and len(why.strip()) > 20
               for _, cat, scope, why in rows)


@pytest.mark.needs_cppcheck
def test_sources_have_no_findings():
    """What `make lint` runs: no finding left after the deviations."""
    assert misra.main([]) == 0


@pytest.mark.needs_cppcheck
def test_injected_required_violation_fails_lint(tmp_path, capsys):
    """The same command on a copy of the sources with `if (n)` on an int (rule 14.4,
    required): a finding at that line, which no deviation hides, and lint's exit 1."""
    for f in C_DIR.iterdir():
        shutil.copy(f, tmp_path / f.name)
    src = tmp_path / "gainsched_runtime.c"
    text = src.read_text()
    anchor = "if (mirrored && (status & GS_NO_GAINS) == 0) {"
    assert text.count(anchor) == 1
    line = text[: text.index(anchor)].count("\n") + 1
    src.write_text(text.replace(anchor, anchor + "\n"
                                "        int n = status & GS_INFEASIBLE;\n"
                                "        if (n) {\n"
                                "            status |= GS_INFEASIBLE;\n"
                                "        }"))
    sources = [str(tmp_path / s.name) for s in misra.SOURCES]
    assert misra.main(sources) == 1  # lint's exit on the copy
    err = capsys.readouterr().err
    hits = [ln for ln in err.splitlines() if "misra-c2012-14.4" in ln]
    assert hits == [f"{src}:{line + 2}:12: misra-c2012-14.4 (required)"], err
    assert "(1 required)" in err
