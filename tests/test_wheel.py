"""The package works from a wheel, run from another folder (issue 13).

The wheel is built from this checkout, installed alone into a folder (its
dependencies come from this environment), and every command that needs files
of the package runs from a fresh folder with that install first on the path:
the compiled kernels and the C runtime compile from package data, the shipped
scenarios load, and nothing reaches back into the checkout.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from support import small_config_text

ROOT = Path(__file__).parents[1]


def _small_config(path: Path) -> Path:
    path.write_text(small_config_text(name="wheel"))
    return path


@pytest.mark.slow
def test_wheel_install_runs_from_another_folder(tmp_path):
    dist, site, work = tmp_path / "dist", tmp_path / "site", tmp_path / "work"
    work.mkdir()
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                            str(dist), str(ROOT)], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr
    (wheel,) = dist.glob("gainsched-*.whl")
    inst = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q",
                           "--target", str(site), str(wheel)], capture_output=True, text=True,
                          timeout=300)
    assert inst.returncode == 0, inst.stderr
    env = dict(os.environ, PYTHONPATH=str(site), GAINSCHED_CACHE=str(tmp_path / "cache"))

    def run(*args, code=0):
        res = subprocess.run([sys.executable, "-m", "gainsched", *map(str, args)], cwd=work,
                             env=env, capture_output=True, text=True, timeout=300)
        assert res.returncode == code, (args, res.stdout, res.stderr)
        return res

    where = subprocess.run([sys.executable, "-c", "import gainsched; print(gainsched.__file__)"],
                           cwd=work, env=env, capture_output=True, text=True)
    assert Path(where.stdout.strip()).is_relative_to(site), where.stdout  # not the checkout
    cfg = _small_config(work / "wheel.toml")
    run("validate", cfg)
    run("nominal", cfg, "--speed", "9", "--tilt", "20")
    run("build", cfg, "-o", "out")  # native kernels and the C runtime from package data
    assert sorted(p.name for p in (work / "out").iterdir()) == [
        "gainsched_control.c", "gainsched_control.h", "gainsched_runtime.c",
        "gainsched_runtime.h", "wheel.h5", "wheel_control.h", "wheel_gains.h"]
    run("inspect", "out/wheel.h5")
    run("export-c", "out/wheel.h5", "-o", "fw")
    run("simulate", cfg, "--tables", "out/wheel.h5", "--scenario", "braking", "-o", "sim")
    assert (work / "sim" / "metrics.json").is_file()
    assert not (ROOT / "sim").exists()
