"""Numbers in the docs that come from a config or the committed table stay equal to them."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np

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
