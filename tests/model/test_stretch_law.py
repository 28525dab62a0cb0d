"""The empirical tether stretch in tension (issue 37): ``tether_stretch``, a power series
in the tether tension for a stretch residual no effect of the library explains.

Checked against independent references: the series written out term by term, the
linear elasticity's static stretch ``f / k`` (a closed form), the plausibility of a
monotone law, and a table built with the law against one built without it.
"""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.model.effects import (
    EFFECTS,
    TENSION_ORDER,
    TENSION_UNIT_N,
    TetherStretchSeries,
    tether_stretch_of,
)
from gainsched.model.symmetry import (
    azimuth_invariance_error,
    effect_symmetry_errors,
    table_refusal,
)

from support import small_config_text


def test_stretch_is_the_power_series_and_nests_the_linear_elasticity():
    """sum_k s_k (f / 10 N)^k written out, 0 on a slack tether (f <= 0); with s1 alone it
    is the spring's static stretch f / k at s1 = 10 N / k (1e-15 m)."""
    rng = np.random.default_rng(4)
    s = {f"s{k}": float(rng.uniform(-0.01, 0.01)) for k in range(1, TENSION_ORDER + 1)}
    f = rng.uniform(-5.0, 80.0, 200)  # N, slack samples included
    x = np.maximum(f, 0.0) / TENSION_UNIT_N
    want = s["s1"] * x + s["s2"] * x ** 2 + s["s3"] * x ** 3
    np.testing.assert_allclose(TetherStretchSeries(**s).stretch(f), want, rtol=1e-12,
                               atol=1e-15)
    assert np.all(TetherStretchSeries(**s).stretch(f)[f <= 0] == 0.0)
    k = 3000.0  # N/m
    np.testing.assert_allclose(TetherStretchSeries(s1=TENSION_UNIT_N / k).stretch(f),
                               np.maximum(f, 0.0) / k, rtol=1e-14, atol=1e-15)


def test_only_the_stretch_law_stretches_the_tether():
    """tether_stretch_of sums the laws of the effects that have one and is None without
    any: no other effect of the registry stretches the tether, and the law changes no
    thrust and no force."""
    f = np.linspace(0.0, 60.0, 7)
    assert tether_stretch_of([EFFECTS[k]() for k in EFFECTS if k != "tether_stretch"], f) is None
    a, b = TetherStretchSeries(s1=0.002), TetherStretchSeries(s2=0.0005)
    np.testing.assert_allclose(tether_stretch_of([a, b], f), a.stretch(f) + b.stretch(f),
                               rtol=1e-15)
    assert [k for k, c in EFFECTS.items() if c.stretch_only] == ["tether_stretch"]
    T = np.array([[2.0, 3.0, 4.0, 5.0]])
    assert np.array_equal(a.modify_thrust(T, None, None), T) and a.wrench(T, None) is None


def test_a_table_can_hold_it():
    """A function of the tension alone, with no force: S1 and S2 hold and a level circle
    is the same at every azimuth, so no refusal."""
    eff = TetherStretchSeries(s1=0.003, s2=0.001, s3=-0.0002)
    assert table_refusal(eff) == ""
    assert effect_symmetry_errors(eff) == {"S1": 0.0, "S2": 0.0}
    assert azimuth_invariance_error(eff) == 0.0


@pytest.mark.slow
def test_the_build_holds_it_with_the_same_gains():
    """A build with [effects.tether_stretch] is the build without it, bit for bit (the law
    changes no force of the model the table is built on)."""
    from gainsched.config import config_from_text, set_section
    from gainsched.model.reduced import Model
    from gainsched.schedule.grid import build_grid

    text = small_config_text(name="line", grid__speeds=[6.0, 9.0], grid__tilts_deg=[0.0, 20.0],
                             grid__azimuth_samples=8)
    plain = config_from_text(text, "line.toml")
    law = config_from_text(set_section(text, "effects.tether_stretch",
                                       [("s1", 0.003, None), ("s2", 0.001, None)]), "law.toml")
    assert [e.kind for e in Model(law).effects if e.kind == "tether_stretch"]
    a, b = build_grid(plain), build_grid(law)
    assert not np.asarray(b.reasons).any()
    np.testing.assert_array_equal(a.K, b.K)


def test_a_stretch_that_falls_with_tension_is_implausible():
    """5 mm (f/10 N) - 1 mm (f/10 N)^2 peaks at 25 N and falls 6.25 mm by 50 N: no tether
    shortens when pulled harder; a stiffening law, or the same turn beyond the flown
    tensions, is plausible, and a wiggle under the tolerance too."""
    bad = TetherStretchSeries(s1=0.005, s2=-0.001)
    why = bad.implausible_tension((5.0, 50.0))
    assert why.startswith("tether_stretch falls by 6.2 mm as the tension rises to 50.0 N "
                          "inside the flown 5.0-50.0 N"), why
    assert bad.implausible_tension((5.0, 20.0)) == ""
    assert TetherStretchSeries(s1=0.001, s2=0.0005, s3=0.0001).implausible_tension(
        (0.0, 60.0)) == ""
    assert TetherStretchSeries(s1=-0.0001).implausible_tension((0.0, 40.0)) == ""  # 0.4 mm
