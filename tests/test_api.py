"""The public API (``gainsched/__init__.py``, docs/api.md).

Every exported name resolves to the object of its module, ``import gainsched`` imports
none of them, every function has a numpydoc docstring with each parameter, the return
value and an Example (``numpydoc.validate``), every result class documents each of its
fields, and every Example runs (doctest). docs/api.md is generated from the docstrings;
``python tests/test_api.py`` rewrites it.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from numpydoc.docscrape import ClassDoc
from numpydoc.validate import validate

import gainsched

from support import run_examples

REPO = Path(__file__).resolve().parents[1]
API_PAGE = REPO / "docs" / "api.md"
NAMES = [n for n in gainsched.__all__ if n != "__version__"]

#: numpydoc.validate codes every exported function and class must pass: a docstring with
#: a summary, every parameter documented (with a description) and no unknown one, in
#: order, a Returns section, an Examples section.
REQUIRED = {"GL08", "SS01", "PR01", "PR02", "PR03", "PR07", "RT01", "EX01"}


def _summary(obj) -> str:
    """The first line of an object's docstring."""
    return inspect.getdoc(obj).splitlines()[0].strip()


def api_page() -> str:
    """docs/api.md: every exported name with its one-line summary, by task."""
    lines = [
        "# Python API",
        "",
        "<!-- Generated from the docstrings by `python tests/test_api.py`; "
        "tests/test_api.py checks it is current. -->",
        "",
        "Everything the command line does is a function you can call. The names below are",
        "exported by the package itself (`import gainsched as gs`); each has a numpydoc",
        "docstring with shapes, units and an Example (`help(gs.solve_circle)`) that the",
        "tests run from the repository root. Other modules are internal and may change.",
        "",
        "Two example scripts show whole tasks: `examples/plot_gains.py` (a gain schedule",
        "plotted in 15 lines) and `examples/model_vs_measurement.py` (compare, diagnose,",
        "apply and compare again, from Python). Conventions and units:",
        "[conventions.md](conventions.md); the table's contents:",
        "[table-format.md](table-format.md).",
        "",
    ]
    for task, module, names in gainsched.API:
        lines += [f"## {task} (`gainsched.{module}`)", "", "| name | what it is |", "|---|---|"]
        for name in names:
            obj = getattr(gainsched, name)
            kind = "class" if inspect.isclass(obj) else "function"
            lines.append(f"| `{name}` ({kind}) | {_summary(obj)} |")
        lines.append("")
    return "\n".join(lines)


def test_every_name_resolves_to_its_module_object():
    for task, module, names in gainsched.API:
        mod = __import__(f"gainsched.{module}", fromlist=["_"])
        for name in names:
            assert getattr(gainsched, name) is getattr(mod, name), (task, name)
            assert name in mod.__all__, f"{name} is not in gainsched.{module}.__all__"
    assert len(NAMES) == len(set(NAMES))
    with pytest.raises(AttributeError, match="no attribute 'solve'"):
        gainsched.solve  # noqa: B018
    assert set(NAMES) <= set(dir(gainsched))


def test_import_gainsched_is_light():
    """The names are imported on first use: the command line does not pay for all of them."""
    code = ("import sys, gainsched; print(sorted(m for m in sys.modules "
            "if m.startswith('gainsched.') or m in ('scipy', 'matplotlib', 'h5py')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_api_page_is_current():
    assert API_PAGE.read_text() == api_page(), (
        "docs/api.md is stale: run `python tests/test_api.py` to regenerate it")


def _qualname(name: str) -> str:
    obj = getattr(gainsched, name)
    return f"{obj.__module__}.{obj.__qualname__}"


@pytest.mark.parametrize("name", NAMES)
def test_docstring_is_numpydoc_with_every_parameter(name):
    obj = getattr(gainsched, name)
    if dataclasses.is_dataclass(obj):
        documented = {n.strip() for p in ClassDoc(obj, config={"show_class_members": False})
                      ["Attributes"] for n in p.name.split(",")}
        missing = [f.name for f in dataclasses.fields(obj) if f.name not in documented]
        assert not missing, f"{name}: fields without an Attributes entry: {missing}"
        assert _summary(obj), name
        return
    codes = REQUIRED - ({"RT01"} if inspect.isclass(obj) else set())
    errors = [(c, m) for c, m in validate(_qualname(name))["errors"] if c in codes]
    assert not errors, f"{name}: {errors}"


@pytest.fixture(scope="module")
def example_dir(tmp_path_factory):
    """A working directory like the repository root: configs/, tables/, examples/ (links)."""
    d = tmp_path_factory.mktemp("examples")
    for sub in ("configs", "tables", "examples"):
        (d / sub).symlink_to(REPO / sub)
    return d


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_docstring_examples_run(name, example_dir, monkeypatch):
    run_examples(getattr(gainsched, name), name, example_dir, monkeypatch)


def test_readme_python_example_runs(example_dir, monkeypatch, capsys):
    """The README's "From Python" block runs and prints what its comments say."""
    text = (REPO / "README.md").read_text()
    block = re.search(r"## From Python.*?```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(example_dir)
    exec(compile(block, "README.md", "exec"), {})
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("(2, 36, 4, 11) [0.95")


if __name__ == "__main__":
    os.chdir(REPO)
    API_PAGE.write_text(api_page())
    print(f"wrote {API_PAGE}")


def test_reprs_are_one_short_line(paper_table):
    """Issue 39: the objects a notebook shows (config, table, comparison, diagnosis, a
    candidate's result) print as one line of at most 300 characters naming what they
    are, not their arrays (repr(Table) was 213,033 characters)."""
    import gainsched as gs

    from support import PAPER_TOML, REPO

    cfg = gs.load_config(PAPER_TOML)
    logs = [REPO / "examples" / "flights" / f for f in ("v3.csv", "v9.csv")]
    d = gs.diagnose(cfg, logs, candidates=["drag", "rotor_drag"])
    for obj, start in ((cfg, "Config('paper', "), (paper_table, "Table('paper', "),
                       (d.base, "Comparison('paper', 2 segments, normalised RMS "),
                       (d, "Diagnosis('paper', 2 flights, "),
                       (d.results[0], f"CandidateResult({d.results[0].name!r}, ")):
        text = repr(obj)
        assert text.startswith(start) and "\n" not in text and len(text) <= 300, text
