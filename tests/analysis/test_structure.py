"""Phase-locked residual structure (gainsched.analysis.structure, issue 16): block means
over revolutions find a systematic residual that the overall RMS hides, name its sector
and amplitude, and stay quiet on noise."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from gainsched.analysis.structure import ALPHA, binned_means, findings

from support import PAPER_TOML


def _segments(seed, dip=0.0, center=115.0, width=15.0, n_seg=6, turns=4.0, n=2000):
    """Synthetic residual segments: white noise of RMS 1 on two axes, plus on "normal" a
    box dip of ``dip`` over ``center +- width / 2`` deg of azimuth."""
    rng = np.random.default_rng(seed)
    out = []
    for s in range(n_seg):
        t = np.arange(n) * 0.005
        az = (37.0 * s + np.linspace(0, 360 * turns, n)) % 360
        d = (az - center + 180) % 360 - 180
        normal = rng.standard_normal(n) + dip * (np.abs(d) < width / 2)
        out.append(SimpleNamespace(
            t=t, residual={"normal": normal, "yaw": rng.standard_normal(n)},
            variables={"azimuth": az, "airspeed": 9 + 0.1 * rng.standard_normal(n),
                       "thrust": 5 + 0.1 * rng.standard_normal(n)}))
    return out


NOISE = {"normal": 1.0, "yaw": 1.0}


def test_block_means_are_the_revolution_averages():
    """Second formulation: the bin mean is the plain average over revolutions of each
    revolution's mean in the bin, and the pooled standard error shrinks as 1/sqrt(blocks)."""
    res = _segments(0, n_seg=1, turns=3.0, n=3000)
    bm = binned_means(res, ["normal"], "azimuth", n_bins=12)["normal"]
    r = res[0]
    rev = np.floor(np.unwrap(np.deg2rad(r.variables["azimuth"])) / (2 * np.pi)).astype(int)
    b = np.clip(np.digitize(r.variables["azimuth"], bm.edges) - 1, 0, 11)
    for k in range(12):
        means = [r.residual["normal"][(rev == j) & (b == k)].mean()
                 for j in np.unique(rev) if np.any((rev == j) & (b == k))]
        assert bm.n_blocks[k] == len(means)
        assert bm.mean[k] == pytest.approx(np.mean(means), rel=1e-12, abs=1e-12)
    ratio = bm.se * np.sqrt(bm.n_blocks)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)  # one pooled variance


def test_dip_below_the_noise_floor_is_found():
    """A dip of 1.5x the noise over 15 deg is 1.04x the noise overall (an overall-RMS gate
    passes it) but is found: sector within 15 deg, amplitude within 30 %."""
    res = _segments(1, dip=-1.5)
    e = np.concatenate([r.residual["normal"] for r in res])
    assert np.sqrt(np.mean(e**2)) < 1.25
    found, _ = findings(res, NOISE)
    assert found, "the dip must be found"
    f = found[0]
    assert (f.axis, f.variable) == ("normal", "azimuth")
    assert abs((f.center - 115.0 + 180) % 360 - 180) <= 15
    assert f.amplitude == pytest.approx(-1.5, rel=0.3)
    assert abs(f.amplitude + 1.5) <= f.ci95 + 0.3
    assert "azimuth" in f.sentence() and "noise floor" in f.sentence()


def test_sector_wraps_through_zero():
    res = _segments(2, dip=-2.0, center=0.0, width=30.0)
    f = findings(res, NOISE)[0][0]
    assert abs((f.center + 180) % 360 - 180) <= 15 and f.hi - f.lo <= 60


def test_noise_alone_gives_no_finding():
    """The t tests alone (noise floors set tiny so the amplitude gate never acts): at the
    family-wise level ALPHA = 1 %, 20 independent noise campaigns give at most one false
    finding (binomial: P(>= 2) = 1.7 % at the nominal level; measured 0)."""
    tiny = {"normal": 1e-6, "yaw": 1e-6}
    false = sum(bool(findings(_segments(100 + s), tiny)[0]) for s in range(20))
    assert ALPHA == 0.01 and false <= 1
    # and with the real floors (1 per sample) the bin means of noise are far below them
    assert not any(findings(_segments(100 + s), NOISE)[0] for s in range(5))


