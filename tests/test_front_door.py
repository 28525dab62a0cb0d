"""No bad input or fault gets past the front door (issue 12): tables, outputs, options.

The contract: one line ``gainsched: error: FILE: KEY: ...`` naming the file and
the key, dataset, column or option; exit code 2; no traceback; the old outputs
intact. (Config and flight-log checks: tests/test_config.py, tests/analysis/test_logs.py.)
"""

from __future__ import annotations

import errno
import os
import struct

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

import gainsched.schedule.grid
from gainsched.cli import cli
from gainsched.errors import InputError
from gainsched.publish import JOURNAL, publish, recover, staged
from gainsched.schedule.tables import _dataset_sha256, _datasets, _root_sha256, load_table

from support import PAPER_H5 as TABLE
from support import PAPER_TOML as PAPER
from support import REPO, paper_config_text, small_config_text

FLIGHT = REPO / "examples" / "flights" / "v9.csv"


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(res, *needles, code=2):
    """The promised failure: exit code, one stderr line with every needle, no traceback."""
    assert res.exit_code == code, (res.exit_code, res.output)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("gainsched: error: "), lines[0]
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
    assert "Traceback" not in res.output
    return lines[0]


# ------------------------------------------------------------------ corrupt tables


def _feasible_K_index(path):
    t = load_table(path)
    i, j, k = np.argwhere(t.reasons[1:] == 0)[0]
    return int(i), int(j), int(k)


def _edit_K(path, fn, *, rechecksum=False):
    """Edit one gains/K entry at a feasible point in place (keeping the attributes)."""
    i, j, k = _feasible_K_index(path)
    with h5py.File(path, "r+") as f:
        K = f["gains/K"][()]
        K[i, j, k, 0, 0] = fn(K[i, j, k, 0, 0])
        f["gains/K"][...] = K
        if rechecksum:  # a tool that "repairs" the checksums: the finiteness check still holds
            digests = {}
            for name, ds in _datasets(f).items():
                digests[name] = ds.attrs["sha256"] = _dataset_sha256(ds[()])
            f.attrs["data_sha256"] = _root_sha256(dict(f.attrs), digests)
    return i, j, k


def _flip_exponent_bit(x):
    (bits,) = struct.unpack("<Q", struct.pack("<d", x))
    (y,) = struct.unpack("<d", struct.pack("<Q", bits ^ (1 << 61)))
    return y


CORRUPTIONS = {
    "nan": lambda x: np.nan,
    "huge": lambda x: 1e300,
    "exponent-bit": _flip_exponent_bit,
}


@pytest.fixture()
def table_copy(tmp_path):
    dst = tmp_path / "paper.h5"
    dst.write_bytes(TABLE.read_bytes())
    return dst


@pytest.mark.parametrize("kind", list(CORRUPTIONS))
@pytest.mark.parametrize("command", ["inspect", "check", "export-c", "simulate"])
def test_corrupt_gain_is_refused_everywhere(table_copy, tmp_path, kind, command):
    """A NaN, 1e300 or one flipped exponent bit in gains/K at a feasible point: every
    command that reads the table refuses it, naming the dataset; export-c writes nothing."""
    _edit_K(table_copy, CORRUPTIONS[kind])
    out = tmp_path / "out"
    args = {
        "inspect": ["inspect", table_copy],
        "check": ["check", table_copy, "--speed-stride", "9"],
        "export-c": ["export-c", table_copy, "-o", out, "--no-code-size"],
        "simulate": ["simulate", PAPER, "--tables", table_copy, "--scenario", "horizontal",
                     "-o", out],
    }[command]
    one_line_error(_run(*args), table_copy, "gains/K", "checksum mismatch")
    assert not out.exists() or not any(out.iterdir())


def test_non_finite_gain_with_repaired_checksum_names_the_index(table_copy):
    i, j, k = _edit_K(table_copy, CORRUPTIONS["nan"], rechecksum=True)
    with pytest.raises(InputError, match=r"non-finite value at a feasible point") as exc:
        load_table(table_copy)
    assert exc.value.where == f"gains/K[{i}, {j}, {k}]"


def test_intact_table_loads(table_copy):
    t = load_table(table_copy)
    assert t.attrs["data_sha256"] and np.isfinite(t.K[t.reasons[1:] == 0]).all()


@pytest.mark.parametrize("attr", ["state_names", "tool_version", "config_name", "data_sha256"])
def test_table_missing_attribute_is_named(table_copy, attr):
    with h5py.File(table_copy, "r+") as f:
        del f.attrs[attr]
    one_line_error(_run("inspect", table_copy), table_copy, attr)


