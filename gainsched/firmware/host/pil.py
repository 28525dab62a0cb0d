"""Processor in the loop: the C runtime, the controller and a table on an emulated
Cortex-M4F.

The runtime, the table's header and a bare-metal query driver
(``templates/pil_driver.in.c``; the controller: ``templates/control_pil.in.c``; their
board support ``templates/pil_board.c`` and ``templates/pil.ld``) are cross-compiled with
``arm-none-eabi-gcc`` for the paper's kind of flight controller (Cortex-M4F with its
single-precision FPU, hard-float ABI) and run on QEMU's ``mps2-an386`` board; the
queries go in and the outputs come out through ARM semihosting. The tests compare
every output bit for bit with the host build and the Python reference
(``tests/firmware/test_pil.py``); ``make bench`` counts the instructions a lookup executes
(:func:`instructions_per_lookup`). The tools come from the distribution's packages
(Debian: ``gcc-arm-none-eabi``, ``libnewlib-arm-none-eabi``, ``qemu-system-arm``).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cfiles import copy_runtime, write_file, write_header
from ..controller import ControlOutputs
from ..header import firmware_data
from ..runtime import Lookup
from ..sources import render, resource
from .compiler import M4F_CFLAGS, STRICT_CFLAGS, compile_or_raise
from .sil import driver_values, write_controller

__all__ = ["QEMU_MACHINE", "PilTools", "pil_tools", "build_pil", "run_pil",
           "instructions_per_lookup", "build_control_pil", "run_control_pil",
           "instructions_per_step"]

#: the emulated board: an MPS2 FPGA image with a Cortex-M4F
QEMU_MACHINE = "mps2-an386"
#: what :func:`pil_tools` looks for, and the Debian packages that install it
TOOLS = {"arm-none-eabi-gcc": "gcc-arm-none-eabi", "qemu-system-arm": "qemu-system-arm"}


@dataclass(frozen=True)
class PilTools:
    """The tools of processor in the loop, as :func:`pil_tools` found them.

    Attributes
    ----------
    gcc : str
        The cross compiler, ``arm-none-eabi-gcc``.
    qemu : str
        The emulator, ``qemu-system-arm``.
    """

    gcc: str
    qemu: str


def pil_tools() -> PilTools | None:
    """The paths of ``arm-none-eabi-gcc`` and ``qemu-system-arm``, or None when either is
    missing."""
    gcc, qemu = (shutil.which(t) for t in TOOLS)
    return PilTools(gcc, qemu) if gcc and qemu else None


def _cross_build(out: Path, elf: Path, sources, *, std: str, ftz: bool, opt: str,
                 extra=()) -> Path:
    """Cross-compile ``sources`` with the board support (``pil_board.c``) and the linker
    script into ``elf`` for Cortex-M4F; raises RuntimeError with the compiler's output."""
    tools = pil_tools()
    if tools is None:
        raise RuntimeError("arm-none-eabi-gcc or qemu-system-arm not found")
    ld = write_file(out / "pil.ld", render("pil.ld"))
    write_file(out / "pil_board.h", resource("templates", "pil_board.h"))
    board = write_file(out / "pil_board.c", resource("templates", "pil_board.c"))
    flags = [f for f in STRICT_CFLAGS if not f.startswith("-std=")]
    flags = [f"-std={std}", *flags, *M4F_CFLAGS, opt, "-ffreestanding", "-nostdlib",
             "-nostartfiles", f"-I{out}", *(["-DGS_PIL_FTZ"] if ftz else []), *extra]
    cmd = [tools.gcc, *flags, "-T", str(ld), "-o", str(elf), *map(str, sources), str(board),
           "-lgcc"]
    compile_or_raise(cmd)
    return elf


