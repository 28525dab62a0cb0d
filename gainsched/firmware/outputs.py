"""The output set of a build: the HDF5 table, its C header and the runtime, as one unit.

Every check that can fail runs on the bytes in memory (the table is read back
through :func:`~gainsched.schedule.tables.table_from_bytes`, the header rendered from
it) before the first byte reaches the output folder; the set is then
published together (:func:`~gainsched.publish.publish`), so a failed or
interrupted build leaves the old set or the new one, never a mix.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import GainschedWarning, InputError
from ..publish import publish
from ..schedule.grid import check_effect_symmetries, mirror_config
from ..schedule.tables import config_from_table, table_bytes, table_from_bytes
from .cfiles import c_files
from .compact import CompactData, CompactInterpolator, compact_data
from .controller import controller_params
from .host.check import MidpointCheck, midpoint_check
from .runtime import RuntimeData, runtime_data

__all__ = ["DEFAULT_FLASH_BYTES", "OutputSet", "output_set", "check_outputs", "output_files",
           "firmware_form", "certificate_lines", "table_config", "write_outputs"]


#: the flash budget of a table's data when the config states none
#: (``firmware.max_table_bytes``): 1 MiB, the flash of common Cortex-M4F flight controllers
#: (STM32F405, STM32F427); a table over it builds with a one-line warning
DEFAULT_FLASH_BYTES = 1 << 20


@dataclass(frozen=True)
class OutputSet:
    """A build's outputs, checked, before they are published.

    Attributes
    ----------
    files : dict
        File name -> bytes: ``NAME.h5``, ``NAME_gains.h``, ``NAME_control.h``,
        ``gainsched_runtime.h``, ``gainsched_runtime.c``, ``gainsched_trig.h``,
        ``gainsched_control.h``, ``gainsched_control.c``.
    form : RuntimeData or CompactData
        What the C header holds (``[firmware] format``).
    certificate : MidpointCheck or None
        The compact table checked against directly solved gains at the cell midpoints
        (None for the dense format, which ``gainsched check`` checks on demand).
    """

    files: dict
    form: RuntimeData | CompactData
    certificate: MidpointCheck | None


def firmware_form(config, table, progress=None):
    """The table as the config's firmware gets it, with its certificate.

    Dense: the runtime data. Compact: the series of :func:`~.compact.compact_data`
    (``firmware.azimuth_error``), certified at every cell midpoint against directly
    solved gains (:func:`~.host.check.midpoint_check`): the largest relative gain error must
    be within ``grid.max_interpolation_error`` and every midpoint loop closed with the
    table's gains stable. Either format must fit ``firmware.max_table_bytes`` (with none
    stated, a table over :data:`DEFAULT_FLASH_BYTES` is built with a warning).

    Parameters
    ----------
    config : Config or None
        The table's config (None: the dense form, no budget).
    table : Table
        The built table.
    progress : callable, optional
        Called with 1 per checked speed midpoint (the compact certificate).

    Returns
    -------
    (RuntimeData or CompactData, MidpointCheck or None)

    Raises
    ------
    InputError
        Naming the config and the key whose bound is not met, and where.
    """
    form = runtime_data(table)
    if config is None:
        return form, None
    fw = config.firmware
    cert = None
    if fw.format == "compact":
        form = compact_data(form, fw.azimuth_error, source=config.source)
        cert = midpoint_check(table, lookup=CompactInterpolator(form), progress=progress)
        _check_certificate(config, cert)
    _check_budget(config, form)
    return form, cert


def _check_budget(config, form) -> None:
    """The table's data against the flash budget: ``firmware.max_table_bytes`` refuses a
    table over it; with no budget stated, a table over :data:`DEFAULT_FLASH_BYTES` is
    built with a one-line warning. Either names the way out: a dense table's compact
    form and its size (the series only, uncertified: the build certifies it when asked
    for), a compact one's key."""
    fw = config.firmware
    budget = DEFAULT_FLASH_BYTES if fw.max_table_bytes is None else fw.max_table_bytes
    if form.nbytes() <= budget:
        return
    if fw.format == "dense":
        try:
            way = (f"[firmware] format = \"compact\" holds "
                   f"{compact_data(form, fw.azimuth_error).nbytes():,} bytes")
        except InputError as exc:  # no series fits: the compact form has no size
            way = f"the compact format cannot hold it either ({exc.message})"
    else:
        way = "raise firmware.azimuth_error or thin the grid"
    held = f"the {fw.format} table holds {form.nbytes():,} bytes of data"
    if fw.max_table_bytes is not None:
        raise InputError(config.source, "firmware.max_table_bytes",
                         f"{budget:,} bytes exceeded: {held}; {way}")
    warnings.warn(f"{config.source}: firmware.max_table_bytes: {held}, more than "
                  f"{budget:,} bytes, the flash assumed where the config states no budget "
                  f"(set it to yours); {way}", GainschedWarning, stacklevel=3)


