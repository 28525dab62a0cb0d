"""``gainsched improve`` (issue 39): compare, diagnose and apply in rounds, rebuild, report.

- On the example flights it finds what examples/model_vs_measurement.py finds (thrust
  change by momentum theory and a motor lag, fitted together) and the residual falls to
  the noise floor; the config keeps its name.
- The command writes the improved config, tables whose C symbols are the original
  config's, and the report (JSON, Markdown, PNG) of the error round by round and of the
  standard flights flown on the improved model with the old and the new table; bad
  arguments are refused before any work.
- On a campaign of a user's vehicle (not the paper's) with a hidden effect, the rebuilt
  table flies the hidden-effect plant itself far better than the old one.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

import gainsched as gs
from gainsched.cli import cli

from support import PAPER_H5, PAPER_TOML, REPO, small_config_text

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
    assert CliRunner().invoke(cli, ["build", "small.toml", "-o", "old"]).exit_code == 0
    res = CliRunner().invoke(cli, ["improve", "small.toml", *map(str, FLIGHTS), "-o", "imp",
                                   "--tables", "old/small.h5", "--duration", "1"])
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
    # the standard flights inside the small grid (6-9 m/s, 0-20 deg), old table and new
    flights = data["flights"]
    assert [f["name"] for f in flights["flights"]] == ["v9", "tilt20-v8"]
    assert {f["name"] for f in flights["not_flown"]} == {"v3", "v15", "tilt40-v7", "speedup",
                                                         "braking"}
    assert flights["plant"] == "small" and flights["plant_is_new_design"]
    assert flights["old_table"] == "old/small.h5" and flights["new_table"] == "imp/tables/small.h5"
    assert flights["new_table_config_sha256"] == cfg.sha256 != flights["old_table_config_sha256"]
    assert "flights on the improved model `small`, old -> new table (2 flights of 1 s" in \
        res.output
    md = (tmp_path / "imp" / "report" / "improve.md").read_text()
    assert "## The standard flights, old table against new" in md and "| **all** |" in md
    # the rebuilt table over the fit's 95 % box, printed and in the report (issue 56)
    u = data["uncertain"]
    assert u["focus"] == "thrust_momentum + motor_lag" and u["stable"]
    assert u["kinds"].count("corner") == 2 ** len(u["params"]) and 0 < u["worst"][
        "multiplier"] < 1
    assert "imp/tables/small.h5: the table's loops on " in res.output
    assert "## The new table under the fit's uncertainty" in md and "PASS" in md


@pytest.mark.slow
def test_no_build_says_the_flights_were_not_flown(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(cli, ["improve", str(PAPER_TOML), *map(str, FLIGHTS), "-o", "imp",
                                   "--no-build", "--rounds", "1"])
    assert res.exit_code == 0, res.output
    assert not (tmp_path / "imp" / "tables").exists() and "flights on" not in res.output
    data = json.loads((tmp_path / "imp" / "report" / "improve.json").read_text())
    assert data["flights"] is None and data["flights_not_flown"] == "--no-build"
    assert data["uncertain"] is None and "plants of the diagnosis" not in res.output
    assert "Not flown: --no-build." in (tmp_path / "imp" / "report" / "improve.md").read_text()


@pytest.mark.parametrize("args, needle", [
    (["improve", str(PAPER_TOML), str(FLIGHTS[0]), "-o", "x"], "at least two flights"),
    (["improve", str(PAPER_TOML), str(FLIGHTS[0]), str(FLIGHTS[0]), "-o", "x"], "LOG"),
    (["improve", str(PAPER_TOML), *map(str, FLIGHTS[:2]), "-o", "x", "--rounds", "0"],
     "--rounds"),
    (["improve", str(PAPER_TOML), *map(str, FLIGHTS[:2]), "-o", "x", "--duration", "0.5"],
     "--duration"),
    (["improve", str(PAPER_TOML), *map(str, FLIGHTS[:2]), "-o", "x", "--no-build",
      "--tables", str(PAPER_H5)], "--no-build flies none"),
    (["improve", "small.toml", *map(str, FLIGHTS[:2]), "-o", "x", "--tables", str(PAPER_H5)],
     "built from another config than small.toml"),
])
def test_improve_refuses_before_any_work(tmp_path, monkeypatch, args, needle):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2 and needle in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "x").exists()


#: a user's vehicle, not the paper's: heavier, shorter arms, a longer tether; a grid of
#: 3-12 m/s and 0-20 deg (the standard flights v3, v9, tilt20-v8, speedup and braking fly
#: inside it, v15 and tilt40-v7 outside)
USER_VEHICLE = {"name": "user", "vehicle.mass": 0.8, "vehicle.arm_length": 0.15,
                "vehicle.inertia": [4e-3, 4e-3, 7e-3], "vehicle.thrust_max": 5.0,
                "tether.length": 2.5, "grid.speeds": [3, 6, 9, 12], "grid.tilts_deg": [0, 20]}
#: per hidden effect of the campaign: what improve applies, and the most the rebuilt
#: table's RMS tracking errors over the flights may be, as a share of the old table's, on
#: the hidden-effect plant.
#: - "example" (momentum theory and a 30 ms motor lag, rigid tether). Measured: along
#:   track 0.167 -> 0.00049 m (0.0029), out of the plane 0.175 -> 0.00072 m (0.0041); on
#:   the improved model 0.0024 and 0.0029; per flight at most 0.2 (v3, where the old
#:   table's error is 1.4 mm). The old controller's feed-forward lacks the thrust loss and
#:   the motor lag.
#: - "lag_on_stiff_tether" (issue 59: a 35 ms motor lag on a k = 2e5 N/m tether, which the
#:   simulator flies in maximal coordinates). Measured (2 s flights): along track
#:   0.037, out of the plane 0.019 (speed-up 21 -> 0.34 mm, braking 26 -> 0.77 mm); at
#:   3 m/s both tables fly within the motion-capture noise (0.2 and 0.3 mm along track).
#: - "cog_offset" (issue 53: the centre of mass 3 mm to the right, 2 mm below the frame
#:   centre, HIDDEN). The tether's 44 N tension at 12 m/s on that lever needs a roll
#:   torque beyond the 0.8 kg vehicle's 5 N motors: the improved model's braking needs
#:   thrusts outside 0.1-5 N over 47 % of the flight (flown, not compared: both tables
#:   saturate), and it has no nominal along the speed-up at all (its trim does not
#:   converge; not flown); both say why. On the rest, measured: along track 0.18 ->
#:   0.0003-0.0012 m per flight.
#: (Flying the old table twice gives 1.0: the test fails.)
#: Per case: (what improve applies, the largest ratio, the standard flights inside the
#: tables' speeds that are not flown or not compared, each saying why)
IMPROVE_CASES = {
    "example": ("thrust_momentum + motor_lag", 0.05, ()),
    "lag_on_stiff_tether": ("motor_lag + tether_elasticity", 0.1, ()),
    "cog_offset": ("cog_offset", 0.05, ("speedup", "braking")),
}
#: a flight's RMS error (m) below which old and new are both at the motion-capture noise
#: (0.5 mm, gainsched.sim.campaign.default_flights): "lower on every flight" above it
AT_NOISE = 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("hidden", list(IMPROVE_CASES))
def test_rebuilt_tables_fly_the_hidden_effect_plant_better_than_the_old(tmp_path, monkeypatch,
                                                                        hidden):
    """A user's vehicle flies a campaign (gainsched campaign, 2 s flights) on a plant with
    hidden effects; improve finds them, rebuilds and flies the standard flights on the
    improved model (with a motor lag on an elastic tether: issue 59). Flown again on the
    hidden-effect plant itself (the truth improve never saw), the rebuilt table's RMS
    along-track and out-of-plane errors over the flights are at most the case's share of
    the old table's, and lower on every flight (but where both are at the noise,
    AT_NOISE)."""
    from gainsched.sim.campaign import HIDDEN, plant_config
    from gainsched.sim.oldnew import fly_old_new

    applied, better_by, not_flown = IMPROVE_CASES[hidden]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "user.toml").write_text(small_config_text(**USER_VEHICLE))
    run = CliRunner().invoke
    assert run(cli, ["build", "user.toml", "-o", "old"]).exit_code == 0
    res = run(cli, ["campaign", "user.toml", "--tables", "old/user.h5", "--hidden", hidden,
                    "--duration", "2", "-o", "logs"])
    assert res.exit_code == 0, res.output
    res = run(cli, ["improve", "user.toml", *sorted(map(str, (tmp_path / "logs").glob("*.csv"))),
                    "--tables", "old/user.h5", "--duration", "2", "-o", "imp"])
    assert res.exit_code == 0, res.output
    assert f"{applied} applied" in res.output
    new_cfg = gs.load_config(tmp_path / "imp" / "user.toml")
    if hidden == "lag_on_stiff_tether":  # the lag and the stiffness found (truth: HIDDEN)
        fx = {s.name: s.param_dict() for s in new_cfg.effects}
        assert fx["motor_lag"]["tau"] == pytest.approx(HIDDEN[hidden].truth[2], rel=0.05)
        assert new_cfg.tether.link == "spring-damper"
        assert new_cfg.tether.stiffness == pytest.approx(2e5, rel=0.15)

    # the report's flights: on the improved model
    data = json.loads((tmp_path / "imp" / "report" / "improve.json").read_text())
    flown = [f["name"] for f in data["flights"]["flights"]]
    assert flown == [n for n in ("v3", "v9", "tilt20-v8", "speedup", "braking")
                     if n not in not_flown], data["flights"]
    why = {f["name"]: f["reason"] for f in data["flights"]["not_flown"]}
    assert all(why[n].startswith(("the design model `user` has no nominal along this flight",
                                  "beyond the vehicle under the new model")) for n in not_flown)
    for key in ("rms_along_track_m", "rms_out_of_plane_m"):
        assert data["flights"]["summary"][key]["ratio"] <= better_by, data["flights"]["summary"]

    # the same flights on the hidden-effect plant, the old table against the rebuilt one
    old_cfg = gs.load_config(tmp_path / "user.toml")
    truth = plant_config(old_cfg, hidden)
    fl = fly_old_new(old_cfg, gs.load_table(tmp_path / "old" / "user.h5"), new_cfg,
                     gs.load_table(tmp_path / "imp" / "tables" / "user.h5"), truth, duration=2)
    assert [f.name for f in fl.flights] == flown and not fl.plant_is_new
    s = fl.summary()
    for key in ("rms_along_track_m", "rms_out_of_plane_m"):
        assert s[key]["ratio"] <= better_by, (key, s[key])
        assert all(f.new[key] < max(f.old[key], AT_NOISE) for f in fl.flights), (
            key, fl.flights)
    assert s["slack_events"]["new"] == 0


def test_improve_never_writes_over_its_inputs(tmp_path, monkeypatch):
    """The improved config keeps CONFIG's name, so `improve out/paper.toml LOGS -o out` would
    replace its own input; refused in one line, before any work, the input untouched."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    cfg = tmp_path / "out" / "paper.toml"
    cfg.write_text(PAPER_TOML.read_text())
    res = CliRunner().invoke(cli, ["improve", "out/paper.toml", *map(str, FLIGHTS[:2]),
                                   "-o", "out"])
    assert res.exit_code == 2, res.output
    assert res.output.strip() == ("gainsched: error: command line: -o: out/paper.toml is the input "
                                  "CONFIG: give a new file (an input is never overwritten)")
    assert cfg.read_text() == PAPER_TOML.read_text()


