"""Numbers in the docs that come from a config or the committed table stay equal to them,
and the sample outputs in the docs are what the commands print (issue 39)."""

from __future__ import annotations

import difflib
import glob
import re
import shlex
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.constants import Reason
from gainsched.schedule.tables import load_table

ROOT = Path(__file__).resolve().parents[1]


def _flatten(d, prefix=""):
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        out.update(_flatten(v, key + ".") if isinstance(v, dict) else {key: v})
    return out


def test_readme_config_snippet_is_the_paper_config():
    """Every key of the README's config example that configs/paper.toml also sets has
    its value (the example is the paper config, annotated)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"## Config format.*?```toml\n(.*?)```", text, re.S).group(1)
    readme = _flatten(tomllib.loads(block))
    paper = _flatten(tomllib.loads((ROOT / "configs/paper.toml").read_text()))
    shared = sorted(set(readme) & set(paper))
    assert len(shared) >= 20, shared
    wrong = {k: (readme[k], paper[k]) for k in shared if readme[k] != paper[k]}
    assert not wrong, wrong


def test_table_format_lists_the_paper_tables_circles_without_gains():
    text = (ROOT / "docs/table-format.md").read_text()
    rows = re.findall(r"^\| (\d+) \| ([\d., -]+) \| ([\d., -]+) \|$", text, re.M)
    documented = {}
    for tilt, slack, low in rows:
        for bit, cell in ((Reason.SLACK, slack), (Reason.THRUST_LOW, low)):
            for v in re.findall(r"[\d.]+", cell):
                documented[(float(tilt), float(v))] = int(bit)
    t = load_table(ROOT / "tables/paper.h5")
    actual = {}
    for ia, a in enumerate(np.rad2deg(t.tilt)):
        for iv, v in enumerate(t.speed):
            r = np.bitwise_or.reduce(t.reasons[ia, iv])
            if r:
                actual[(round(float(a), 6), float(v))] = int(r & ~Reason.ELSEWHERE)
    assert documented == actual


# ------------------------------------------------------------ sample outputs (issue 39)
# A sample output in README.md or docs/*.md is a fenced block tagged ``console`` (it may be
# indented, in a list item): each ``$ gainsched ARGS`` line is a command, run from a folder
# where configs/, examples/ and tables/ are the checkout's, and the lines after it, up to
# the next ``$`` line, are its standard output, line for line; a line ``...`` stands for
# any number of lines (none included), and ``…`` in a line any text (for digits past a
# result's precision, which differ from run to run: a fit's full float64 repr, say, and
# for nothing deterministic). ``$ cat FILE`` shows a file a command wrote. The
# commands of one page run in order in one folder (a later one reads what an earlier one
# wrote); a command given twice on a page runs once. To update a sample: run its command
# and paste what it prints. Every console block has at least one ``$`` line.

SAMPLE_PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_CONSOLE = re.compile(r"^( *)```console\n(.*?)^\1```", re.M | re.S)


def _samples(text: str) -> list[tuple[str, list[str]]]:
    """``(command, documented lines)`` of every console block of a page, in order."""
    out = []
    for m in _CONSOLE.finditer(text):
        indent = len(m.group(1))
        lines = [ln[indent:].rstrip() for ln in m.group(2).splitlines()]
        assert lines and lines[0].startswith("$ "), f"a console block with no command: {lines}"
        for ln in lines:
            if ln.startswith("$ "):
                out.append((ln[2:].strip(), []))
            else:
                out[-1][1].append(ln)
    return out


def _matches(documented: list[str], real: list[str]) -> bool:
    pattern = "".join(r"(?:.*\n)*?" if ln == "..." else
                      ".*?".join(map(re.escape, ln.split("…"))) + r"\n" for ln in documented)
    return re.fullmatch(pattern, "".join(ln.rstrip() + "\n" for ln in real)) is not None


def _run_sample(command: str, cwd: Path) -> list[str]:
    from gainsched.cli import cli

    words = shlex.split(command)
    args = [a for w in words[1:] for a in (sorted(glob.glob(w, root_dir=cwd))
                                           if any(c in w for c in "*?[") else [w])]
    if words[0] == "cat":
        return (cwd / args[0]).read_text().splitlines()
    assert words[0] == "gainsched", f"a sample of {words[0]!r}: only gainsched and cat run"
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, (command, res.output)
    return res.stdout.splitlines()


#: pages whose samples take more than a few seconds (diagnose twice and a campaign; the
#: build of a chosen grid): about 20 s each on 2 idle cores
SLOW_PAGES = {"model-vs-measurement.md", "grid.md"}


@pytest.mark.parametrize("page", [
    pytest.param(p, id=p.name, marks=[pytest.mark.slow] if p.name in SLOW_PAGES else [])
    for p in SAMPLE_PAGES if _CONSOLE.search(p.read_text())])
def test_sample_outputs_are_what_the_commands_print(page, tmp_path, monkeypatch):
    """Every console block of the page: its commands print what it shows (a diff of
    documented against real output otherwise)."""
    for name in ("configs", "examples", "tables"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    ran, wrong = {}, []
    for command, documented in _samples(page.read_text()):
        if command not in ran:
            ran[command] = _run_sample(command, tmp_path)
        if not _matches(documented, ran[command]):
            diff = difflib.unified_diff(documented, ran[command], "documented", "real",
                                        lineterm="", n=1)
            wrong.append(f"$ {command}\n" + "\n".join(diff))
    assert not wrong, f"{page.name}: samples that are not the real output:\n" + \
        "\n\n".join(wrong)


def test_the_pages_with_sample_outputs_keep_them():
    """The sample outputs of the README and the model-vs-measurement walk-through are
    checked (a block retagged away from ``console`` would silently leave the test)."""
    n = {p.name: len(_samples(p.read_text())) for p in SAMPLE_PAGES}
    assert n["README.md"] >= 2 and n["model-vs-measurement.md"] >= 5 and n["grid.md"] >= 1, n


def test_elided_lines_match_any_number_of_lines():
    assert _matches(["a", "...", "d"], ["a", "b", "c", "d"])
    assert _matches(["a", "...", "b"], ["a", "b"])
    assert _matches(["...", "c"], ["a", "b", "c"])
    assert not _matches(["a", "c"], ["a", "b", "c"])
    assert not _matches(["a", "...", "c"], ["a", "b", "c", "d"])
    assert not _matches(["a.b"], ["axb"])
    assert _matches(["x = 0.12…  # m"], ["x = 0.1234    # m"])
    assert not _matches(["x = 0.12…  # m"], ["x = 0.1334    # m"])
