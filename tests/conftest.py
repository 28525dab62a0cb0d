"""Shared fixtures: the paper config (DESIGN.md section 8) and the reduced model built from it."""

from __future__ import annotations

from pathlib import Path

import pytest

from gainsched.config import load_config
from gainsched.model import Model

REPO = Path(__file__).parents[1]
PAPER_TOML = REPO / "configs" / "paper.toml"


@pytest.fixture(scope="session")
def paper_path() -> Path:
    """Absolute path of configs/paper.toml."""
    return PAPER_TOML


@pytest.fixture(scope="session")
def paper_text() -> str:
    """The text of configs/paper.toml."""
    return PAPER_TOML.read_text()


@pytest.fixture(scope="session")
def paper_config():
    """The loaded paper config (frozen; safe to share)."""
    return load_config(PAPER_TOML)


@pytest.fixture(scope="session")
def model(paper_config):
    """Reduced model of the paper vehicle with the config's effects (drag)."""
    return Model(paper_config)


@pytest.fixture(scope="session")
def model_nodrag(paper_config):
    """Reduced model of the paper vehicle without any effect (conservative with zero thrust)."""
    return Model(paper_config, effects=())