def _improved(monkeypatch, tmp_path, **keys):
    """Let ``improve`` find a motor lag at once (its diagnosis stands in: the steps after
    it are what these tests break) and give the config those keys on top."""
    from types import SimpleNamespace

    import gainsched.analysis.improve as imp_mod

    old = gs.config_from_text(small_config_text(), str(tmp_path / "small.toml"))
    new = gs.config_from_text(small_config_text(**{"effects.motor_lag.tau": 0.03, **keys}),
                              str(tmp_path / "small.toml"))
    d = SimpleNamespace(accepted=SimpleNamespace(name="motor_lag"), applied=["motor_lag"],
                        verdict="missing effect")
    rounds = [imp_mod.Round(old, SimpleNamespace(normalized_rms=lambda: 3.0), d),
              imp_mod.Round(new, SimpleNamespace(normalized_rms=lambda: 1.0), None)]
    monkeypatch.setattr(imp_mod, "improve", lambda *a, **k: imp_mod.Improvement(rounds))


def test_a_failed_flight_step_keeps_the_config_tables_and_report(tmp_path, monkeypatch):
    """Fault injection (issue 59): the flights of the old and the new table raise. The
    improved config, the rebuilt tables and the report (saying which step failed) are
    published; one line names the step and the fault; exit 1; no traceback."""
    import gainsched.sim.oldnew

    def broken(*args, **kwargs):
        raise NotImplementedError("injected: the simulator cannot fly this")

    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    assert CliRunner().invoke(cli, ["build", "small.toml", "-o", "old"]).exit_code == 0
    _improved(monkeypatch, tmp_path)
    monkeypatch.setattr(gainsched.sim.oldnew, "fly_old_new", broken)
    res = CliRunner().invoke(cli, ["improve", "small.toml", *map(str, FLIGHTS[:2]), "-o", "out",
                                   "--tables", "old/small.h5"])
    assert res.exit_code == 1, res.output
    assert "Traceback" not in res.output and isinstance(res.exception, SystemExit)
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("gainsched: error:")]
    assert errors == ["gainsched: error: improve: the step 'fly the old and the new tables' "
                      "failed: NotImplementedError: injected: the simulator cannot fly this "
                      "(what was done before it is in out)"], res.stderr
    assert "out: small.toml (motor_lag applied), report/, tables/" in res.stdout
    cfg = gs.load_config(tmp_path / "out" / "small.toml")
    assert any(s.name == "motor_lag" for s in cfg.effects)
    assert gs.load_table(tmp_path / "out" / "tables" / "small.h5").built_from(cfg)
    data = json.loads((tmp_path / "out" / "report" / "improve.json").read_text())
    assert data["flights"] is None and data["flights_not_flown"].startswith(
        "the step 'fly the old and the new tables' failed: NotImplementedError")
    assert not list((tmp_path / "out").glob(".gainsched-stage*"))


