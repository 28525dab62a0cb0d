"""Both flight directions in one table, for a vehicle that is not its own mirror image
(issue 53; docs/symmetry.md, "A vehicle that is not its own mirror image").

A centre of mass off the plane of symmetry or unequal motors make the vehicle's S2 mirror
image another vehicle: its reversed circles are its image's forward circles, mirrored.
The build solves the image on the same axes (``GridResult.reverse``), the table holds it
under ``reverse/`` and the runtime reads it for the mirrored queries. Checked against
direct solves of the reversed circles and against the one-direction table, which misses
by the asymmetry; the firmware's C runtime (``gs_table.reverse``) against the Python
reference, ``gs_verify`` of the pair, ``gainsched build`` of such a vehicle and the C
controller flown in the loop.
"""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.errors import InputError
from gainsched.firmware.feedforward import feedforward
from gainsched.firmware.host.check import midpoint_check
from gainsched.firmware.host.lookup import CRuntime, build_host
from gainsched.firmware.runtime import BAD_TABLE, OK, UNUSABLE, Interpolator, runtime_data
from gainsched.schedule.grid import build_grid, mirror_config, solve_circle
from gainsched.schedule.path import circle_path
from gainsched.schedule.refine import refine_grid
from gainsched.schedule.tables import load_table, table_bytes, table_from_bytes
from gainsched.sim.loop import Scenario, c_runtime_scheduler, metrics, simulate, table_scheduler

from support import PAPER_H5, REPO, rechecksum, small_config, small_config_text

#: the COG 3 mm to the side and 2 mm forward, motor 1 at 94 %
ASYMMETRY = {"effects.cog_offset.y": 0.003, "effects.cog_offset.x": 0.002,
             "effects.motor_efficiency.eta1": 0.94}
SPEED, TILT = 9.0, np.deg2rad(20.0)  # a grid circle of the small grid


@pytest.fixture(scope="module")
def asymmetric():
    """The small grid of the asymmetric vehicle: config, grid, the table's bytes and it
    loaded."""
    cfg = small_config(**ASYMMETRY)
    grid = build_grid(cfg)
    data = table_bytes(cfg, grid)
    return cfg, grid, data, table_from_bytes(data, "asymmetric.h5")


def test_the_build_solves_the_mirror_image_for_the_reversed_circles(asymmetric):
    """``GridResult.reverse`` is the grid of the mirror image's config, number for number;
    a symmetric vehicle has none."""
    cfg, grid, _, _ = asymmetric
    image = build_grid(mirror_config(cfg))
    assert grid.reverse is not None and image.reverse is not None  # the image's image
    for f in ("K", "u_d", "phi_d", "tension", "reasons", "spectral_radius"):
        np.testing.assert_array_equal(getattr(grid.reverse, f), getattr(image, f), err_msg=f)
    assert not np.array_equal(grid.reverse.u_d, grid.u_d)
    assert build_grid(small_config()).reverse is None


def test_a_two_direction_table_round_trips_under_its_checksums(asymmetric, tmp_path):
    """The table holds the image's grid under ``reverse/`` (``Table.reverse``, with the
    image's firmware record), the checksums cover it, and a table of a symmetric
    vehicle has no such group."""
    cfg, grid, data, table = asymmetric
    rev = table.reverse
    np.testing.assert_array_equal(rev.K, grid.reverse.K[1:])
    np.testing.assert_array_equal(rev.u_d, grid.reverse.u_d)
    np.testing.assert_array_equal(rev.reasons, grid.reverse.reasons)
    assert rev.reverse is None and rev.xi_dot is table.xi_dot
    assert rev.firmware is not None and rev.source == "asymmetric.h5 (reverse/)"
    path = tmp_path / "edited.h5"
    path.write_bytes(data)
    with h5py.File(path, "r+") as f:
        assert "reverse/gains/K" in f and "reverse/mirror_image" in f
        f["reverse/nominal/u_d"][0, 0, 0, 0] += 0.5
    with pytest.raises(InputError, match=r"reverse/nominal/u_d: checksum mismatch"):
        table_from_bytes(path.read_bytes(), path)
    with h5py.File(path, "r+") as f:  # checksums "repaired": the finiteness check names it
        f["reverse/gains/K"][0, 0, 0, 0, 0] = np.nan
        rechecksum(f)
    with pytest.raises(InputError, match=r"reverse/gains/K\[0, 0, 0\]: non-finite value"):
        table_from_bytes(path.read_bytes(), path)
    symmetric = table_from_bytes(table_bytes(small_config(), build_grid(small_config())))
    assert symmetric.reverse is None


