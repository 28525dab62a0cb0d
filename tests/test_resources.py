"""The reference configs ship with the package (issue 36): a bare name loads the shipped
config, a file of that name in the current folder comes first, an unknown name lists
what ships; the shipped list is the checkout's configs/ folder (one list)."""

from __future__ import annotations

import pytest

from gainsched.config import load_config
from gainsched.errors import InputError
from gainsched.resources import config_path, reference_config, reference_configs

from support import PAPER_TOML, REPO


def test_shipped_configs_are_the_configs_folder():
    assert reference_configs() == tuple(sorted(p.stem for p in (REPO / "configs").glob("*.toml")))
    assert "paper" in reference_configs()
    for name in reference_configs():
        shipped = reference_config(name).read_bytes()
        assert shipped == (REPO / "configs" / f"{name}.toml").read_bytes()
    assert reference_config("nosuch") is None


def test_bare_name_loads_the_shipped_config(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no configs/ here
    cfg = load_config("paper")
    assert cfg.text == load_config(PAPER_TOML).text and cfg.name == "paper"
    assert cfg.sha256 == load_config(PAPER_TOML).sha256


def test_a_file_of_that_name_comes_first(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paper").write_text(PAPER_TOML.read_text().replace("mass = 0.5 ", "mass = 0.6 "))
    assert str(config_path("paper")) == "paper"  # the file here, not the shipped one
    assert load_config("paper").vehicle.mass == pytest.approx(0.6)


@pytest.mark.parametrize("given", ["nosuch", "sub/paper", "paper.toml"])
def test_what_is_not_shipped_is_a_path(tmp_path, monkeypatch, given):
    """A name with a folder or a suffix is a path, never a shipped config; an unknown bare
    name says which configs ship."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match="cannot read") as err:
        load_config(given)
    assert str(err.value).startswith(given)
    assert ("the shipped configs are heavy_auto, paper" in str(err.value)) == (given == "nosuch")