def test_table_with_three_states_is_refused(table_copy):
    with h5py.File(table_copy, "r+") as f:
        for name in ("gains/K_tilt0", "gains/K"):
            data = f[name][()][..., :3]
            del f[name]
            f[name] = data
        q = f["weights/Q"][()][:3, :3]
        del f["weights/Q"]
        f["weights/Q"] = q
    one_line_error(_run("inspect", table_copy), table_copy, "gains/K_tilt0", "state columns")


def test_inspect_all_infeasible_table(tmp_path):
    """A table gainsched built itself with no feasible circle (too slow: slack)."""
    cfg = tmp_path / "slow.toml"
    cfg.write_text(paper_config_text(name="slow", grid__speeds=[0.5, 1.0]))
    res = _run("build", cfg, "-o", tmp_path / "out")
    assert res.exit_code == 0, res.output
    res = _run("inspect", tmp_path / "out" / "slow.h5")
    assert res.exit_code == 0, res.output
    assert "no feasible circle" in res.stdout


# ------------------------------------------------------------------ options


@pytest.mark.parametrize("args, needles", [
    (["nominal", PAPER, "--speed", "1e308"], ["--speed", "finite number in [-100, 100]"]),
    (["nominal", PAPER, "--speed", "nan"], ["--speed"]),
    (["nominal", PAPER, "--speed", "10", "--samples", "100000"], ["--samples"]),
    (["check", TABLE, "--max-error", "nan"], ["--max-error"]),
    (["simulate", PAPER, "--tables", TABLE, "--scenario", "horizontal", "--speed", "nan",
      "-o", "x"], ["--speed"]),
    (["simulate", PAPER, "--tables", TABLE, "--scenario", "horizontal", "--speed", "1e6",
      "-o", "x"], ["--speed"]),
    (["simulate", PAPER, "--tables", TABLE, "--scenario", "horizontal", "--speed", "0",
      "-o", "x"], ["--speed", "(0, 100]"]),
    (["build", PAPER, "--jobs", "many"], ["--jobs"]),
    (["build"], ["CONFIG"]),
    (["no-such-command"], ["no-such-command"]),
    (["build", PAPER, "--no-such-option"], ["--no-such-option"]),
])
def test_bad_options_give_one_line(args, needles, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    line = one_line_error(_run(*args), "command line", *needles)
    assert "Usage:" not in line
    assert not (tmp_path / "x").exists()


# ------------------------------------------------------------------ output side


@pytest.fixture()
def regular_file(tmp_path):
    f = tmp_path / "afile"
    f.write_text("not a folder\n")
    return f


def test_build_under_a_regular_file_fails_before_the_build(regular_file, monkeypatch):
    def never(*a, **k):
        raise AssertionError("the build ran before the output folder was checked")

    monkeypatch.setattr(gainsched.schedule.grid, "build_grid", never)
    one_line_error(_run("build", PAPER, "-o", regular_file / "sub"), regular_file / "sub",
                   "-o", "regular file")


@pytest.mark.parametrize("command", ["export-c", "compare", "diagnose", "apply", "nominal",
                                     "simulate", "paper", "campaign", "sweep", "inspect"])
def test_output_under_a_regular_file(regular_file, command):
    bad = regular_file / "sub"
    args, option = {
        "export-c": (["export-c", TABLE, "-o", bad, "--no-code-size"], "-o"),
        "inspect": (["inspect", TABLE, "--out", bad], "--out"),
        "compare": (["compare", PAPER, FLIGHT, "-o", bad], "-o"),
        "diagnose": (["diagnose", PAPER, FLIGHT, "--report", bad], "--report"),
        "apply": (["diagnose", PAPER, FLIGHT, "--apply", "-o", bad / "new.toml"], "-o"),
        "sweep": (["sweep", PAPER, "--vary", "vehicle.mass=0.5", "-o", bad], "-o"),
        "nominal": (["nominal", PAPER, "--speed", "9", "--csv", bad / "n.csv"], "--csv"),
        "simulate": (["simulate", PAPER, "--tables", TABLE, "--scenario", "horizontal",
                      "-o", bad], "-o"),
        "paper": (["paper", "--quick", "-o", bad], "-o"),
        "campaign": (["campaign", PAPER, "--tables", TABLE, "-o", bad], "-o"),
    }[command]
    one_line_error(_run(*args), option, "regular file")


def _disk_full_after(monkeypatch, n_ok):
    """os.write / file writes in a stage fail with ENOSPC after ``n_ok`` files."""
    import gainsched.publish as pub

    real = pub._fsync
    calls = []

    def fake(path):
        calls.append(path)
        if len(calls) > n_ok:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path)

    monkeypatch.setattr(pub, "_fsync", fake)


