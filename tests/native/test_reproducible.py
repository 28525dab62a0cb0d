"""Byte-identical tables on every machine (issue 12; gainsched.native.reproducible).

One machine stands in for many: numpy's OpenBLAS and numpy's SIMD dispatch are
switched to other CPU families with ``OPENBLAS_CORETYPE`` and
``NPY_DISABLE_CPU_FEATURES`` (the families this CPU can run), combined with
BLAS thread counts and every local backend. Each combination builds the same
config in a fresh process; all outputs (HDF5, header, runtime) must equal the
reference build of this test process bit for bit. A control run with the pin
switched off shows that those families really round differently, i.e. that the
comparison has the power to fail.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gainsched.config import load_config
from gainsched.model.reduced import Model
from gainsched.native import cpu_flags, reproducible
from gainsched.schedule.grid import build_grid
from gainsched.schedule.tables import table_bytes

from support import auto_text, small_config_text

#: OpenBLAS kernel families and the CPU flags they need
FAMILIES = {
    "Haswell": ("avx2", "fma"),
    "Zen": ("avx2", "fma"),
    "SkylakeX": ("avx512f", "avx512bw", "avx512dq", "avx512vl", "avx512cd"),
    "Sandybridge": ("avx",),
    "Nehalem": ("sse4_2",),
    "Prescott": ("pni",),  # SSE3 is "pni" in /proc/cpuinfo
}
OUTPUTS = ("gainsched_control.c", "gainsched_control.h", "gainsched_runtime.c",
           "gainsched_runtime.h", "gainsched_trig.h", "det.h5", "det_control.h", "det_gains.h")
#: (kernel family, BLAS threads, numpy dispatch switched off, build options)
MATRIX = [
    ("Haswell", "2", "", ("-j", "2")),
    ("Zen", "1", "", ("--backend", "sequential")),
    ("SkylakeX", "2", "", ("--backend", "threading", "-j", "2")),
    ("Sandybridge", "2", "X86_V3", ("-j", "1")),
    ("Nehalem", "1", "X86_V3", ("-j", "2")),
    ("Prescott", "2", "", ("--backend", "threading", "-j", "2")),
]

pytestmark = pytest.mark.skipif(
    not reproducible.pin_available(), reason="no pin on this CPU (needs x86-64, AVX2, FMA)"
)


def _runs(family: str) -> bool:
    return all(f in cpu_flags() for f in FAMILIES[family])


def _env(family, threads, npy_off, **extra):
    env = {k: v for k, v in os.environ.items() if k not in reproducible.PINNED_ENV}
    env.update(OPENBLAS_CORETYPE=family, OPENBLAS_NUM_THREADS=threads, OMP_NUM_THREADS=threads,
               **extra)
    if npy_off:
        env["NPY_DISABLE_CPU_FEATURES"] = npy_off
    return env


def _cli_build(cfg_path: Path, out: Path, options, env) -> bytes:
    cmd = [sys.executable, "-m", "gainsched", "build", str(cfg_path), "-o", str(out), *options]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUTS)
    return b"".join((out / n).read_bytes() for n in OUTPUTS)


@pytest.fixture(scope="module")
def det(tmp_path_factory):
    """A small config with tilt 0 (DARE) and tilted circles (periodic recursion, doubling,
    interpolated linearisation), its in-process table bytes and its CLI build here."""
    d = tmp_path_factory.mktemp("det")
    path = d / "det.toml"
    path.write_text(small_config_text(grid__speeds=[4, 9, 15], grid__tilts_deg=[0, 20, 35],
                                      name="det"))
    cfg = load_config(path)
    data = table_bytes(cfg, build_grid(cfg, n_jobs=2), Model(cfg))
    ref = _cli_build(path, d / "ref", ("-j", "2"), dict(os.environ))
    return path, data, ref


@pytest.mark.slow
def test_in_process_build_equals_cli_build(det):
    """The library (pinned pool or pinned process) and the command agree."""
    path, data, ref = det
    assert (path.parent / "ref" / "det.h5").read_bytes() == data


@pytest.mark.slow
@pytest.mark.parametrize("family, threads, npy_off, options", MATRIX,
                         ids=[f"{m[0]}-{m[1]}thr-{'_'.join(m[3])}" for m in MATRIX])
def test_same_bytes_on_every_kernel_family_thread_count_backend(det, tmp_path, family, threads,
                                                                npy_off, options):
    if not _runs(family):
        pytest.skip(f"this CPU cannot run the {family} kernels")
    path, _, ref = det
    got = _cli_build(path, tmp_path / "out", options, _env(family, threads, npy_off))
    assert got == ref, f"{family}, {threads} BLAS threads, {options}: table bits differ"


_LIBRARY_BUILD = """
import hashlib, sys
from gainsched.native import reproducible
from gainsched.native import cpu_flags
from gainsched.config import load_config
from gainsched.schedule.grid import build_grid
from gainsched.model.reduced import Model
from gainsched.schedule.tables import table_bytes
assert not reproducible.process_pinned(), reproducible.fingerprint()
cfg = load_config(sys.argv[1])
print(hashlib.sha256(table_bytes(cfg, build_grid(cfg, n_jobs=1), Model(cfg))).hexdigest())
"""


@pytest.mark.slow
def test_unpinned_process_builds_in_pinned_workers(det):
    """A Python session whose numpy runs other kernels (Sandybridge BLAS, no AVX2 loops)
    still gets the reference table: build_grid sends the circles to pinned workers."""
    path, data, _ = det
    env = _env("Sandybridge", "2", "X86_V3")
    res = subprocess.run([sys.executable, "-c", _LIBRARY_BUILD, str(path)], env=env,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == hashlib.sha256(data).hexdigest()


@pytest.mark.slow
def test_the_matrix_can_fail(det, tmp_path):
    """Control: with the pin off, Sandybridge kernels (AVX, no FMA) change the bits. Were
    they equal, the matrix above would prove nothing about kernel families."""
    path, _, _ = det
    off = dict(GAINSCHED_PIN="0")
    a = _cli_build(path, tmp_path / "a", ("-j", "1"), _env("Haswell", "1", "", **off))
    b = _cli_build(path, tmp_path / "b", ("-j", "1"), _env("Sandybridge", "1", "", **off))
    assert a != b


def test_pin_environ_and_fingerprint():
    env = {"OPENBLAS_CORETYPE": "SkylakeX"}
    assert reproducible.pin_environ(env) is True
    assert env == reproducible.PINNED_ENV
    assert "Haswell" in reproducible.fingerprint() or not reproducible.process_pinned()
    assert reproducible.status()


def test_pin_off_switch(monkeypatch):
    monkeypatch.setenv("GAINSCHED_PIN", "0")
    env: dict[str, str] = {}
    assert reproducible.pin_environ(env) is False and env == {}


@pytest.fixture(scope="module")
def det_auto(tmp_path_factory):
    """A config whose axes the build chooses (issue 23), and its CLI build here."""
    d = tmp_path_factory.mktemp("det_auto")
    path = d / "det.toml"
    path.write_text(auto_text(name="det"))
    return path, _cli_build(path, d / "ref", ("-j", "2"), dict(os.environ))


@pytest.mark.slow
@pytest.mark.parametrize("family, threads, npy_off, options", [MATRIX[3], MATRIX[2]],
                         ids=["Sandybridge-noAVX2-j1", "SkylakeX-threading-j2"])
def test_chosen_grid_same_bytes_on_other_kernel_families(det_auto, tmp_path, family, threads,
                                                         npy_off, options):
    """The refinement's decisions and its circles do not depend on the kernels either."""
    if not _runs(family):
        pytest.skip(f"this CPU cannot run the {family} kernels")
    path, ref = det_auto
    got = _cli_build(path, tmp_path / "out", options, _env(family, threads, npy_off))
    assert got == ref, f"{family}, {threads} BLAS threads, {options}: chosen table bits differ"
