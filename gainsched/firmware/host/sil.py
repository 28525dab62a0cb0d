"""Software in the loop: the C controller (``gainsched_control.c``) compiled for the host
and called step by step through ctypes.

:func:`build_controller` compiles the table's header, its ``<name>_control.h``, the
runtime, the controller and a small driver (``templates/control_sil.in.c``) into a
shared library; :class:`CController` runs it: one step per call in the simulator's
loop (``simulate(..., controller="firmware")`` with the C runtime), or a whole
recorded input sequence per call (the tests, against the Python reference
:class:`~gainsched.firmware.controller.Controller`).
"""

from __future__ import annotations

import ctypes
import tempfile
from pathlib import Path

import numpy as np

from ..cfiles import copy_runtime, write_control_header, write_file, write_header
from ..controller import MAX_INT, N_INPUT, ControllerParams, ControlOutputs
from ..header import firmware_data
from ..runtime import BAD_ARG
from ..sources import render
from .compiler import STRICT_CFLAGS, compile_or_raise, require_cc

__all__ = ["N_OUTPUT", "write_controller", "driver_values", "build_controller",
           "CController"]

#: the driver's output row: thrust (4), status (int32 bits), z (10)
N_OUTPUT = 15


def write_controller(table, params: ControllerParams, out_dir) -> tuple[Path, Path]:
    """Write the firmware's controller sources for ``table`` into ``out_dir``: the table
    header, ``<name>_control.h`` with ``params``, the runtime and the controller. Returns
    the C files to compile (:attr:`~gainsched.firmware.cfiles.RuntimeFiles.sources`: the
    runtime's, the controller's)."""
    data = firmware_data(table)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_header(data, out)
    write_control_header(data, params, out)
    return copy_runtime(out).sources


def driver_values(data, params: ControllerParams) -> dict:
    """The values the SIL and PIL drivers' templates are rendered with: the table's name,
    and the ``gs_ctrl_params`` fields in :meth:`ControllerParams.c_fields` order as the
    flat float array the drivers read (``n_params``, ``setup``: the assignments from
    ``pv``, ``getters``: the generated params back as floats)."""
    setup, getters = [], []
    for name, ctype, value in params.c_fields():
        lvalues = ([f"p->{name}"] if ctype in ("float", "uint32_t") else
                   [f"p->{name}[{j}]" for j in range(len(value))])
        real = ctype.startswith("float")  # "float" or "float[n]"
        for lv in lvalues:
            i = len(setup)
            setup.append(f"    {lv} = pv[{i}];" if real else f"    {lv} = (uint32_t)pv[{i}];")
            getters.append(lv if real else f"(float){lv}")
    return dict(name=data.name, tool_version=data.meta.get("tool_version", "?"),
                n_params=str(len(setup)), setup="\n".join(setup),
                getters=",\n        ".join(getters))


def build_controller(table, params: ControllerParams, out_dir, *, cc=None, opt="-O2",
                     extra=()) -> Path:
    """Compile the controller with ``table`` for the host as a shared library (the strict
    warning set, -Werror); returns its path. Raises RuntimeError without a C compiler
    or when the build fails."""
    data = firmware_data(table)
    cc = require_cc(cc)
    out = Path(out_dir)
    sources = write_controller(data, params, out)
    shim = write_file(out / f"{data.name}_control_sil.c",
                  render("control_sil.in.c", **driver_values(data, params)))
    lib = out / f"lib{data.name}_control.so"
    cmd = [cc, *STRICT_CFLAGS, opt, f"-I{out}", "-shared", "-fPIC", *extra, "-o", str(lib),
           str(shim), *map(str, sources)]
    compile_or_raise(cmd)
    return lib


