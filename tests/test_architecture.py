"""The package's layers (issue 13; docs/architecture.md).

The import-linter contract in pyproject.toml (run by ``make lint``) orders the
modules in layers; these tests keep it honest: every module is in a layer, the
import graph (lazy imports inside functions included) has no cycle, and an
injected back-edge breaks the contract. A second contract keeps the firmware off the
model (issue 40: the firmware comes from the table alone); an injected
``firmware -> model`` edge breaks it. Inside the firmware, what ships sits below the
host tools of ``firmware.host`` (issue 54); a shipped module importing one breaks it.
"""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).parents[1]
PACKAGE = ROOT / "gainsched"
CONTRACT = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
LINT = Path(sys.executable).with_name("lint-imports")


def _contract(kind: str) -> dict:
    """The one contract of type ``kind`` over the whole package in pyproject.toml
    ("layers", "forbidden"); the sub-packages' own layers contracts are not it."""
    (contract,) = [c for c in CONTRACT["contracts"] if c["type"] == kind
                   and c.get("containers", ["gainsched"]) == ["gainsched"]]
    return contract


def _layer_modules() -> list[str]:
    contract = _contract("layers")
    return [m.strip() for layer in contract["layers"] for m in layer.split("|")]


def test_every_module_is_in_a_layer():
    """A new top-level module or sub-package must be placed in the contract, or it would
    escape it."""
    package = ROOT / "gainsched"
    members = {p.stem for p in package.glob("*.py") if p.stem != "__init__"}
    members |= {p.parent.name for p in package.glob("*/__init__.py")}
    listed = _layer_modules()
    assert len(listed) == len(set(listed)), "a member is listed twice"
    assert set(listed) == members


@pytest.mark.parametrize("container", ["gainsched.firmware", "gainsched.firmware.host"])
def test_every_firmware_module_is_in_a_layer(container):
    """Issue 54: the firmware's two trades (what ships, the host tools) are layers of
    their own contracts; a new module of either must be placed in them."""
    (contract,) = [c for c in CONTRACT["contracts"] if c.get("containers") == [container]]
    package = ROOT.joinpath(*container.split("."))
    members = {p.stem for p in package.glob("*.py") if p.stem != "__init__"}
    members |= {p.parent.name for p in package.glob("*/__init__.py")}
    listed = [m.strip() for layer in contract["layers"] for m in layer.split("|")]
    assert len(listed) == len(set(listed)), "a member is listed twice"
    assert set(listed) == members


def test_no_import_cycle():
    graph = grimp.build_graph("gainsched", exclude_type_checking_imports=True)
    mods = sorted(m for m in graph.modules if m != "gainsched")
    seen, stack, on_stack = {}, [], set()

    def visit(m):  # depth-first search for a back edge
        seen[m] = True
        stack.append(m)
        on_stack.add(m)
        for d in sorted(graph.find_modules_directly_imported_by(m)):
            if d == "gainsched":
                continue
            if d in on_stack:
                cycle = stack[stack.index(d):] + [d]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if d not in seen:
                visit(d)
        stack.pop()
        on_stack.discard(m)

    for m in mods:
        if m not in seen:
            visit(m)


#: imports made for annotations only (``if TYPE_CHECKING:``): the contract and the cycle
#: check above do not see them (exclude_type_checking_imports), so each is listed here
#: with why it stays; none may be added (the budget takes a structural type of its own,
#: gainsched.config.BuildConfig, not the Config).
TYPE_ONLY_IMPORTS = {
    ("gainsched.model.reduced", "gainsched.config"): "Model is made from a Config",
    ("gainsched.config._plausible", "gainsched.config._reader"): "check_circles reads the "
    "Config that the config reader validates through it",
}


def type_only_imports(package: str = "gainsched") -> set[tuple[str, str]]:
    """(importer, imported) edges that exist only under ``if TYPE_CHECKING:``."""
    full = grimp.build_graph(package, exclude_type_checking_imports=False, cache_dir=None)
    run = grimp.build_graph(package, exclude_type_checking_imports=True, cache_dir=None)
    return {(m, d) for m in full.modules
            for d in full.find_modules_directly_imported_by(m)
            - run.find_modules_directly_imported_by(m)}


def test_type_only_imports_are_the_listed_ones():
    found = type_only_imports()
    assert found == set(TYPE_ONLY_IMPORTS), sorted(found ^ set(TYPE_ONLY_IMPORTS))
    assert not any(m == "gainsched.config._budget" for m, _ in found)


def _lint(package_parent: Path, cwd: Path) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(package_parent), "PATH": str(Path(sys.executable).parent)}
    cmd = [str(LINT), "--no-cache", "--config", str(ROOT / "pyproject.toml")]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.skipif(not LINT.exists(), reason="import-linter not installed")
def test_contract_is_kept():
    res = _lint(ROOT, ROOT)
    assert res.returncode == 0, res.stdout + res.stderr


