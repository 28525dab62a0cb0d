"""``gainsched improve`` (issue 39): compare, diagnose and apply in rounds, rebuild, report.

- On the example flights it finds what examples/model_vs_measurement.py finds (thrust
  change by momentum theory and a motor lag, fitted together) and the residual falls to
  the noise floor; the config keeps its name.
- The command writes the improved config, tables whose C symbols are the original
  config's, and the report (JSON, Markdown, PNG) of the error round by round; bad
  arguments are refused before any work.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

import gainsched as gs
from gainsched.cli import cli

from support import PAPER_TOML, REPO, small_config_text

FLIGHTS = sorted((REPO / "examples" / "flights").glob("*.csv"))


@pytest.mark.slow
def test_improve_finds_what_the_example_loop_finds():
    """The rounds of examples/model_vs_measurement.py in one call: one accepted joint fit
    (thrust_momentum + motor_lag), then "no effect needed"; the residual falls from 7x to
    about 1x the noise floor; the name stays 'paper'."""
    imp = gs.improve(gs.load_config(PAPER_TOML), FLIGHTS, rounds=3)
    assert imp.applied == ["thrust_momentum + motor_lag"], imp
    assert imp.config.name == "paper"
    assert imp.rounds[-1].diagnosis.verdict.startswith("no effect needed"), imp
    assert imp.rounds[-1].rms < 1.25 < 5.0 < imp.rounds[0].rms
    assert {e.name for e in imp.config.effects} == {"drag", "thrust_momentum", "motor_lag"}


@pytest.mark.slow
def test_the_command_writes_config_tables_with_the_same_symbols_and_the_report(tmp_path,
                                                                               monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    res = CliRunner().invoke(cli, ["improve", "small.toml", *map(str, FLIGHTS), "-o", "imp"])
    assert res.exit_code == 0, res.output
    assert "imp: small.toml (thrust_momentum + motor_lag applied), report/, tables/" in \
        res.output
    assert "imp/tables/small.h5: " in res.output and ".gainsched-stage" not in res.output
    cfg = gs.load_config(tmp_path / "imp" / "small.toml")
    assert cfg.name == "small" and {"thrust_momentum", "motor_lag"} <= {
        e.name for e in cfg.effects}
    header = (tmp_path / "imp" / "tables" / "small_gains.h").read_text()
    assert "small_table" in header and "SMALL_N_STATE" in header
    assert gs.load_table(tmp_path / "imp" / "tables" / "small.h5").built_from(cfg)
    data = json.loads((tmp_path / "imp" / "report" / "improve.json").read_text())
    rms = [r["normalized_rms"] for r in data["rounds"]]
    assert rms[-1] < 0.3 * rms[0] and data["applied"] == ["thrust_momentum + motor_lag"]
    for f in ("improve.md", "improve.png"):
        assert (tmp_path / "imp" / "report" / f).stat().st_size > 0


@pytest.mark.parametrize("args, needle", [
    (["improve", str(PAPER_TOML), str(FLIGHTS[0]), "-o", "x"], "at least two flights"),
    (["improve", str(PAPER_TOML), str(FLIGHTS[0]), str(FLIGHTS[0]), "-o", "x"], "LOG"),
    (["improve", str(PAPER_TOML), *map(str, FLIGHTS[:2]), "-o", "x", "--rounds", "0"],
     "--rounds"),
])
def test_improve_refuses_before_any_work(tmp_path, monkeypatch, args, needle):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2 and needle in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "x").exists()
