"""Config variants (gainsched.config, ``_edit``): the TOML document edited, everything else kept."""

from __future__ import annotations

import tomllib

import pytest

from gainsched.config import (
    config_from_text,
    get_value,
    remove_key,
    set_section,
    set_value,
    set_values,
)

from support import PAPER_TOML as PAPER


def test_set_value_keeps_everything_else():
    text = PAPER.read_text()
    new = set_value(text, "vehicle", "mass", 0.55, "kg; fitted")
    old_lines, new_lines = text.splitlines(), new.splitlines()
    changed = [(a, b) for a, b in zip(old_lines, new_lines, strict=True) if a != b]
    assert len(changed) == 1 and changed[0][1].startswith("mass = 0.55")
    assert "# kg; fitted" in changed[0][1]
    assert config_from_text(new).vehicle.mass == 0.55
    assert get_value(new, "vehicle", "mass") == 0.55


def test_full_precision():
    """A fitted value survives the round trip bit for bit (the regex editor kept 6 digits)."""
    x = 0.1 + 0.2
    new = set_value(PAPER.read_text(), "effects.drag", "mu1", x)
    assert config_from_text(new).effects[0].param_dict()["mu1"] == x
    with pytest.raises(ValueError):
        set_value(PAPER.read_text(), "vehicle", "mass", float("nan"))


def test_new_section_and_key():
    text = PAPER.read_text()
    new = set_section(text, "effects.rotor_drag", [("k_rd", 0.015, "s/m")], "fitted")
    new = set_value(new, "analysis", "latency_s", 0.012, "s")
    cfg = config_from_text(new)
    assert dict(next(s for s in cfg.effects if s.name == "rotor_drag").params)["k_rd"] == 0.015
    assert cfg.analysis.latency_s == 0.012
    # the effects table sits after the existing [effects.*] tables
    assert new.index("[effects.drag]") < new.index("[effects.rotor_drag]") < new.index(
        "[environment]")
    assert "# fitted" in new and "# s/m" in new
    # replacing a section rewrites only it
    again = set_section(new, "effects.rotor_drag", [("k_rd", 0.02, None)])
    assert tomllib.loads(again)["effects"]["rotor_drag"] == {"k_rd": 0.02}
    assert again.count("[effects.rotor_drag]") == 1
    assert again.replace("k_rd = 0.02", "") .count("mu1 = 0.172") == 1


def test_root_key_and_remove():
    text = 'name = "a"  # c\n\n[x]\ny = 1\nz = 2\n'
    renamed = set_value(text, "", "name", "b")
    assert tomllib.loads(renamed)["name"] == "b" and "# c" in renamed
    assert tomllib.loads(remove_key(text, "x", "z"))["x"] == {"y": 1}
    assert get_value(text, "x", "q") is None and get_value(text, "nope", "y") is None


def test_set_values_for_sweeps():
    """Dotted keys, list entries (the inertia diagonal), a new root key before the tables."""
    text = 'schema = "gainsched-config/1"\n\n[vehicle]\nmass = 0.5  # kg\n' \
           'inertia = [2.5e-3, 2.5e-3, 4.5e-3]\n'
    new = set_values(text, {"name": "v1", "vehicle.inertia.2": 4.6e-3, "vehicle.mass": 0.45})
    d = tomllib.loads(new)
    assert d["name"] == "v1" and d["vehicle"] == {"mass": 0.45, "inertia": [2.5e-3, 2.5e-3,
                                                                           4.6e-3]}
    assert "# kg" in new
    matrix = 'x = 1\n\n[vehicle]\ninertia = [[1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0]]\n'
    d = tomllib.loads(set_values(matrix, {"vehicle.inertia.1": 2.5}))
    assert d["vehicle"]["inertia"] == [[1.0, 0, 0], [0, 2.5, 0], [0, 0, 3.0]]


def test_config_variant_carries_its_own_text_and_hash():
    """Config.with_values: the one variant path for code (check's doubled azimuth grid,
    diagnose's config candidates): text, hash and values agree, comments survive, and a
    bad value is refused naming the key."""
    import hashlib

    from gainsched.config import load_config
    from gainsched.errors import InputError

    cfg = load_config(PAPER)
    var = cfg.with_values({"vehicle.mass": 0.5123456789012345, "grid.azimuth_samples": 72})
    assert var.vehicle.mass == 0.5123456789012345 and var.grid.azimuth_samples == 72
    assert var.sha256 == hashlib.sha256(var.text.encode()).hexdigest() != cfg.sha256
    assert "# kg" in var.text and var.source == cfg.source
    assert var.tether == cfg.tether and var.effects == cfg.effects
    with pytest.raises(InputError, match=r"paper.toml: vehicle.mass: "):
        cfg.with_values({"vehicle.mass": -1.0})


def test_an_effects_table_in_pieces_is_edited(tmp_path):
    """Issue 53: ``[effects.rotor_drag]`` added at the end of a config, after other
    sections (valid TOML: ``[effects]`` written in pieces) is read, and every edit works
    on it: a new effect, a replaced one, a value, a removed key (diagnose --apply and
    improve write through these); the other pieces stay where they are."""
    text = PAPER.read_text() + "\n[effects.rotor_drag]\nk_rd = 0.01\n"
    assert {s.name for s in config_from_text(text).effects} == {"drag", "rotor_drag"}
    new = set_section(text, "effects.motor_lag", [("tau", 0.03, "s; fitted")], "diagnose")
    new = set_section(new, "effects.rotor_drag", [("k_rd", 0.02, None)])
    new = set_value(new, "effects.drag", "mu1", 0.2)
    new = remove_key(new, "analysis", "latency_s")
    cfg = config_from_text(new)
    assert {s.name: s.param_dict() for s in cfg.effects} == {
        "drag": {"mu1": 0.2, "mu2": 0.0025}, "motor_lag": {"tau": 0.03},
        "rotor_drag": {"k_rd": 0.02}}
    assert new.index("[effects.drag]") < new.index("[environment]") < new.index(
        "[effects.rotor_drag]")
    assert get_value(new, "effects.motor_lag", "tau") == 0.03
