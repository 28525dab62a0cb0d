"""Schedulers: the gain lookups a simulated flight takes its gains (and the firmware's
nominal and controller) from.

:class:`Scheduler` is the interface :func:`~gainsched.sim.loop.simulate` flies: the
firmware's lookups as methods. :class:`TableScheduler` answers them with the Python
reference of the C runtime, :class:`CRuntimeScheduler` with the compiled C runtime itself;
:func:`table_scheduler`, :func:`c_runtime_scheduler` and :func:`runtime_scheduler` make
them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..errors import InputError
from ..firmware.feedforward import FeedForward, feedforward
from ..firmware.runtime import BAD_ARG

__all__ = [
    "Scheduler",
    "TableScheduler",
    "CRuntimeScheduler",
    "table_scheduler",
    "c_runtime_scheduler",
    "RUNTIMES",
    "runtime_scheduler",
]


class Scheduler(ABC):
    """The firmware's lookups of one gain table, the interface a simulated flight flies.

    Each method is one of the firmware's calls (docs/runtime.md):

    - ``sched(xi, xi_dot, alpha) -> (K, status)`` (``gs_lookup``): at the azimuth xi
      (rad), its rate xi_dot (rad/s) and the tilt alpha (rad), the gains ``K``, ndarray
      of shape (4, n) (N per unit of LQR state), and the lookup's status bits (int);
    - ``sched.batch(xi, xi_dot, alpha) -> (K (m, 4, n), status (m,) int)``: the same
      numbers for arrays of m queries, where ``sched.batched`` is true (the simulator
      then looks the reference's gains up in blocks of steps);
    - ``sched.feedforward(path, alpha)`` (``gs_lookup_nominal``): the firmware's nominal
      along a reference :class:`~gainsched.schedule.path.AzimuthPath`, a
      :class:`~gainsched.firmware.feedforward.FeedForward`;
    - ``sched.controller(params)``: the firmware's whole control step
      (:mod:`gainsched.firmware.controller`) with its
      :class:`~gainsched.firmware.controller.ControllerParams`.

    ``data`` is the table in the firmware's form (``controller_params`` sizes from it);
    ``source`` (str) names the runtime (:func:`runtime_scheduler` sets it; ``"table"``
    otherwise). :func:`~gainsched.sim.loop.simulate` also takes a plain callable
    ``(xi, xi_dot, alpha) -> (K, status)``: the path controller, one lookup per step.

    Examples
    --------
    >>> sched = gs.table_scheduler(gs.load_table("tables/paper.h5"))
    >>> isinstance(sched, gs.Scheduler), sched.batched, sched.source
    (True, True, 'table')
    >>> K, status = sched(0.5, 9.0 / 1.6, 0.0)
    >>> K.shape, status
    ((4, 11), 0)
    """

    #: which runtime answers (``runtime_scheduler`` sets it on the instance)
    source: str = "table"
    #: :meth:`batch` is offered: arrays of queries, the numbers of single queries
    batched: ClassVar[bool] = False
    #: the table flown, in the firmware's form (RuntimeData or CompactData)
    data = None

    @abstractmethod
    def __call__(self, xi, xi_dot, alpha) -> tuple[np.ndarray, int]:
        """``gs_lookup``: the gains K (4, n) and the status bits at one query."""

    def batch(self, xi, xi_dot, alpha) -> tuple[np.ndarray, np.ndarray]:
        """Arrays of queries (m,) -> K (m, 4, n), status (m,) int: the same numbers as
        one call per query (only where :attr:`batched`)."""
        raise NotImplementedError(f"{type(self).__name__} has no batch lookup")

    @abstractmethod
    def feedforward(self, path, alpha: float) -> FeedForward:
        """``gs_lookup_nominal`` along a reference path: the firmware's nominal."""

    @abstractmethod
    def controller(self, params):
        """The firmware's control step with ``params`` (a ``ControllerParams``)."""


class TableScheduler(Scheduler):
    """The Python reference of the C runtime (:func:`table_scheduler` makes one)."""

    batched: ClassVar[bool] = True

    def __init__(self, table):
        from ..firmware.compact import CompactData, CompactInterpolator
        from ..firmware.runtime import Interpolator

        self.interp = (CompactInterpolator(table) if isinstance(table, CompactData)
                       else Interpolator(table))
        self._query = self.interp.query  # one query per call: the scalar fast path
        self.data = self.interp.data  # the table it flies (controller_params sizes from it)

    def __call__(self, xi, xi_dot, alpha):
        K, _, _, status = self._query(xi, xi_dot, alpha)
        return K, status

    def batch(self, xi, xi_dot, alpha):
        r = self.interp(xi, xi_dot, alpha)
        return r.K, r.status.astype(int)

    def feedforward(self, path, alpha):
        return feedforward(self.interp, path, alpha)

    def controller(self, params):
        """The Python reference of the firmware's controller."""
        from ..firmware.controller import Controller

        return Controller(params, self.interp)


class CRuntimeScheduler(Scheduler):
    """The compiled C runtime through ctypes (:func:`c_runtime_scheduler` makes one)."""

    def __init__(self, table, build_dir=None):
        import ctypes
        import tempfile

        from ..firmware.header import firmware_data
        from ..firmware.host.lookup import CRuntime, build_host

        data = firmware_data(table)
        self._tmp = None  # a temporary build directory lives as long as the scheduler
        if build_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="gainsched-rt-")
            build_dir = self._tmp.name
        self.build_dir = Path(build_dir)
        rt = CRuntime(build_host(data, self.build_dir), data)
        n = data.dims[3]
        self._q = np.zeros(3, dtype=np.float32)
        self._K = np.zeros((4, n), dtype=np.float32)
        self._S = np.zeros(1, dtype=np.int32)
        Ub = np.zeros(4, dtype=np.float32)
        Pb = np.zeros(1, dtype=np.float32)
        self._buffers = (Ub, Pb)
        # our own function object with raw pointers (CRuntime's ndpointer argtypes cost
        # microseconds of checks per call); the pointers stay valid: the buffers live here
        fn = rt.lib[f"{data.name}_lookup_batch"]
        fn.restype = None
        fn.argtypes = [ctypes.c_size_t] + [ctypes.c_void_p] * 5
        self._fn = fn
        self._ptrs = [b.ctypes.data for b in (self._q, self._K, Ub, Pb, self._S)]
        self._lib = None  # the C controller's library, compiled on first use
        self.data = data  # the table it flies (controller_params sizes from it)
        self.runtime = rt  # keeps the library alive

    def __call__(self, xi, xi_dot, alpha):
        q = self._q
        q[0], q[1], q[2] = xi, xi_dot, alpha
        self._fn(1, *self._ptrs)
        return self._K.astype(np.float64), int(self._S[0])

    def feedforward(self, path, alpha):
        """``gs_lookup_nominal`` along a reference: the gains and the firmware's nominal
        (:class:`~gainsched.firmware.feedforward.FeedForward` with ``K``), all from C."""
        ref = np.stack([path.xi, *path.d], axis=1)
        K, U, X, T, S = self.runtime.nominal(ref, alpha)
        if np.any(S & BAD_ARG):
            raise InputError(str(self.data.name), "vehicle", "the table carries no "
                             "closed-form constants: no manoeuvre feed-forward")
        return FeedForward(X.astype(np.float64), U.astype(np.float64), T.astype(np.float64),
                           S.astype(int), K)

    def controller(self, params):
        """The C controller with ``params`` (gainsched_control.c; compiled once)."""
        from ..firmware.host.sil import CController, build_controller

        if self._lib is None:
            self._lib = build_controller(self.data, params, self.build_dir / "control")
        return CController(self.data, params, lib_path=self._lib)


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
    TableScheduler
        A :class:`Scheduler`; ``lookup(xi, xi_dot, alpha) -> (K, status)``: at the azimuth
        xi (rad), the azimuth
        rate xi_dot (rad/s) and the tilt alpha (rad), the gains ``K``, ndarray of shape
        (4, n) (N per unit of LQR state: rad, rad/s, rad s), and the status bits (int;
        0: OK, 0x01 ``CLAMPED_SPEED``: outside the table's speeds, ...; see
        :func:`gainsched.firmware.runtime.status_text`). Its methods:
        ``lookup.batch(xi, xi_dot, alpha) -> (K (m, 4, n), status (m,) int)``, the same
        numbers for arrays of m queries; ``lookup.feedforward(path, alpha)``, the
        firmware's nominal along a reference, and ``lookup.controller(params)``, the
        firmware's control step (``simulate(..., controller="firmware")``); its
        attribute ``lookup.interp``, the :class:`~gainsched.firmware.runtime.Interpolator`.

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
    return TableScheduler(table)