def build_pil(table, out_dir, *, std: str = "c99", ftz: bool = False, opt: str = "-O2",
              extra=()) -> Path:
    """Cross-compile the table, the runtime and the query driver for Cortex-M4F.

    Parameters
    ----------
    table : Table, RuntimeData or CompactData
        The table, in the format the firmware gets.
    out_dir : path-like
        Build folder (created).
    std : str, default "c99"
        The C dialect (``"gnu11"``: GCC's default, where it would contract
        multiply-adds; the runtime turns that off itself).
    ftz : bool, default False
        Run with flush-to-zero (FPSCR.FZ = 1).
    opt : str, default "-O2"
    extra : sequence of str
        More compiler flags.

    Returns
    -------
    Path
        The ELF image for :func:`run_pil`.

    Raises
    ------
    RuntimeError
        No cross compiler, or the build fails (its output in the message).
    """
    data = firmware_data(table)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_header(data, out)
    runtime_c = copy_runtime(out).runtime_c
    driver = write_file(out / f"{data.name}_pil.c",
                    render("pil_driver.in.c", name=data.name, NAME=data.name.upper(),
                           tool_version=data.meta.get("tool_version", "?")))
    return _cross_build(out, out / f"{data.name}_pil.elf", [driver, runtime_c], std=std,
                        ftz=ftz, opt=opt, extra=extra)


def build_control_pil(table, params, out_dir, *, std: str = "c99", ftz: bool = False,
                      opt: str = "-O2", extra=()) -> Path:
    """Cross-compile the controller (``gainsched_control.c`` with the runtime and the
    table) and its step driver for Cortex-M4F: the image for :func:`run_control_pil`.
    Parameters as :func:`build_pil`; ``params`` the
    :class:`~gainsched.firmware.controller.ControllerParams` of ``<name>_control.h``
    (the driver sets its own at run time)."""
    data = firmware_data(table)
    out = Path(out_dir)
    sources = write_controller(data, params, out)
    values = driver_values(data, params)
    shim = write_file(out / f"{data.name}_control_sil.c", render("control_sil.in.c", **values))
    driver = write_file(out / f"{data.name}_control_pil.c", render("control_pil.in.c", **values))
    return _cross_build(out, out / f"{data.name}_control_pil.elf", [driver, shim, *sources],
                        std=std, ftz=ftz, opt=opt, extra=extra)


def _qemu(elf: Path, cwd: Path, extra=(), timeout: float = 600.0):
    """Run an image on the emulated board with semihosting (files relative to ``cwd``)."""
    cmd = [pil_tools().qemu, "-M", QEMU_MACHINE, "-nographic", "-monitor", "none", "-serial",
           "none", "-semihosting-config", "enable=on,target=native", *extra, "-kernel", str(elf)]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)


def _instructions(elf: Path, files: dict) -> int:
    """Guest instructions of one run of ``elf`` with the input ``files`` (name -> bytes):
    QEMU's one-instruction-per-block execution trace (``-singlestep -d exec,nochain``)."""
    with tempfile.TemporaryDirectory(prefix="gainsched-pil-") as tmp:
        for name, data in files.items():
            (Path(tmp) / name).write_bytes(data)
        log = Path(tmp) / "exec.log"
        _qemu(Path(elf).resolve(), Path(tmp), ["-singlestep", "-d", "exec,nochain", "-D",
                                                 str(log)])
        with open(log, "rb") as fh:
            return sum(chunk.count(b"Trace ") for chunk in iter(lambda: fh.read(1 << 20), b""))


