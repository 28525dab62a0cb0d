"""The flight envelope (gainsched.schedule.envelope, ``inspect --out``) of the committed
paper table: categories agree with the table's reasons and with the closed-form lowest
taut speed (paper eq. 19), and the CLI writes the PNG and JSON as one set."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.config import load_config
from gainsched.constants import Reason
from gainsched.schedule.envelope import CATEGORIES, envelope_from_table, envelope_png

from support import PAPER_H5, PAPER_TOML


@pytest.fixture(scope="module")
def env(paper_table):
    return envelope_from_table(paper_table)


def test_categories_follow_the_reasons(paper_table, env):
    has_gains = np.isfinite(paper_table.spectral_radius)
    cat = np.array(CATEGORIES)[env.category]
    assert np.array_equal(has_gains, np.isin(cat, CATEGORIES[:2]))
    bits = np.bitwise_or.reduce(paper_table.reasons, axis=-1)
    assert np.array_equal(cat == "tether slack", ~has_gains & (bits & Reason.SLACK > 0))
    # offsets exactly where the table stores non-zero coefficients
    nonzero = np.any(paper_table.offsets != 0, axis=(-2, -1))
    assert np.array_equal(cat == "feasible with attitude offsets", nonzero & has_gains)
    assert sum(env.counts().values()) == paper_table.spectral_radius.size


def test_paper_envelope_has_only_slack_holes(env):
    """Issue 15: on configs/paper.toml every circle up to 40 deg with a taut tether has
    gains; the holes are the slack circles at low speed."""
    counts = env.counts()
    assert set(counts) == {"feasible", "feasible with attitude offsets", "tether slack"}
    # the circles the zero-offset nominal could not fly (40 deg 11-15, 37 deg 12-15,
    # 34 deg 13-15, 28 deg 15 m/s) are the ones with offsets
    with_offsets = {(round(float(np.rad2deg(a))), float(v))
                    for (i, j), c in np.ndenumerate(env.category) if c == 1
                    for a, v in [(env.tilt[i], env.speed[j])]}
    assert with_offsets == ({(40, v) for v in (11.0, 12.0, 13.0, 14.0, 15.0)}
                            | {(37, v) for v in (12.0, 13.0, 14.0, 15.0)}
                            | {(34, v) for v in (13.0, 14.0, 15.0)} | {(28, 15.0)})
    assert np.all(np.rad2deg(env.max_offset) <= 10.0 + 1e-9)


def test_slack_is_below_the_closed_form_taut_speed(env):
    """Independent check: eq. 19, v_min = sqrt(r (T_min / m + g sin alpha)); every slack
    circle is slower than it and every circle at or above it is taut."""
    cfg = load_config(PAPER_TOML)
    r, m, g = cfg.radius, cfg.vehicle.mass, cfg.g
    for i, a in enumerate(env.tilt):
        v_min = np.sqrt(r * (cfg.feasibility.min_tension / m + g * np.sin(a)))
        slack = env.category[i] == CATEGORIES.index("tether slack")
        assert np.all(env.speed[slack] < v_min)
        assert not np.any(slack & (env.speed >= v_min))
    # the drawn curve is the same formula
    v_curve = np.sqrt(r * (cfg.feasibility.min_tension / m + g * np.sin(env.taut_tilt)))
    np.testing.assert_allclose(env.taut_speed, v_curve, rtol=1e-12)


def test_png_and_json(env):
    png = envelope_png(env)
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    data = json.loads(json.dumps(env.to_json()))
    assert data["counts"] == env.counts()
    assert len(data["category"]) == env.tilt.size
    assert len(data["category"][0]) == env.speed.size


def test_inspect_out_writes_the_envelope(tmp_path, env):
    res = CliRunner().invoke(cli, ["inspect", str(PAPER_H5), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert "envelope: " in res.output and "tether slack" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["envelope.json", "envelope.png"]
    data = json.loads((tmp_path / "envelope.json").read_text())
    assert data["config"] == "paper" and data["counts"] == env.counts()
    assert (tmp_path / "envelope.png").read_bytes() == envelope_png(env)
