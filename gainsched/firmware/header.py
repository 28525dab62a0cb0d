"""``<name>_gains.h``: the C header of a table, rendered from ``templates/gains.in.h``.

The header holds the table as C99 ``static const`` data: float32 values written as
hexadecimal float literals (:mod:`.cformat`: exact, so every compiler reproduces the same
bytes and the embedded CRC-32 holds), dimensions as macros, every symbol prefixed with
the table name. Infeasible points have zero gains and a non-zero mask entry. Output is
deterministic: the same table gives the same bytes. A table in either format: the dense
runtime data (:func:`~.runtime.runtime_data`) or the compact series
(:class:`~.compact.CompactData`); :func:`firmware_data` is what a firmware holds of a
table.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .cformat import c_decimal, c_float, c_floats, c_initializer, c_uints
from .compact import CompactData
from .runtime import (
    VEHICLE_FIELDS,
    RuntimeData,
    c_identifier,
    runtime_data,
    vehicle_fields,
)
from .sources import RUNTIME_VERSION, render

__all__ = ["firmware_data", "header_name", "render_header"]


def firmware_data(table):
    """What a firmware holds of ``table``: its :class:`RuntimeData` or
    :class:`~gainsched.firmware.compact.CompactData` as given, else the dense form of a
    loaded table (:func:`runtime.runtime_data`). Raises InputError for a table of both
    flight directions (a vehicle that is not its own mirror image, docs/symmetry.md): the
    C runtime holds one."""
    data = table if isinstance(table, RuntimeData | CompactData) else runtime_data(table)
    base = data.base if isinstance(data, CompactData) else data
    if base.reverse is not None:
        raise InputError(getattr(table, "source", "") or base.name, "reverse",
                         "holds both flight directions (the vehicle is not its own mirror "
                         "image, docs/symmetry.md), and the firmware's C runtime holds one")
    return data


def header_name(data) -> str:
    return f"{data.name}_gains.h"


def render_header(data) -> str:
    """The text of ``<name>_gains.h`` for a table in either format: dense runtime data
    (:func:`runtime.runtime_data`) or its compact form
    (:class:`~gainsched.firmware.compact.CompactData`)."""
    from ..constants import MASK_NO_GAINS, REASONS

    compact = isinstance(data, CompactData)
    base = data.base if compact else data
    n_a, n_v, n_xi, n = base.dims
    meta = base.meta
    bits = "; ".join(f"{b:#04x} {t}" for b, t in REASONS.items())
    values = dict(
        name=base.name,
        NAME=base.name.upper(),
        config_name=meta.get("config_name", base.name),
        tool_version=meta.get("tool_version", "?"),
        config_sha256=base.config_sha256,
        n_tilt=n_a,
        n_speed=n_v,
        n_xi=n_xi,
        n_state=n,
        n_tilt_k=max(1, n_a - 1),
        radius=c_decimal(meta.get("radius_m", 0.0)),
        rate_hz=c_decimal(meta.get("rate_hz", 0.0)),
        xi_note=f"{360 / n_xi:g} deg steps",
        speed_note=", ".join(f"{v:g}" for v in base.speed),
        tilt_note=", ".join(f"{v:g}" for v in np.round(np.rad2deg(base.tilt.astype(float)), 6))
        + " deg",
        xi_scale=c_float(base.xi_scale),
        crc32_hex=f"{data.crc32():08x}",
        data_bytes=data.nbytes(),
        runtime_version=RUNTIME_VERSION,
        control_law=str(meta.get("control_law", "u = u_d - K (x - x_d)")),
        state_names=", ".join(base.state_names) if base.state_names else "?",
        mask_bits=f"{bits}; {MASK_NO_GAINS:#04x} no gains stored (zeros)",
        xi=c_initializer(base.xi, c_floats),
        speed=c_initializer(base.speed, c_floats),
        xi_dot=c_initializer(base.xi_dot, c_floats),
        tilt=c_initializer(base.tilt, c_floats),
        state_sign=c_initializer(base.state_sign, c_floats, per_line=11),
        state_perm=c_initializer(base.state_perm, c_uints, per_line=11),
        n_xi_tilt0=base.n_xi_tilt0,
    )
    values["state_macros"] = _state_macros(base)
    values.update(_compact_values(data) if compact else _dense_values(base))
    values.update(_vehicle_values(base))
    values.update(_offsets_values(base))
    return render("gains.in.h", **values)


def _dense_values(data: RuntimeData) -> dict:
    """Template values of a dense table's per-azimuth arrays."""
    n_a, n_v, n_xi, n = data.dims
    name, NAME = data.name, data.name.upper()
    K = data.K if n_a > 1 else np.zeros((1, n_v, n_xi, 4, n), dtype=np.float32)
    arrays = render(
        "dense_values.in.h", name=name, NAME=NAME,
        tilt0_note=("independent of xi" if data.n_xi_tilt0 == 1
                    else "per azimuth: an effect changes with the azimuth"),
        K_tilt0=c_initializer(data.K_tilt0.reshape(n_v, data.n_xi_tilt0, 4, n), c_floats),
        K=c_initializer(K, c_floats),
        u_d=c_initializer(data.u_d, c_floats, per_line=4),
        phi_d=c_initializer(data.phi_d, c_floats),
        mask=c_initializer(data.mask, c_uints, per_line=18))
    dense = (f"{NAME}_N_XI_TILT0", f"&{name}_K_tilt0[0][0][0][0]",
             f"&{name}_K[0][0][0][0][0]", f"&{name}_u_d[0][0][0][0]", f"&{name}_phi_d[0][0][0]")
    return dict(
        format_macros=f"#define {NAME}_FORMAT GS_FORMAT_DENSE /* values at every azimuth */",
        value_arrays=arrays, mask_ref=f"&{name}_mask[0][0][0]",
        dense_part=_part(dense), compact_part=_part(("0u", "0u", "NULL", "NULL", "NULL")))