@pytest.mark.slow
def test_thrust_dip_in_a_flight_campaign(fly):
    """Issue 16's must-show on the project's simulator: a 5 % thrust dip at 115 deg
    (width 12 deg), outside the library, whose overall residual stays below 1.25x the
    noise floor (the 7 flights of the default campaign, 2.5 s each):

    - reported as significant structure with the right sector (+- 15 deg) and amplitude
      (+- 30 % of the dip's own contribution, computed by the plant model minus the
      design model on the measured states);
    - no physical candidate explains it, the empirical azimuth series does: accepted,
      the held-out binned structure falls >= 70 %, its deepest point within 15 deg of
      the dip; ``--apply`` writes it into a config from which tables rebuild.

    Measured: normal -0.33 +- 0.06 m/s^2 at 105-135 deg (t = -9.2); thrust_azimuth with
    6 harmonics, -3.9 % at 114 deg, held-out binned structure -80 %.

    The issue's logs had no accelerometer: analysed with it, the normal axis' floor falls
    from 0.25 to 0.09 m/s^2 and the dip is no longer below it (the sensor shows it
    plainly), so this test analyses the pose and gyro only (``use_accelerometer``
    off)."""
    from gainsched.analysis.compare import UNITS, compare, predict
    from gainsched.analysis.diagnose import apply_candidate, diagnose
    from gainsched.config import config_from_text, load_config
    from gainsched.model.effects import ThrustAzimuth, registered_effect
    from gainsched.model.reduced import Model
    from gainsched.sim.campaign import HIDDEN, plant_config

    paper = load_config(PAPER_TOML).with_values({"analysis.use_accelerometer": False})
    logs = fly("azimuth_thrust_dip", real_tether=False)  # the flights do not read [analysis]
    cmp = compare(paper, logs)
    assert all(s.rms_over_noise < 1.25 for s in cmp.stats.values())
    assert cmp.structure, cmp.where["sentence"]
    f = cmp.structure[0]
    assert (f.axis, f.variable) == ("normal", "azimuth")
    assert abs((f.center - 115.0 + 180) % 360 - 180) <= 15
    # the dip's own contribution: plant minus design prediction on the measured states
    h = HIDDEN["azimuth_thrust_dip"]
    with registered_effect(h.custom):
        plant = Model(plant_config(paper, h))
        design = Model(paper)
        expected = []
        for m, r in zip(cmp.measured, cmp.residuals, strict=True):
            c = m.core
            d = predict(plant, m).acc[c, 1] - predict(design, m).acc[c, 1]
            expected.append(SimpleNamespace(t=r.t, variables=r.variables,
                                            residual={"normal": d}))
    bm = binned_means(expected, ["normal"], "azimuth", units=UNITS)["normal"]
    sector = (bm.centers % 360 >= f.lo % 360) & (bm.centers % 360 <= f.lo % 360 + (f.hi - f.lo))
    truth = float(np.average(bm.mean[sector], weights=bm.n_blocks[sector]))
    assert f.amplitude == pytest.approx(truth, rel=0.3), (f.amplitude, truth)
    assert math.isfinite(f.ci95)

    d = diagnose(paper, logs, comparison=cmp)
    a = d.accepted
    assert a is not None and a.name == "thrust_azimuth" and a.empirical, d.verdict
    assert a.below_noise and a.structure_reduction >= 0.7, a.structure_reduction
    assert d.verdict.startswith("no physical effect of the library explains"), d.verdict
    physical = [r for r in d.results if not r.empirical]
    assert not any(r.passes for r in physical)
    eff = ThrustAzimuth(**a.values)
    xi = np.deg2rad(np.arange(360.0))
    factor = eff.factor(SimpleNamespace(p_C=np.stack([np.cos(xi), np.sin(xi), 0 * xi], -1),
                                        v_C=np.stack([-np.sin(xi), np.cos(xi), 0 * xi], -1),
                                        alpha=0.0))
    deepest = float(np.rad2deg(xi[np.argmin(factor)]))
    assert abs((deepest - 115.0 + 180) % 360 - 180) <= 15, deepest
    cfg = config_from_text(apply_candidate(paper, a), "applied.toml")
    assert any(s.name == "thrust_azimuth" for s in cfg.effects)
    # and tables rebuild with it (two speeds, two tilts: the tilt-0 gains per azimuth)
    from gainsched.schedule.grid import build_grid
    from gainsched.schedule.tables import table_bytes, table_from_bytes

    small = cfg.with_values({"grid.speeds": [8.0, 9.0], "grid.tilts_deg": [0.0, 20.0]})
    table = table_from_bytes(table_bytes(small, build_grid(small), Model(small)))
    assert table.per_azimuth_tilt0 and not table.reasons.any()