@pytest.mark.skipif(not LINT.exists(), reason="import-linter not installed")
@pytest.mark.parametrize("module, back_edge", [
    ("constants.py", "from . import cli  # injected\n"),  # the base imports the top
    ("config/_reader.py",
     "def _f():\n    from ..schedule.grid import build_grid  # injected, lazy\n"),
    ("publish.py", "from . import resources  # injected: a sibling of one layer\n"),
    ("model/reduced.py", "from ..schedule import grid  # injected: model above schedule\n"),
    # inside the packages of private modules: a lower concept reaching a higher one
    ("analysis/diagnose/_candidates.py", "from . import _fit  # injected\n"),
    ("analysis/compare/_measured.py", "from . import _residual  # injected\n"),
    ("analysis/logs/_schema.py", "from . import _read  # injected\n"),
    # the firmware: what ships reaching a host tool; a host tool's base reaching PIL
    ("firmware/header.py", "from .host import lookup  # injected: shipped imports host\n"),
    ("firmware/cfiles.py",
     "def _f():\n    from .host.compiler import STRICT_CFLAGS  # injected, lazy\n"),
    ("firmware/host/compiler.py", "from . import pil  # injected\n"),
])
def test_contract_fails_on_an_injected_back_edge(tmp_path, module, back_edge):
    copy = tmp_path / "gainsched"
    shutil.copytree(ROOT / "gainsched", copy, ignore=shutil.ignore_patterns("__pycache__"))
    with open(copy / module, "a") as f:
        f.write("\n" + back_edge)
    res = _lint(tmp_path, tmp_path)
    assert res.returncode != 0 and "BROKEN" in res.stdout, res.stdout + res.stderr


def test_the_firmware_contract_forbids_the_model():
    """The contract that keeps the firmware off the model names them and allows only
    indirect imports (firmware -> schedule -> model: the schedule owns the model)."""
    contract = _contract("forbidden")
    assert contract["source_modules"] == ["gainsched.firmware"]
    assert contract["forbidden_modules"] == ["gainsched.model"]
    assert contract["allow_indirect_imports"] is True


@pytest.mark.skipif(not LINT.exists(), reason="import-linter not installed")
@pytest.mark.parametrize("module, edge", [
    ("firmware/runtime.py", "from ..model.reduced import Model  # injected\n"),
    ("firmware/controller.py",
     "def _f():\n    from ..model import geometry  # injected, lazy\n"),
])
def test_contract_fails_on_an_injected_firmware_to_model_edge(tmp_path, module, edge):
    """firmware -> model is allowed by the layers (firmware is above model): only the
    forbidden contract catches it, and says which."""
    copy = tmp_path / "gainsched"
    shutil.copytree(ROOT / "gainsched", copy, ignore=shutil.ignore_patterns("__pycache__"))
    with open(copy / module, "a") as f:
        f.write("\n" + edge)
    res = _lint(tmp_path, tmp_path)
    assert res.returncode != 0, res.stdout + res.stderr
    broken = [line for line in res.stdout.splitlines() if line.endswith("BROKEN")]
    assert broken == ["firmware from the table alone: firmware does not import model BROKEN"], (
        res.stdout)


#: commands whose work is not yet a study of gainsched.studies (issue 54's ratchet: an entry
#: goes when its study comes; none may be added)
NOT_YET_STUDIES: set[str] = set()


def _commands() -> dict[str, ast.FunctionDef]:
    """Every command of the command line (a function decorated ``@cli.command(...)``) by
    its name on the command line, read from gainsched/cli's syntax trees."""
    out = {}
    for path in sorted((PACKAGE / "cli").glob("*.py")):
        for node in ast.parse(path.read_text()).body:
            if not isinstance(node, ast.FunctionDef):
                continue
            for dec in node.decorator_list:
                call = dec if isinstance(dec, ast.Call) else None
                fn = call.func if call else dec
                if isinstance(fn, ast.Attribute) and fn.attr == "command":
                    named = [a.value for a in (call.args if call else [])
                             if isinstance(a, ast.Constant)]
                    out[named[0] if named else node.name.replace("_", "-")] = node
    return out


def _studies_called(fn: ast.FunctionDef) -> list[str]:
    """The functions of gainsched.studies a command imports and calls."""
    names = {}
    for node in ast.walk(fn):
        if isinstance(node, ast.ImportFrom) and node.module == "studies" and node.level == 2:
            names.update({a.asname or a.name: a.name for a in node.names})
    return [names[n.func.id] for n in ast.walk(fn)
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in names]


#: the studies a command calls in a mode of its own, besides its one study: ``convert
#: --list`` lists the topics (studies.topics) instead of converting, ``check
#: --uncertain`` closes the loops over a diagnosis's box (studies.check_uncertain)
MODES = {"convert": ("topics",), "check": ("check_uncertain",)}


