"""Automatic breakpoints (issue 23; gainsched.schedule.refine, docs/grid.md).

- the range syntax of ``[grid] speeds`` / ``tilts_deg`` and its errors;
- the chosen grid meets the bound where ``gainsched check`` measures it: the float32
  runtime's lookups against direct LQR solves at every cell midpoint
  (:func:`gainsched.midpoint_check`, a second code path), gains, thrusts and roll,
  and every midpoint loop closed with interpolated gains is stable;
- every circle is solved once (the reuse counter), and the grid equals the direct
  build of the chosen axes;
- deterministic: the same bytes with 1 or 2 workers (the kernel families:
  tests/native/test_reproducible.py);
- a bound the max count cannot meet, or the azimuth samples cannot, is a one-line
  error naming the key and the cell; the envelope's edge is resolved;
- build, inspect and check report the choice; the table records it.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.config import config_from_text
from gainsched.errors import InputError
from gainsched.firmware.host.check import midpoint_check
from gainsched.firmware.outputs import output_files
from gainsched.schedule.grid import build_grid
from gainsched.schedule.refine import ERROR_QUANTUM, midpoint_errors, refine_grid
from gainsched.schedule.tables import table_from_bytes

from support import AUTO_SPEEDS as SPEEDS
from support import AUTO_TILTS as TILTS
from support import auto_text, small_config_text


@pytest.fixture(scope="module")
def chosen():
    cfg = config_from_text(auto_text(), "auto.toml")
    solved = []
    choice = refine_grid(cfg, n_jobs=1, progress=solved.append)
    return cfg, choice, sum(solved)


# ------------------------------------------------------------------------ the syntax


def test_range_syntax_gives_seeds_and_the_range():
    cfg = config_from_text(auto_text(), "auto.toml")
    assert cfg.grid.auto
    assert cfg.grid.speeds.tolist() == [6.0, 9.0, 12.0]
    assert np.rad2deg(cfg.grid.tilts).tolist() == pytest.approx([0.0, 15.0, 30.0])
    assert (cfg.grid.speeds_auto.lo, cfg.grid.speeds_auto.hi,
            cfg.grid.speeds_auto.max_count) == (6.0, 12.0, 9)
    listed = config_from_text(small_config_text(), "list.toml")
    assert not listed.grid.auto and listed.grid.speeds_auto is None


@pytest.mark.parametrize("speeds, tilts, key", [
    (dict(min=6, max=12), TILTS, "grid.speeds.max_count"),
    (dict(min=6, max=12, max_count=1), TILTS, "grid.speeds.max_count"),
    (dict(min=6, max=12, max_count=4.0), TILTS, "grid.speeds.max_count"),
    (dict(min=6, max=12, max_count=True), TILTS, "grid.speeds.max_count"),
    (dict(min=12, max=6, max_count=9), TILTS, "grid.speeds.max"),
    (dict(min=0, max=6, max_count=9), TILTS, "grid.speeds.min"),
    (dict(min=6, max=12, max_count=9, step=1), TILTS, "grid.speeds.step"),
    (dict(min=6, max=200, max_count=9), TILTS, "grid.speeds.max"),
    (dict(min=6, max=12, max_count=99999), TILTS, "grid.speeds.max_count"),
    (SPEEDS, dict(min=5, max=30, max_count=9), "grid.tilts_deg.min"),
    (SPEEDS, dict(min=0, max=95, max_count=9), "grid.tilts_deg.max"),
    (SPEEDS, dict(min=0, max=30, max_count=9, foo=1), "grid.tilts_deg.foo"),
    (SPEEDS, dict(min=0, max="30", max_count=9), "grid.tilts_deg.max"),
])
def test_bad_ranges_name_the_key(speeds, tilts, key):
    with pytest.raises(InputError) as info:
        config_from_text(auto_text(speeds=speeds, tilts=tilts), "bad.toml")
    assert str(info.value).startswith(f"bad.toml: {key}:"), str(info.value)


def test_build_grid_refuses_a_range():
    cfg = config_from_text(auto_text(), "auto.toml")
    with pytest.raises(InputError, match=r"auto\.toml: grid\.speeds: is a range"):
        build_grid(cfg)


# ------------------------------------------------------------------ the error measure


def test_midpoint_errors_against_hand_values():
    K_d = np.zeros((1, 4, 2))
    K_d[0, 0] = [3.0, 4.0]  # |K_d|_F = 5
    K = K_d.copy()
    K[0, 1, 0] = 0.5  # |K - K_d|_F = 0.5
    u_d, u = np.array([[1.0, 2.0, 4.0, 2.0]]), np.array([[1.0, 2.1, 4.0, 2.0]])
    gain, thrust, roll = midpoint_errors(K, K_d, u, u_d, np.array([0.21]), np.array([0.2]),
                                         4.0, 0.5)
    np.testing.assert_allclose([gain[0], thrust[0], roll[0]], [0.1, 0.025, 0.02], rtol=1e-12)


# ------------------------------------------------------------------ the chosen grid


@pytest.mark.slow
def test_chosen_grid_meets_the_bound_where_check_measures_it(chosen):
    """The independent reference: the runtime's float32 lookups of the written table
    against direct solves at every cell midpoint, with the loop closed."""
    cfg, choice, _ = chosen
    files = output_files(choice.config, choice.grid, grid_auto=choice.record())
    table = table_from_bytes(files["auto.h5"], "auto.h5")
    res = midpoint_check(table)
    bound = cfg.grid.max_interpolation_error
    assert res.skipped == 0 and res.rel_err.size == 16 * len(choice.config.grid.speeds[1:]) \
        * len(choice.config.grid.tilts[1:])
    assert res.max_err <= bound and res.max_nominal_err <= bound
    assert all(c.rho_interp < 1 for c in res.circles)
    # the build's own certificate is the same measurement in float64
    assert choice.gain_error == pytest.approx(res.max_err, abs=1e-5)
    assert max(choice.thrust_error, choice.roll_error) == pytest.approx(
        res.max_nominal_err, abs=1e-5)
    # refinement happened: the seeds alone (3 x 3) do not meet the bound
    assert choice.config.grid.speeds.size * choice.config.grid.tilts.size > 9
    seeds = config_from_text(auto_text(speeds=[6, 9, 12], tilts=[0, 15, 30]), "s.toml")
    seed_table = table_from_bytes(output_files(seeds, build_grid(seeds))["auto.h5"], "s.h5")
    coarse = midpoint_check(seed_table)
    assert max(coarse.max_err, coarse.max_nominal_err) > bound


def test_every_circle_is_solved_once_and_equals_the_direct_build(chosen):
    cfg, choice, solved = chosen
    g = choice.config.grid
    assert solved == choice.circles + choice.centres  # no circle twice
    assert choice.circles >= g.speeds.size * g.tilts.size
    assert choice.centres_final == choice.cells == (g.speeds.size - 1) * (g.tilts.size - 1)
    direct = build_grid(choice.config)
    for name in ("K", "S", "u_d", "phi_d", "tension", "spectral_radius", "mode_tau"):
        np.testing.assert_allclose(getattr(choice.grid, name), getattr(direct, name),
                                   rtol=1e-9, atol=1e-12, err_msg=name)
    np.testing.assert_array_equal(choice.grid.reasons, direct.reasons)
    np.testing.assert_array_equal(choice.grid.steps, direct.steps)


def test_the_chosen_config_keeps_the_range_as_a_comment(chosen):
    _, choice, _ = chosen
    text = choice.config.text
    line = next(x for x in text.splitlines() if x.startswith("speeds ="))
    assert "chosen by the build from {min = 6.0, max = 12.0, max_count = 9}" in line
    assert not choice.config.grid.auto
    again = config_from_text(text, "again.toml")
    assert again.grid.speeds.tolist() == choice.config.grid.speeds.tolist()


def test_same_bytes_with_one_or_two_workers(chosen):
    cfg, choice, _ = chosen
    two = refine_grid(cfg, n_jobs=2)
    a = output_files(choice.config, choice.grid, grid_auto=choice.record())
    b = output_files(two.config, two.grid, grid_auto=two.record())
    assert a == b


def test_decisions_use_rounded_errors():
    """One quantum of margin: a grid whose worst error is at the bound to the last bits
    still fails (so check's float32 lookups cannot land above it)."""
    from gainsched.schedule.refine import quanta

    assert quanta(0.019951) == 200 and quanta(0.0199499) == 199
    assert quanta(math.inf) == math.inf
    assert ERROR_QUANTUM == 1e-4


# ------------------------------------------------------------------ errors


def test_max_count_too_small_names_the_key_and_the_cell():
    cfg = config_from_text(auto_text(speeds=dict(min=6, max=12, max_count=3),
                                     tilts=[0, 15, 30], n_xi=32, bound=1.5), "tight.toml")
    with pytest.raises(InputError) as info:
        refine_grid(cfg)
    msg = str(info.value)
    assert msg.startswith("tight.toml: grid.speeds.max_count: 3 breakpoints are not enough "
                          "for 1.5 %: the cell "), msg
    assert re.search(r"has \d+\.\d\d % at its centre", msg)


def test_too_few_azimuth_samples_names_the_key():
    cfg = config_from_text(auto_text(n_xi=8, bound=5), "az.toml")
    with pytest.raises(InputError, match=r"^az\.toml: grid\.azimuth_samples: 8 samples are "
                       r"too few for 5 %: the interpolation along the azimuth alone"):
        refine_grid(cfg)


def test_the_envelope_edge_is_resolved():
    """Slow circles at large tilts are slack: the cells the edge runs through are halved
    until they span at most 1/16 of the speed range."""
    cfg = config_from_text(auto_text(speeds=dict(min=1.5, max=9.5, max_count=40),
                                     tilts=[0, 20, 40], bound=20), "edge.toml")
    choice = refine_grid(cfg)
    v = choice.config.grid.speeds
    ok = np.isfinite(choice.grid.spectral_radius)
    assert not ok.all()  # the edge is in the range
    for i in range(ok.shape[0]):
        for j in range(v.size - 1):
            if ok[i, j] != ok[i, j + 1]:
                assert v[j + 1] - v[j] <= (9.5 - 1.5) / 16


# ------------------------------------------------------------------ the commands


@pytest.mark.slow
def test_build_inspect_check_report_the_choice(tmp_path):
    path = tmp_path / "auto.toml"
    path.write_text(auto_text())
    run = CliRunner().invoke
    res = run(cli, ["build", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert "grid chosen for 3 %:" in res.output
    assert re.search(r"circles solved = \d+ breakpoints, each once \(\d+ reused", res.output)
    table = tmp_path / "out" / "auto.h5"
    res = run(cli, ["inspect", str(table)])
    assert res.exit_code == 0, res.output
    assert "grid chosen by the build for 3% (docs/grid.md): speeds {min = 6.0" in res.output
    res = run(cli, ["inspect", str(table), "--json"])
    record = json.loads(res.output)["grid_auto"]
    assert record["bound"] == 0.03 and record["tilts_deg"].startswith("{min = 0.0")
    # issue 39: the config with the ranges built it (the table embeds the chosen one), so
    # no "built from another config" warning; another config still gets it
    from gainsched.config import load_config
    from gainsched.schedule.tables import load_table

    t = load_table(table)
    assert record["source_config_sha256"] == load_config(path).sha256 != t.config_sha256
    assert t.built_from(load_config(path)) and t.built_from(config_from_text(t.config_text))
    assert not t.built_from(config_from_text(auto_text().replace("mass = 0.5", "mass = 0.55")))
    res = run(cli, ["campaign", str(path), "--tables", str(table), "--duration", "1", "-o",
                    str(tmp_path / "flights")])
    assert res.exit_code == 0 and "built from another config" not in res.output, res.output
    res = run(cli, ["check", str(table)])
    assert res.exit_code == 0, res.output
    assert "PASS: gain, thrust and roll error <= 3%" in res.output
    # a stricter bound than the build's fails check, as it should
    res = run(cli, ["check", str(table), "--max-error", "0.5"])
    assert res.exit_code == 1 and "FAIL" in res.output


def test_sweep_chooses_each_variants_grid(tmp_path):
    path = tmp_path / "auto.toml"
    path.write_text(auto_text(bound=5))
    res = CliRunner().invoke(cli, ["sweep", str(path), "--vary", "vehicle.mass=0.5,0.55",
                                   "-o", str(tmp_path / "sw")])
    assert res.exit_code == 0, res.output
    from gainsched.schedule.tables import load_table

    for toml in sorted((tmp_path / "sw").glob("*.toml")):
        table = load_table(toml.with_suffix(".h5"))
        assert table.grid_auto["bound"] == 0.05
        chosen = config_from_text(toml.read_text(), str(toml))  # the chosen config
        assert not chosen.grid.auto
        np.testing.assert_array_equal(table.speed, chosen.grid.speeds)


def test_budget_counts_an_automatic_axis_at_its_max_count():
    from gainsched.config import estimate_build

    auto = config_from_text(auto_text(), "auto.toml")
    listed = config_from_text(auto_text(
        speeds=[float(v) for v in np.linspace(6, 12, 9)],
        tilts=[float(a) for a in np.linspace(0, 30, 9)]), "list.toml")
    a, b = estimate_build(auto), estimate_build(listed)
    assert (a.cpu_s, a.peak_bytes) == (b.cpu_s, b.peak_bytes)
    az = estimate_build(config_from_text(auto_text(n_xi=dict(min=8, max=64)), "az.toml"))
    at_max = estimate_build(config_from_text(auto_text(n_xi=64), "max.toml"))
    assert (az.cpu_s, az.peak_bytes) == (at_max.cpu_s, at_max.peak_bytes)


# ------------------------------------------------------------------ the azimuth count


@pytest.mark.parametrize("n_xi, key", [
    (dict(min=7, max=64), "grid.azimuth_samples.min"),
    (dict(min=8, max=6), "grid.azimuth_samples.max"),
    (dict(min=8, max=8192), "grid.azimuth_samples.max"),
    (dict(min=8), "grid.azimuth_samples.max"),
    (dict(min=8, max=64, step=2), "grid.azimuth_samples.step"),
])
def test_bad_azimuth_ranges_name_the_key(n_xi, key):
    with pytest.raises(InputError) as info:
        config_from_text(auto_text(n_xi=n_xi), "bad.toml")
    assert str(info.value).startswith(f"bad.toml: {key}:"), str(info.value)


def test_the_azimuth_count_is_chosen_by_doubling():
    """8 samples are too few for 3 % (test_too_few_azimuth_samples_names_the_key); from
    a range the build doubles the count until the azimuth alone takes at most half the
    bound, and the independent check passes on every azimuth midpoint."""
    cfg = config_from_text(auto_text(n_xi=dict(min=8, max=64)), "az.toml")
    solved = []
    choice = refine_grid(cfg, progress=solved.append)
    n = choice.config.grid.azimuth_samples
    assert n in (16, 32, 64) and choice.restarts >= 1
    assert choice.azimuth_error <= 0.5 * cfg.grid.max_interpolation_error
    assert sum(solved) == choice.circles + choice.centres + choice.dropped
    line = next(x for x in choice.config.text.splitlines() if x.startswith("azimuth_samples"))
    assert f"azimuth_samples = {n}" in line and "{min = 8, max = 64}" in line
    files = output_files(choice.config, choice.grid, grid_auto=choice.record())
    res = midpoint_check(table_from_bytes(files["auto.h5"], "auto.h5"))
    assert res.xi.size == n * (choice.config.grid.speeds.size - 1) * (
        choice.config.grid.tilts.size - 1)
    assert max(res.max_err, res.max_nominal_err) <= cfg.grid.max_interpolation_error


def test_an_azimuth_range_too_small_names_its_max():
    cfg = config_from_text(auto_text(n_xi=dict(min=4, max=8), bound=3), "az.toml")
    with pytest.raises(InputError, match=r"^az\.toml: grid\.azimuth_samples\.max: 8 samples "
                       r"are too few for 3 %"):
        refine_grid(cfg)


def test_validate_says_the_build_chooses(tmp_path):
    path = tmp_path / "auto.toml"
    path.write_text(auto_text(n_xi=dict(min=8, max=64)))
    res = CliRunner().invoke(cli, ["validate", str(path)])
    assert res.exit_code == 0, res.output
    assert ("grid     speeds 6..12 m/s (at most 9, chosen), tilts 0..30 deg (at most 9, "
            "chosen), 8..64 azimuth samples (chosen)") in res.output
    assert "chosen by the build for 3 % at the cell midpoints" in res.output