def c_runtime_scheduler(table, build_dir=None):
    """Gain lookup through the compiled C runtime (the firmware code): (xi, xi_dot, alpha)
    -> (K (4, n) float64 of the runtime's float32 gains, status int).

    The table, ``gainsched_runtime.c`` and the batch shim are compiled for the host with
    :func:`gainsched.firmware.host.lookup.build_host` into ``build_dir`` (default: a temporary
    directory that lives as long as the returned scheduler) and called through ctypes,
    one query per call with preallocated buffers. Raises RuntimeError without a C
    compiler.

    Parameters
    ----------
    table : Table, RuntimeData or CompactData
        The table, in the format the firmware holds (a loaded table: the dense one).
    build_dir : path, optional
        Where to compile (default: a temporary directory).

    Returns
    -------
    CRuntimeScheduler
        A :class:`Scheduler` (no ``batch``): the lookup, the firmware's nominal
        (``gs_lookup_nominal``) and the C controller (``gainsched_control.c``, compiled on
        first use).
    """
    return CRuntimeScheduler(table, build_dir)


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
    Scheduler
        A scheduler for :func:`simulate`, ``(xi, xi_dot, alpha) -> (K (4, n), status)``
        (see :func:`table_scheduler`), with ``feedforward`` and ``controller`` for
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
