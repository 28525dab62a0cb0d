"""A table's C files for the firmware, from the table alone: ``gainsched export-c``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ._report import SILENT, Reporter

__all__ = ["Export", "export_c"]


@dataclass(frozen=True, eq=False)
class Export:
    """What :func:`export_c` wrote.

    Attributes
    ----------
    files : list of Path
        ``NAME_gains.h``, ``NAME_control.h``, the runtime's and the controller's files.
    form : RuntimeData or CompactData
        What the header holds.
    certificate : MidpointCheck or None
        The compact form's certificate at the cell midpoints (None: dense).
    said : tuple of str
        :meth:`lines`.
    """

    files: list
    form: object
    certificate: object
    said: tuple

    def lines(self) -> list[str]:
        """What ``gainsched export-c`` prints: the files, the table's format, CRC and
        config hash, the flash footprint and the compact form's certificate."""
        return list(self.said)


def export_c(table, out_dir=None, *, fmt: str = "config", motor_order: str = "config",
             command: str = "config", thr_mdl_fac: float | None = None,
             thrust_max_n: float | None = None, code_size: bool = True,
             reporter: Reporter = SILENT) -> Export:
    """Write a table's C header, the controller's parameters and the C runtime and
    controller beside them: what ``gainsched export-c TABLE -o OUT_DIR`` does
    (docs/runtime.md). Rendered from the table alone: no model code runs.

    Parameters
    ----------
    table : path-like
        The gain table (HDF5).
    out_dir : path-like, optional
        The output folder (default: the table's).
    fmt : {"config", "dense", "compact"}
        The header's table format: the table's config's (``[firmware] format``), values
        per azimuth, or Fourier series per circle certified at the cell midpoints.
    motor_order : {"config", "gainsched", "px4"}
        The numbering of the controller's outputs.
    command : {"config", "thrust", "normalized"}
        The controller's outputs: thrusts in N, or commands 0..1 through the thrust curve.
    thr_mdl_fac : float, optional
        The thrust curve's quadratic part (PX4's THR_MDL_FAC), for normalised commands.
    thrust_max_n : float, optional
        Thrust at full command, N (default: the config's ``vehicle.thrust_max``).
    code_size : bool, default True
        Compile the runtime to measure its flash footprint.
    reporter : Reporter, optional
        Shows the compact form's certification; default: nothing.

    Returns
    -------
    Export
        The files and :meth:`Export.lines`, what the command prints.

    Examples
    --------
    >>> import tempfile
    >>> e = gs.studies.export_c("tables/paper.h5", tempfile.mkdtemp(), code_size=False)
    >>> sorted(p.name for p in e.files)[:3]
    ['gainsched_control.c', 'gainsched_control.h', 'gainsched_runtime.c']
    """
    from ..firmware.cfiles import c_files
    from ..firmware.controller import controller_params, outputs_from_config
    from ..firmware.host.size import flash_summary
    from ..firmware.outputs import certificate_lines, firmware_form, table_config
    from ..firmware.sources import CONTROL_FILES, RUNTIME_FILES
    from ..publish import check_out_dir, publish
    from ..schedule.tables import load_table

    out_dir = Path(table).parent if out_dir is None else Path(out_dir)
    t = load_table(table)
    cfg = table_config(t, fmt)
    outputs = {k: v for k, v in (("firmware.motor_order", motor_order),
                                 ("firmware.command", command),
                                 ("firmware.thr_mdl_fac", thr_mdl_fac),
                                 ("firmware.thrust_max_N", thrust_max_n))
               if v not in (None, "config")}
    if outputs and cfg is None:
        raise InputError(str(table), "config_text", "the controller's outputs need the "
                         "table's config, which this installation cannot load")
    if outputs:
        cfg = cfg.with_values(outputs, source=f"{table} (export-c options)")
    fmt = "dense" if cfg is None else cfg.firmware.format
    # a bad folder fails before the certification
    check_out_dir(out_dir, names=[*RUNTIME_FILES, *CONTROL_FILES])
    n_mid = max(t.speed.size - 1, 1) if fmt == "compact" else 0
    with reporter.bar("certify compact table", n_mid, "speed", show=n_mid > 0) as bar:
        form, cert = firmware_form(cfg, t, progress=bar.update)
    params = controller_params(t, **(outputs_from_config(cfg) if outputs else {}))
    paths = publish(out_dir, c_files(form, params))
    said = [*(f"wrote {p}" for p in paths),
            f"  {form.name}: {fmt}, CRC-32 0x{form.crc32():08x}, config "
            f"sha256 {t.config_sha256[:12]}",
            *(f"  {line}" for line in flash_summary(form, compile_code=code_size))]
    if cert is not None:
        said += [f"  {line}" for line in certificate_lines(cfg, cert)]
    return Export(paths, form, cert, tuple(said))
