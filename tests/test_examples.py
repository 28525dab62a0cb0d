"""The example scripts (examples/*.py) run as a user runs them, from a directory like the
repository root, and do what they say."""

from __future__ import annotations

import runpy
import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest

import gainsched as gs

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"


@pytest.fixture
def root_like(tmp_path, monkeypatch):
    """A working directory with configs/, tables/, examples/ (links to the repository's)."""
    for sub in ("configs", "tables", "examples"):
        (tmp_path / sub).symlink_to(REPO / sub)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_plot_gains_is_15_lines_and_plots_the_table(root_like, monkeypatch):
    """The plotted curves pass through the table's gains at its grid azimuths (float32 data,
    so rel. 1e-6), for the speeds and the entry the labels name."""
    src = (EXAMPLES / "plot_gains.py").read_text()
    code = src.split('"""')[2]  # after the module docstring
    lines = [ln for ln in code.splitlines() if ln.strip()]
    assert len(lines) <= 15, f"{len(lines)} lines"
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.close("all")
    monkeypatch.setattr(sys, "argv", ["plot_gains.py", "tables/paper.h5", "gains.png"])
    runpy.run_path(str(EXAMPLES / "plot_gains.py"), run_name="__main__")
    assert (root_like / "gains.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = gs.load_table(REPO / "tables/paper.h5")
    K = table.K_full()  # (n_a, n_v, n_xi, 4, n)
    i_tilt = int(np.argmin(abs(table.tilt - np.deg2rad(20.0))))
    assert np.isclose(table.tilt[i_tilt], np.deg2rad(20.0), atol=1e-7)
    j = table.state_names.index("delta")
    curves = plt.gca().get_lines()
    assert len(curves) == len(table.speed[::4]) >= 4
    step = 360 // table.xi.size  # the plot samples every degree; the grid every `step`
    drawn = 0
    for line, k in zip(curves, range(0, table.speed.size, 4), strict=True):
        assert line.get_label() == f"{table.speed[k]:g} m/s"
        y = line.get_ydata()[:-1:step]
        ref = K[i_tilt, k, :, 0, j]
        feasible = table.reasons[i_tilt, k] == 0
        if not feasible.any():  # a circle without gains is not drawn (not drawn as zero)
            assert np.isnan(line.get_ydata()).all()
            continue
        drawn += 1
        np.testing.assert_allclose(y[feasible], ref[feasible], rtol=1e-6,
                                   atol=1e-6 * abs(ref).max())
    assert drawn >= 4
    plt.close("all")


@pytest.mark.slow
def test_model_vs_measurement_loop_finds_the_effects_and_converges(root_like):
    """The loop from Python on the example flights: two effects are added (forward
    selection finds both in the first round), the last round says no effect is needed,
    the improved config is valid and the reports are written."""
    run = subprocess.run([sys.executable, str(EXAMPLES / "model_vs_measurement.py"), "out"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    out = run.stdout
    lines = out.splitlines()
    last = max(i for i, line in enumerate(lines) if line.startswith("round "))
    assert last > 0 and lines[last + 1].strip().startswith("no effect needed"), out
    improved = gs.load_config(root_like / "out" / "improved.toml")
    assert {"thrust_momentum", "motor_lag"} <= {e.name for e in improved.effects}
    final = gs.compare(improved, sorted((REPO / "examples/flights").glob("*.csv")))
    assert final.normalized_rms() < 1.25
    n_rounds = int(lines[last].split()[1].rstrip(":"))
    for k in range(1, n_rounds + 1):
        assert (root_like / "out" / f"round{k}" / "diagnose.json").is_file()
    assert (root_like / "out" / "final" / "compare.json").is_file()
    assert "gainsched build out/improved.toml" in out
