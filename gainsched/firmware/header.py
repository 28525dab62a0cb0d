"""``<name>_gains.h``: the C header of a table, rendered from ``templates/gains.in.h``.

The header holds the table as C99 ``static const`` data: float32 values written as
hexadecimal float literals (:mod:`.cformat`: exact, so every compiler reproduces the same
bytes and the embedded CRC-32 holds), dimensions as macros, every symbol prefixed with
the table name; a table of both flight directions adds its reverse half's arrays and
``gs_table`` (``<name>_reverse_table``). Infeasible points have zero gains and a non-zero
mask entry. Output is deterministic: the same table gives the same bytes. A table in
either format: the dense runtime data (:func:`~.runtime.runtime_data`) or the compact
series (:class:`~.compact.CompactData`); :func:`firmware_data` is what a firmware holds
of a table.
"""

from __future__ import annotations

import dataclasses

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
    loaded table (:func:`runtime.runtime_data`). A table of both flight directions (a
    vehicle that is not its own mirror image, docs/symmetry.md) keeps its ``reverse``
    half (``gs_table.reverse``)."""
    data = table if isinstance(table, RuntimeData | CompactData) else runtime_data(table)
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
        margins_note="\n * ".join(str(meta.get("margins", "stability margins: not in this "
                                   "table ([control] margins = false)")).splitlines()),
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
    values.update(_reverse_values(base))
    return render("gains.in.h", **values)


def _reverse_values(data: RuntimeData) -> dict:
    """Template values of a dense table's reverse half (both flight directions,
    ``gs_table.reverse``): its arrays and its ``gs_table`` (the table's axes and state
    map, which it shares bit for bit), or nothing."""
    r = data.reverse
    if r is None:
        return dict(directions_note="", reverse_data="",
                    reverse_ref="    NULL, /* reverse: the vehicle is its own mirror image */\n")
    name, NAME = data.name, data.name.upper()
    for key in ("xi", "speed", "xi_dot", "tilt", "state_sign", "state_perm"):
        if getattr(r, key).tobytes() != getattr(data, key).tobytes():
            raise InputError(name, f"reverse/{key}", "differs from the table's: the two "
                             "flight directions share their axes and state map")
    rname, RNAME = f"{name}_reverse", f"{NAME}_REVERSE"
    half = dataclasses.replace(r, name=rname)
    dense = _dense_values(half, NAME, f"{RNAME}_N_XI_TILT0")
    vehicle = _vehicle_values(half)
    offsets = _offsets_values(half, NAME)
    H = offsets["offset_harmonics"]
    fields = [f"{NAME}_FORMAT", f"{NAME}_N_TILT", f"{NAME}_N_SPEED", f"{NAME}_N_XI",
              f"{NAME}_N_STATE", f"{NAME}_XI_SCALE", f"{name}_xi", f"{name}_speed",
              f"{name}_xi_dot", f"{name}_tilt", f"{name}_state_sign", f"{name}_state_perm",
              f"&{rname}_mask[0][0][0]",
              "{ /* dense part */\n" + dense["dense_part"] + "\n    }",
              "{ /* compact part */\n" + dense["compact_part"] + "\n    }",
              vehicle["vehicle_ref"], f"{H}u", offsets["offsets_ref"], f"{RNAME}_CRC32",
              "NULL /* the reverse half has none */"]
    body = "".join([
        "\n/* ---- the reverse half: the same table of the vehicle's mirror image (docs/"
        "symmetry.md),\n * read for xi_dot < 0 before the S2 output map; the table's axes "
        "and state map ---- */\n",
        f"#define {RNAME}_N_XI_TILT0 {r.n_xi_tilt0}u /* azimuths of {rname}_K_tilt0 */\n",
        f"#define {RNAME}_CRC32 0x{r.crc32():08x}u /* CRC-32 of the reverse half's data */\n\n",
        dense["value_arrays"], vehicle["vehicle_data"], offsets["offsets_data"],
        f"\nstatic const gs_table {rname}_table = {{\n",
        "".join(f"    {f},\n" for f in fields), "};\n"])
    return dict(directions_note=(
        "\n * both flight directions: the vehicle is not its own mirror image (docs/"
        f"symmetry.md);\n * {rname}_table (its mirror image's) serves xi_dot < 0"),
        reverse_data=body, reverse_ref=f"    &{rname}_table,\n")


def _dense_values(data: RuntimeData, NAME: str | None = None,
                  n_xi_tilt0: str | None = None) -> dict:
    """Template values of a dense table's per-azimuth arrays (``NAME``: the prefix of the
    dimension macros, the table's own by default)."""
    n_a, n_v, n_xi, n = data.dims
    name, NAME = data.name, NAME or data.name.upper()
    K = data.K if n_a > 1 else np.zeros((1, n_v, n_xi, 4, n), dtype=np.float32)
    arrays = render(
        "dense_values.in.h", name=name, NAME=NAME,
        N_XI_TILT0=n_xi_tilt0 or f"{NAME}_N_XI_TILT0",
        tilt0_note=("independent of xi" if data.n_xi_tilt0 == 1
                    else "per azimuth: an effect changes with the azimuth"),
        K_tilt0=c_initializer(data.K_tilt0.reshape(n_v, data.n_xi_tilt0, 4, n), c_floats),
        K=c_initializer(K, c_floats),
        u_d=c_initializer(data.u_d, c_floats, per_line=4),
        phi_d=c_initializer(data.phi_d, c_floats),
        mask=c_initializer(data.mask, c_uints, per_line=18))
    dense = (n_xi_tilt0 or f"{NAME}_N_XI_TILT0", f"&{name}_K_tilt0[0][0][0][0]",
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


def _offsets_values(data: RuntimeData, NAME: str | None = None) -> dict:
    """Template values of the nominal's attitude offsets (or their absence)."""
    if data.offsets is None:
        return dict(offset_harmonics=0, offsets_data="", offsets_ref="NULL")
    name, NAME = data.name, NAME or data.name.upper()
    H = (data.offsets.shape[-1] - 1) // 2
    body = (f"/* pitch and yaw offsets of the nominal per circle, rad: Fourier coefficients "
            f"in the\n * azimuth [1, cos k xi, sin k xi], k = 1..{H}: "
            f"[tilt][speed][theta, chi][2 H + 1] */\n"
            f"static const float {name}_offsets[{NAME}_N_TILT][{NAME}_N_SPEED][2][{2 * H + 1}] = "
            f"{{\n{c_initializer(data.offsets, c_floats, per_line=7)}\n}};\n")
    return dict(offset_harmonics=H, offsets_data=body, offsets_ref=f"&{name}_offsets[0][0][0][0]")
