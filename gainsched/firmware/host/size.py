"""The flash footprint of a table's firmware: the table's data bytes per array and the
runtime's code bytes, compiled here (:func:`code_bytes`; the build's and
``gainsched export-c``'s size lines, :func:`flash_summary`).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..cfiles import copy_runtime
from ..header import firmware_data
from .compiler import M4F_CFLAGS, STRICT_CFLAGS, find_cc

__all__ = ["CodeSize", "code_bytes", "flash_summary"]


@dataclass(frozen=True)
class CodeSize:
    """The runtime's code size, as :func:`code_bytes` measured it.

    Attributes
    ----------
    nbytes : int
        Bytes of the ``.text*`` and ``.rodata*`` sections of its object file.
    description : str
        The target, the compiler and the optimisation (``"Cortex-M4F arm-none-eabi-gcc
        -Os"``).
    """

    nbytes: int
    description: str


def code_bytes(*, cross: bool | None = None, opt: str = "-Os") -> CodeSize | None:
    """Code bytes of the runtime (``.text*`` and ``.rodata*`` sections of its object file).

    Uses arm-none-eabi-gcc for Cortex-M4F when available (or ``cross=True``), else the
    host compiler. Returns the :class:`CodeSize`, or None when no compiler works.
    """
    use_cross = bool(find_cc(cross=True)) if cross is None else cross
    cc = find_cc(cross=use_cross)
    if cc is None:
        return None
    size_tool = shutil.which("arm-none-eabi-size" if use_cross else "size")
    flags = [*STRICT_CFLAGS, opt, "-ffunction-sections"] + (list(M4F_CFLAGS) if use_cross else [])
    with tempfile.TemporaryDirectory() as tmp:
        src = copy_runtime(tmp).runtime_c
        obj = Path(tmp) / "rt.o"
        res = subprocess.run([cc, *flags, "-c", str(src), "-o", str(obj)], capture_output=True)
        if res.returncode or size_tool is None:
            return None
        out = subprocess.run([size_tool, "-A", str(obj)], capture_output=True, text=True).stdout
    total = 0
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].startswith((".text", ".rodata")) and parts[1].isdigit():
            total += int(parts[1])
    target = "Cortex-M4F" if use_cross else "host"
    return CodeSize(total, f"{target} {Path(cc).name} {opt}")


def flash_summary(table, *, compile_code: bool = True) -> list[str]:
    """Lines describing the flash footprint: table bytes per array and runtime code bytes."""
    data = firmware_data(table)
    sizes = {k: len(b) for k, b in data.crc_chunks() if k not in ("dims", "xi_scale")}
    big = ", ".join(f"{k} {v}" for k, v in sizes.items() if v >= 1024)
    lines = [f"flash: table data {data.nbytes()} bytes ({data.nbytes() / 1024:.1f} KiB; {big})"]
    if compile_code:
        size = code_bytes()
        if size is None:
            lines.append("flash: runtime code size unknown (no working C compiler)")
        else:
            lines.append(f"flash: runtime code {size.nbytes} bytes ({size.description}, "
                         ".text + .rodata)")
    return lines
