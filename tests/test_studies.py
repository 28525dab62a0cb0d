"""The workflow layer (:mod:`gainsched.studies`, issue 54): what a command does, a script
does with the same function and gets the same files and lines."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import gainsched as gs
from gainsched import studies
from gainsched.cli import cli
from gainsched.errors import InputError
from gainsched.studies import Reporter, build, output_names, table_for

from support import REPO, run_examples, small_config_text


class _Recording(Reporter):
    """A reporter that keeps what it was told: the bars' names, totals and counts, and
    the notes."""

    def __init__(self):
        self.bars, self.notes, self.said = [], [], []

    def bar(self, desc, total=None, unit="it", *, show=True):
        rec = self.bars
        rec.append([desc, total, 0])

        class Bar:
            def __enter__(self):
                return self

            def __exit__(self, *exc):
                return False

            def update(self, n=1):
                rec[-1][2] += n

            def set_postfix_str(self, text, refresh=True):
                pass

        return Bar()

    def note(self, text, bar=None):
        self.notes.append(text)

    def line(self, text):
        self.said.append(text)


def test_build_in_python_is_the_command(tmp_path, monkeypatch):
    """``gs.build(config, out)`` publishes the bytes ``gainsched build CONFIG -o OUT``
    does (every file of the set) and its ``lines()`` are what the command prints but the
    build's seconds; its reporter counted every speed of the grid."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    res = CliRunner().invoke(cli, ["build", "small.toml", "-o", "cli"])
    assert res.exit_code == 0, res.output
    rec = _Recording()
    done = gs.build("small.toml", "lib", jobs=1, reporter=rec)
    names = output_names(done.config)
    assert sorted(p.name for p in (tmp_path / "cli").iterdir()) == sorted(names)
    for name in names:
        assert (tmp_path / "lib" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()
    assert [done.table, *done.c_files] == [Path("lib") / n for n in
                                           done.outputs.files]
    def timeless(lines):  # the build's seconds differ from run to run
        return [re.sub(r", [0-9.]+ s, ", ", _ s, ", ln) for ln in lines]

    assert timeless(done.lines(shown=Path("cli"))) == timeless(res.output.splitlines())
    assert rec.bars[0][:2] == ["build small", 2] and rec.bars[0][2] == 2


def test_build_refuses_before_any_work(tmp_path):
    """A bad output folder is refused naming it, before the grid is solved (nothing
    written, no bar started)."""
    (tmp_path / "small.toml").write_text(small_config_text())
    (tmp_path / "file").write_text("not a folder")
    rec = _Recording()
    with pytest.raises(InputError, match="-o"):
        build(tmp_path / "small.toml", tmp_path / "file", reporter=rec)
    assert rec.bars == []


def test_the_table_of_a_config_is_the_working_folders_when_built_from_it(tmp_path,
                                                                       monkeypatch):
    """table_for: ``tables/NAME.h5`` of the working folder when built from the config;
    another config's table there is not taken (the cache's is built instead, noted)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    cfg = gs.load_config("small.toml")
    gs.build(cfg, "tables", jobs=1)
    table, path = table_for(cfg)
    assert str(path) == "tables/small.h5" and table.built_from(cfg)
    other = gs.load_config("small.toml").with_values({"vehicle.mass": 0.52})
    monkeypatch.setenv("GAINSCHED_CACHE", str(tmp_path / "cache"))
    rec = _Recording()
    table2, path2 = table_for(other, reporter=rec)
    assert table2.built_from(other) and path2.is_relative_to(tmp_path / "cache")
    assert rec.notes == [f"built {path2}"]


@pytest.mark.slow
def test_improve_in_python_is_the_command(tmp_path, monkeypatch):
    """``gs.improve(config, logs, out)`` (issue 54's must-show): the same improved config,
    rebuilt table bytes, report figures (the rounds and the flights old against new) and
    printed lines as ``gainsched improve CONFIG LOGS -o OUT`` (the small grid on the example
    flights, one round)."""
    import json

    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    logs = [str(p) for p in sorted((REPO / "examples" / "flights").glob("*.csv"))]
    assert CliRunner().invoke(cli, ["build", "small.toml", "-o", "old"]).exit_code == 0
    res = CliRunner().invoke(cli, ["improve", "small.toml", *logs, "-o", "cli", "--rounds",
                                   "1", "--tables", "old/small.h5"])
    assert res.exit_code == 0, res.output
    done = gs.improve("small.toml", logs, "lib", rounds=1, old_table="old/small.h5")
    assert done.applied and done.failed is None and done.build is not None
    for f in ("small.toml", "tables/small.h5", "tables/small_gains.h"):
        assert (tmp_path / "lib" / f).read_bytes() == (tmp_path / "cli" / f).read_bytes(), f
    lib, cli_ = (json.loads((tmp_path / d / "report" / "improve.json").read_text())
                 for d in ("lib", "cli"))
    assert lib["rounds"] == cli_["rounds"]
    assert lib["flights"]["summary"] == cli_["flights"]["summary"]
    assert lib["flights"]["flights"] == cli_["flights"]["flights"]
    # the rebuilt table under the fit's uncertainty (issue 56), the same both ways
    assert lib["uncertain"] == cli_["uncertain"] and lib["uncertain"]["stable"]
    u, table = done.uncertain, gs.load_table(tmp_path / "lib" / "tables" / "small.h5")
    assert u.focus == done.applied[-1] and u.kinds[0] == "estimate"
    # the estimate is the improved config the table was built from (the fit applied over
    # it replaces its own effects, not added twice): its loops are the table's own, but
    # for the gains read back from the table's 8 azimuth samples (1.2e-3 here)
    np.testing.assert_allclose(u.rho[0], table.spectral_radius, atol=3e-3)
    assert "PASS: every loop stable over the box" in res.output

    def same(lines, folder):  # the folders' names and the build's seconds aside
        return [re.sub(r", [0-9.]+ s, ", ", _ s, ", ln).replace(folder, "OUT") for ln in lines]

    assert same(done.lines(), "lib") == same(res.output.splitlines(), "cli")


def test_sweep_and_campaign_in_python_are_the_commands(tmp_path, monkeypatch):
    """``gs.sweep`` writes the variants' files and results ``gainsched sweep`` writes (the
    tables' bytes, sweep.csv), ``gs.campaign`` the logs ``gainsched campaign`` writes,
    byte for byte; each prints its ``lines()`` (the sweep's seconds aside)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    run = CliRunner().invoke
    res = run(cli, ["sweep", "small.toml", "--vary", "vehicle.mass=0.45,0.55", "-o", "s_cli",
                    "-j", "1"])
    assert res.exit_code == 0, res.output
    done = gs.sweep("small.toml", "s_lib", vary=["vehicle.mass=0.45,0.55"], jobs=1)
    files = sorted(p.name for p in (tmp_path / "s_cli").iterdir())
    assert files == sorted(p.name for p in (tmp_path / "s_lib").iterdir()) and len(files) == 6
    for f in files:
        if f != "sweep.json":  # it says where and when
            assert (tmp_path / "s_lib" / f).read_bytes() == (tmp_path / "s_cli" / f).read_bytes()
    assert [re.sub(r"[0-9.]+ s$", "", ln) for ln in done.lines()] == \
        [re.sub(r"[0-9.]+ s$", "", ln.replace("s_cli", "s_lib")) for ln in res.output.splitlines()]

    table = tmp_path / "s_lib" / f"{done.plan.variants[0].name}.h5"
    cfg = tmp_path / "s_lib" / f"{done.plan.variants[0].name}.toml"
    res = run(cli, ["campaign", str(cfg), "--tables", str(table), "--duration", "1",
                    "--hidden", "motor_lag", "-o", "c_cli"])
    assert res.exit_code == 0, res.output
    flown = gs.campaign(cfg, table, "c_lib", hidden="motor_lag", duration=1.0)
    assert sorted(p.name for p in flown.files) == sorted(
        p.name for p in (tmp_path / "c_cli").iterdir())
    for p in flown.files:
        assert p.read_bytes() == (tmp_path / "c_cli" / p.name).read_bytes(), p.name
    assert flown.lines() == [ln.replace("c_cli", "c_lib") for ln in res.output.splitlines()
                             if not ln.startswith("gainsched: warning")]


def test_validate_and_nominal_in_python_are_the_commands(tmp_path, monkeypatch):
    """``gs.studies.validate`` gives the lines ``gainsched validate`` prints;
    ``gs.studies.nominal`` the lines ``gainsched nominal`` prints, the same CSV bytes, and
    its arrays are the table's columns."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    run = CliRunner().invoke
    res = run(cli, ["validate", "small.toml"])
    assert res.exit_code == 0, res.output
    v = studies.validate("small.toml")
    assert v.lines() == res.stdout.splitlines() and v.taut_speeds.shape == (2,)
    assert studies.validate(gs.load_config("small.toml")).lines()[1:] == v.lines()[1:]

    res = run(cli, ["nominal", "small.toml", "--speed", "-9", "--tilt", "15", "--samples",
                    "6", "--csv", "cli.csv"])
    assert res.exit_code == 0, res.output
    c = studies.nominal("small.toml", -9.0, 15.0, 6, csv="lib.csv")
    assert c.lines() == res.stdout.replace("cli.csv", "lib.csv").splitlines()
    assert (tmp_path / "lib.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    assert c.csv == Path("lib.csv") and c.thrusts.shape == (6, 4)
    rows = np.loadtxt(tmp_path / "lib.csv", delimiter=",", skiprows=1, usecols=range(9))
    np.testing.assert_allclose(rows[:, 3:7], c.thrusts, rtol=1e-8)
    np.testing.assert_allclose(rows[:, 0], c.xi, rtol=1e-8)


def test_validate_and_nominal_refuse_before_any_work(tmp_path, monkeypatch):
    """A bad config, speed, tilt, sample count or CSV file is refused naming it, before the
    circle is solved (nothing written)."""
    import gainsched.schedule.nominal as nominal_module

    (tmp_path / "bad.toml").write_text('name = "x"\n')
    with pytest.raises(InputError, match="bad.toml"):
        studies.validate(tmp_path / "bad.toml")

    def unsolvable(*args, **kwargs):
        raise AssertionError("the circle was solved")

    monkeypatch.setattr(nominal_module, "circle_nominal", unsolvable)
    (tmp_path / "small.toml").write_text(small_config_text())
    cfg = tmp_path / "small.toml"
    for kwargs, option in (({"speed": 0.0}, "--speed"), ({"speed": float("nan")}, "--speed"),
                           ({"speed": 9.0, "tilt": 90.0}, "--tilt"),
                           ({"speed": 9.0, "samples": 3}, "--samples"),
                           ({"speed": 9.0, "csv": tmp_path}, "--csv"),
                           ({"speed": 9.0, "csv": tmp_path / "bad.toml" / "x.csv"}, "--csv")):
        with pytest.raises(InputError, match=option):
            studies.nominal(cfg, **kwargs)
    with pytest.raises(InputError, match="bad.toml"):
        studies.nominal(tmp_path / "bad.toml", 9.0, csv=tmp_path / "x.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "small.toml"]


@pytest.fixture(scope="module")
def small_table(tmp_path_factory):
    """The small grid's table (2 speeds x 2 tilts x 8 azimuths), built once."""
    out = tmp_path_factory.mktemp("small")
    (out / "small.toml").write_text(small_config_text())
    return gs.build(out / "small.toml", out / "tables", jobs=1).table


def test_inspect_in_python_is_the_command(small_table, tmp_path, monkeypatch):
    """``gs.studies.inspect`` gives the lines ``gainsched inspect`` prints (text, with the
    runtime's flash footprint and the envelope's files) and, as JSON, the summary
    ``--json`` prints; its envelope files are the command's, byte for byte."""
    import json

    monkeypatch.chdir(tmp_path)
    run = CliRunner().invoke
    res = run(cli, ["inspect", str(small_table), "-o", "cli"])
    assert res.exit_code == 0, res.output
    rec = _Recording()
    ins = studies.inspect(small_table, "lib", reporter=rec)
    assert ins.lines() == res.stdout.replace("cli/", "lib/").splitlines()
    assert ins.flash and rec.bars == [[f"inspect {ins.table.name}", 2, 2]]
    assert (tmp_path / "lib" / "envelope.png").read_bytes() == (
        tmp_path / "cli" / "envelope.png").read_bytes()
    res = run(cli, ["inspect", str(small_table), "--json"])
    assert res.exit_code == 0, res.output
    quick = studies.inspect(small_table, code_size=False)
    assert quick.lines(as_json=True) == [res.stdout.removesuffix("\n")]
    assert quick.summary() == json.loads(res.stdout) and quick.flash == ()
    assert quick.summary()["c_prefix"] == "small"


def test_inspect_refuses_before_any_work(small_table, tmp_path):
    """An output folder that is a file, or a file that is no table, is refused naming
    it before anything is compiled or drawn."""
    (tmp_path / "file").write_text("not a folder")
    rec = _Recording()
    with pytest.raises(InputError, match="--out"):
        studies.inspect(small_table, tmp_path / "file", reporter=rec)
    with pytest.raises(InputError, match="not a readable HDF5 table"):
        studies.inspect(tmp_path / "file", reporter=rec)
    assert rec.bars == []


def test_check_in_python_is_the_command(small_table, tmp_path, monkeypatch):
    """``gs.studies.check`` tells the lines ``gainsched check`` prints (the seconds
    aside) as they come, keeps them in ``lines()``, and fails where the command exits 1;
    a stride past the last midpoint is refused before the check."""
    def timeless(lines):
        return [re.sub(r", [0-9.]+ s$", ", _ s", ln) for ln in lines]

    run = CliRunner().invoke
    for args, ok in ((["--max-error", "0.01"], False), (["--max-error", "50"], True),
                     (["--compact", "1", "--max-error", "50"], True)):
        res = run(cli, ["check", str(small_table), *args])
        assert res.exit_code == (0 if ok else 1), res.output
        rec = _Recording()
        values = dict(zip(args[::2], map(float, args[1::2]), strict=True))
        done = studies.check(small_table, max_error=values["--max-error"],
                             azimuth_error=values.get("--compact"), reporter=rec)
        assert done.ok is ok and rec.said == done.lines()
        assert timeless(done.lines()) == timeless(res.stdout.splitlines())
        assert (done.compact is not None) == ("--compact" in values)
        assert rec.bars == [[f"check {small_table.stem}", 1, 1]]
    rec = _Recording()
    with pytest.raises(InputError, match="--speed-stride"):
        studies.check(small_table, speed_stride=2, reporter=rec)
    assert rec.bars == [] and rec.said == []


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in studies.__all__ if not hasattr(gs, n)])
def test_the_examples_of_the_studies_the_package_root_does_not_export_run(name, tmp_path,
                                                                          monkeypatch):
    """gs.studies.compare and .diagnose (their names at the package root are the analyses'
    own) and the helpers: every Example runs, in a folder like the repository root (the
    root's exports run in tests/test_api.py)."""
    for sub in ("configs", "tables", "examples"):
        (tmp_path / sub).symlink_to(REPO / sub)
    run_examples(getattr(studies, name), name, tmp_path, monkeypatch)
