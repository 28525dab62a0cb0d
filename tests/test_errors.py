"""The error classes (gainsched/errors.py): usable as the built-ins they are, and an
InputError raised inside code that catches ``ValueError`` keeps its message (issue 40).

An :class:`InputError` is a :class:`ValueError` (python-control's habit); every
``except ValueError`` in the package around code that may raise an InputError must let
it through (``except InputError: raise`` first) or it would be swallowed or re-wrapped
with a worse message. The tests below go through two such sites with a real damaged
table, and a static scan refuses a new handler that catches ValueError around a
``raise InputError`` of its own ``try`` body.
"""

from __future__ import annotations

import ast
from pathlib import Path

import h5py
import numpy as np
import pytest

from gainsched.errors import GainschedError, InputError
from gainsched.firmware.host.check import check_runtime_data
from gainsched.schedule.tables import load_table

from support import PAPER_H5, REPO


def test_input_error_is_a_value_error():
    err = InputError("configs/paper.toml", "vehicle.mass", "must be > 0, got -0.5")
    assert isinstance(err, ValueError) and isinstance(err, GainschedError)
    assert issubclass(InputError, ValueError)
    with pytest.raises(ValueError, match=r"^configs/paper.toml: vehicle.mass: must be > 0"):
        raise err
    # the attributes and the one-line text are unchanged by the second base
    assert (err.source, err.where, err.message, err.exit_code) == (
        "configs/paper.toml", "vehicle.mass", "must be > 0, got -0.5", 2)
    assert str(err) == "configs/paper.toml: vehicle.mass: must be > 0, got -0.5"
    assert err.args == (str(err),)


def test_other_errors_stay_what_they_were():
    """Only a bad value is a ValueError: the base class and the solver failures are not."""
    from gainsched.schedule.trim import TrimError

    assert not issubclass(GainschedError, ValueError)
    assert not issubclass(TrimError, ValueError)


@pytest.fixture()
def edited_table(tmp_path):
    """The committed table with one gain changed and the checksums left as they were."""
    path = tmp_path / "paper.h5"
    path.write_bytes(PAPER_H5.read_bytes())
    with h5py.File(path, "r+") as f:
        K = f["gains/K"][()]
        K[np.unravel_index(np.flatnonzero(np.isfinite(K))[0], K.shape)] += 1.0
        f["gains/K"][...] = K
    return path


def test_checksum_mismatch_keeps_the_dataset(edited_table):
    """tables._verify raises InputError inside a ``try`` that catches ValueError: the
    dataset it names survives (re-wrapped, it would read "unreadable dataset (...)")."""
    with pytest.raises(InputError) as exc:
        load_table(edited_table)
    assert exc.value.source == str(edited_table)
    assert exc.value.where == "gains/K"
    assert exc.value.message.startswith("checksum mismatch: the data changed after the build")
    assert "unreadable" not in str(exc.value)


def test_check_runtime_data_keeps_the_file_and_key(edited_table, tmp_path):
    """check_runtime_data turns a ValueError into an InputError: an InputError
    from the table reader passes unchanged (re-wrapped, its text would name the file
    twice and lose the key)."""
    with pytest.raises(InputError) as exc:
        check_runtime_data(edited_table)
    assert (exc.value.source, exc.value.where) == (str(edited_table), "gains/K")
    assert str(exc.value).count(str(edited_table)) == 1
    not_a_table = tmp_path / "paper.toml"
    not_a_table.write_text("name = 1\n")
    with pytest.raises(InputError) as exc:
        check_runtime_data(not_a_table)
    assert exc.value.where == ""
    assert str(exc.value).startswith(f"{not_a_table}: not a readable HDF5 table (")
    assert str(exc.value).count(str(not_a_table)) == 1


# ------------------------------------------------------------------ static scan


def _catches_value_error(handler: ast.ExceptHandler) -> bool:
    """Names ValueError (a bare ``except`` or ``except Exception`` caught an InputError
    before it was a ValueError too: not new, and those sites clean up and re-raise)."""
    if handler.type is None:
        return False
    types = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return any(ast.unparse(t).split(".")[-1] == "ValueError" for t in types)


def _lets_input_error_through(handler: ast.ExceptHandler) -> bool:
    if handler.type is None:
        return False
    types = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    names = {ast.unparse(t).split(".")[-1] for t in types}
    return "InputError" in names and [type(s) for s in handler.body] == [ast.Raise] and \
        handler.body[0].exc is None


def _raises_input_error(body: list[ast.stmt]) -> bool:
    for node in ast.walk(ast.Module(body=body, type_ignores=[])):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and \
                ast.unparse(node.exc.func).split(".")[-1] == "InputError":
            return True
    return False


def swallowing_sites(root: Path) -> list[str]:
    """``file:line`` of each ``try`` whose body raises InputError itself and whose
    handlers catch ValueError without a re-raising ``except
    InputError`` before."""
    found = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Try) or not _raises_input_error(node.body):
                continue
            for h in node.handlers:
                if _lets_input_error_through(h):
                    break
                if _catches_value_error(h):
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno}")
                    break
    return found


def test_no_handler_swallows_its_own_input_error():
    assert swallowing_sites(REPO / "gainsched") == []


def test_the_scan_finds_a_swallowing_handler(tmp_path):
    """The scan can fail: a handler written the old way is found, the fixed one is not."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "bad.py").write_text(
        "def f(x):\n    try:\n        if x < 0:\n            raise InputError('s', 'k', 'm')\n"
        "    except (OSError, ValueError) as exc:\n        raise InputError('s', '', str(exc))\n")
    (pkg / "good.py").write_text(
        "def f(x):\n    try:\n        if x < 0:\n            raise InputError('s', 'k', 'm')\n"
        "    except InputError:\n        raise\n    except ValueError:\n        pass\n")
    assert swallowing_sites(pkg) == ["pkg/bad.py:2"]
