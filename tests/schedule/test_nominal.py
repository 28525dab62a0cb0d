"""Nominal trajectories (gainsched.schedule.nominal, paper Sec. III)."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.integrate import cumulative_trapezoid

from gainsched.cli import cli
from gainsched.schedule.nominal import REASONS, circle_nominal, min_taut_speed, nominal_from_path
from gainsched.schedule.path import maneuver_path

SLACK, THRUST_LOW = 1, 2
assert REASONS[SLACK] == "tether slack" and REASONS[THRUST_LOW] == "thrust below minimum"

# paper Sec. V: speed-up 2 -> 11.3 m/s with peak 12.5 m/s^2, stop 11.3 -> 1.0 m/s with 17.5
MANEUVERS = {"speed-up": (2.0, 11.3, 6.25), "stop": (11.3, 1.0, 8.75)}


def relative_residual(model, nom):
    """max |f(z_d, u_d) - z_dot_d| / max |z_dot_d| over the whole trajectory."""
    f = model.f(nom.z, nom.u, nom.alpha)
    return np.abs(f - nom.z_dot).max() / np.abs(nom.z_dot).max()


def eq18(model, xi_dot, xi, alpha):
    """Paper eq. 18: f_t = m r xi'^2 - m g sin(alpha) sin(xi), N."""
    return model.m * model.r * xi_dot**2 - model.m * model.g * np.sin(alpha) * np.sin(xi)


def maneuver(model, name, n=2001, pad=0.3):
    v0, v1, a = MANEUVERS[name]
    dur = abs(v1 - v0) / a
    t = np.linspace(-pad, dur + pad, n)
    return maneuver_path(v0, v1, a, model.r, t), dur


# --------------------------------------------------------------------------- (1) the model holds


@pytest.mark.slow
@pytest.mark.parametrize("tilt_deg", [0, 20, 40])
@pytest.mark.parametrize("speed", [3.0, 9.0, 15.0])
def test_circle_nominal_satisfies_model(model, paper_config, speed, tilt_deg):
    alpha = np.deg2rad(tilt_deg)
    nom = circle_nominal(model, speed, alpha, 72)
    if speed < min_taut_speed(paper_config, alpha):
        assert (speed, tilt_deg) == (3.0, 40)  # the only slack combination of this grid
        assert np.any(nom.reasons & SLACK)
        pytest.skip("tether slack: the reduced model does not apply")
    assert not np.any(nom.reasons & SLACK)
    assert relative_residual(model, nom) <= 1e-9
    # over one whole period, for both directions
    assert nom.z[-1, 1] - nom.z[0, 1] == pytest.approx(2 * np.pi * 71 / 72, rel=1e-12)
    assert relative_residual(model, circle_nominal(model, -speed, alpha, 72)) <= 1e-9


def test_slow_tilted_circle_is_reported_slack(model):
    nom = circle_nominal(model, 3.0, np.deg2rad(40), 72)
    assert np.any(nom.reasons & SLACK)
    assert nom.tension.min() < model.config.feasibility.min_tension


@pytest.mark.parametrize("name", list(MANEUVERS))
def test_maneuver_nominal_satisfies_model(model, name):
    path, _ = maneuver(model, name)
    nom = nominal_from_path(model, path, 0.0)
    # taut throughout (the stop ends at 1.0 m/s: 0.31 N, inside the 0.5 N margin, so the
    # margin bit is set there, but the reduced model still applies)
    assert nom.tension.min() > 0.3
    assert relative_residual(model, nom) <= 1e-9


def test_residual_detects_a_wrong_input(model):
    """The residual check can fail: a 1 % collective error is far above 1e-9."""
    nom = circle_nominal(model, 9.0, np.deg2rad(20), 36)
    bad = type(nom)(nom.t, nom.z, nom.z_dot, 1.01 * nom.u, nom.tension, nom.alpha, nom.reasons)
    assert relative_residual(model, bad) > 1e-4


# --------------------------------------------------------------------------- (2) maneuver path


