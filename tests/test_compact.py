"""The compact table form (gainsched/firmware/compact.py): the Fourier fit against closed
forms, the float32 lookup against an independent float64 evaluation and the dense
lookup's statuses, the symmetry maps, gs_sincosf's replica against libm, and the
certification on the paper table (gains solved directly at the cell midpoints)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_runtime import PAPER_H5, query_mix, synthetic_table

from gainsched.constants import MASK_NO_GAINS
from gainsched.errors import InputError
from gainsched.firmware.check import midpoint_check
from gainsched.firmware.compact import (
    CompactInterpolator,
    compact_data,
    fit_harmonics,
    sincos_f32,
)
from gainsched.firmware.runtime import (
    F32,
    PI_F,
    Interpolator,
    fundamental_domain,
    runtime_data,
)
from gainsched.schedule.tables import load_table


def _series64(coef, xi):
    """A value's Fourier series in float64, straight from the definition (cos and sin of
    k xi by numpy): ``coef`` (2 H + 1,) = mean, cos 1, sin 1, ..."""
    k = np.arange(1, (coef.size - 1) // 2 + 1)
    return coef[0] + np.cos(np.outer(xi, k)) @ coef[1::2] + np.sin(np.outer(xi, k)) @ coef[2::2]


def smooth_table(n_xi=16, seed=1, harmonics=3):
    """:func:`synthetic_table`'s grid and infeasible points with gains, thrusts and roll
    that are random trigonometric polynomials of degree ``harmonics`` in the azimuth (the
    level circle's gains constant), so that a series holds them exactly."""
    t = synthetic_table(n_xi=n_xi, seed=seed)
    rng = np.random.default_rng(seed)
    k = np.arange(1, harmonics + 1)
    basis = np.concatenate([np.ones((n_xi, 1)), np.cos(np.outer(t.xi, k)),
                            np.sin(np.outer(t.xi, k))], axis=1)  # (n_xi, 2 H + 1)
    decay = 1.0 / (1.0 + np.r_[0, k, k]) ** 2  # smaller higher harmonics

    def poly(*shape):
        return rng.normal(size=shape + (basis.shape[1],)) * decay

    n_a, n_v = t.reasons.shape[:2]
    n = t.K.shape[-1]
    K = np.einsum("avrsj,xj->avxrs", poly(n_a - 1, n_v, 4, n), basis)
    K = np.where(np.isnan(t.K), np.nan, K)
    u_d = 1.5 + 0.3 * np.einsum("avrj,xj->avxr", poly(n_a, n_v, 4), basis)
    phi_d = 0.3 * np.einsum("avj,xj->avx", poly(n_a, n_v), basis)
    return dataclasses.replace(t, K=K, u_d=u_d, phi_d=phi_d)


@pytest.fixture(scope="module")
def paper():
    table = load_table(PAPER_H5)
    return table, runtime_data(table), compact_data(runtime_data(table))


# --------------------------------------------------------------------------- sin, cos


def test_sincos_replica_is_within_its_bound_of_libm():
    """gs_sincosf's Python replica against numpy's float64 sin and cos on |x| <= 1e4: the
    stated bound 1.5e-7 (docs/runtime.md; measured 8.8e-8) holds, and at 0 and -0 the
    values are exact."""
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-1e4, 1e4, 200_000), rng.uniform(-7, 7, 200_000),
                        np.arange(-64, 65) * np.pi / 4]).astype(np.float32)
    s, c = sincos_f32(x)
    assert s.dtype == c.dtype == np.float32
    xd = x.astype(np.float64)
    assert np.abs(s - np.sin(xd)).max() <= 1.5e-7
    assert np.abs(c - np.cos(xd)).max() <= 1.5e-7
    s0, c0 = sincos_f32(np.array([0.0, -0.0], dtype=np.float32))
    assert c0.tolist() == [1.0, 1.0] and s0.tolist() == [0.0, 0.0]
    assert not np.any(np.signbit(s0))  # as gs_sincosf: -0 < 0 is false, sin(-0) = +0


# --------------------------------------------------------------------------- the fit


