"""Comment-preserving config edits used by ``diagnose --apply``."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from gainsched.config import config_from_text
from gainsched.tomledit import fmt_value, get_value, remove_key, set_section, set_value

PAPER = Path(__file__).resolve().parents[1] / "configs/paper.toml"


def test_set_value_keeps_everything_else():
    text = PAPER.read_text()
    new = set_value(text, "vehicle", "mass", 0.55, "kg; fitted")
    old_lines, new_lines = text.splitlines(), new.splitlines()
    changed = [(a, b) for a, b in zip(old_lines, new_lines, strict=True) if a != b]
    assert len(changed) == 1 and changed[0][1].startswith("mass = 0.55")
    assert "# kg; fitted" in changed[0][1]
    assert config_from_text(new).vehicle.mass == 0.55
    assert get_value(new, "vehicle", "mass") == "0.55"


def test_new_section_and_key():
    text = PAPER.read_text()
    new = set_section(text, "effects.rotor_drag", [("k_rd", 0.015, "s/m")], "fitted")
    new = set_value(new, "analysis", "latency_s", 0.012, "s")
    cfg = config_from_text(new)
    assert dict(next(s for s in cfg.effects if s.name == "rotor_drag").params)["k_rd"] == 0.015
    assert cfg.analysis.latency_s == 0.012
    # the effects table sits after the existing [effects.*] tables
    assert new.index("[effects.rotor_drag]") < new.index("[environment]")
    # replacing a section rewrites only it
    again = set_section(new, "effects.rotor_drag", [("k_rd", 0.02, None)])
    assert tomllib.loads(again)["effects"]["rotor_drag"] == {"k_rd": 0.02}
    assert again.count("[effects.rotor_drag]") == 1


def test_root_key_and_remove():
    text = 'name = "a"  # c\n\n[x]\ny = 1\nz = 2\n'
    assert tomllib.loads(set_value(text, "", "name", "b"))["name"] == "b"
    assert tomllib.loads(remove_key(text, "x", "z"))["x"] == {"y": 1}


def test_fmt_value():
    assert fmt_value(0.1 + 0.2) == "0.3"
    assert fmt_value(True) == "true" and fmt_value(3) == "3" and fmt_value('a"b') == '"a\\"b"'
    with pytest.raises(ValueError):
        fmt_value(float("nan"))
