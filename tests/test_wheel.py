"""The package works from a wheel, run from another folder (issue 13).

The wheel is built from this checkout, installed alone into a folder (its
dependencies come from this environment), and every command that needs files
of the package runs from a fresh folder with that install first on the path:
the compiled kernels and the C runtime compile from package data, the shipped
scenarios and reference configs load (``gs.load_config("paper")``), ``gainsched paper
--quick`` flies with no config or table given (its table from the cache, seeded with
the committed table as a first use would leave it: tests/schedule/test_cached.py builds
one), ``gainsched convert`` turns a PX4 ULog into the project's format with a map beside
the shipped ones, and nothing reaches back into the checkout.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from gainsched.analysis.logs import load_channel_map, read_log
from gainsched.config import load_config
from gainsched.rotations import matrix_from_quaternion, quaternion_from_matrix
from gainsched.schedule.cached import cached_table_path

from support import PAPER_H5, small_config_text, write_ulog

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
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {f"gainsched/configs/{p.name}" for p in (ROOT / "configs").glob("*.toml")} <= names
    maps = "gainsched/analysis/logs/maps"
    assert {f"{maps}/px4.toml", f"{maps}/ros2.toml"} <= names
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
        "gainsched_runtime.h", "gainsched_trig.h", "wheel.h5", "wheel_control.h",
        "wheel_gains.h"]
    run("inspect", "out/wheel.h5")
    run("export-c", "out/wheel.h5", "-o", "fw")
    run("simulate", cfg, "--tables", "out/wheel.h5", "--scenario", "braking", "-o", "sim")
    assert (work / "sim" / "metrics.json").is_file()
    shipped = subprocess.run([sys.executable, "-c", "import gainsched as gs; "
                              "print(gs.load_config('paper').sha256)"], cwd=work, env=env,
                             capture_output=True, text=True)
    assert shipped.stdout.strip() == load_config(ROOT / "configs/paper.toml").sha256, shipped
    seeded = tmp_path / "cache" / "tables" / cached_table_path(load_config("paper")).name
    seeded.parent.mkdir(parents=True)
    shutil.copyfile(PAPER_H5, seeded)
    res = run("paper", "--quick", "-o", "rep")
    assert (work / "rep" / "report.json").is_file() and "built" not in res.stderr
    # a PX4 ULog of the example flight (NED/FRD, normalised commands) through the shipped
    # px4 map (its gyro and accelerometer channels left out)
    (log,) = read_log(ROOT / "examples/flights/v9.csv")
    ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    q = quaternion_from_matrix(ned @ matrix_from_quaternion(log.q) @ np.diag([1.0, -1, -1]))
    us = np.round((log.t + 5.0) * 1e6).astype(np.uint64)
    p_ned = log.p_I @ ned.T
    ctl = log.T_cmd[:, [3, 1, 0, 2]] / 3.5  # PX4's motors 1..4 are the tool's 4, 2, 1, 3
    write_ulog(work / "v9.ulg", {
        "vehicle_local_position": {"timestamp": us, "x": p_ned[:, 0], "y": p_ned[:, 1],
                                   "z": p_ned[:, 2]},
        "vehicle_attitude": {"timestamp": us, **{f"q[{j}]": q[:, j] for j in range(4)}},
        "actuator_motors": {"timestamp": us, **{f"control[{j}]": ctl[:, j] for j in range(4)}},
    }, {"THR_MDL_FAC": 0.0})
    shipped_px4 = Path(load_channel_map("px4").source).read_text()
    (work / "map.toml").write_text(shipped_px4.split("[gyro]")[0] + "[motors]" +
                                   shipped_px4.split("[motors]")[1])
    res = run("convert", "v9.ulg", "-o", "v9.csv", "--map", "map.toml", "--config", "paper")
    assert "motors: actuator_motors" in res.stdout and (work / "v9.csv").is_file()
    assert not (ROOT / "sim").exists()