def test_fit_recovers_a_trigonometric_polynomial_exactly():
    """Samples of a degree-3 trigonometric polynomial: the DFT gives its coefficients to
    rounding, every value takes at most 3 harmonics, and a constant takes none."""
    rng = np.random.default_rng(2)
    n, N = 2, 16
    coef = rng.normal(size=(7, 3, 4 * n + 5)) / np.array([1, 2, 2, 4, 4, 8, 8])[:, None, None]
    coef[1:, 0, :] = 0.0  # circle 0: constant in the azimuth
    xi = 2 * np.pi * np.arange(N) / N
    f = np.stack([np.stack([_series64(coef[:, c, e], xi) for e in range(coef.shape[-1])], -1)
                  for c in range(3)], 1)
    H, got, err = fit_harmonics(f, n, 1e-9)
    assert H.max() <= 3 and np.all(H[0] == 0)
    np.testing.assert_allclose(got[:7], coef, atol=1e-12)
    assert np.all(err <= 1e-9)


def test_fit_meets_the_bound_with_the_fewest_harmonics_for_thrust_and_roll(paper):
    """On the paper table: every feasible circle meets the bound at its azimuth samples
    (an independent float64 evaluation of the stored float32 series), and a thrust or
    roll series with one harmonic fewer would not (their counts are each the fewest)."""
    table, d, c = paper
    n_a, n_v, n_xi, n = d.dims
    nk = 4 * n
    xi = d.xi.astype(np.float64)
    vals = np.concatenate([Interpolator(d)._K.reshape(n_a, n_v, n_xi, nk),
                           d.u_d.reshape(n_a, n_v, n_xi, 4).astype(float),
                           d.phi_d.reshape(n_a, n_v, n_xi, 1).astype(float)], -1)
    checked = 0
    for i in range(n_a):
        for j in range(n_v):
            series = c.series(i, j)
            if not series:
                assert c.mask[i, j] & MASK_NO_GAINS
                continue
            f = vals[i, j]
            fit = np.stack([_series64(s.astype(np.float64), xi) for s in series], -1)
            eK = np.linalg.norm(fit[:, :nk] - f[:, :nk], axis=1) / np.linalg.norm(f[:, :nk], axis=1)
            assert eK.max() <= c.bound * 1.001, (i, j)
            u_scale = np.abs(f[:, nk:nk + 4]).max()
            for e in range(nk, nk + 5):
                scale = u_scale if e < nk + 4 else max(np.abs(f[:, -1]).max(), 0.01)
                assert np.abs(fit[:, e] - f[:, e]).max() <= c.bound * scale * 1.001
                h = int(c.harmonics[i, j, e])
                if h:
                    fewer = _series64(series[e][:2 * h - 1].astype(np.float64), xi)
                    assert np.abs(fewer - f[:, e]).max() > c.bound * scale * 0.999, (i, j, e)
            checked += 1
    assert checked == int(np.count_nonzero(~(c.mask & MASK_NO_GAINS).astype(bool))) == 113


def test_compact_form_layout_and_size(paper):
    """Level circles of the paper table hold one coefficient per value, infeasible circles
    none; the coefficient count is what the harmonics say; the whole form is under
    160 KiB where the dense one is 815 KiB; building it twice gives the same bytes."""
    table, d, c = paper
    n_value = c.n_value
    assert n_value == 4 * 11 + 5
    good = ~(c.mask & MASK_NO_GAINS).astype(bool)
    assert np.all(c.harmonics[0][good[0]] == 0)
    assert np.all(c.harmonics[~good] == 0)
    assert c.coef.size == int((2 * c.harmonics[good].astype(int) + 1).sum())
    assert c.nbytes() <= 160 * 1024 < d.nbytes() // 5
    again = compact_data(runtime_data(table))
    assert again.coef.tobytes() == c.coef.tobytes()
    assert again.harmonics.tobytes() == c.harmonics.tobytes()


# --------------------------------------------------------------------------- the lookup


