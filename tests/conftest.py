"""Shared fixtures: the paper config (configs/paper.toml) and the reduced model built from it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from gainsched.config import load_config
from gainsched.model.reduced import Model
from gainsched.schedule.nominal import nominal_from_path
from gainsched.schedule.path import circle_path, period

REPO = Path(__file__).parents[1]
PAPER_TOML = REPO / "configs" / "paper.toml"
#: the open-loop reference circle of the link-model tests: m/s, rad
CIRCLE_SPEED, CIRCLE_TILT = 8.0, np.deg2rad(20.0)


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


@pytest.fixture(scope="session")
def circle(model):
    """Nominal 8 m/s circle at 20 deg: the Nominal and a periodic spline of u_d(t), N."""
    T = period(CIRCLE_SPEED, model.r)
    t = np.linspace(0.0, T, 721)
    nom = nominal_from_path(model, circle_path(CIRCLE_SPEED, model.r, t), CIRCLE_TILT)
    assert np.all(nom.reasons == 0)
    spline = CubicSpline(t, nom.u, bc_type="periodic")
    return nom, (lambda s: spline(s % T))
