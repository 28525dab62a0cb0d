"""The gain viewer (``gainsched plot``, :mod:`gainsched.schedule.viewer`): the files, and
the plotted values against the table's own arrays (read back from the figures)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.schedule.tables import load_table
from gainsched.schedule.viewer import _midpoint_grid, gain_file_name, schedule_figures

from support import PAPER_H5, small_config_text


@pytest.fixture(scope="module")
def figs(paper_table):
    """The paper table's figures (:func:`schedule_figures`), drawn once for the module's
    tests (they only read them) and closed after them."""
    import matplotlib.pyplot as plt

    figures = schedule_figures(paper_table)
    yield figures
    for f in figures.values():
        plt.close(f)


def _mesh(fig, gid):
    found = [c for ax in fig.axes for c in ax.collections if c.get_gid() == gid]
    assert len(found) == 1, gid
    return found[0]


def _values(mesh, shape):
    """The array a QuadMesh draws, NaN where masked (blank)."""
    a = mesh.get_array()
    return np.ma.filled(np.ma.asarray(a, dtype=float), np.nan).reshape(shape)


@pytest.mark.slow
def test_cli_plot_writes_the_pngs_and_a_summary_of_the_table(tmp_path):
    """``gainsched plot TABLE -o DIR --json`` (the small grid's table: two tilts, the
    level one with its gain per speed; the paper table's figures are read back by the
    tests below): one gain page per tilt, the envelope, nominal and spectral-radius pages
    and plots.json, all listed there; the summary's gain ranges are the table's (per
    tilt, input and state, over the feasible azimuth samples: computed here from
    ``K_tilt0`` and ``K`` directly)."""
    (tmp_path / "small.toml").write_text(small_config_text())
    built = CliRunner().invoke(cli, ["build", str(tmp_path / "small.toml"), "-o",
                                     str(tmp_path / "t")])
    assert built.exit_code == 0, built.output
    paper_table = load_table(tmp_path / "t" / "small.h5")
    out = tmp_path / "plots"
    r = CliRunner().invoke(cli, ["plot", str(tmp_path / "t" / "small.h5"), "-o", str(out),
                                 "--json"])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.output)
    assert summary == json.loads((out / "plots.json").read_text())
    expected = {gain_file_name(a) for a in paper_table.tilt} | {
        "envelope.png", "nominal.png", "spectral_radius.png", "time_constant.png",
        "gain_margin.png", "delay_margin.png", "plots.json"}
    assert set(summary["files"]) == expected == {p.name for p in out.iterdir()}
    for name in expected - {"plots.json"}:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    names = paper_table.attrs["state_names"].split(",")
    assert summary["state_names"] == names
    assert summary["tilts_deg"] == pytest.approx(np.rad2deg(paper_table.tilt).tolist())
    ok = paper_table.reasons == 0
    for i, a in enumerate(paper_table.tilt):
        if i == 0:  # one gain per speed: feasible where any azimuth is (a level circle)
            K, sel = paper_table.K_tilt0, ok[0].all(-1)
        else:
            K, sel = paper_table.K[i - 1], ok[i]
        got = summary["gains"][f"{np.rad2deg(a):g}"]
        for r_, inp in enumerate(("T1", "T2", "T3", "T4")):
            for c, nm in enumerate(names):
                col = K[..., r_, c][sel]
                assert got[inp][nm] == pytest.approx([col.min(), col.max()], rel=1e-12), (
                    i, inp, nm)
    rho = np.array([[np.nan if x is None else x for x in row]
                    for row in summary["spectral_radius"]])
    np.testing.assert_array_equal(rho, paper_table.spectral_radius)


@pytest.mark.slow
def test_plotted_maps_are_the_tables_arrays(paper_table, figs):
    """Every map draws the table's values at its grid points (no resampling), blank
    exactly where the circle sample is infeasible: every gain entry at two tilts, the
    nominal thrusts and roll at every tilt, the spectral radius, the slowest time constant."""
    ok = paper_table.reasons == 0
    K = paper_table.K_full()
    n_v, n_xi = paper_table.speed.size, paper_table.xi.size
    for i in (0, 3):
        fig = figs[gain_file_name(paper_table.tilt[i])]
        for r in range(4):
            for c in range(K.shape[-1]):
                got = _values(_mesh(fig, f"K_{r}_{c}"), (n_v, n_xi))
                want = np.where(ok[i], K[i, ..., r, c], np.nan)
                np.testing.assert_array_equal(got, want, err_msg=f"tilt {i} K[{r},{c}]")
    nom = figs["nominal.png"]
    for i in range(paper_table.tilt.size):
        for m in range(4):
            np.testing.assert_array_equal(
                _values(_mesh(nom, f"u_d_{i}_{m}"), (n_v, n_xi)),
                np.where(ok[i], paper_table.u_d[i, ..., m], np.nan))
        np.testing.assert_allclose(
            _values(_mesh(nom, f"phi_d_{i}"), (n_v, n_xi)),
            np.where(ok[i], np.rad2deg(paper_table.phi_d[i]), np.nan), rtol=1e-15)
    np.testing.assert_array_equal(
        _values(_mesh(figs["spectral_radius.png"], "spectral_radius"),
                paper_table.spectral_radius.shape), paper_table.spectral_radius)
    np.testing.assert_array_equal(
        _values(_mesh(figs["time_constant.png"], "time_constant"),
                paper_table.spectral_radius.shape), paper_table.mode_tau[..., 0])
    lm = paper_table.margins()
    for name, values in (("gain_margin", 20 * np.log10(lm.gain_down)),
                         ("delay_margin", 1e3 * lm.delay)):
        np.testing.assert_array_equal(
            _values(_mesh(figs[f"{name}.png"], name), lm.delay.shape), values)


def test_midpoint_error_map_takes_the_max_over_azimuth():
    speed = np.array([2.0, 2.0, 2.0, 5.0, 5.0, 2.0])
    tilt = np.array([0.1, 0.1, 0.3, 0.1, 0.3, 0.3])
    err = np.array([0.01, 0.03, np.nan, 0.02, 0.005, 0.004])
    vs, ts, grid = _midpoint_grid((speed, tilt, err))
    np.testing.assert_array_equal(vs, [2.0, 5.0])
    np.testing.assert_array_equal(ts, [0.1, 0.3])
    np.testing.assert_array_equal(grid, [[0.03, 0.02], [0.004, 0.005]])


@pytest.mark.parametrize("args", [
    ["plot", "tables/paper.h5"],  # -o missing
    ["plot"],  # TABLE missing
    ["build", "configs/paper.toml", "--jobs", "many"],
    ["inspect", "tables/paper.h5", "--bogus"],
    ["no-such-command"],
])
def test_usage_errors_are_one_line_with_exit_2(args):
    """A usage error prints one line, ``gainsched: error: command line: ...``, exit 2
    (click's own format is four lines with the message last)."""
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gainsched: error: command line: "), lines


def test_plot_of_a_missing_table_names_the_file(tmp_path):
    r = CliRunner().invoke(cli, ["plot", str(tmp_path / "none.h5"), "-o", str(tmp_path / "o")])
    assert r.exit_code == 2
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and "none.h5" in lines[0], lines


def test_inspect_json_is_the_table_at_a_glance(paper_table):
    """``inspect --json``: the grid, the feasible fraction per circle, the spectral radius
    (None where infeasible) and the gain ranges, equal to the table's arrays; the same
    summary ``plot`` writes into plots.json."""
    r = CliRunner().invoke(cli, ["inspect", str(PAPER_H5), "--json"])
    assert r.exit_code == 0, r.output
    js = json.loads(r.output)
    np.testing.assert_array_equal(js["speeds_mps"], paper_table.speed)
    assert js["azimuth_samples"] == paper_table.xi.size
    np.testing.assert_array_equal(js["feasible_fraction"], (paper_table.reasons == 0).mean(-1))
    rho = np.array([[np.nan if x is None else x for x in row] for row in js["spectral_radius"]])
    np.testing.assert_array_equal(rho, paper_table.spectral_radius)
    assert js["worst_spectral_radius"] == np.nanmax(paper_table.spectral_radius)
    assert sum(js["reasons"].values()) >= np.count_nonzero(paper_table.reasons)
    assert js["config_sha256"] == paper_table.config_sha256


def test_gain_maps_carry_units_colorbars_and_a_map_for_their_sign(paper_table, figs):
    """Issue 39: every gain map has its colorbar and its gain's unit (N per the state's
    unit), a diverging map centred on 0 for gains of both signs and a sequential one for
    one-signed gains."""
    from gainsched.schedule.viewer import gain_unit

    assert [gain_unit(n) for n in ("delta", "xi_dot", "omega_x", "int_delta", "motor_lag_0")] \
        == ["N/rad", "N/(rad/s)", "N/(rad/s)", "N/(rad s)", "N/N"]
    fig = figs[gain_file_name(paper_table.tilt[3])]
    ok = paper_table.reasons[3] == 0
    K = paper_table.K_full()[3]
    names = paper_table.state_names
    for r in range(4):
        for c in range(K.shape[-1]):
            mesh = _mesh(fig, f"K_{r}_{c}")
            assert mesh.colorbar is not None
            assert gain_unit(names[c]) in mesh.axes.get_title()
            fin = K[..., r, c][ok]
            if fin.min() < 0 < fin.max():
                lo, hi = mesh.get_clim()
                assert mesh.get_cmap().name == "coolwarm" and lo == -hi
            else:
                assert mesh.get_cmap().name == "viridis"


def test_every_picture_is_legible_at_its_saved_size(paper_table, figs):
    """Issue 56: rendered at its saved size, no text of any picture of ``gainsched plot``
    and ``inspect`` (the gain maps, the nominal, the spectral radius, time-constant and
    margin maps, the envelope) runs off the figure or over another text (a colorbar's labels
    over the next map, a title over its colorbar's label); the values printed in the
    cells are black on light cells and white on dark ones, never a hue on a hue."""
    import matplotlib.pyplot as plt

    from gainsched.schedule.envelope import envelope_figure, envelope_from_table

    from support import text_problems

    env = envelope_figure(envelope_from_table(paper_table))
    try:
        for name, fig in [*figs.items(), ("envelope.png", env)]:
            assert text_problems(fig) == [], name
    finally:
        plt.close(env)
    assert {"gain_margin.png", "delay_margin.png"} <= set(figs)
    for name in ("spectral_radius.png", "delay_margin.png"):
        cells = [t for t in figs[name].axes[0].texts]
        assert cells and {t.get_color() for t in cells} <= {"black", "white"}, name
