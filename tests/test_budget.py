"""Build budget (gainsched.config's ``_budget``): estimates follow the grid sweep, absurd
builds are refused at validation, quickly, naming the file and the key that drives the estimate."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from gainsched.config import (
    GIB,
    Grid,
    Limits,
    check_budget,
    config_from_text,
    estimate_build,
    load_config,
    set_values,
)
from gainsched.constants import TILT_BATCH
from gainsched.errors import InputError
from gainsched.schedule import grid as grid_mod


def _set(text: str, values: dict) -> str:
    """``values`` (dotted keys) set in the config text (gainsched.config, ``_edit``)."""
    new = set_values(text, values)
    assert new != text
    return new


def _sub(text: str, key: str, value: str) -> str:
    """``key = value`` substituted in the text: only for the huge axes (10^4 to 10^6
    values), which the config editor (tomlkit) would take seconds to minutes to write (8 s for
    10^4 floats, growing with the square of the length)."""
    new = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text)
    assert new != text
    return new


def _floats(a) -> str:
    return "[" + ", ".join(repr(float(x)) for x in a) + "]"


def test_model_follows_the_grid_sweep(paper_config):
    """Steps per period and the tilt batch are those of gainsched.schedule.grid."""
    cfg = paper_config
    est = estimate_build(cfg)
    steps = [grid_mod.steps_per_period(v, cfg.radius, cfg.control.dt) for v in cfg.grid.speeds]
    assert est.steps_max == max(steps) == 7734  # 1.3 m/s
    assert TILT_BATCH == grid_mod.TILT_BATCH
    n = 11  # paper: drag has no state
    n_a = len(cfg.grid.tilts)  # 7 tilts, one batch
    assert n_a == 7 <= TILT_BATCH
    assert est.worker_bytes == 2 * 8 * n_a * 7734 * (n * n + 4 * n)
    assert est.table_bytes == n_a * 19 * 36 * (n * n + 4 * n + 8) * 8
    assert est.peak_bytes == est.worker_bytes + 2 * est.table_bytes
    # calibrated on the paper vehicle, every circle feasible: an upper bound of its 1.6 s
    assert 1.5 < est.cpu_s < 10
    assert est.peak_bytes < 0.2 * GIB
    assert check_budget(cfg, "paper.toml") == est


def test_effect_states_count(paper_text):
    """Motor lag adds 4 states to the LQR state: n = 15."""
    cfg = config_from_text(_set(paper_text, {"effects.motor_lag.tau": 0.03}), "lag.toml")
    est = estimate_build(cfg)
    assert est.worker_bytes == 2 * 8 * 7 * 7734 * (15 * 15 + 4 * 15)  # 7 tilts


@pytest.mark.parametrize(
    ("case", "edit", "key", "words"),
    [
        ("azimuth 1e6", lambda t: _set(t, {"grid.azimuth_samples": 1000000}),
         "grid.azimuth_samples", "[4, 4096]"),
        ("rate 1e9", lambda t: _set(t, {"control.rate_hz": 1e9}), "control.rate_hz",
         "<= 100000 Hz"),
        ("1e6 speeds", lambda t: _sub(t, "speeds", _floats(np.linspace(2, 15, 10**6))),
         "grid.speeds", "at most 1 MiB"),
        ("1e5 tilts", lambda t: _sub(t, "tilts_deg", _floats(np.linspace(0, 80, 10**5))),
         "grid.tilts_deg", "at most 1 MiB"),
        ("1000 x 100 grid",
         lambda t: _set(t, {"grid.speeds": [float(v) for v in np.linspace(2, 15, 1000)],
                            "grid.tilts_deg": [float(a) for a in np.linspace(0, 45, 100)]}),
         "grid.speeds", "GiB per worker (the table of 100 tilts x 1000 speeds x 36 azimuth"),
        ("1e5 Hz at 0.5 m/s",
         lambda t: _set(t, {"control.rate_hz": 1e5, "grid.speeds": [0.5, 15]}),
         "control.rate_hz",
         "GiB per worker (control.rate_hz 100000 Hz: 2e+06 steps per period at 0.5 m/s); "
         "limit limits.max_memory_gib = 8"),
        ("900 m tether", lambda t: _set(t, {"tether.length": 900.0}), "tether.length",
         "GiB per worker (tether.length 900 m: a 900.1 m circle, 4.4e+06 steps per period"),
        ("1 mm/s", lambda t: _set(t, {"grid.speeds": [0.001, 15]}), "grid.speeds",
         "GiB per worker (grid.speeds down to 0.001 m/s: 1e+07 steps per period at 1000 Hz)"),
        ("10000 speeds", lambda t: _sub(t, "speeds", _floats(np.linspace(2, 15, 10000))),
         "grid.speeds", "CPU-s to build (7 tilts x 10000 speeds = 70000 circles); "
         "limit limits.max_build_cpu_s = 1800"),
    ],
    ids=lambda x: x if isinstance(x, str) and " " in x else None,
)
def test_absurd_builds_refused_when_the_config_loads(paper_text, tmp_path, case, edit, key,
                                                     words):
    """Refused by the config's own check (an estimate, no circle solved), naming the key.
    (How fast: ``make bench`` times builds; a unit test does not time.)"""
    path = tmp_path / "big.toml"
    path.write_text(edit(paper_text))
    with pytest.raises(InputError) as info:
        load_config(path)
    assert info.value.source == str(path) and info.value.where == key, str(info.value)
    assert words in info.value.message, info.value.message


def test_estimate_of_a_million_speeds(paper_config):
    """The estimate of a grid the text limit would refuse first (1 MiB) still names the key
    and the count: it is arithmetic over the speeds, vectorised."""
    g = paper_config.grid
    speeds = np.linspace(2, 15, 10**6)
    cfg = dataclasses.replace(paper_config, grid=Grid(speeds, g.tilts, g.azimuth_samples))
    with pytest.raises(InputError) as info:
        check_budget(cfg, "million.toml")
    assert info.value.where == "grid.speeds" and "1000000 speeds" in info.value.message


def test_limits_section(paper_text):
    low_mem = _set(paper_text, {"limits.max_memory_gib": 0.01})
    with pytest.raises(InputError) as info:
        config_from_text(low_mem, "low.toml")
    assert info.value.where == "grid.speeds"
    assert info.value.message.endswith("limit limits.max_memory_gib = 0.01")
    low_cpu = _set(paper_text, {"limits.max_build_cpu_s": 1})
    with pytest.raises(InputError, match=r"^low.toml: grid.tilts_deg: needs about 5 CPU-s"):
        config_from_text(low_cpu, "low.toml")
    # raising the limits admits what the defaults refuse
    big = _sub(paper_text, "speeds", _floats(np.linspace(2, 15, 10000)))
    with pytest.raises(InputError, match="max_build_cpu_s = 1800"):
        config_from_text(big, "big.toml")
    cfg = config_from_text(_set(big, {"limits.max_build_cpu_s": 1e4}), "big.toml")
    assert cfg.limits == Limits(8.0, 1e4)


def test_config_objects_default_limits(paper_config):
    assert paper_config.limits == Limits()
    fields = {f.name: f for f in dataclasses.fields(paper_config)}
    assert fields["limits"].default_factory is Limits
