"""The compact table form (gainsched/firmware/compact.py): the Fourier fit against closed
forms, the float32 lookup against an independent float64 evaluation and the dense
lookup's statuses, the symmetry maps, gs_sincosf's replica against libm, and the
certification on the paper table (gains solved directly at the cell midpoints)."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from gainsched.constants import MASK_NO_GAINS
from gainsched.errors import InputError
from gainsched.firmware import runtime
from gainsched.firmware.compact import (
    NOMINAL_SHARE,
    CompactInterpolator,
    compact_data,
    fit_harmonics,
    sincos_f32,
)
from gainsched.firmware.header import render_header
from gainsched.firmware.host.check import midpoint_check
from gainsched.firmware.host.lookup import CRuntime, build_host
from gainsched.firmware.runtime import (
    F32,
    PI_F,
    Interpolator,
    fundamental_domain,
    runtime_data,
)
from gainsched.schedule.tables import load_table

from support import PAPER_H5, PAPER_TOML, query_mix, small_config_text, synthetic_table


def _series64(coef, xi):
    """A value's Fourier series in float64, straight from the definition (cos and sin of
    k xi by numpy): ``coef`` (2 H + 1,) = mean, cos 1, sin 1, ..."""
    k = np.arange(1, (coef.size - 1) // 2 + 1)
    return coef[0] + np.cos(np.outer(xi, k)) @ coef[1::2] + np.sin(np.outer(xi, k)) @ coef[2::2]


def smooth_table(n_xi=16, seed=1, harmonics=3, **kw):
    """:func:`synthetic_table`'s grid and infeasible points with gains, thrusts and roll
    that are random trigonometric polynomials of degree ``harmonics`` in the azimuth (the
    level circle's gains constant), so that a series holds them exactly."""
    t = synthetic_table(n_xi=n_xi, seed=seed, **kw)
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
    K0 = t.K_tilt0
    if K0.ndim == 4:  # level-circle gains per azimuth: smooth too
        K0 = np.where(np.isnan(K0), np.nan, np.einsum("vrsj,xj->vxrs", poly(n_v, 4, n), basis))
    return dataclasses.replace(t, K_tilt0=K0, K=K, u_d=u_d, phi_d=phi_d)


@pytest.fixture(scope="module")
def paper(paper_table):
    """The paper table, its dense runtime form and its compact form."""
    return paper_table, runtime_data(paper_table), compact_data(runtime_data(paper_table))


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
    (an independent float64 evaluation of the stored float32 series; the nominal thrusts
    and roll a quarter of it), and a thrust or roll series with one harmonic fewer would
    not (their counts are each the fewest)."""
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
            u_scale = np.abs(f[:, nk:nk + 4]).max() * NOMINAL_SHARE
            for e in range(nk, nk + 5):
                scale = u_scale if e < nk + 4 else max(np.abs(f[:, -1]).max(), 0.01) * \
                    NOMINAL_SHARE
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
    within 2.5 % of the gain norm (each is within about 1.2 % of directly solved gains
    along the azimuth: docs/runtime.md)."""
    table, d, c = paper
    x, v, a = query_mix(d, 40_000, seed=4)
    ref, got = Interpolator(d)(x, v, a), CompactInterpolator(c)(x, v, a)
    np.testing.assert_array_equal(got.status, ref.status)
    dead = (got.status & 0x38) != 0
    assert np.all(got.K[dead] == 0) and np.all(got.u_d[dead] == 0) and np.all(got.phi_d[dead] == 0)
    live = ~dead
    nrm = np.linalg.norm(ref.K[live], axis=(1, 2))
    rel = np.linalg.norm(got.K[live] - ref.K[live], axis=(1, 2)) / nrm
    assert rel.max() <= 0.025


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


@pytest.mark.slow
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
    worst_direct = max(x.rho_direct for x in comp.circles if np.isfinite(x.rho_interp))
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
    assert "compact form at 0.5% on the azimuth samples: 139,065 bytes of table data (dense " \
           "834,147)" in r.output
    assert "PASS" in r.output
    bad = CliRunner().invoke(cli, ["check", str(PAPER_H5), "--compact", "1e-9"])
    assert bad.exit_code == 2
    assert f"{PAPER_H5}: --compact: 1e-09 % not met at speed" in bad.output
    assert "Traceback" not in bad.output


# --------------------------------------------------------------------------- the C runtime

#: compact tables the C runtime is held to its reference on: the paper's, and smooth
#: synthetic ones with effect states (motor lag: the S2 map permutes columns), an
#: along-track integral, and level-circle gains per azimuth
COMPACT_TABLES = {
    "paper": lambda: load_table(PAPER_H5),
    "smooth_lag": lambda: smooth_table(name="smooth_lag", motor_lag=True, seed=3),
    "smooth_int": lambda: smooth_table(name="smooth_int", azimuth_integral=True, seed=4),
    "smooth_xi0": lambda: smooth_table(name="smooth_xi0", tilt0_per_azimuth=True, seed=5),
}


@pytest.fixture(scope="module", params=list(COMPACT_TABLES))
def compiled(request, tmp_path_factory):
    """(CompactData, CompactInterpolator, CRuntime) per table (its tests are marked
    ``needs_cc``)."""
    data = compact_data(runtime_data(COMPACT_TABLES[request.param]()))
    lib = build_host(data, tmp_path_factory.mktemp(request.param))
    return data, CompactInterpolator(data), CRuntime(lib, data)


def _same_bits(a, b):
    """Every output of two lookups bit for bit (float32), and the statuses."""
    for x, y in ((a.K, b.K), (a.u_d, b.u_d), (a.phi_d, b.phi_d)):
        x32, y32 = np.asarray(x, np.float32), np.asarray(y, np.float32)
        assert x32.tobytes() == y32.tobytes(), np.flatnonzero((x32 != y32).reshape(len(x32), -1)
                                                              .any(1))[:5]
    np.testing.assert_array_equal(np.asarray(a.status, np.int32), np.asarray(b.status, np.int32))


@pytest.mark.slow
@pytest.mark.needs_cc
def test_c_runtime_equals_the_reference_bit_for_bit(compiled):
    """gs_lookup on a compact table against CompactInterpolator: every output and status
    identical, bit for bit, on the runtime tests' query families (interior, both
    symmetry maps, edges, snap bands, clamps, infeasible points, NaN/inf, limits); 1 M
    queries on the paper table. The queries cover every symmetry branch and status."""
    data, ref, c = compiled
    m = 1_000_000 if data.name == "paper" else 60_000
    x, v, a = query_mix(data.base, m, seed=11)
    r_py, r_c = ref(x, v, a), c(x, v, a)
    _same_bits(r_py, r_c)
    for bit in (runtime.CLAMPED_SPEED, runtime.CLAMPED_TILT, runtime.BAD_INPUT,
                runtime.INFEASIBLE, runtime.NO_GAINS):
        assert np.count_nonzero(r_py.status & bit) > 50, hex(bit)
    assert np.count_nonzero(r_py.status == 0) > m // 10


#: the index of each compact array in the batch shim's ``verify_flipped``
FLIPPABLE = {"xi": 0, "speed": 1, "xi_dot": 2, "tilt": 3, "state_sign": 8, "state_perm": 9,
             "mask": 10, "vehicle": 11, "offsets": 12, "harmonics": 13, "coef_start": 14,
             "coef": 15}


@pytest.mark.needs_cc
def test_crc_and_verify_catch_every_flipped_byte(compiled):
    """The C runtime's CRC-32 of a compact table is zlib's of the documented chunks,
    gs_verify accepts it, and refuses it with one bit flipped at the start, middle or
    end of any array."""
    data, _, c = compiled
    assert c.crc32() == data.crc32() == zlib_crc(data)
    assert c.verify() == runtime.OK
    for label, chunk in data.crc_chunks():
        if label not in FLIPPABLE:
            continue
        for byte in {0, len(chunk) // 2, len(chunk) - 1}:
            for flip in (0x01, 0x80):
                assert c.verify_flipped(FLIPPABLE[label], byte, flip) == runtime.BAD_TABLE, (
                    label, byte, flip)


def zlib_crc(data) -> int:
    """CRC-32 of the compact chunks, written out from the documented order
    (docs/runtime.md): dims, xi_scale, format, n_harmonics, n_coef, the axes, the state
    map, mask, harmonics, coef_start, coef, vehicle, offsets."""
    import zlib

    b = data.base
    u32 = lambda *v: np.array(v, dtype="<u4").tobytes()  # noqa: E731
    f32 = lambda x: np.ascontiguousarray(x, dtype="<f4").tobytes()  # noqa: E731
    blob = (u32(*b.dims) + f32([b.xi_scale]) + u32(1, data.n_harmonics, data.coef.size)
            + f32(b.xi) + f32(b.speed) + f32(b.xi_dot) + f32(b.tilt) + f32(b.state_sign)
            + b.state_perm.tobytes() + data.mask.tobytes() + data.harmonics.tobytes()
            + data.start.astype("<u4").tobytes() + f32(data.coef))
    if b.vehicle is not None:
        blob += f32(b.vehicle)
    if b.offsets is not None:
        blob += u32((b.offsets.shape[-1] - 1) // 2) + f32(b.offsets)
    return zlib.crc32(blob)


@pytest.mark.slow
@pytest.mark.needs_cc
@pytest.mark.parametrize("fmt", ["dense", "compact"])
def test_dialect_optimisation_and_contraction_do_not_change_the_bits(fmt, tmp_path):
    """The runtime turns contraction off itself: built as firmware is (-std=gnu11 -O3 for
    this CPU, where GCC would fuse multiply-adds; -Os), both formats return the bits of
    the strict -std=c99 -O2 build on 100 k mixed queries."""
    d = runtime_data(load_table(PAPER_H5))
    data = d if fmt == "dense" else compact_data(d)
    x, v, a = query_mix(d, 100_000, seed=12)
    base = CRuntime(build_host(data, tmp_path / "c99"), data)(x, v, a)
    for name, extra in (("gnu11", ("-std=gnu11", "-march=native", "-O3")), ("os", ("-Os",))):
        rt = CRuntime(build_host(data, tmp_path / name, extra=extra), data)
        _same_bits(rt(x, v, a), base)


# --------------------------------------------------------------------------- build, config


#: a coarse grid (its cells interpolate to about 3 %: the bound is raised to 5 %)
SMALL = {"grid.speeds": [6, 8, 10], "grid.tilts_deg": [0, 10, 20], "grid.azimuth_samples": 16,
         "grid.max_interpolation_error": 5.0}


def _small_config(tmp_path, name, extra="", **values):
    """The paper config on a 3 x 3 grid, as a file, with ``values`` set (dotted keys) and
    ``extra`` TOML appended."""
    text = small_config_text(**{**SMALL, "name": name, **values})
    path = tmp_path / f"{name}.toml"
    path.write_text(text + extra)
    return path


def test_firmware_config_keys_are_validated(tmp_path):
    """[firmware] format, azimuth_error (percent), max_table_bytes and
    grid.max_interpolation_error (percent): defaults, values, and one-line errors naming
    the key."""
    import gainsched as gs

    cfg = gs.load_config(_small_config(tmp_path, "k0"))
    assert (cfg.firmware.format, cfg.firmware.azimuth_error, cfg.firmware.max_table_bytes,
            cfg.grid.max_interpolation_error) == ("dense", 0.01, None, 0.05)
    cfg = gs.load_config(_small_config(tmp_path, "k1", '\n[firmware]\nformat = "compact"\n'
                                       'azimuth_error = 1.0\nmax_table_bytes = 200000\n'))
    assert (cfg.firmware.format, cfg.firmware.azimuth_error, cfg.firmware.max_table_bytes) == (
        "compact", 0.01, 200000)
    for extra, key in (('format = "sparse"', "firmware.format"),
                       ("azimuth_error = 0", "firmware.azimuth_error"),
                       ("azimuth_error = 120", "firmware.azimuth_error"),
                       ("max_table_bytes = 1.5", "firmware.max_table_bytes"),
                       ("colour = 1", "firmware.colour")):
        with pytest.raises(InputError, match=key.replace(".", r"\.")):
            gs.load_config(_small_config(tmp_path, "k2", f"\n[firmware]\n{extra}\n"))


def _build(tmp_path, name, extra="", **values):
    from click.testing import CliRunner

    from gainsched.cli import cli

    out = tmp_path / f"out_{name}"
    r = CliRunner().invoke(cli, ["build", str(_small_config(tmp_path, name, extra, **values)),
                                 "-o", str(out)])
    return r, out


def test_build_writes_a_certified_compact_header(tmp_path):
    """``format = "compact"``: the build prints the form's size against the dense one and
    its certificate (gain error at the cell midpoints, closed loops with the table's
    gains); the header is the compact form of the table it writes, byte for byte, and the
    HDF5 table is the dense build's."""
    r, out = _build(tmp_path, "cmp", '\n[firmware]\nformat = "compact"\n')
    assert r.exit_code == 0, r.output
    assert "firmware table: compact, " in r.output and "(dense: " in r.output
    assert "certified at " in r.output and "closed loop at " in r.output
    table = load_table(out / "cmp.h5")
    form = compact_data(runtime_data(table))
    header = (out / "cmp_gains.h").read_text()
    assert header == render_header(form)
    assert "#define CMP_FORMAT GS_FORMAT_COMPACT" in header
    chk = midpoint_check(table, lookup=CompactInterpolator(form))
    assert f"max gain error {100 * chk.max_err:.2f} %" in r.output
    r2, out2 = _build(tmp_path, "cmp2")  # dense: same table data
    assert r2.exit_code == 0 and "firmware table: dense" in r2.output
    t2 = load_table(out2 / "cmp2.h5")
    np.testing.assert_array_equal(t2.K, table.K)


@pytest.mark.parametrize("extra,values,key", [
    ('\n[firmware]\nformat = "compact"\n', {"grid.max_interpolation_error": 0.01},
     "grid.max_interpolation_error"),
    ('\n[firmware]\nmax_table_bytes = 1000\n', {}, "firmware.max_table_bytes"),
])
def test_a_bound_the_firmware_table_misses_stops_the_build(tmp_path, extra, values, key):
    """A compact table whose certificate misses grid.max_interpolation_error (0.01 % here)
    and a table over the flash budget: one line naming the config and the key, exit code
    2, nothing published."""
    r, out = _build(tmp_path, "bad", extra, **values)
    assert r.exit_code == 2, r.output
    assert f"bad.toml: {key}: " in r.output and "Traceback" not in r.output
    assert len(r.output.strip().splitlines()) == 1
    assert not out.exists() or not any(out.glob("bad*"))
    if key == "firmware.max_table_bytes":  # the way out, with its size (issue 59)
        size = re.search(r'format = "compact" holds ([0-9,]+) bytes', r.output)
        assert size and 1000 < int(size.group(1).replace(",", "")) < int(re.search(
            r"the dense table holds ([0-9,]+) bytes", r.output).group(1).replace(",", ""))


def test_a_table_over_the_default_flash_builds_and_says_so(tmp_path, monkeypatch):
    """No budget in the config: a table over DEFAULT_FLASH_BYTES (1 MiB; here lowered to
    the small table's scale) is built, and one warning line names the key, the size and
    the compact format's size; under it, no warning."""
    from gainsched.firmware import outputs

    r, _ = _build(tmp_path, "under")
    assert r.exit_code == 0 and "warning" not in r.output, r.output
    monkeypatch.setattr(outputs, "DEFAULT_FLASH_BYTES", 1000)
    r, out = _build(tmp_path, "over")
    assert r.exit_code == 0, r.output
    warned = [ln for ln in r.output.splitlines() if ln.startswith("gainsched: warning:")]
    assert len(warned) == 1 and "over.toml: firmware.max_table_bytes: the dense table " \
        "holds" in warned[0] and "more than 1,000 bytes" in warned[0], r.output
    assert 'format = "compact" holds' in warned[0]
    assert (out / "over.h5").exists()


def test_export_c_and_check_follow_the_tables_format(tmp_path):
    """``export-c --format compact`` writes the certified compact header (the dense one by
    default for a dense config); ``check`` on a table built compact checks the compact
    form without being asked."""
    from click.testing import CliRunner

    from gainsched.cli import cli

    r, out = _build(tmp_path, "ex", '\n[firmware]\nformat = "compact"\n')
    assert r.exit_code == 0, r.output
    chk = CliRunner().invoke(cli, ["check", str(out / "ex.h5")])
    assert chk.exit_code == 0 and "compact form at 1% on the azimuth samples" in chk.output
    dense = CliRunner().invoke(cli, ["export-c", str(out / "ex.h5"), "-o", str(tmp_path / "d"),
                                     "--format", "dense", "--no-code-size"])
    assert dense.exit_code == 0 and "ex: dense, CRC-32" in dense.output
    assert "GS_FORMAT_DENSE" in (tmp_path / "d/ex_gains.h").read_text()
    comp = CliRunner().invoke(cli, ["export-c", str(out / "ex.h5"), "-o", str(tmp_path / "c"),
                                    "--no-code-size"])
    assert comp.exit_code == 0 and "ex: compact, CRC-32" in comp.output
    assert (tmp_path / "c/ex_gains.h").read_text() == (out / "ex_gains.h").read_text()


# --------------------------------------------------------------------------- in closed loop


@pytest.mark.slow
@pytest.mark.parametrize("tilt_deg", [0.0, 20.0, 40.0])
def test_the_simulator_flies_compact_tables_as_dense_ones(paper, tilt_deg):
    """The standard circles (horizontal scenario: motion-capture noise 0.5 mm / 0.2 deg,
    started 0.01 rad off) at 6, 9 and 15 m/s flown with the compact table's gains: the
    out-of-plane RMS within 10 % of the dense table's (measured within 0.4 %)."""
    import gainsched as gs

    table, d, c = paper
    cfg = gs.load_config(PAPER_TOML)
    base = gs.load_scenario("horizontal")
    for v in (6.0, 9.0, 15.0):
        scn = dataclasses.replace(base, tilt=np.deg2rad(tilt_deg), speed=v, duration=6.0)
        rms = [gs.metrics(gs.simulate(cfg, gs.table_scheduler(tab), scn))["rms_out_of_plane_m"]
               for tab in (d, c)]
        assert rms[1] == pytest.approx(rms[0], rel=0.10), (v, rms)


@pytest.mark.slow
@pytest.mark.needs_cc
@pytest.mark.parametrize("fmt", ["dense", "compact"])
def test_flush_to_zero_does_not_change_the_bits(fmt, tmp_path):
    """A firmware may run with flush-to-zero (FPSCR.FZ = 1; on this host MXCSR FTZ + DAZ):
    the runtime's sign tests read the sign bit, so a negative subnormal tilt or azimuth
    rate takes its symmetry map either way, and every output of 100 k mixed queries plus
    those is the same bit for bit with the flush on and off. (The queries are float32
    before the switch: numpy's own conversions would flush them too.)"""
    d = runtime_data(load_table(PAPER_H5))
    data = d if fmt == "dense" else compact_data(d)
    rt = CRuntime(build_host(data, tmp_path), data)
    x, v, a = query_mix(d, 100_000, seed=13)
    tiny = -1e-40  # a negative subnormal float32
    # a reversed direction by a subnormal (clamped to the slowest level circle, which has
    # gains: its mirror shows), a subnormal tilt below zero, a subnormal azimuth
    x = np.concatenate([x, [0.3, 0.3, 0.3, tiny]])
    v = np.concatenate([v, [tiny, 5.0, -tiny, 5.0]])
    a = np.concatenate([a, [0.0, tiny, 0.0, 0.2]])
    with np.errstate(over="ignore"):
        x, v, a = (np.asarray(q, dtype=np.float32) for q in (x, v, a))
    assert np.signbit(v[-4]) and v[-4] != 0 and np.abs(v[-4]) < np.finfo(np.float32).tiny
    off = rt(x, v, a)
    assert off.status[-4] == runtime.CLAMPED_SPEED  # gains there: the mirror is visible
    if not rt.flush_to_zero(True):
        pytest.skip("no flush-to-zero switch on this host")
    try:
        on = rt(x, v, a)
    finally:
        rt.flush_to_zero(False)
    _same_bits(on, off)
