"""The C outputs of a table, as files: ``<name>_gains.h`` (:mod:`.header`),
``<name>_control.h`` (:mod:`.control_header`) and the hand-written runtime and
controller beside them (:mod:`.sources`).

:func:`c_files` is the set in memory (file name -> bytes); :func:`write_c_outputs`
publishes it at once (:func:`gainsched.publish.publish`); :func:`write_header`,
:func:`write_control_header` and :func:`copy_runtime` write one part each (atomically),
for the host builds of :mod:`gainsched.firmware.host`. The runtime is documented in
docs/runtime.md.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..publish import publish, write_atomic
from .control_header import control_header_name, render_control_header
from .header import firmware_data, header_name, render_header
from .sources import CONTROL_FILES, RUNTIME_FILES, resource

__all__ = ["RuntimeFiles", "write_file", "write_header", "write_control_header",
           "copy_runtime", "c_files", "write_c_outputs"]


@dataclass(frozen=True)
class RuntimeFiles:
    """Where :func:`copy_runtime` put the hand-written C.

    Attributes
    ----------
    runtime_h, runtime_c : Path
        The lookup: ``gainsched_runtime.h``, ``gainsched_runtime.c``.
    trig_h : Path
        The runtime's trigonometry, ``gainsched_trig.h``.
    control_h, control_c : Path
        The controller: ``gainsched_control.h``, ``gainsched_control.c``.
    """

    runtime_h: Path
    runtime_c: Path
    trig_h: Path
    control_h: Path
    control_c: Path

    @property
    def sources(self) -> tuple[Path, Path]:
        """The translation units to compile: the runtime's, then the controller's."""
        return self.runtime_c, self.control_c

    @property
    def paths(self) -> tuple[Path, ...]:
        """Every file, headers and sources."""
        return self.runtime_h, self.runtime_c, self.trig_h, self.control_h, self.control_c


def write_file(path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically, then give it the usual permissions (the
    temporary file is created 0600); returns the path."""
    path = Path(path)
    write_atomic(path, text.encode())
    umask = os.umask(0)
    os.umask(umask)
    path.chmod(0o644 & ~umask)
    return path


def write_header(table, out_dir) -> Path:
    """Write ``OUT_DIR/<name>_gains.h`` for a loaded table (atomically); returns the path."""
    data = firmware_data(table)
    return write_file(Path(out_dir) / header_name(data), render_header(data))


def write_control_header(table, params, out_dir) -> Path:
    """Write ``OUT_DIR/<name>_control.h`` of ``table`` with the controller's parameters
    ``params`` (:class:`~gainsched.firmware.controller.ControllerParams`); returns the
    path."""
    data = firmware_data(table)
    return write_file(Path(out_dir) / control_header_name(data),
                      render_control_header(data, params))


def copy_runtime(out_dir) -> RuntimeFiles:
    """Copy :data:`~.sources.RUNTIME_FILES` (``gainsched_runtime.[ch]``,
    ``gainsched_trig.h``) and :data:`~.sources.CONTROL_FILES` (``gainsched_control.[ch]``)
    into ``out_dir`` (atomically); returns where each went."""
    names = dict(zip(("runtime_h", "runtime_c", "trig_h"), RUNTIME_FILES, strict=True))
    names.update(zip(("control_h", "control_c"), CONTROL_FILES, strict=True))
    return RuntimeFiles(**{key: write_file(Path(out_dir) / fname, resource("c", fname))
                           for key, fname in names.items()})


def c_files(table, params=None) -> dict[str, bytes]:
    """The C outputs of a loaded table (or its :class:`~.runtime.RuntimeData`): file name
    -> bytes, header first, then the runtime and the controller, and with the controller's
    parameters ``params`` (:class:`~gainsched.firmware.controller.ControllerParams`)
    ``<name>_control.h``. Raises InputError if the table cannot be represented."""
    data = firmware_data(table)
    files = {header_name(data): render_header(data).encode()}
    if params is not None:
        files[control_header_name(data)] = render_control_header(data, params).encode()
    files.update((f, resource("c", f).encode()) for f in RUNTIME_FILES + CONTROL_FILES)
    return files


def write_c_outputs(table_path, out_dir=None) -> list[Path]:
    """Header, controller parameters, runtime and controller for the table file
    ``table_path`` into ``out_dir`` (default: the table's folder), published together
    (:func:`gainsched.publish.publish`). Returns the written paths, header first."""
    from ..schedule.tables import load_table
    from .controller import controller_params

    table = load_table(table_path)
    out_dir = Path(table_path).parent if out_dir is None else Path(out_dir)
    # everything from the table: its gains and its firmware record
    return publish(out_dir, c_files(table, controller_params(table)))