def run_pil(elf, xi, xi_dot, alpha, n_state: int) -> Lookup:
    """Look up queries on the emulated Cortex-M4F.

    Parameters
    ----------
    elf : path-like
        An image of :func:`build_pil`.
    xi, xi_dot, alpha : array_like, shape (m,)
        Queries (rad, rad/s, rad), taken as float32.
    n_state : int
        The table's LQR state dimension.

    Returns
    -------
    Lookup
        ``K`` (m, 4, n), ``u_d`` (m, 4), ``phi_d`` (m,) float32 as the target computed
        them; ``status`` (m,) int32.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        q = np.ascontiguousarray(np.stack(
            [np.asarray(v, dtype=np.float32).reshape(-1) for v in (xi, xi_dot, alpha)], 1))
    m, nk = q.shape[0], 4 * n_state
    with tempfile.TemporaryDirectory(prefix="gainsched-pil-") as tmp:
        (Path(tmp) / "q.bin").write_bytes(q.tobytes())
        res = _qemu(Path(elf).resolve(), Path(tmp))
        raw = (Path(tmp) / "o.bin").read_bytes() if (Path(tmp) / "o.bin").exists() else b""
    rows = np.frombuffer(raw, dtype=np.float32).reshape(-1, nk + 6)
    if rows.shape[0] != m:
        raise RuntimeError(f"the emulated target returned {rows.shape[0]} of {m} lookups "
                           f"(qemu exit {res.returncode}: {res.stderr.strip()[-300:]})")
    status = rows[:, nk + 5].copy().view(np.int32)
    return Lookup(rows[:, :nk].reshape(m, 4, n_state).copy(), rows[:, nk:nk + 4].copy(),
                  rows[:, nk + 4].copy(), status)


def instructions_per_lookup(elf, xi, xi_dot, alpha, n_state: int) -> float:
    """Guest instructions one lookup executes on the emulated Cortex-M4F, on average over
    the queries: the driver's trace with the queries minus its trace with none (the
    start-up and the semihosting calls)."""
    counts = []
    for k in (0, np.size(xi)):
        with np.errstate(over="ignore", invalid="ignore"):
            q = np.stack([np.asarray(v, dtype=np.float32).reshape(-1)[:k]
                          for v in (xi, xi_dot, alpha)], 1)
        counts.append(_instructions(elf, {"q.bin": np.ascontiguousarray(q).tobytes()}))
    return (counts[1] - counts[0]) / max(np.size(xi), 1)


def _control_files(params, rows, reset) -> dict:
    """The control driver's input files: parameters (+ reset state) and the rows."""
    start = np.zeros(11) if reset is None else np.concatenate([[1.0], *reset])
    return {"p.bin": np.concatenate([params.c_array(), start]).astype(np.float32).tobytes(),
            "q.bin": np.ascontiguousarray(rows, dtype=np.float32).tobytes()}


def run_control_pil(elf, params, rows, reset=None) -> ControlOutputs:
    """Run the controller on the emulated Cortex-M4F over recorded input rows.

    Parameters
    ----------
    elf : path-like
        An image of :func:`build_control_pil`.
    params : ControllerParams
    rows : array_like, shape (m, N_INPUT)
        The steps' inputs (:data:`~gainsched.firmware.controller.INPUT_COLUMNS`), float32.
    reset : tuple of array_like, optional
        ``(p_I, v_I, q_IB)``: start the estimator there (``gs_ctrl_reset``).

    Returns
    -------
    ControlOutputs
        ``out`` (m, 4) float32, ``status`` (m,) int32, ``z`` (m, 10) float32: as
        :meth:`gainsched.firmware.host.sil.CController.run` on the host.
    """
    with tempfile.TemporaryDirectory(prefix="gainsched-pil-") as tmp:
        for name, data in _control_files(params, rows, reset).items():
            (Path(tmp) / name).write_bytes(data)
        res = _qemu(Path(elf).resolve(), Path(tmp))
        out = Path(tmp) / "o.bin"
        raw = out.read_bytes() if out.exists() else b""
    o = np.frombuffer(raw, dtype=np.float32).reshape(-1, 15)
    if o.shape[0] != len(rows):
        raise RuntimeError(f"the emulated target returned {o.shape[0]} of {len(rows)} steps "
                           f"(qemu exit {res.returncode}: {res.stderr.strip()[-300:]})")
    return ControlOutputs(o[:, :4].copy(), o[:, 4].copy().view(np.int32), o[:, 5:].copy())


def instructions_per_step(elf, params, rows, reset=None) -> float:
    """Guest instructions one control step (``gs_ctrl_update``, lookup included) executes
    on the emulated Cortex-M4F, on average over the rows: the trace with the rows minus
    the trace with none."""
    rows = np.asarray(rows)
    runs = [_instructions(elf, _control_files(params, rows[:k], reset))
            for k in (0, len(rows))]
    return (runs[1] - runs[0]) / max(len(rows), 1)