def test_lookup_equals_a_float64_evaluation_of_the_series(paper):
    """The float32 lookup against the series evaluated in float64 from the definition,
    weighted bilinearly over the four circles of the cell, at random interior queries:
    equal to 1e-5 of the gain norm (float32 rounding of the recurrence and the sums)."""
    table, d, c = paper
    look = CompactInterpolator(c)
    rng = np.random.default_rng(3)
    r = float(table.attrs["radius_m"])
    j = rng.integers(3, d.dims[1] - 1, 200)
    i = rng.integers(0, 3, 200)
    fv, fa = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)
    v = (d.speed[j] + fv * (d.speed[j + 1] - d.speed[j])) / r
    a = d.tilt[i] + fa * (d.tilt[i + 1] - d.tilt[i])
    x = rng.uniform(-7, 7, 200)
    out = look(x, v, a)
    assert np.all(out.status == 0)
    n = d.dims[3]
    for q in range(200):
        # the azimuth and the cell's fractions as the runtime computes them (float32)
        dom = fundamental_domain(d, x[q], v[q], a[q])
        x32 = float(dom.xi[0])
        (i0, i1, wa), (k0, k1, wv) = dom.tilt_cell, dom.speed_cell
        wa, wv = float(wa[0]), float(wv[0])
        ref = np.zeros(c.n_value)
        for ii, jj, w in ((i0, k0, (1 - wa) * (1 - wv)), (i0, k1, (1 - wa) * wv),
                          (i1, k0, wa * (1 - wv)), (i1, k1, wa * wv)):
            ref += w * np.array([_series64(s.astype(np.float64), np.array([x32]))[0]
                                 for s in c.series(int(ii[0]), int(jj[0]))])
        K = ref[:4 * n].reshape(4, n)
        scale = np.linalg.norm(K)
        assert np.abs(out.K[q] - K).max() <= 1e-5 * scale
        assert np.abs(out.u_d[q] - ref[4 * n:4 * n + 4]).max() <= 1e-5 * np.abs(ref[4 * n:]).max()
        assert abs(out.phi_d[q] - ref[-1]) <= 1e-6


def test_statuses_are_the_dense_lookups_and_values_agree(paper):
    """On the query families of the C runtime's tests (interior, both symmetry maps,
    edges, snap bands, clamps, infeasible points, NaN/inf and limits), the compact
    lookup's statuses equal the dense lookup's (the paper table has no partly feasible
    circle), outputs are zero where unusable, and the gains agree with the dense table
    within 1.5 % of the gain norm (azimuth interpolation error of either form)."""
    table, d, c = paper
    x, v, a = query_mix(d, 40_000, seed=4)
    ref, got = Interpolator(d)(x, v, a), CompactInterpolator(c)(x, v, a)
    np.testing.assert_array_equal(got.status, ref.status)
    dead = (got.status & 0x38) != 0
    assert np.all(got.K[dead] == 0) and np.all(got.u_d[dead] == 0) and np.all(got.phi_d[dead] == 0)
    live = ~dead
    nrm = np.linalg.norm(ref.K[live], axis=(1, 2))
    rel = np.linalg.norm(got.K[live] - ref.K[live], axis=(1, 2)) / nrm
    assert rel.max() <= 0.015


def test_symmetry_maps_are_exact(paper):
    """S2 and S1 in the compact lookup, bit for bit: the reversed direction is the
    mirrored lookup at ``pi - xi`` mapped back (``K -> P_u K P_x``), and a negative tilt
    is the positive one at ``xi + pi`` (float32 arithmetic as the runtime's)."""
    table, d, c = paper
    look = CompactInterpolator(c)
    rng = np.random.default_rng(5)
    x = rng.uniform(-3, 3, 500).astype(np.float32)
    v = F32(9.0 / float(table.attrs["radius_m"]))
    a = F32(np.deg2rad(23.0))
    neg = look(x, -v, a)
    pos = look((PI_F - x).astype(np.float32), v, a)
    P = np.zeros((d.dims[3],) * 2)
    P[d.state_perm, np.arange(d.dims[3])] = d.state_sign
    np.testing.assert_array_equal(neg.K, pos.K[:, ::-1, :] @ P)
    np.testing.assert_array_equal(neg.u_d, pos.u_d[:, ::-1])
    np.testing.assert_array_equal(neg.phi_d, -pos.phi_d)
    tilted = look(x, v, -a)
    shifted = look((x + PI_F).astype(np.float32), v, a)
    np.testing.assert_array_equal(tilted.K, shifted.K)