def table_config(table, fmt: str = "config"):
    """The config a table was built from (its embedded text), with ``[firmware] format``
    set to ``fmt`` unless ``fmt`` is ``"config"``; None when this process cannot load it
    (an effect registered elsewhere) and ``fmt`` is not ``"compact"``: the dense header
    needs no config. Raises InputError when ``"compact"`` needs the unloadable config,
    and for any other fault of the embedded config
    (:func:`~gainsched.schedule.tables.config_from_table`)."""
    cfg = config_from_table(table, unknown_effect_ok=fmt != "compact")
    if cfg is None:
        return None
    if fmt not in ("config", cfg.firmware.format):
        cfg = cfg.with_values({"firmware.format": fmt})
    return cfg


def _check_certificate(config, cert: MidpointCheck) -> None:
    """Refuse a compact table whose midpoint error exceeds the bound or whose loop with
    the table's gains is unstable at a midpoint circle."""
    bound = config.grid.max_interpolation_error
    if math.isfinite(cert.max_err) and cert.max_err > bound:
        v, a, x, e = cert.worst_point()
        raise InputError(config.source, "grid.max_interpolation_error",
                         f"{100 * bound:g} % not met by the compact table: {100 * e:.2f} % at "
                         f"{v:g} m/s, tilt {math.degrees(a):g} deg, xi {math.degrees(x):g} deg "
                         "(lower firmware.azimuth_error or refine the grid there)")
    for v, a, rho, _ in cert.circles:
        if not rho < 1 and math.isfinite(rho):
            raise InputError(config.source, "firmware.format",
                             f"the compact table's gains do not stabilise the midpoint circle "
                             f"{v:g} m/s, tilt {math.degrees(a):g} deg (spectral radius "
                             f"{rho:.5f}): lower firmware.azimuth_error")


def certificate_lines(config, cert: MidpointCheck) -> list[str]:
    """What ``gainsched build`` prints of a compact table's certificate: the largest gain
    error at the cell midpoints against the bound, and the worst closed loop (spectral
    radius and slowest time constant) with the table's gains and with the direct ones."""
    out = [f"certified at {np.count_nonzero(np.isfinite(cert.rel_err))} cell midpoints: max "
           f"gain error {100 * cert.max_err:.2f} % (median {100 * cert.median_err:.2f} %, "
           f"bound {100 * config.grid.max_interpolation_error:g} %)"]
    live = [c for c in cert.circles if math.isfinite(c[2])]
    if live:
        worst = max(live, key=lambda c: c[2])
        r = config.radius

        def tau(v, rho):  # slowest closed-loop time constant of a circle, s
            return -2 * math.pi * r / v / math.log(rho)

        slow = max(live, key=lambda c: tau(c[0], c[2]))
        out.append(f"closed loop at {len(live)} midpoint circles: worst spectral radius "
                   f"{worst[2]:.5f} (direct gains {worst[3]:.5f}) at {worst[0]:g} m/s, tilt "
                   f"{math.degrees(worst[1]):g} deg; slowest mode {tau(slow[0], slow[2]):.3g} s "
                   f"(direct {tau(slow[0], slow[3]):.3g} s)")
    return out


def check_outputs(config) -> None:
    """Refuse, before any work, a config whose build outputs cannot be written: an effect
    no table holds (:func:`~gainsched.schedule.grid.check_effect_symmetries`: a wind,
    flight time) and the compact firmware format for a vehicle that is not its own mirror
    image (its table holds both flight directions, the compact form one;
    docs/symmetry.md). Raises InputError naming the config and the key; the check of
    ``gainsched build`` and of the rebuilds of ``improve`` and ``diagnose --apply``."""
    check_effect_symmetries(config)
    if config.firmware.format == "compact" and mirror_config(config) is not None:
        raise InputError(config.source, "firmware.format",
                         "\"compact\" holds one flight direction; this vehicle is not its own "
                         "mirror image, its table holds both (docs/symmetry.md): use \"dense\"")