@pytest.mark.parametrize("name", list(MANEUVERS))
def test_maneuver_path_integrates(model, name):
    v0, v1, a = MANEUVERS[name]
    r = model.r
    path, dur = maneuver(model, name, n=40001)
    t, xi, (xd, xdd, xddd, xdddd) = path.t, path.xi, path.d
    assert dur == pytest.approx(abs(v1 - v0) / a)
    # speeds before / after, and the end speed reached exactly at t = dur
    assert r * xd[0] == pytest.approx(v0, rel=1e-14) and r * xd[-1] == pytest.approx(v1, rel=1e-12)
    at_end = maneuver_path(v0, v1, a, r, np.array([dur, 0.9 * dur]))
    assert r * at_end.d[0][0] == pytest.approx(v1, rel=1e-12)
    assert abs(r * at_end.d[0][1] - v1) > 1e-3
    # tangential acceleration: zero outside [0, dur], peak 2a in the middle, sign of v1 - v0
    a_t = r * xdd
    assert np.all(a_t[(t < 0) | (t > dur)] == 0)
    assert np.abs(a_t).max() == pytest.approx(2 * a, rel=1e-6)
    assert np.abs(a_t[np.argmin(np.abs(t - dur / 2))]) == pytest.approx(2 * a, rel=1e-6)
    assert np.all(np.sign(a_t[(t > 0) & (t < dur)]) == np.sign(v1 - v0))
    # integrals (trapezoid, dt = 5e-5 s; error ~ dt^2 max|xi'''| T / 12 << 1e-6)
    xd_int = xd[0] + cumulative_trapezoid(xdd, t, initial=0)
    np.testing.assert_allclose(xd_int, xd, rtol=0, atol=1e-7)
    xi_int = xi[0] + cumulative_trapezoid(xd, t, initial=0)
    np.testing.assert_allclose(xi_int, xi, rtol=0, atol=1e-7)
    # higher derivatives against central differences (inside the manoeuvre, where smooth)
    dt = t[1] - t[0]
    inner = (t > 0.01) & (t < dur - 0.01)
    for lo, hi in ((xdd, xddd), (xddd, xdddd)):
        cd = (lo[2:] - lo[:-2]) / (2 * dt)
        scale = np.abs(hi).max()
        np.testing.assert_allclose(cd[inner[1:-1]], hi[1:-1][inner[1:-1]], rtol=0,
                                   atol=1e-6 * scale)


# --------------------------------------------------------------------------- (3)-(5) tension


@pytest.mark.parametrize(("speed", "tilt_deg"), [(4.0, 0), (9.0, 20), (15.0, 40), (-7.0, 30)])
def test_tension_is_eq18(model, speed, tilt_deg):
    """Eq. 18 is the tension of the zero-offset nominal (theta = chi = 0): checked with
    ``attitude_offsets = "zero"`` (at 15 m/s, 40 deg the paper config adds offsets)."""
    from gainsched.model.reduced import Model

    model = Model(model.config.with_values({"feasibility.attitude_offsets": "zero"}))
    alpha = np.deg2rad(tilt_deg)
    nom = circle_nominal(model, speed, alpha, 48)
    expected = eq18(model, nom.z[:, 3], nom.z[:, 1], alpha)
    np.testing.assert_allclose(nom.tension, expected, rtol=1e-12, atol=0)
    from_model = model.evaluate(nom.z, nom.u, alpha).tension
    np.testing.assert_allclose(from_model, expected, rtol=1e-9, atol=0)


def test_tether_carries_more_than_13_g_at_15_m_s(model, paper_config):
    """Paper headline: at 15 m/s on the horizontal circle the tether carries more than
    13 g (the model's tension, not the arithmetic v^2 / r)."""
    nom = circle_nominal(model, 15.0, 0.0, 12)
    assert np.all(nom.reasons == 0)
    tension = model.evaluate(nom.z, nom.u, 0.0).tension
    assert tension.min() > 13 * model.m * paper_config.g


