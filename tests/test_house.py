"""The house's size rules (issue 40): no module of ``gainsched/`` over 700 lines and no
function over 100 lines, except the entries of the allow-lists below, each with its
reason and its length today as a ceiling it may not grow past (a ratchet: an entry goes
when its module or function is split, and a new one needs a reason here)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).parents[1] / "gainsched"
MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 100

#: module -> (its ceiling in lines, why it is longer than MAX_MODULE_LINES today): none
#: left (issue 40 split the last ones); a new entry needs its reason here
MODULES: dict[str, tuple[int, str]] = {}

#: "module:function" -> (its ceiling in lines, why it is longer than MAX_FUNCTION_LINES):
#: none left (issue 40 split the last ones)
FUNCTIONS: dict[str, tuple[int, str]] = {}


def _lines() -> tuple[dict[str, int], dict[str, int]]:
    modules, functions = {}, {}
    for path in sorted(PACKAGE.rglob("*.py")):
        name = path.relative_to(PACKAGE.parent).as_posix()
        text = path.read_text()
        modules[name] = text.count("\n")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                key = f"{name}:{node.name}"
                functions[key] = max(functions.get(key, 0),
                                     node.end_lineno - node.lineno + 1)
    return modules, functions


@pytest.mark.parametrize("kind", ["module", "function"])
def test_nothing_is_longer_than_the_house_allows(kind):
    """Every module within 700 lines and every function within 100, or on the allow-list
    within its ceiling; every allow-list entry still needed (a split module leaves it)."""
    modules, functions = _lines()
    sizes, allowed, limit = ((modules, MODULES, MAX_MODULE_LINES) if kind == "module"
                             else (functions, FUNCTIONS, MAX_FUNCTION_LINES))
    over = {k: n for k, n in sizes.items() if n > limit}
    unlisted = {k: n for k, n in over.items() if k not in allowed}
    grown = {k: (n, allowed[k][0]) for k, n in over.items()
             if k in allowed and n > allowed[k][0]}
    stale = sorted(k for k in allowed if sizes.get(k, 0) <= limit)
    assert not unlisted, f"{kind}s over {limit} lines: {unlisted}"
    assert not grown, f"{kind}s grown past their ceiling (lines, ceiling): {grown}"
    assert not stale, f"allow-list entries no longer needed: {stale}"
    for key, (_, why) in allowed.items():
        assert why.strip(), f"{key}: say why"