def test_reversed_queries_read_the_mirror_image(asymmetric):
    """At the stored azimuths of a reversed circle the lookup equals the direct solve of
    that circle (float32 data: 1e-5); the one-direction table (the vehicle's own forward
    circle mirrored) misses it by more than 1 N; forward queries are the same in both;
    the scalar path gives the same bits."""
    cfg, _, _, table = asymmetric
    direct = solve_circle(cfg, -SPEED, [TILT])
    n_xi = table.xi.size
    xi = -2 * np.pi * np.arange(n_xi) / n_xi  # the reversed circle's samples
    xi_dot = -SPEED / cfg.radius
    both, one = Interpolator(table), Interpolator(dataclasses.replace(table, reverse=None))
    r = both(xi, xi_dot, TILT)
    assert np.all(r.status == 0)
    scale = np.abs(direct.K[0]).max()
    np.testing.assert_allclose(r.K, direct.K[0], rtol=0, atol=1e-5 * scale)
    np.testing.assert_allclose(r.u_d, direct.u_d[0], rtol=0, atol=1e-5)
    np.testing.assert_allclose(r.phi_d, direct.phi_d[0], rtol=0, atol=1e-6)
    assert np.abs(one(xi, xi_dot, TILT).u_d - direct.u_d[0]).max() > 1.0  # N
    fwd = np.linspace(0.0, 6.0, 7)
    a, b = both(fwd, -xi_dot, TILT), one(fwd, -xi_dot, TILT)
    for f in ("K", "u_d", "phi_d", "status"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    for x in (0.3, 2.0, 4.1):
        K, U, P, status = both.query(x, xi_dot, TILT)
        ref = both(x, xi_dot, TILT)
        np.testing.assert_array_equal(K, ref.K)
        np.testing.assert_array_equal(U, ref.u_d)
        assert P == float(ref.phi_d) and status == int(ref.status)


@pytest.fixture(scope="module")
def compiled(asymmetric, tmp_path_factory):
    """The two-direction table's runtime data, its Python reference and its C runtime, and
    the C runtime of the one-direction table (``reverse`` dropped)."""
    _, _, _, table = asymmetric
    data = runtime_data(table)
    one = dataclasses.replace(data, reverse=None)
    c = CRuntime(build_host(data, tmp_path_factory.mktemp("both")), data)
    c_one = CRuntime(build_host(one, tmp_path_factory.mktemp("one")), one)
    return data, Interpolator(data), c, c_one


def _quadrants(d, m, seed):
    """``m`` queries inside and a little beyond the table, a quarter in each quadrant of
    (sign of xi_dot, sign of alpha)."""
    rng = np.random.default_rng(seed)
    vmax, amax = float(d.xi_dot[-1]), float(d.tilt[-1])
    xi = rng.uniform(-2 * np.pi, 2 * np.pi, m)
    v = np.resize([1.0, -1.0, 1.0, -1.0], m) * rng.uniform(0.8 * float(d.xi_dot[0]),
                                                              1.1 * vmax, m)
    a = np.resize([1.0, 1.0, -1.0, -1.0], m) * rng.uniform(0.0, 1.1 * amax, m)
    return xi, v, a


@pytest.mark.needs_cc
def test_the_c_runtime_reads_the_mirror_image_as_the_python_reference(compiled):
    """The compiled C runtime on the two-direction table: 800 queries, 200 in each quadrant
    of (xi_dot, alpha) signs: the status of the Python reference, K and u_d within 1e-5
    relative and phi_d within 1e-5 rad (tests/firmware/test_runtime.py's bounds;
    measured 7e-8, 1.1e-7, 7.7e-8); the nominal (gs_lookup_nominal) on a reversed circle
    as the Python feed-forward (tests/firmware/test_feedforward_c.py's bounds). On the
    reversed queries the one-direction runtime differs by more than 1 N; on the forward
    ones it gives the same bits."""
    data, ref, c, c_one = compiled
    # the flash budget counts both halves (the axes and state map once; measured: 8487
    # bytes against 4299)
    assert 1.9 * c_one.data.nbytes() < data.nbytes() < 2 * c_one.data.nbytes()
    xi, v, a = _quadrants(data, 800, seed=53)
    r_py, r_c = ref(xi, v, a), c(xi, v, a)
    np.testing.assert_array_equal(r_c.status, r_py.status.astype(np.int32))
    live = (r_py.status & UNUSABLE) == 0
    assert np.count_nonzero(live & (v < 0)) > 200
    nrm = np.linalg.norm(r_py.K.reshape(v.size, -1), axis=1)[live]
    relK = np.abs(r_py.K - r_c.K).reshape(v.size, -1).max(1)[live] / nrm
    relU = (np.abs(r_py.u_d - r_c.u_d).max(1)[live]
            / np.linalg.norm(r_py.u_d, axis=1)[live])
    absP = np.abs(r_py.phi_d - r_c.phi_d)[live]
    assert relK.max() <= 1e-5 and relU.max() <= 1e-5 and absP.max() <= 1e-5, (
        relK.max(), relU.max(), absP.max())
    one = c_one(xi, v, a)
    fwd, rev = v > 0, (v < 0) & live & ((one.status & UNUSABLE) == 0)
    for f in ("K", "u_d", "phi_d", "status"):
        np.testing.assert_array_equal(getattr(one, f)[fwd], getattr(r_c, f)[fwd])
    assert np.abs(one.u_d[rev] - r_c.u_d[rev]).max() > 1.0  # N
    r = float(data.vehicle[2])
    for alpha in (TILT, -TILT):
        path = circle_path(-SPEED, r, np.arange(0.0, 1.0, 1e-2), 0.3)
        ff = feedforward(ref, path, alpha)
        K, U, X, ten, S = c.nominal(np.stack([path.xi, *path.d], axis=1), alpha)
        np.testing.assert_array_equal(S, ff.status)
        np.testing.assert_allclose(U, ff.u_d, rtol=1e-5, atol=1e-5)
        err = np.abs(X - ff.x_d) / (1 + np.abs(ff.x_d))
        assert err.max() <= 1e-5, err.max(0)
        assert np.abs(ff.x_d[:, 6]).max() > 1e-4  # the image's yaw offset is flown
        _, U1, X1, _, _ = c_one.nominal(np.stack([path.xi, *path.d], axis=1), alpha)
        assert np.abs(U1 - U).max() > 1.0


#: gs_verify of the pair, edited copies of the generated tables (their CRCs recomputed
#: where the edit is not the data's own: only the pair rule can refuse those)
PAIR_CHECKS = r"""
#include <stdlib.h>
#include <string.h>
#include "asym_gains.h"

int pair_verify(int which)
{
    gs_table t = asym_table;
    gs_table r = asym_reverse_table;
    gs_table rr = asym_reverse_table;
    float tilt[ASYM_N_TILT];
    float u_d[ASYM_N_TILT * ASYM_N_SPEED * ASYM_N_XI * 4u];
    t.reverse = &r;
    memcpy(tilt, asym_tilt, sizeof tilt);
    memcpy(u_d, asym_reverse_u_d, sizeof u_d);
    switch (which) {
    case 0: break;                          /* the copy as generated */
    case 1: u_d[7] += 0.25f; r.dense.u_d = u_d; break; /* a reverse value */
    case 2: tilt[ASYM_N_TILT - 1u] *= 1.01f; r.tilt = tilt; break; /* another tilt axis */
    case 3: r.reverse = &rr; break;         /* the reverse has a reverse */
    default: break;
    }
    if (which >= 2) { /* every CRC right: the pair rule alone can refuse */
        r.crc32 = gs_table_crc32(&r);
        t.crc32 = gs_table_crc32(&t);
    }
    return gs_verify(&t);
}

int pair_verify_generated(void) { return asym_verify(); }
"""


@pytest.mark.needs_cc
def test_gs_verify_checks_each_half_and_the_pair(asymmetric, tmp_path):
    """``gs_verify`` of the two-direction table is GS_OK, and GS_BAD_TABLE for a corrupted
    value of the reverse half (its own CRC), a reverse half with another tilt axis and one
    with a reverse of its own (both with every CRC recomputed: the pair check refuses)."""
    import ctypes

    from gainsched.firmware.cfiles import copy_runtime, write_header
    from gainsched.firmware.host.compiler import STRICT_CFLAGS

    from support import compile_c

    _, _, _, table = asymmetric
    data = dataclasses.replace(runtime_data(table), name="asym")
    data = dataclasses.replace(data, reverse=dataclasses.replace(data.reverse, name="asym"))
    write_header(data, tmp_path)
    runtime_c = copy_runtime(tmp_path).runtime_c
    (tmp_path / "pair.c").write_text(PAIR_CHECKS)
    lib = tmp_path / "libpair.so"
    compile_c([*STRICT_CFLAGS, "-shared", "-fPIC", f"-I{tmp_path}", "-o", str(lib),
               str(tmp_path / "pair.c"), str(runtime_c)])
    so = ctypes.CDLL(str(lib))
    assert so.pair_verify_generated() == OK
    assert [so.pair_verify(k) for k in range(4)] == [OK, BAD_TABLE, BAD_TABLE, BAD_TABLE]


def test_gainsched_build_writes_the_two_direction_table_and_its_c_files(tmp_path):
    """``gainsched build`` of the asymmetric vehicle: exit 0, the table with its reverse
    half and the C files, whose header holds both halves (the reverse table first, the
    table pointing at it); the compact format, which holds one direction, is refused in
    one line naming firmware.format, before any work."""
    (tmp_path / "asym.toml").write_text(small_config_text(name="asym", **ASYMMETRY))
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["build", str(tmp_path / "asym.toml"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert load_table(out / "asym.h5").reverse is not None
    h = (out / "asym_gains.h").read_text()
    assert h.index("static const gs_table asym_reverse_table") < h.index(
        "static const gs_table asym_table")
    assert "    &asym_reverse_table,\n};" in h and "both flight directions" in h
    assert (out / "gainsched_runtime.c").exists() and (out / "asym_control.h").exists()
    (tmp_path / "c.toml").write_text(small_config_text(name="c", firmware__format="compact",
                                                       **ASYMMETRY))
    res = CliRunner().invoke(cli, ["build", str(tmp_path / "c.toml"), "-o",
                                   str(tmp_path / "c")])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "c.toml: firmware.format: \"compact\" holds one" in lines[0]
    assert not (tmp_path / "c").exists()


@pytest.mark.slow
def test_the_header_of_a_symmetric_table_is_the_committed_one(tmp_path):
    """``make tables`` into a temporary folder: every file equals the committed tables/
    (the paper vehicle is its own mirror image: its table and header are unchanged by the
    reverse member)."""
    res = CliRunner().invoke(cli, ["build", str(REPO / "configs/paper.toml"), "-o",
                                   str(tmp_path)])
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in (REPO / "tables").iterdir() if p.is_file())
    assert names == sorted(p.name for p in tmp_path.iterdir() if p.is_file())
    for name in names:
        assert (tmp_path / name).read_bytes() == (REPO / "tables" / name).read_bytes(), name
    assert "reverse_table" not in (tmp_path / "paper_gains.h").read_text()


def test_the_firmware_controller_flies_reversed_circles_on_the_two_direction_table(
        asymmetric):
    """The firmware's control step in Python (table lookups for gains and nominal) on the
    asymmetric vehicle, 8 m/s at 15 deg, 3 s each way: reversed, the two-direction table
    tracks as it does forwards (measured: max |delta error| 0.0020 rad, |xi error| 0.0053
    rad against 0.0020 and 0.0097 forwards), the one-direction table misses the reversed
    circle (0.027 and 0.28 rad) and no forward flight changes."""
    cfg, _, _, table = asymmetric
    one = dataclasses.replace(table, reverse=None)

    def errors(tab, speed):
        r = simulate(cfg, table_scheduler(tab), Scenario("d", np.deg2rad(15.0), speed, 3.0),
                     controller="firmware")
        assert r.t.size == 3001  # flew the whole circle
        return np.abs(r.z[:, :2] - r.z_d[:, :2]).max(axis=0)  # delta, xi (rad)

    fwd, rev, rev_one = errors(table, 8.0), errors(table, -8.0), errors(one, -8.0)
    np.testing.assert_array_equal(errors(one, 8.0), fwd)
    assert np.all(rev <= 1.5 * fwd), (rev, fwd)
    assert np.all(rev_one > 5 * rev), (rev_one, rev)


def test_the_midpoint_check_covers_the_reversed_circles(asymmetric):
    """``midpoint_check`` of a two-direction table checks the reversed circles too
    (negative speeds: the direct solve run backwards against the lookups that read the
    mirror image), each direction within the small grid's accuracy and stable; the same
    check of the one-direction table finds its reversed circles far off."""
    _, _, _, table = asymmetric
    chk = midpoint_check(table)
    back = chk.speed < 0
    assert back.any() and (~back).any()
    np.testing.assert_array_equal(np.unique(np.abs(chk.speed[back])),
                                  np.unique(chk.speed[~back]))
    worst = {d: float(np.nanmax(chk.rel_err[m])) for d, m in (("fwd", ~back), ("rev", back))}
    assert worst["rev"] <= 2 * worst["fwd"] and worst["rev"] < 0.2, worst
    assert all(c.rho_interp < 1 for c in chk.circles if c.speed < 0)
    # the same reversed lookups on the one-direction table: the asymmetry, not the grid
    one = Interpolator(dataclasses.replace(table, reverse=None))
    xi, v, a = chk.xi[back], chk.speed[back] / table.attrs["radius_m"], chk.tilt[back]
    ok = np.isfinite(chk.u_err[back])
    u_one = one(xi[ok], v[ok], a[ok]).u_d
    u_two = Interpolator(table)(xi[ok], v[ok], a[ok]).u_d
    assert np.abs(u_one - u_two).max() > 1.0 > float(np.nanmax(chk.u_err[back]))  # N


def test_inspect_says_the_table_holds_both_directions(asymmetric, tmp_path):
    """``gainsched inspect`` of a two-direction table says so in one line (its flash
    footprint compiled with both halves); a symmetric table's lines do not."""
    from gainsched.studies import inspect

    _, _, data, _ = asymmetric
    (tmp_path / "asym.h5").write_bytes(data)
    res = CliRunner().invoke(cli, ["inspect", str(tmp_path / "asym.h5")])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert sum("both flight directions" in line for line in lines) == 1, lines
    assert not any("both flight directions" in line
                   for line in inspect(PAPER_H5, code_size=False).lines())


def test_an_automatic_grid_is_chosen_for_both_directions():
    """``refine_grid`` of the asymmetric vehicle solves and certifies its mirror image
    beside it, circle for circle: the chosen grid holds both halves and the midpoint
    check meets the 2 % bound on the forward and the reversed circles (measured: 1.57 %
    and 1.45 % with speeds 6, 6.75, .., 9 m/s, where the symmetric vehicle needs 6, 7.5,
    9)."""
    auto = {"grid.speeds": {"min": 6, "max": 9, "max_count": 8},
            "grid.tilts_deg": {"min": 0, "max": 20, "max_count": 8},
            "grid.azimuth_samples": 16}
    choice = refine_grid(small_config(**ASYMMETRY, **auto))
    assert choice.grid.reverse is not None and choice.max_error <= 0.02
    table = table_from_bytes(table_bytes(choice.config, choice.grid,
                                         grid_auto=choice.record()), "auto.h5")
    chk = midpoint_check(table)
    back = chk.speed < 0
    assert back.any() and (~back).any()
    assert float(np.nanmax(chk.rel_err)) <= 0.02, float(np.nanmax(chk.rel_err))
    assert max(c.rho_interp for c in chk.circles) < 1


@pytest.mark.needs_cc
def test_the_c_controller_flies_reversed_circles_as_the_python_reference(asymmetric, tmp_path):
    """Software in the loop: the C runtime and controller (``c_runtime_scheduler``) fly the
    asymmetric vehicle's reversed circle, 8 m/s at 15 deg for 3 s, as the Python reference
    (``table_scheduler``, controller "firmware"): positions within 1e-6 m and the same
    statuses (tests/sim/test_closed_loop.py), tracking metrics within 5 %
    (tests/firmware/test_controller.py; measured: 6.3e-8 m, |xi error| 0.0053 rad both);
    the C runtime of the one-direction table misses the circle (measured: 0.28 rad)."""
    cfg, _, _, table = asymmetric
    scn = Scenario("d", np.deg2rad(15.0), -8.0, 3.0)
    one = dataclasses.replace(table, reverse=None)
    r_c = simulate(cfg, c_runtime_scheduler(table, tmp_path / "both"), scn,
                   controller="firmware")
    r_py = simulate(cfg, table_scheduler(table), scn, controller="firmware")
    r_one = simulate(cfg, c_runtime_scheduler(one, tmp_path / "one"), scn, controller="firmware")
    assert r_c.t.size == r_py.t.size == 3001
    assert np.abs(r_c.p_I - r_py.p_I).max() <= 1e-6
    np.testing.assert_array_equal(r_c.status, r_py.status)
    m_c, m_py = metrics(r_c), metrics(r_py)
    for k in ("rms_out_of_plane_m", "rms_along_track_m", "rms_speed_error_mps"):
        assert abs(m_c[k] - m_py[k]) <= 0.05 * m_py[k] + 1e-6, (k, m_c[k], m_py[k])
    err = np.abs(r_c.z[:, :2] - r_c.z_d[:, :2]).max(axis=0)
    err_one = np.abs(r_one.z[:, :2] - r_one.z_d[:, :2]).max(axis=0)
    assert np.all(err_one > 5 * err), (err_one, err)


def test_the_outputs_check_refuses_a_compact_two_direction_table_before_any_work():
    """``check_outputs``, which ``gainsched build`` and the rebuilds of ``improve`` and
    ``diagnose --apply`` run first: the compact format of a vehicle that is not its own
    mirror image is refused naming firmware.format; the dense one, and the compact one of
    a symmetric vehicle, pass."""
    from gainsched.firmware.outputs import check_outputs

    with pytest.raises(InputError, match=r"^small.toml: firmware.format: \"compact\" holds one"):
        check_outputs(small_config(firmware__format="compact", **ASYMMETRY))
    check_outputs(small_config(**ASYMMETRY))
    check_outputs(small_config(firmware__format="compact"))