@pytest.mark.parametrize("tilt_deg", [0, 20, 40])
def test_min_taut_speed_is_eq19(model, paper_config, tilt_deg):
    alpha = np.deg2rad(tilt_deg)
    f_min = paper_config.feasibility.min_tension
    v = min_taut_speed(paper_config, alpha)
    assert v == pytest.approx(
        np.sqrt(model.r * (f_min / model.m + model.g * np.sin(alpha))), rel=1e-15
    )
    n = 72  # a multiple of 4: xi = pi/2 (lowest tension) is sampled
    nom = circle_nominal(model, v, alpha, n)
    assert nom.tension.min() == pytest.approx(f_min, abs=1e-9)
    assert np.any(circle_nominal(model, v * (1 - 1e-6), alpha, n).reasons & SLACK)
    assert not np.any(circle_nominal(model, v * (1 + 1e-6), alpha, n).reasons & SLACK)


# ----------------------------------------------------------- (6) the reference vehicle's numbers


def test_design_expectations_tilt_0(model):
    for speed in np.arange(3.0, 15.5, 1.0):
        nom = circle_nominal(model, speed, 0.0, 36)
        assert np.all(nom.reasons == 0), speed
        assert 1.2 <= nom.u.min() and nom.u.max() <= 1.65, speed
        assert 2.8 <= nom.tension.min() and nom.tension.max() <= 70.5, speed
    assert circle_nominal(model, 3.0, 0.0, 36).tension.min() == pytest.approx(2.8125, rel=1e-12)
    assert circle_nominal(model, 15.0, 0.0, 36).tension.max() == pytest.approx(70.3125, rel=1e-12)


def test_design_expectations_tilt_40(model):
    """The zero-offset nominal (``attitude_offsets = "zero"``) at 40 deg: slack at 3 m/s,
    a motor below thrust_min at 12-15 m/s (-0.85 N at 15 m/s); tests/schedule/test_offsets.py
    shows the free offsets that fix it."""
    from gainsched.model.reduced import Model

    model = Model(model.config.with_values({"feasibility.attitude_offsets": "zero"}))
    alpha = np.deg2rad(40)
    assert np.any(circle_nominal(model, 3.0, alpha, 360).reasons & SLACK)
    nom = circle_nominal(model, 15.0, alpha, 360)
    assert nom.u.min() == pytest.approx(-0.85, abs=0.02)
    assert np.any(nom.reasons & THRUST_LOW)
    assert not np.any(nom.reasons & SLACK)
    for speed in (12.0, 13.0, 14.0):
        assert circle_nominal(model, speed, alpha, 360).u.min() < 0.1


# --------------------------------------------------------------------------- (7) CLI

CSV_HEADER = ["xi_deg", "roll_deg", "T_C_N", "T1_N", "T2_N", "T3_N", "T4_N", "tension_N",
              "g_load", "feasibility"]


def test_cli_nominal_csv(model, paper_path, tmp_path):
    out = tmp_path / "out.csv"
    args = ["nominal", str(paper_path), "--speed", "10", "--tilt", "20", "--csv", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    with out.open(newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == CSV_HEADER
    data = np.array([[float(x) for x in row[:-1]] for row in rows[1:]])
    assert data.shape == (12, 9)  # default --samples 12
    xi = np.deg2rad(data[:, 0])
    expected = eq18(model, 10.0 / model.r, xi, np.deg2rad(20))
    np.testing.assert_allclose(data[:, 7], expected, rtol=1e-8)  # CSV has 9 significant digits
    np.testing.assert_allclose(data[:, 3:7].sum(1), data[:, 2], rtol=1e-8)
    assert all(row[-1] == "ok" for row in rows[1:])


def test_cli_nominal_rejects_zero_speed(paper_path):
    result = CliRunner().invoke(cli, ["nominal", str(paper_path), "--speed", "0"])
    assert result.exit_code == 2
    err = result.stderr.strip().splitlines()
    assert len(err) == 1 and "--speed" in err[0], result.stderr
    assert "Traceback" not in result.stderr + result.stdout