@pytest.mark.slow
def test_compare_on_a_full_disk_keeps_the_old_report(tmp_path, monkeypatch):
    out = tmp_path / "report"
    res = _run("compare", PAPER, FLIGHT, "-o", out, "--no-paper")
    assert res.exit_code == 0, res.output
    old = {p.name: p.read_bytes() for p in out.iterdir()}
    _disk_full_after(monkeypatch, 1)
    one_line_error(_run("compare", PAPER, FLIGHT, "-o", out), out, "-o", "disk full")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == old


def test_build_on_a_full_disk_keeps_the_old_set(tmp_path, monkeypatch):
    cfg = tmp_path / "small.toml"
    cfg.write_text(small_config_text(grid__azimuth_samples=None))  # the paper's 36 azimuths
    out = tmp_path / "out"
    assert _run("build", cfg, "-o", out).exit_code == 0
    old = {p.name: p.read_bytes() for p in out.iterdir()}
    cfg.write_text(small_config_text(grid__azimuth_samples=12))
    _disk_full_after(monkeypatch, 2)
    one_line_error(_run("build", cfg, "-o", out), out, "-o", "disk full")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == old


# ------------------------------------------------------------------ publish


def test_publish_replaces_the_set_and_leaves_nothing_else(tmp_path):
    out = tmp_path / "out"
    publish(out, {"a.h5": b"1", "a.h": b"1"})
    publish(out, {"a.h5": b"2", "a.h": b"2"})
    assert sorted(os.listdir(out)) == ["a.h", "a.h5"]
    assert (out / "a.h5").read_bytes() == (out / "a.h").read_bytes() == b"2"


def test_killed_after_the_commit_point_is_rolled_forward(tmp_path):
    """A journal with its stage (a run killed during the renames) completes the new set on
    the next run; stages and temp files of runs killed earlier are removed."""
    out = tmp_path / "out"
    publish(out, {"t.h5": b"old", "t.h": b"old"})
    stage = out / ".gainsched-stage-x1"
    stage.mkdir()
    (stage / "t.h").write_bytes(b"new")  # t.h5 was renamed already when the run died
    (out / "t.h5").write_bytes(b"new")
    (out / JOURNAL).write_text('{"stage": ".gainsched-stage-x1", "files": ["t.h5", "t.h"]}')
    (out / ".gainsched-stage-dead").mkdir()
    (out / ".t.h5.abc.tmp").write_bytes(b"half")
    assert (out / "t.h").read_bytes() == b"old"  # the mix a reader could see until then
    recover(out)
    assert sorted(os.listdir(out)) == ["t.h", "t.h5"]
    assert (out / "t.h").read_bytes() == (out / "t.h5").read_bytes() == b"new"


def test_staged_block_that_raises_changes_nothing(tmp_path):
    out = tmp_path / "out"
    publish(out, {"r.json": b"old"})
    with pytest.raises(RuntimeError):
        with staged(out) as stage:
            (stage / "r.json").write_bytes(b"new")
            (stage / "sub").mkdir()
            (stage / "sub" / "p.png").write_bytes(b"png")
            raise RuntimeError("plot failed")
    assert sorted(os.listdir(out)) == ["r.json"] and (out / "r.json").read_bytes() == b"old"
    with staged(out) as stage:
        (stage / "sub").mkdir()
        (stage / "sub" / "p.png").write_bytes(b"png")
    assert (out / "sub" / "p.png").read_bytes() == b"png" and (out / "r.json").exists()


@pytest.mark.parametrize("err, words", [(errno.EROFS, "read-only file system"),
                                        (errno.EACCES, "permission denied"),
                                        (errno.ENOSPC, "disk full")])
def test_unwritable_folder_is_named(tmp_path, monkeypatch, err, words):
    """Read-only, forbidden or full (simulated: the tests run as root, which ignores
    permissions): one line naming the folder and the option, before any work."""
    import gainsched.publish as pub

    def refuse(*a, **k):
        raise OSError(err, os.strerror(err))

    monkeypatch.setattr(pub.tempfile, "mkstemp", refuse)
    one_line_error(_run("build", PAPER, "-o", tmp_path / "out"), tmp_path / "out", "-o", words)


def test_a_forged_journal_moves_nothing_outside_the_folder(tmp_path):
    """The journal is read from the output folder: names that leave it are ignored."""
    out = tmp_path / "out"
    publish(out, {"t.h5": b"old"})
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"keep")
    (out / JOURNAL).write_text('{"stage": "..", "files": ["victim.txt"]}')  # take a file
    recover(out)
    assert victim.read_bytes() == b"keep" and (out / "t.h5").read_bytes() == b"old"
    assert sorted(os.listdir(out)) == ["t.h5"]