def test_every_command_is_a_call_of_one_study():
    """Issue 54: the command line only parses, calls one public function of the workflow
    layer and prints; the commands not yet there are listed (a ratchet). No command
    module imports from another."""
    from gainsched import studies

    commands = _commands()
    assert {"build", "improve", "simulate", "paper", "campaign", "sweep", "compare",
            "diagnose"} <= set(commands), sorted(commands)
    for name, fn in commands.items():
        called = _studies_called(fn)
        if name in NOT_YET_STUDIES:
            assert not called, f"{name} calls {called}: take it off NOT_YET_STUDIES"
            continue
        called = [c for c in called if c not in MODES.get(name, ())]  # another mode's
        assert len(called) == 1 and called[0] in studies.__all__, (name, called)
    assert NOT_YET_STUDIES <= set(commands), NOT_YET_STUDIES - set(commands)
    for path in sorted((PACKAGE / "cli").glob("_*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                assert node.module in (None, "_base"), f"{path.name} imports {node.module}"


#: what opens a file or parses a log format: none of it outside gainsched/analysis/logs
_LOG_LIBRARIES = {"pyulog", "rosbags", "h5py", "csv"}
_FILE_CALLS = {"open", "read_text", "read_bytes", "loadtxt", "genfromtxt", "File"}


def _log_reading(source: str) -> list[str]:
    """What in ``source`` (a module's text) reads a file or reaches into the log package's
    private modules: the import of a log library, a call that opens a file, an import of
    ``gainsched.analysis.logs._*``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name.split(".")[0] in _LOG_LIBRARIES]
        elif isinstance(node, ast.ImportFrom):
            parts = (node.module or "").split(".")
            if node.level == 0 and parts[0] in _LOG_LIBRARIES:
                found.append(node.module)
            if "logs" in parts and parts[-1].startswith("_") or (
                    parts[-1] == "logs" and any(a.name.startswith("_") for a in node.names)):
                found.append(f"{'.' * node.level}{node.module}")
        elif isinstance(node, ast.Call):
            fn = node.func
            name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", None)
            if name in _FILE_CALLS:
                found.append(f"{name}() on line {node.lineno}")
    return found


@pytest.mark.parametrize("source", [
    "import pyulog\n", "from rosbags.highlevel import AnyReader\n", "import h5py\n",
    "from pathlib import Path\nPath('x.csv').read_text()\n", "open('flight.csv')\n",
    "import numpy as np\nnp.loadtxt('f.csv')\n", "from ..logs._foreign import read_topics\n",
    "from ..logs import _cache\n",
])
def test_the_log_reading_check_sees_a_reader(source):
    assert _log_reading(source), source


def test_only_the_log_package_reads_log_files():
    """Issue 54: readers, channel maps, the cache of converted logs and the consistency
    checks live in gainsched/analysis/logs behind its public names; no other module of
    analysis/ opens a file, imports a log format's library or a private module of logs."""
    analysis = PACKAGE / "analysis"
    for path in sorted(analysis.rglob("*.py")):
        if (analysis / "logs") in path.parents:
            continue
        assert not _log_reading(path.read_text()), (path, _log_reading(path.read_text()))


def _private_imports(module: str, source: str, is_package: bool = False) -> list[str]:
    """The underscore names that ``module`` (dotted, its text ``source``) imports from a
    module other than a private sibling: ``from .trim import _newton`` in a module of
    ``schedule/`` is one, ``from ._checks import _canonical`` in ``logs/_read.py`` is not
    (private modules of one package share their helpers)."""
    package = module if is_package else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = package.split(".")[:len(package.split(".")) - node.level + 1]
            source_mod = ".".join(base + ([node.module] if node.module else []))
        else:
            source_mod = node.module or ""
        if not source_mod.startswith("gainsched"):
            continue
        home, _, leaf = source_mod.rpartition(".")
        for alias in node.names:
            name = alias.name
            if not name.startswith("_") or name.startswith("__"):
                continue
            if (PACKAGE.parent / Path(*source_mod.split("."), f"{name}.py")).exists():
                continue  # a private module, imported by its name
            if not (leaf.startswith("_") and home == package):
                found.append(f"{source_mod}.{name}")
    return found


@pytest.mark.parametrize("module, source", [
    ("gainsched.schedule.offsets", "from .trim import _newton\n"),
    ("gainsched.studies._build", "from ..schedule.grid import _solve_speed\n"),
    ("gainsched.studies._build", "from ..analysis.logs._read import _canonical\n"),
    ("gainsched.cli._tables", "from gainsched.schedule.certificate import _quanta\n"),
])
def test_the_private_name_check_sees_a_reach_in(module, source):
    assert _private_imports(module, source), source


def test_no_module_imports_another_modules_private_names():
    """Issue 54: a leading underscore means "this module's own"; such a name is imported
    only between the private modules of one package (logs/_read.py from logs/_checks.py),
    never from a public module (schedule/offsets.py from schedule/trim.py) nor across
    packages."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        is_package = rel.name == "__init__"
        module = ".".join(rel.parent.parts if is_package else rel.parts)
        if hits := _private_imports(module, path.read_text(), is_package):
            found[module] = hits
    assert not found, found