class CController:
    """The C controller of one table, on the host (``gs_ctrl`` through ctypes).

    Parameters
    ----------
    table : Table, RuntimeData or CompactData
        The table in the format the firmware holds.
    params : ControllerParams
        The controller's parameters (:func:`~gainsched.firmware.controller.controller_params`).
    build_dir : path-like, optional
        Where to compile; default a temporary folder that lives as long as this object.
    lib_path : path-like, optional
        A library :func:`build_controller` made for the same table (any parameters: they
        are set here): no compilation.

    Raises
    ------
    RuntimeError
        No C compiler, or ``gs_ctrl_init`` refused the parameters (GS_BAD_ARG).

    Examples
    --------
    >>> from gainsched.firmware.controller import N_INPUT, controller_params
    >>> table = gs.load_table("tables/paper.h5")
    >>> ctl = CController(table, controller_params(gs.load_config("configs/paper.toml"), table))
    >>> thrust, status, z = ctl.step(np.zeros(N_INPUT))  # nothing measured: idle
    >>> thrust.tolist(), hex(status)  # the idle thrust, thrust_min in float32
    ([0.10000000149011612, 0.10000000149011612, 0.10000000149011612, 0.10000000149011612], '0x2081')
    """

    def __init__(self, table, params: ControllerParams, build_dir=None, lib_path=None):
        data = firmware_data(table)
        self._tmp = None
        if lib_path is None:
            if build_dir is None:
                self._tmp = tempfile.TemporaryDirectory(prefix="gainsched-ctrl-")
                build_dir = self._tmp.name
            lib_path = build_controller(data, params, build_dir)
        self.params, self.data = params, data
        self.lib = lib = ctypes.CDLL(str(lib_path))
        nm = data.name
        size = getattr(lib, f"{nm}_sil_size")
        size.restype = ctypes.c_size_t
        self._mem = ctypes.create_string_buffer(int(size()))
        fp = ctypes.POINTER(ctypes.c_float)
        setup = getattr(lib, f"{nm}_sil_setup")
        setup.argtypes, setup.restype = [ctypes.c_void_p, fp], ctypes.c_int
        self._reset = getattr(lib, f"{nm}_sil_reset")
        self._reset.argtypes, self._reset.restype = [ctypes.c_void_p, fp], ctypes.c_int
        self._run = getattr(lib, f"{nm}_sil_run")
        self._run.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p,
                              ctypes.c_void_p]
        self._run.restype = None
        self._integ = getattr(lib, f"{nm}_sil_integ")
        self._integ.argtypes, self._integ.restype = [ctypes.c_void_p, fp], None
        pv = params.c_array()  # the driver copies it into the gs_ctrl_params in _mem
        if setup(self._mem, pv.ctypes.data_as(fp)) & BAD_ARG:
            raise RuntimeError(f"gs_ctrl_init refused the parameters {params}")
        self._row = np.zeros(N_INPUT, dtype=np.float32)
        self._out = np.zeros(N_OUTPUT, dtype=np.float32)
        self._row_p, self._out_p = self._row.ctypes.data, self._out.ctypes.data

    @property
    def integ(self) -> np.ndarray:
        """The integral states now (``gs_ctrl.integ``, rad s), one per ``params.int_of``."""
        out = np.zeros(MAX_INT, dtype=np.float32)
        self._integ(self._mem, out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)))
        return out[:len(self.params.int_of)].copy()

    def reset(self, p_I, v_I, q_IB) -> int:
        """Start the estimator at a known state (``gs_ctrl_reset``): GS_OK or GS_BAD_ARG."""
        pvq = np.concatenate([p_I, v_I, q_IB]).astype(np.float32)
        return int(self._reset(self._mem, pvq.ctypes.data_as(ctypes.POINTER(ctypes.c_float))))

    def step(self, row) -> ControlOutputs:
        """One ``gs_ctrl_update``: inputs (N_INPUT,) -> ``out`` (4,) (thrusts, N, or
        commands), ``status`` int, ``z`` (10,)."""
        self._row[:] = row
        self._run(self._mem, 1, self._row_p, self._out_p)
        o = self._out
        return ControlOutputs(o[:4].astype(np.float64), int(o[4:5].view(np.int32)[0]),
                              o[5:].astype(np.float64))

    def run(self, rows) -> ControlOutputs:
        """A recorded input sequence (m, N_INPUT) in one call: ``out`` (m, 4) float32,
        ``status`` (m,) int32, state estimates ``z`` (m, 10) float32."""
        rows = np.ascontiguousarray(rows, dtype=np.float32)
        out = np.zeros((len(rows), N_OUTPUT), dtype=np.float32)
        self._run(self._mem, len(rows), rows.ctypes.data, out.ctypes.data)
        return ControlOutputs(out[:, :4], out[:, 4].copy().view(np.int32), out[:, 5:])
