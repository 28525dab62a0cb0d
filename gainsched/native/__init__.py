"""Compiled compute kernels: small C files built with the system compiler on first use.

The heavy inner loops (Riccati recursion, plant integration) are short
fixed-size C programs in ``gainsched/firmware/c/`` (``riccati.c``, ``plant.c``...). No
library on the package registry does a batched small-matrix Riccati step or a
tethered-quadcopter RK4 step, and numpy's per-call overhead dominates at these
sizes, hence hand-written C. They are compiled once per machine with the host
``cc`` into a cache directory and loaded with ctypes; every kernel has a numpy
fallback that computes the same thing, used when no compiler is present or
``GAINSCHED_NATIVE=0``.

Vector width: a kernel is built for this CPU's widest vector unit it can use
(:func:`vector_flags`: AVX-512, AVX2, else the SSE2/NEON baseline) and told the
width in doubles (``GS_VEC_DOUBLES``); the Riccati kernel computes that many
independent operating points per instruction. Building for one ISA (rather
than GCC ``target_clones`` of all of them) keeps the first-use compile at a
few seconds and lets each ISA use its own register width.

Determinism: the flags keep IEEE semantics (no ``-ffast-math``, no FMA
contraction, no ``-march=native``) and the vector width only changes how many
points share an instruction, never the order of the operations of one point,
so a kernel gives the same bits on any x86-64 machine whatever its vector unit
(checked in ``tests/schedule/test_lqr.py`` by building every variant the host can run).

Cache: ``$GAINSCHED_CACHE`` or ``$XDG_CACHE_HOME/gainsched`` (default
``~/.cache/gainsched``); the library name carries a hash of the source, the
flags and the compiler version, and is written atomically, so concurrent
builders (joblib workers) never see a half-written file.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from functools import cache
from importlib import resources
from pathlib import Path

__all__ = ["CFLAGS", "VECTOR_ISAS", "load", "available", "build", "cache_dir", "vector_flags",
           "vector_variants", "cpu_flags", "find_cc"]

CFLAGS = ("-O3", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off", "-fno-math-errno",
          "-fno-semantic-interposition")

#: x86-64 vector ISAs the kernels are built for, widest first: (cpuinfo flag, doubles
#: per register). Without any of them: the baseline (SSE2 on x86-64, NEON on arm64).
VECTOR_ISAS = (("avx512f", 8), ("avx2", 4))
BASELINE_DOUBLES = 2


def cache_dir() -> Path:
    """Directory of the compiled kernels."""
    env = os.environ.get("GAINSCHED_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "gainsched"


def _enabled() -> bool:
    return os.environ.get("GAINSCHED_NATIVE", "1") not in ("0", "false", "no", "off")


def _cc_version(cc: str) -> str:
    try:
        res = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return res.stdout.splitlines()[0] if res.returncode == 0 and res.stdout else ""


@cache
def cpu_flags() -> frozenset[str]:
    """The CPU feature flags the kernel reports (Linux x86-64; empty elsewhere)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return frozenset()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    return frozenset(line.split(":", 1)[1].split())
    except OSError:
        pass
    return frozenset()


def vector_variants() -> list[tuple[str, ...]]:
    """Flags of every vector variant this CPU can run, widest first, baseline last."""
    cpu = cpu_flags()
    out = [(f"-m{isa}", f"-DGS_VEC_DOUBLES={w}") for isa, w in VECTOR_ISAS if isa in cpu]
    return out + [(f"-DGS_VEC_DOUBLES={BASELINE_DOUBLES}",)]


def vector_flags() -> tuple[str, ...]:
    """Flags for this CPU's widest vector unit, e.g. ``("-mavx2", "-DGS_VEC_DOUBLES=4")``."""
    return vector_variants()[0]


def find_cc(cross: bool = False) -> str | None:
    """The host C compiler (``$CC``, cc, gcc, clang), or arm-none-eabi-gcc with ``cross``."""
    if cross:
        return shutil.which("arm-none-eabi-gcc")
    for cand in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cand and shutil.which(cand):
            return cand
    return None


def build(name: str, flags: tuple[str, ...] = ()) -> Path | None:
    """Compile ``gainsched/firmware/c/<name>.c`` with :data:`CFLAGS` plus ``flags`` (cached).

    Returns the shared library's path, or None if there is no working compiler or the
    compile fails (an unknown ``-m`` flag on an old compiler, say).
    """
    cc = find_cc()
    if cc is None:
        return None
    src = resources.files("gainsched.native").joinpath(f"{name}.c").read_text()
    version = _cc_version(cc)
    if not version:
        return None
    cmd = CFLAGS + tuple(flags)
    key = hashlib.sha256("\0".join([src, " ".join(cmd), version]).encode()).hexdigest()[:16]
    out = cache_dir() / f"{name}-{key}.so"
    if not out.exists():
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
                c_file = Path(tmp) / f"{name}.c"
                c_file.write_text(src)
                tmp_so = Path(tmp) / out.name
                res = subprocess.run([cc, *cmd, str(c_file), "-o", str(tmp_so), "-lm"],
                                     capture_output=True, text=True, timeout=300)
                if res.returncode != 0:
                    return None
                os.replace(tmp_so, out)  # atomic: other processes see all or nothing
        except (OSError, subprocess.TimeoutExpired):
            return None
    return out


@cache
def _load(name: str) -> ctypes.CDLL | None:
    # the host's vector variant, else the baseline (a compiler without the -m flag)
    variants = vector_variants()
    for flags in dict.fromkeys([variants[0], variants[-1]]):
        path = build(name, flags)
        if path is not None:
            try:
                return ctypes.CDLL(str(path))
            except OSError:
                continue
    return None


def load(name: str) -> ctypes.CDLL | None:
    """The compiled kernel library ``gainsched/firmware/c/<name>.c``, or None (use the fallback)."""
    return _load(name) if _enabled() else None


def available(name: str) -> bool:
    """Whether :func:`load` gives a compiled library for ``name``."""
    return load(name) is not None
