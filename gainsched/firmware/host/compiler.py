"""The C compilers of the host tools: which one (:func:`require_cc`, over
:func:`gainsched.native.find_cc`), with which flags (:data:`STRICT_CFLAGS`, the
warning set every shipped file compiles clean under; :data:`M4F_CFLAGS`, the
Cortex-M4F target), and a compile that fails with the compiler's output
(:func:`compile_or_raise`).
"""

from __future__ import annotations

import subprocess

from ...native import find_cc

__all__ = ["STRICT_CFLAGS", "M4F_CFLAGS", "find_cc", "require_cc", "compile_or_raise"]

#: the strict warning set, -Werror: what the shipped C compiles clean under
STRICT_CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror")
#: Cortex-M4F flags of ``make firmware-size`` and :func:`~.size.code_bytes`
M4F_CFLAGS = ("-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard")


def require_cc(cc: str | None = None) -> str:
    """``cc``, else the host C compiler (:func:`~gainsched.native.find_cc`); raises
    RuntimeError when there is none."""
    cc = cc or find_cc()
    if cc is None:
        raise RuntimeError("no C compiler found (set CC)")
    return cc


def compile_or_raise(cmd) -> None:
    """Run the compiler command ``cmd``; raises RuntimeError with the command and the
    compiler's output when it fails."""
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{res.stderr}")
