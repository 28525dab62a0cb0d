"""The C lookup on the host: a table compiled with the runtime and the batch shim
(``templates/batch.in.c``) by :func:`build_host`, into a shared library that
:class:`CRuntime` calls through ctypes or a driver program (tests, benchmarks,
``make fuzz``'s sanitizers).
"""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..cfiles import copy_runtime, write_file, write_header
from ..header import firmware_data
from ..runtime import Lookup, RuntimeData
from ..sources import render
from .compiler import STRICT_CFLAGS, compile_or_raise, require_cc

__all__ = ["build_host", "CRuntime", "NominalBatch", "TrigBatch"]


class NominalBatch(NamedTuple):
    """What :meth:`CRuntime.nominal` returns: float32 outputs of ``gs_lookup_nominal``
    for m references."""

    #: (m, 4, n) gains
    K: np.ndarray
    #: (m, 4) nominal thrusts, N
    u_d: np.ndarray
    #: (m, 10) nominal state
    x_d: np.ndarray
    #: (m,) tether tension, N
    tension: np.ndarray
    #: (m,) int32 status bits
    status: np.ndarray


class TrigBatch(NamedTuple):
    """What :meth:`CRuntime.trig` returns: the runtime's own functions on (m,) float32."""

    #: ``gs_sincosf(x)``
    sin: np.ndarray
    cos: np.ndarray
    #: ``gs_atan2f(y, x)``
    atan2: np.ndarray
    #: ``gs_sqrtf(x)``
    sqrt: np.ndarray


def build_host(
    table, out_dir, *, cc=None, opt="-O2", sanitize=False, shared=True, extra=()
) -> Path:
    """Compile the table, the runtime and the batch shim for the host.

    ``shared``: a shared library for :class:`CRuntime`; otherwise the driver program
    (``batch``/``bench``/``verify`` modes, see ``templates/batch.in.c``). ``sanitize``
    adds AddressSanitizer + UndefinedBehaviorSanitizer (abort on the first report).
    Compiles with the strict warning set and -Werror. Returns the built file.
    """
    data = firmware_data(table)
    cc = require_cc(cc)
    out_dir = Path(out_dir)
    header = write_header(data, out_dir)
    runtime_c = copy_runtime(out_dir).runtime_c
    shim = out_dir / f"{data.name}_batch.c"
    write_file(
        shim,
        render(
            "batch.in.c",
            name=data.name,
            NAME=data.name.upper(),
            tool_version=data.meta.get("tool_version", "?"),
        ),
    )
    flags = [*STRICT_CFLAGS, opt, "-g", f"-I{out_dir}", *extra]
    if sanitize:
        flags += [
            "-fsanitize=address,undefined",
            "-fno-sanitize-recover=all",
            "-fno-omit-frame-pointer",
        ]
    suffix = "_san" if sanitize else ""
    if shared:
        out = out_dir / f"lib{data.name}_batch{suffix}.so"
        flags += ["-shared", "-fPIC"]
    else:
        out = out_dir / f"{data.name}_batch{suffix}"
        flags += ["-DGS_BATCH_MAIN"]
    cmd = [cc, *flags, "-o", str(out), str(shim), str(runtime_c)]
    compile_or_raise(cmd)
    assert header.exists()
    return out


