"""Compiled compute kernels: small C files built with the system compiler on first use.

The heavy inner loops (Riccati recursion, plant integration) are short
fixed-size C programs in ``gainsched/c/`` (``riccati.c``, ``plant.c``...). No
library on the package registry does a batched small-matrix Riccati step or a
tethered-quadcopter RK4 step, and numpy's per-call overhead dominates at these
sizes, hence hand-written C. They are compiled once per machine with the host
``cc`` into a cache directory and loaded with ctypes; every kernel has a numpy
fallback that computes the same thing, used when no compiler is present or
``GAINSCHED_NATIVE=0``.

Determinism: the flags keep IEEE semantics (no ``-ffast-math``, no FMA
contraction, no ``-march=native``), so a kernel gives the same bits on any
x86-64 machine; vector code paths (``target_clones``) only change how many
independent points are computed per instruction, never the order of the
operations of one point.

Cache: ``$GAINSCHED_CACHE`` or ``$XDG_CACHE_HOME/gainsched`` (default
``~/.cache/gainsched``); the library name carries a hash of the source, the
flags and the compiler version, and is written atomically, so concurrent
builders (joblib workers) never see a half-written file.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
import tempfile
from functools import cache
from importlib import resources
from pathlib import Path

__all__ = ["CFLAGS", "load", "available", "cache_dir"]

CFLAGS = ("-O3", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off", "-fno-math-errno",
          "-fno-semantic-interposition")  # fmt: skip


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
def _load(name: str) -> ctypes.CDLL | None:
    from .codegen import find_cc

    cc = find_cc()
    if cc is None:
        return None
    src = resources.files("gainsched").joinpath("c", f"{name}.c").read_text()
    version = _cc_version(cc)
    if not version:
        return None
    key = hashlib.sha256("\0".join([src, " ".join(CFLAGS), version]).encode()).hexdigest()[:16]
    out = cache_dir() / f"{name}-{key}.so"
    if not out.exists():
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
                c_file = Path(tmp) / f"{name}.c"
                c_file.write_text(src)
                tmp_so = Path(tmp) / out.name
                res = subprocess.run([cc, *CFLAGS, str(c_file), "-o", str(tmp_so), "-lm"],
                                     capture_output=True, text=True, timeout=300)  # fmt: skip
                if res.returncode != 0:
                    return None
                os.replace(tmp_so, out)  # atomic: other processes see all or nothing
        except (OSError, subprocess.TimeoutExpired):
            return None
    try:
        return ctypes.CDLL(str(out))
    except OSError:
        return None


def load(name: str) -> ctypes.CDLL | None:
    """The compiled kernel library ``gainsched/c/<name>.c``, or None (use the fallback)."""
    return _load(name) if _enabled() else None


def available(name: str) -> bool:
    """Whether :func:`load` gives a compiled library for ``name``."""
    return load(name) is not None