def test_a_refused_rebuild_keeps_the_config_and_report(tmp_path, monkeypatch):
    """The improved model's table over the flash budget the config states: the rebuild is
    refused, and the improved config and the report are published without tables; the one
    line names the step, the key and the compact format's size; exit 1 (the rebuild's
    half-written tables are not published)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    _improved(monkeypatch, tmp_path, **{"firmware.max_table_bytes": 1000})
    res = CliRunner().invoke(cli, ["improve", "small.toml", *map(str, FLIGHTS[:2]), "-o", "out2"])
    assert res.exit_code == 1, res.output
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("gainsched: error:")]
    assert len(errors) == 1 and "the step 'rebuild the tables' failed: " in errors[0]
    assert "firmware.max_table_bytes: 1,000 bytes exceeded" in errors[0]
    assert 'format = "compact" holds' in errors[0] and "Traceback" not in res.output
    assert (tmp_path / "out2" / "small.toml").exists()
    assert not (tmp_path / "out2" / "tables").exists()
    md = (tmp_path / "out2" / "report" / "improve.md").read_text()
    assert "Not flown: the step 'rebuild the tables' failed" in md


def test_a_fault_in_the_diagnosis_is_one_line_and_writes_nothing(tmp_path, monkeypatch):
    """Fault injection: the rounds of compare and diagnose raise (not a user error): one
    line naming the step, exit 1, no traceback, nothing written (nothing was done)."""
    import gainsched.analysis.improve as imp_mod

    def broken(*args, **kwargs):
        raise FloatingPointError("injected")

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(imp_mod, "improve", broken)
    res = CliRunner().invoke(cli, ["improve", str(PAPER_TOML), *map(str, FLIGHTS[:2]),
                                   "-o", "out"])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit), res.output
    assert res.stderr.strip() == ("gainsched: error: improve: the step 'compare and diagnose' "
                                  "failed: FloatingPointError: injected")
    assert not (tmp_path / "out").exists()


def test_nothing_applied_rebuilds_nothing_and_prints_the_whole_verdict(tmp_path,
                                                                       monkeypatch):
    """Issue 53: a first round that accepts nothing: no rebuild and no flights (the tables
    would be CONFIG's own), the report says why, and the round's line holds the whole
    verdict, however long."""
    from types import SimpleNamespace

    import gainsched.analysis.improve as imp_mod

    monkeypatch.chdir(tmp_path)
    (tmp_path / "small.toml").write_text(small_config_text())
    cfg = gs.load_config(tmp_path / "small.toml")
    verdict = "no library effect explains it: " + "the residual concentrates there; " * 12
    d = SimpleNamespace(accepted=None, applied=[], verdict=verdict)
    rounds = [imp_mod.Round(cfg, SimpleNamespace(normalized_rms=lambda: 3.0), d)]
    monkeypatch.setattr(imp_mod, "improve", lambda *a, **k: imp_mod.Improvement(rounds))
    res = CliRunner().invoke(cli, ["improve", "small.toml", *map(str, FLIGHTS[:2]), "-o", "out"])
    assert res.exit_code == 0, res.output
    assert f"round 0: normalised RMS 3: {verdict}" in res.output
    assert "out: small.toml (nothing applied), report/; nothing applied, so no tables " \
        "rebuilt and no flights flown" in res.output
    assert not (tmp_path / "out" / "tables").exists() and "flights on" not in res.output
    data = json.loads((tmp_path / "out" / "report" / "improve.json").read_text())
    assert data["flights_not_flown"] == "nothing was applied: the tables are CONFIG's own"