def test_a_smooth_table_is_held_exactly_and_partly_feasible_circles_have_no_gains():
    """A synthetic table whose values are degree-3 trigonometric polynomials: the compact
    lookup returns them at any azimuth (float32 rounding); a circle with an azimuth
    without gains has none at all in the compact form, and its flagged-but-usable
    azimuths' reason bits become the whole circle's."""
    t = smooth_table()
    d = runtime_data(t)
    c = compact_data(d, 1e-6)
    assert c.harmonics.max() == 3
    look = CompactInterpolator(c)
    n_a, n_v, n_xi, n = d.dims
    assert c.mask[2, 3] & MASK_NO_GAINS  # no gains at all (synthetic_table)
    assert c.mask[1, 1] == 2 and not c.mask[1, 1] & MASK_NO_GAINS  # flagged at one azimuth
    x = np.linspace(0, 2 * np.pi, 7)
    got = look(x, t.xi_dot[2], t.tilt[2])  # a grid circle with gains, between samples
    i, j = 2, 2
    want = np.stack([_series64(s.astype(np.float64), x.astype(np.float32).astype(float))
                     for s in c.series(i, j)], -1)
    np.testing.assert_allclose(got.K.reshape(7, -1), want[:, :4 * n], atol=1e-5)
    # the fitted series reproduce the table at its samples
    samples = Interpolator(d)(d.xi, t.xi_dot[2], t.tilt[2])
    np.testing.assert_allclose(look(d.xi, t.xi_dot[2], t.tilt[2]).K, samples.K, atol=2e-5)


def test_a_circle_no_series_fits_is_refused_naming_it():
    """Values that alternate from one azimuth sample to the next (all their energy at the
    Nyquist frequency) cannot be held by a series below it: one line naming the circle
    and what to change."""
    t = smooth_table()
    K = t.K.copy()
    K[0, 1] += 3.0 * (-1.0) ** np.arange(t.xi.size)[:, None, None]
    with pytest.raises(InputError) as exc:
        compact_data(runtime_data(dataclasses.replace(t, K=K)), 0.005)
    msg = str(exc.value)
    assert "firmware.azimuth_error" in msg and "speed 3.5 m/s, tilt 12 deg" in msg
    assert "raise grid.azimuth_samples" in msg


# --------------------------------------------------------------------------- certified


def test_compact_paper_table_is_certified_at_the_cell_midpoints(paper):
    """Gains solved directly at the cell midpoints (every third speed midpoint, all tilt
    and azimuth midpoints): the compact table's largest error is no worse than the dense
    table's at the same points, and the loop closed with its gains along every midpoint
    circle is stable, its worst spectral radius within 1e-3 of the directly solved
    gains' worst."""
    table, d, c = paper
    dense = midpoint_check(table, speed_stride=3)
    comp = midpoint_check(table, speed_stride=3, lookup=CompactInterpolator(c))
    assert comp.skipped == dense.skipped
    assert comp.max_err <= dense.max_err
    assert comp.worst_rho < 1
    worst_direct = max(x[3] for x in comp.circles if np.isfinite(x[2]))
    assert abs(comp.worst_rho - worst_direct) < 1e-3


def test_check_command_certifies_the_compact_form():
    """``gainsched check TABLE --compact 0.5`` prints the compact form's size against the
    dense one and checks it at the midpoints; a bound no series meets at the samples of
    a circle is one line naming it, exit code 2."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    r = CliRunner().invoke(cli, ["check", str(PAPER_H5), "--speed-stride", "6", "--compact",
                                 "0.5"])
    assert r.exit_code == 0, r.output
    assert "compact form at 0.5% on the azimuth samples: 135,121 bytes of table data (dense " \
           "834,147)" in r.output
    assert "PASS" in r.output
    bad = CliRunner().invoke(cli, ["check", str(PAPER_H5), "--compact", "1e-9"])
    assert bad.exit_code == 2
    assert f"{PAPER_H5}: --compact: 1e-09 % not met at speed" in bad.output
    assert "Traceback" not in bad.output
