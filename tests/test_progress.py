"""Issue 39, "Progress": every command that can run for more than a few seconds shows a
progress line (tqdm on stderr) on a terminal, none in a pipe, none under
``gainsched --quiet``; one helper makes them all (gainsched/cli/_base.py, ``_progress``)."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from click.testing import CliRunner

from gainsched.cli import cli

from support import PAPER_H5, PAPER_TOML, REPO, on_terminal, synthetic_table

GAINSCHED = [sys.executable, "-m", "gainsched"]
FLIGHTS = sorted((REPO / "examples" / "flights").glob("*.csv"))

#: commands cheap enough to run three times: (arguments, what their progress line shows)
COMMANDS = {
    "campaign": (["campaign", str(PAPER_TOML), "--tables", str(PAPER_H5), "--duration", "1",
                  "-o", "flights"], r"campaign none: 100%\|.*\| 7/7 .*(flight/s|s/flight)"),
    "compare": (["compare", str(PAPER_TOML), *map(str, FLIGHTS[:2]), "--before",
                 str(PAPER_TOML.with_name("paper_hold.toml"))],
                r"compare paper: 100%\|.*\| 7/7 .*(step/s|s/step)"),
    "check": (["check", str(PAPER_H5), "--speed-stride", "9"],
              r"check paper: 100%\|.*\| 2/2 .*(speed/s|s/speed)"),
    "inspect": (["inspect", str(PAPER_H5), "-o", "flights"],
                r"inspect paper: 100%\|.*\| 2/2 .*(stage/s|s/stage), envelope.png\]"),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_progress_on_a_terminal_not_in_a_pipe_not_with_quiet(command, tmp_path):
    """On a pseudo-terminal the command draws its progress line on stderr; piped, stderr
    has none; with ``gainsched --quiet`` on the terminal, the terminal shows nothing. The
    results (stdout) are the same all three ways."""
    args, line = COMMANDS[command]
    out = lambda i: [a if a != "flights" else f"flights{i}" for a in args]  # noqa: E731
    code, shown = on_terminal([*GAINSCHED, *out(1)], tmp_path)
    assert code == 0 and re.search(line, shown), shown
    piped = subprocess.run([*GAINSCHED, *out(2)], capture_output=True, text=True,
                           cwd=tmp_path, timeout=300)
    assert piped.returncode == 0 and piped.stderr == "", piped.stderr
    code, shown = on_terminal([*GAINSCHED, "--quiet", *out(3)], tmp_path)
    assert code == 0 and shown == "", shown


def test_quiet_is_an_option_of_gainsched_itself():
    """``-q/--quiet`` goes before the command (one option for every command); after a
    command it is a usage error, one line, exit 2."""
    runner = CliRunner()
    res = runner.invoke(cli, ["--help"])
    assert res.exit_code == 0 and "-q, --quiet" in res.output, res.output
    res = runner.invoke(cli, ["-q", "validate", str(PAPER_TOML)])
    assert res.exit_code == 0 and "paper" in res.output, res.output
    res = runner.invoke(cli, ["validate", str(PAPER_TOML), "--quiet"])
    assert res.exit_code == 2 and "No such option '--quiet'" in res.output, res.output


def test_quiet_drops_the_notes_but_not_the_warnings(monkeypatch, tmp_path):
    """``_note`` lines (what was built on the way, where a build runs) go under --quiet;
    a warning stays: here ``paper`` with a table of another config, whose first use
    builds nothing (the table is given) but warns."""
    import gainsched.cli as cli_mod

    def fake_command():
        cli_mod._note("built something on the way")
        import warnings

        from gainsched.errors import GainschedWarning

        warnings.warn("still said", GainschedWarning, stacklevel=1)

    cmd = cli_mod.cli.command("fake-note")(fake_command)
    try:
        runner = CliRunner()
        loud = runner.invoke(cli, ["fake-note"])
        quiet = runner.invoke(cli, ["--quiet", "fake-note"])
    finally:
        cli_mod.cli.commands.pop(cmd.name)
    assert loud.exit_code == 0 and "built something on the way" in loud.output, loud.output
    assert "gainsched: warning: still said" in loud.output, loud.output
    assert quiet.exit_code == 0 and "built something" not in quiet.output, quiet.output
    assert "gainsched: warning: still said" in quiet.output, quiet.output


def test_plot_counts_every_file_it_renders(monkeypatch):
    """``plot``'s progress line counts the files as they are rendered: as many calls as
    ``plot_count`` says and as PNG files come out, the midpoint figure included (the
    figures drawn, not rendered to PNG: the count is what is tested)."""
    import matplotlib.pyplot as plt
    import numpy as np

    from gainsched.schedule import viewer

    monkeypatch.setattr(viewer, "_png", lambda fig: plt.close(fig) or b"png")
    t = synthetic_table(n_a=2, n_v=3, n_xi=8)
    calls = []
    files = viewer.schedule_plots(t, (np.array([3.0]), np.array([0.1]), np.array([0.01])),
                                  progress=calls.append)
    pngs = [f for f in files if f.endswith(".png")]
    assert "midpoint_error.png" in pngs and calls == [1] * len(pngs), (calls, sorted(files))
    assert viewer.plot_count(t, midpoints=True) == len(pngs), sorted(files)