class CRuntime:
    """The C runtime with one table, loaded through ctypes (a :func:`build_host` library)."""

    def __init__(self, lib_path, data: RuntimeData):
        self.data = data
        self.lib = lib = ctypes.CDLL(str(lib_path))
        nm = data.name
        self._batch = getattr(lib, f"{nm}_lookup_batch")
        self._batch.restype = None
        fp = np.ctypeslib.ndpointer(np.float32, flags="C_CONTIGUOUS")
        ip = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
        self._batch.argtypes = [ctypes.c_size_t, fp, fp, fp, fp, ip]
        self._verify = getattr(lib, f"{nm}_verify_table")
        self._verify.restype = ctypes.c_int
        self._crc = getattr(lib, f"{nm}_crc32")
        self._crc.restype = ctypes.c_uint32
        self._flip = getattr(lib, f"{nm}_verify_flipped")
        self._flip.argtypes = [ctypes.c_int, ctypes.c_size_t, ctypes.c_uint]
        self._flip.restype = ctypes.c_int
        self._bench = getattr(lib, f"{nm}_bench")
        self._bench.argtypes = [ctypes.c_size_t, fp, ctypes.c_int]
        self._bench.restype = ctypes.c_double
        self._nominal = getattr(lib, f"{nm}_nominal_batch")
        self._nominal.restype = None
        self._nominal.argtypes = [ctypes.c_size_t, fp, fp, fp, fp, fp, ip]
        self._trig = getattr(lib, f"{nm}_trig_batch")
        self._trig.restype = None
        self._trig.argtypes = [ctypes.c_size_t] + [fp] * 6
        self._bench_nominal = getattr(lib, f"{nm}_bench_nominal")
        self._bench_nominal.argtypes = [ctypes.c_size_t, fp, ctypes.c_int]
        self._bench_nominal.restype = ctypes.c_double
        self._ftz = getattr(lib, f"{nm}_flush_to_zero")
        self._ftz.argtypes = [ctypes.c_int]
        self._ftz.restype = ctypes.c_int
        self._queries = getattr(lib, f"{nm}_bench_queries")
        self._queries.argtypes = [ctypes.c_size_t, ctypes.c_uint32, fp]
        self._queries.restype = None

    def lookup(self, xi, xi_dot, alpha) -> Lookup:
        """Batched C lookups (one ctypes call); same shapes as the Python reference."""
        shape = np.broadcast_shapes(np.shape(xi), np.shape(xi_dot), np.shape(alpha))
        with np.errstate(over="ignore", invalid="ignore"):
            q = np.stack(
                [
                    np.broadcast_to(np.asarray(v, dtype=np.float32), shape).reshape(-1)
                    for v in (xi, xi_dot, alpha)
                ],
                axis=1,
            )
        q = np.ascontiguousarray(q)
        m, n = q.shape[0], self.data.dims[3]
        K = np.full((m, 4 * n), np.float32(12345.0))  # sentinel: must be overwritten
        U = np.full((m, 4), np.float32(12345.0))
        P = np.full(m, np.float32(12345.0))
        S = np.full(m, -1, dtype=np.int32)
        self._batch(m, q, K, U, P, S)
        return Lookup(
            K.reshape(shape + (4, n)), U.reshape(shape + (4,)), P.reshape(shape), S.reshape(shape)
        )

    __call__ = lookup

    def nominal(self, ref, alpha):
        """Batched ``gs_lookup_nominal``: references ``ref`` (m, 5) (xi rad, xi' rad/s,
        xi'' rad/s^2, xi''' rad/s^3, xi'''' rad/s^4) at tilts ``alpha`` (m,) or scalar, rad.

        Returns the :class:`NominalBatch`: ``K`` (m, 4, n), ``u_d`` (m, 4) N, ``x_d``
        (m, 10), ``tension`` (m,) N, ``status`` (m,), float32 outputs of the runtime.
        """
        ref = np.asarray(ref, dtype=np.float64).reshape(-1, 5)
        m, n = ref.shape[0], self.data.dims[3]
        with np.errstate(over="ignore", invalid="ignore"):
            q = np.empty((m, 6), dtype=np.float32)
            q[:, :5] = ref
            q[:, 5] = np.broadcast_to(np.asarray(alpha, dtype=np.float64), (m,))
        K = np.full((m, 4 * n), np.float32(12345.0))  # sentinel: must be overwritten
        U = np.full((m, 4), np.float32(12345.0))
        X = np.full((m, 10), np.float32(12345.0))
        T = np.full(m, np.float32(12345.0))
        S = np.full(m, -1, dtype=np.int32)
        self._nominal(m, q, K, U, X, T, S)
        return NominalBatch(K.reshape(m, 4, n), U, X, T, S)

    def trig(self, x, y):
        """The runtime's ``gs_sincosf(x)``, ``gs_atan2f(y, x)``, ``gs_sqrtf(x)`` on float32
        arrays of one shape (m,): a :class:`TrigBatch`."""
        x = np.ascontiguousarray(x, dtype=np.float32).reshape(-1)
        y = np.ascontiguousarray(y, dtype=np.float32).reshape(-1)
        out = [np.empty_like(x) for _ in range(4)]
        self._trig(x.size, x, y, *out)
        return TrigBatch(*out)

    def flush_to_zero(self, on: bool) -> bool:
        """Flush-to-zero and denormals-are-zero on or off for the calling thread (x86
        MXCSR, as FPSCR.FZ on a Cortex-M4F); False where the host has no such switch."""
        return bool(self._ftz(int(on)))

    def verify(self) -> int:
        return int(self._verify())

    def crc32(self) -> int:
        return int(self._crc())

    def verify_flipped(self, which: int, byte: int, flip: int = 0x01) -> int:
        """``gs_verify`` on a copy with one byte of array ``which`` (CRC order) flipped."""
        return int(self._flip(which, byte, flip))

    def bench_queries(self, m: int, seed: int = 12345) -> np.ndarray:
        q = np.zeros((m, 3), dtype=np.float32)
        self._queries(m, seed, q)
        return q

    def bench(self, q, reps: int = 1, *, nominal: bool = False) -> float:
        """``reps`` passes of lookups over queries ``q`` (m, 3); ``nominal``: with
        ``gs_lookup_nominal`` (derivatives of ``<name>_bench_reference``). Checksum."""
        q = np.ascontiguousarray(q, dtype=np.float32)
        fn = self._bench_nominal if nominal else self._bench
        return float(fn(q.shape[0], q, reps))