def _part(fields) -> str:
    """The initializer lines of a ``gs_dense_part`` or ``gs_compact_part``."""
    return ",\n".join(f"        {v}" for v in fields)


def _compact_values(data) -> dict:
    """Template values of a compact table's series."""
    n_a, n_v, n_xi, n = data.dims
    name, NAME = data.name, data.name.upper()
    n_coef = int(data.coef.size)
    macros = "\n".join([
        f"#define {NAME}_FORMAT GS_FORMAT_COMPACT /* Fourier series in xi per circle */",
        f"#define {NAME}_N_VALUE {data.n_value}u /* series per circle: 4 N_STATE + 4 + 1 */",
        f"#define {NAME}_N_HARMONICS {data.n_harmonics}u /* the most harmonics of any series */",
        f"#define {NAME}_N_COEF {n_coef}u /* coefficients */",
        f"#define {NAME}_N_COEF_ARRAY {max(n_coef, 1)}u /* length of {name}_coef (>= 1) */",
    ])
    arrays = render(
        "compact_values.in.h", name=name, NAME=NAME, n_xi=n_xi,
        azimuth_error=f"{100 * data.bound:g}",
        mask=c_initializer(data.mask, c_uints, per_line=19),
        harmonics=c_initializer(data.harmonics, c_uints, per_line=25),
        coef_start=c_initializer(data.start.reshape(n_a, n_v), c_uints, per_line=10),
        coef=c_initializer(data.coef if n_coef else np.zeros(1, np.float32), c_floats))
    compact = (f"{NAME}_N_HARMONICS", f"{NAME}_N_COEF", f"&{name}_harmonics[0][0][0]",
               f"&{name}_coef_start[0][0]", f"{name}_coef")
    return dict(
        format_macros=macros, value_arrays=arrays, mask_ref=f"&{name}_mask[0][0]",
        dense_part=_part(("0u", "NULL", "NULL", "NULL", "NULL")),
        compact_part=_part(compact))


def _state_macros(data: RuntimeData) -> str:
    """``#define <NAME>_X_<STATE> <column>u`` for every LQR state, and whether each
    integral state of :data:`gainsched.constants.INTEGRATORS` is present."""
    from ..constants import INTEGRATORS

    NAME = data.name.upper()
    lines = [f"#define {NAME}_X_{c_identifier(x).upper()} {j}u"
             for j, x in enumerate(data.state_names)]
    lines += [f"#define {NAME}_HAS_{c_identifier(x).upper()} {int(x in data.state_names)}"
              for x in INTEGRATORS]
    return "\n".join(lines)


def _vehicle_values(data: RuntimeData) -> dict:
    """Template values of the feed-forward's ``gs_vehicle`` (or its absence)."""
    name, NAME = data.name, data.name.upper()
    if data.vehicle is None:
        return dict(has_vehicle=0, vehicle_macros="", vehicle_data="", vehicle_ref="NULL")
    f = vehicle_fields(np.asarray(data.vehicle, dtype=np.float32))
    macros = "\n".join([
        f"#define {NAME}_MASS_KG {c_decimal(f['mass'][0])} /* vehicle mass */",
        f"#define {NAME}_G_MPS2 {c_decimal(f['g'][0])} /* gravity */",
        f"#define {NAME}_MIN_TENSION_N {c_decimal(f['min_tension'][0])} /* taut margin: "
        "GS_LOW_TENSION below */",
        f"#define {NAME}_DRAG_MU1 {c_decimal(f['drag_mu1'][0])} /* body drag "
        "(mu1 + mu2 |v|) v, N s/m */",
        f"#define {NAME}_DRAG_MU2 {c_decimal(f['drag_mu2'][0])} /* N s^2/m^2 */",
    ])
    # one initializer per field, in gs_vehicle order: scalars, then the 3x3 and 4x4 blocks
    inits = [f"    {c_float(x[0])}" if x.size == 1 else
             f"    {{\n{c_initializer(x, c_floats, 2, int(np.sqrt(x.size)))}\n    }}"
             for x in f.values()]
    body = (f"/* closed-form constants of the feed-forward, in gs_vehicle order:\n"
            f" * {', '.join(VEHICLE_FIELDS)} */\n"
            f"static const gs_vehicle {name}_vehicle = {{\n" + ",\n".join(inits) + ",\n};\n")
    return dict(has_vehicle=1, vehicle_macros=macros, vehicle_data=body,
                vehicle_ref=f"&{name}_vehicle")


def _offsets_values(data: RuntimeData) -> dict:
    """Template values of the nominal's attitude offsets (or their absence)."""
    if data.offsets is None:
        return dict(offset_harmonics=0, offsets_data="", offsets_ref="NULL")
    name, NAME = data.name, data.name.upper()
    H = (data.offsets.shape[-1] - 1) // 2
    body = (f"/* pitch and yaw offsets of the nominal per circle, rad: Fourier coefficients "
            f"in the\n * azimuth [1, cos k xi, sin k xi], k = 1..{H}: "
            f"[tilt][speed][theta, chi][2 H + 1] */\n"
            f"static const float {name}_offsets[{NAME}_N_TILT][{NAME}_N_SPEED][2][{2 * H + 1}] = "
            f"{{\n{c_initializer(data.offsets, c_floats, per_line=7)}\n}};\n")
    return dict(offset_harmonics=H, offsets_data=body, offsets_ref=f"&{name}_offsets[0][0][0][0]")