def output_set(config, grid, out_dir=".", progress=None, grid_auto=None) -> OutputSet:
    """The checked outputs of a build (:class:`OutputSet`): the HDF5 table, read back
    through the loader's checks, its C header in the config's format (certified when
    compact, :func:`firmware_form`) and the runtime. ``out_dir`` only names the table
    in error messages; ``progress`` goes to the certificate; ``grid_auto`` is the record
    of axes the build chose (:meth:`gainsched.schedule.refine.GridChoice.record`)."""
    name = f"{config.name}.h5"
    data = table_bytes(config, grid, grid_auto=grid_auto)
    table = table_from_bytes(data, Path(out_dir) / name)
    form, cert = firmware_form(config, table, progress)
    return OutputSet({name: data, **c_files(form, controller_params(table))}, form, cert)


def output_files(config, grid, out_dir=".", grid_auto=None) -> dict[str, bytes]:
    """The files of :func:`output_set` (the table, the headers, the runtime and the
    controller) -> bytes, checked.

    Parameters
    ----------
    config : Config
    grid : GridResult
        The built grid (:func:`gainsched.schedule.grid.build_grid`).
    out_dir : path-like
        Where the files will go (only for the names in error messages).
    grid_auto : dict, optional
        The record of axes the build chose (:meth:`gainsched.GridChoice.record`).
    """
    return output_set(config, grid, out_dir, grid_auto=grid_auto).files


def write_outputs(out_dir, config, grid, grid_auto=None) -> list[Path]:
    """Write a built grid as its output set: the HDF5 table, its C header and the runtime.

    Every check runs on the bytes in memory first (the table is read back through the
    checks of :func:`gainsched.load_table` and the C header rendered from it); the set
    is then published together (:func:`gainsched.publish.publish`): a failed or
    interrupted write leaves the old set or the new one in ``out_dir``, never a mix.
    This is what ``gainsched build CONFIG -o OUT_DIR`` writes.

    Parameters
    ----------
    out_dir : str or path-like
        Output folder, created if needed. Files of the same names there are replaced.
    config : Config
        The config the grid was built from (:func:`gainsched.load_config`); its ``name``
        names the files, its text and SHA-256 are embedded in them.
    grid : GridResult
        The built grid (:func:`gainsched.build_grid` of ``config``).
    grid_auto : dict, optional
        For a grid whose axes the build chose (:func:`gainsched.refine_grid`): its
        record, ``choice.record()``, stored in the table (with ``choice.config`` and
        ``choice.grid`` as ``config`` and ``grid``).

    Returns
    -------
    list of Path
        The written files, ``out_dir / name``: ``NAME.h5`` (the table,
        docs/table-format.md), ``NAME_gains.h`` (the float32 tables for the firmware),
        ``NAME_control.h`` (the controller's parameters from the config),
        ``gainsched_runtime.h`` and ``gainsched_runtime.c`` (the C lookup),
        ``gainsched_trig.h`` (its trigonometry),
        ``gainsched_control.h`` and ``gainsched_control.c`` (the whole control step,
        pose and gyro to thrusts; docs/runtime.md).

    Raises
    ------
    InputError
        ``out_dir`` cannot be written (read-only, disk full, under a regular file, no
        permission), or the table cannot be held by the C runtime (e.g. a value that
        overflows float32 at a feasible point); nothing is written then.

    See Also
    --------
    gainsched.build_grid : The grid to write.
    gainsched.load_table : Read the table back.

    Examples
    --------
    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> small = cfg.with_values({"grid.speeds": [6, 9], "grid.tilts_deg": [0, 20],
    ...                          "grid.azimuth_samples": 8, "name": "small"})
    >>> out = tempfile.mkdtemp()
    >>> paths = gs.write_outputs(out, small, gs.build_grid(small))
    >>> [p.name for p in paths]  # doctest: +NORMALIZE_WHITESPACE
    ['small.h5', 'small_gains.h', 'small_control.h', 'gainsched_runtime.h',
     'gainsched_runtime.c', 'gainsched_trig.h', 'gainsched_control.h', 'gainsched_control.c']
    >>> table = gs.load_table(paths[0])
    >>> table.name, table.K.shape, table.config_sha256 == small.sha256
    ('small', (1, 2, 8, 4, 11), True)
    """
    return publish(out_dir, output_files(config, grid, out_dir, grid_auto))
