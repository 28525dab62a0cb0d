"""Schedulers: the gain lookups a simulated flight takes its gains (and the firmware's
nominal and controller) from."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..firmware.feedforward import FeedForward, feedforward
from ..firmware.runtime import BAD_ARG

__all__ = [
    "table_scheduler",
    "c_runtime_scheduler",
    "RUNTIMES",
    "runtime_scheduler",
]


def table_scheduler(table):
    """Gain lookup of a table through the Python reference of the C runtime, for simulate.

    The lookup is :class:`~gainsched.firmware.runtime.Interpolator`, the reference
    implementation of the firmware's ``gainsched_runtime.c`` (the same cell, weights,
    mirroring and status bits, in float32), one query per call.

    Parameters
    ----------
    table : Table, RuntimeData or CompactData
        The gain schedule (:func:`~gainsched.schedule.tables.load_table`), its dense
        runtime form (:func:`gainsched.firmware.runtime.runtime_data`) or its compact
        form (:func:`gainsched.firmware.compact.compact_data`, looked up by
        :class:`~gainsched.firmware.compact.CompactInterpolator`).

    Returns
    -------
    callable
        ``lookup(xi, xi_dot, alpha) -> (K, status)``: at the azimuth xi (rad), the azimuth
        rate xi_dot (rad/s) and the tilt alpha (rad), the gains ``K``, ndarray of shape
        (4, n) (N per unit of LQR state: rad, rad/s, rad s), and the status bits (int;
        0: OK, 0x01 ``CLAMPED_SPEED``: outside the table's speeds, ...; see
        :func:`gainsched.firmware.runtime.status_text`). Its attributes:
        ``lookup.batch(xi, xi_dot, alpha) -> (K (m, 4, n), status (m,) int)``, the same
        numbers for arrays of m queries; ``lookup.interp``, the
        :class:`~gainsched.firmware.runtime.Interpolator`;
        ``lookup.feedforward(path, alpha)``, the firmware's nominal along a reference
        (``simulate(..., controller="firmware")``).

    Examples
    --------
    >>> table = gs.load_table("tables/paper.h5")
    >>> lookup = gs.table_scheduler(table)
    >>> K, status = lookup(0.5, 9.0 / 1.6, 0.0)  # 9 m/s on the level circle, r = 1.6 m
    >>> K.shape, status
    ((4, 11), 0)
    >>> K, status = lookup(0.5, 32.0 / 1.6, 0.0)  # 32 m/s: clamped to the fastest speed
    >>> status
    1
    >>> xi = np.linspace(0.0, 2 * np.pi, 5)  # one lap, in one call
    >>> K, status = lookup.batch(xi, np.full(5, 9.0 / 1.6), np.deg2rad(20.0))
    >>> K.shape, status.tolist()
    ((5, 4, 11), [0, 0, 0, 0, 0])
    """
    from ..firmware.compact import CompactData, CompactInterpolator
    from ..firmware.controller import Controller
    from ..firmware.runtime import Interpolator

    interp = CompactInterpolator(table) if isinstance(table, CompactData) else Interpolator(table)
    query = interp.query  # one query per call: the scalar fast path

    def lookup(xi, xi_dot, alpha):
        K, _, _, status = query(xi, xi_dot, alpha)
        return K, status

    def batch(xi, xi_dot, alpha):
        """Arrays of queries (m,) -> K (m, 4, n), status (m,) int: the same numbers."""
        r = interp(xi, xi_dot, alpha)
        return r.K, r.status.astype(int)

    lookup.batch = batch
    lookup.interp = interp
    # the firmware's nominal along a reference (simulate(controller="firmware"))
    lookup.feedforward = lambda path, alpha: feedforward(interp, path, alpha)
    # the firmware's whole loop (simulate(controller="firmware")): the Python reference
    lookup.controller = lambda params: Controller(params, interp)
    lookup.data = interp.data  # the table it flies (controller_params sizes from it)
    return lookup


def c_runtime_scheduler(table, build_dir=None):
    """Gain lookup through the compiled C runtime (the firmware code): (xi, xi_dot, alpha)
    -> (K (4, n) float64 of the runtime's float32 gains, status int).

    The table, ``gainsched_runtime.c`` and the batch shim are compiled for the host with
    :func:`gainsched.firmware.codegen.build_host` into ``build_dir`` (default: a temporary
    directory that lives as long as the returned function) and called through ctypes,
    one query per call with preallocated buffers. Raises RuntimeError without a C
    compiler.

    Parameters
    ----------
    table : Table, RuntimeData or CompactData
        The table, in the format the firmware holds (a loaded table: the dense one).
    build_dir : path, optional
    """
    import ctypes
    import tempfile

    from ..firmware.codegen import CRuntime, build_host, firmware_data

    data = firmware_data(table)
    tmp = None
    if build_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="gainsched-rt-")
        build_dir = tmp.name
    rt = CRuntime(build_host(data, Path(build_dir)), data)
    n = data.dims[3]
    q = np.zeros(3, dtype=np.float32)
    Kb = np.zeros((4, n), dtype=np.float32)
    Ub = np.zeros(4, dtype=np.float32)
    Pb = np.zeros(1, dtype=np.float32)
    Sb = np.zeros(1, dtype=np.int32)
    # our own function object with raw pointers (CRuntime's ndpointer argtypes cost
    # microseconds of checks per call); the pointers stay valid: the buffers live here
    fn = rt.lib[f"{data.name}_lookup_batch"]
    fn.restype = None
    fn.argtypes = [ctypes.c_size_t] + [ctypes.c_void_p] * 5
    ptrs = [b.ctypes.data for b in (q, Kb, Ub, Pb, Sb)]

    def lookup(xi, xi_dot, alpha):
        q[0], q[1], q[2] = xi, xi_dot, alpha
        fn(1, *ptrs)
        return Kb.astype(np.float64), int(Sb[0])

    def nominal(path, alpha):
        """``gs_lookup_nominal`` along a reference: the gains and the firmware's nominal
        (:class:`~gainsched.firmware.feedforward.FeedForward` with ``K``), all from C."""
        ref = np.stack([path.xi, *path.d], axis=1)
        K, U, X, T, S = rt.nominal(ref, alpha)
        if np.any(S & BAD_ARG):
            raise InputError(str(data.name), "vehicle", "the table carries no closed-form "
                             "constants: no manoeuvre feed-forward")
        return FeedForward(X.astype(np.float64), U.astype(np.float64), T.astype(np.float64),
                           S.astype(int), K)

    lookup.feedforward = nominal
    built = {}

    def controller(params):
        """The C controller with ``params`` (gainsched_control.c; compiled once)."""
        from ..firmware.sil import CController, build_controller

        if "lib" not in built:
            built["lib"] = build_controller(data, params, Path(build_dir) / "control")
        return CController(data, params, lib_path=built["lib"])

    lookup.controller = controller
    lookup.data = data  # the table it flies (controller_params sizes from it)
    lookup.runtime = rt  # keeps the library (and the temporary directory) alive
    lookup.build_dir = tmp
    return lookup


#: where the simulator's firmware takes its lookups and feed-forward from
RUNTIMES = ("auto", "c", "python")


def runtime_scheduler(table, runtime: str = "auto"):
    """The gain source of a simulated flight: the compiled C runtime or its Python reference.

    The C runtime flies the very code that goes on the vehicle (``gainsched_runtime.c``
    with the table, compiled for the host); its Python reference mirrors it in float32
    arithmetic and needs no compiler.

    Parameters
    ----------
    table : Table or RuntimeData
        The gain schedule (:func:`~gainsched.schedule.tables.load_table`).
    runtime : {"auto", "c", "python"}, default "auto"
        ``"c"``: the compiled C runtime, the firmware's own code
        (:func:`c_runtime_scheduler`: gains and the firmware's nominal from
        ``gs_lookup_nominal``; compiled for the host, a second or two); ``"python"``: its
        Python reference (:func:`table_scheduler`); ``"auto"``: the C runtime when a C
        compiler is found (``CC``), else the reference.

    Returns
    -------
    callable
        A scheduler for :func:`simulate`, ``(xi, xi_dot, alpha) -> (K (4, n), status)``
        (see :func:`table_scheduler`), with ``feedforward`` for
        ``controller="firmware"``; its ``source`` (str) says which runtime it is:
        ``"C runtime (gs_lookup_nominal)"`` or ``"Python reference of the C runtime"``.

    Raises
    ------
    InputError
        ``runtime`` is not one of :data:`RUNTIMES`, or ``"c"`` without a C compiler.

    Examples
    --------
    A flight on what the firmware has: the table's gains and feed-forward only.

    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> sched = gs.runtime_scheduler(gs.load_table("tables/paper.h5"), "python")
    >>> sched.source
    'Python reference of the C runtime'
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> res = gs.simulate(cfg, sched, scn, controller="firmware")
    >>> int(res.status.max()), bool(res.held.any()), bool(res.saturated.any())
    (0, False, False)
    """
    from ..native import find_cc

    if runtime not in RUNTIMES:
        raise InputError("--runtime", runtime, f"must be one of {', '.join(RUNTIMES)}")
    if runtime == "c" or (runtime == "auto" and find_cc() is not None):
        if find_cc() is None:
            raise InputError("--runtime", "c", "no C compiler found (set CC)")
        sched = c_runtime_scheduler(table)
        sched.source = "C runtime (gs_lookup_nominal)"
    else:
        sched = table_scheduler(table)
        sched.source = "Python reference of the C runtime"
    return sched
