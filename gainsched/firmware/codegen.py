"""C outputs of a gain table: ``<name>_gains.h`` plus the hand-written runtime beside it.

The header (template ``templates/gains.in.h``) holds the table as C99 ``static
const`` data: float32 values written as hexadecimal float literals (exact, so
every compiler reproduces the same bytes and the embedded CRC-32 holds),
dimensions as macros, every symbol prefixed with the table name. Infeasible
points have zero gains and a non-zero mask entry. Output is deterministic:
the same table gives the same bytes.

The runtime (``c/gainsched_runtime.[ch]``) is copied next to the header; see
docs/runtime.md. For host-side checks (tests, benchmarks) :func:`build_host`
compiles a table with the runtime and the batch shim (``templates/batch.in.c``)
into a shared library or a driver program, and :class:`CRuntime` calls it
through ctypes.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import string
import subprocess
import textwrap
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..native import find_cc
from ..publish import publish, write_atomic
from .compact import CompactData
from .runtime import (
    VEHICLE_FIELDS,
    Lookup,
    RuntimeData,
    c_identifier,
    runtime_data,
    vehicle_fields,
)

__all__ = [
    "RUNTIME_FILES",
    "STRICT_CFLAGS",
    "c_float",
    "c_floats",
    "render",
    "render_header",
    "firmware_data",
    "write_header",
    "copy_runtime",
    "c_files",
    "write_c_outputs",
    "flash_summary",
    "code_bytes",
    "build_host",
    "CRuntime",
]

#: the lookup (its header and source, which also implements the trigonometry) and the
#: trigonometry's header (docs/runtime.md, "Files")
RUNTIME_FILES = ("gainsched_runtime.h", "gainsched_runtime.c", "gainsched_trig.h")
#: the controller (pose and gyro to thrusts) shipped beside the runtime
CONTROL_FILES = ("gainsched_control.h", "gainsched_control.c")
RUNTIME_VERSION = 5
STRICT_CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror")
#: Cortex-M4F flags of ``make firmware-size`` and :func:`code_bytes`
M4F_CFLAGS = ("-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard")


def _resource(*parts) -> str:
    return resources.files("gainsched.firmware").joinpath(*parts).read_text()


def render(template: str, **values) -> str:
    """Fill ``templates/<template>`` (``${key}`` placeholders; C never uses ``$``)."""
    return string.Template(_resource("templates", template)).substitute(values)


# --------------------------------------------------------------------------- formatting


def c_float(x) -> str:
    """Exact C99 float literal of a float32 value (hexadecimal, ``0x1.8p+1f``)."""
    f = float(np.float32(x))
    if not np.isfinite(f):
        raise ValueError(f"non-finite value {f} cannot be emitted")
    if f == 0:
        return "-0.0f" if np.signbit(f) else "0.0f"
    mant, exp = f.hex().split("p")
    mant = mant.rstrip("0").rstrip(".")
    return f"{mant}p{exp}f"


def c_decimal(x) -> str:
    """Shortest decimal C float literal of a float32 value (for macros meant to be read)."""
    return np.format_float_positional(np.float32(x), unique=True, trim="0") + "f"


@lru_cache(maxsize=1)
def _hex_tables():
    """Text pieces of :func:`c_floats`: three hex digits of a 12-bit half of the mantissa,
    with and without their trailing zeros, and ``p<exponent>f`` per biased exponent."""
    full = np.array([f"{h:03x}" for h in range(4096)], dtype=object)
    stripped = np.array([t.rstrip("0") for t in full.tolist()], dtype=object)
    power = np.array([f"p{e - 127:+d}f" for e in range(256)], dtype=object)
    return full, stripped, power


def c_floats(values) -> list[str]:
    """:func:`c_float` of every value of an array, the same text, ~10x faster (a table's
    header has 10^5 to 10^6 values): a normal float32 is ``0x1.`` and its 23 mantissa
    bits as six hex digits without their trailing zeros, then ``p`` and the unbiased
    exponent (``float.hex``); the pieces come from tables indexed by the bits, joined
    in numpy's object loops. Zeros are ``0.0f``; subnormals take :func:`c_float`."""
    full, stripped, power = _hex_tables()
    f = np.asarray(values, dtype=np.float32).ravel()
    if not np.all(np.isfinite(f)):
        c_float(f[~np.isfinite(f)][0])  # raises, naming the value
    bits = f.view(np.uint32)
    exp = (bits >> 23) & 0xFF
    mant = (bits & 0x7FFFFF) << 1  # 24 bits: six hex digits
    hi, lo = mant >> 12, mant & 0xFFF
    digits = np.where(lo == 0, stripped[hi], full[hi] + stripped[lo])
    head = np.where(bits >> 31 == 1, "-0x1", "0x1").astype(object)
    text = head + np.where(digits == "", "", ".").astype(object) + digits + power[exp]
    zero = (bits & 0x7FFFFFFF) == 0
    text[zero] = np.where(bits[zero] >> 31 == 1, "-0.0f", "0.0f")
    for i in np.flatnonzero((exp == 0) & ~zero).tolist():
        text[i] = c_float(f[i])
    return text.tolist()


def _c_uints(values) -> list[str]:
    """C unsigned literals (``3u``) of an array's values (or of one value)."""
    return [f"{int(x)}u" for x in np.ravel(values)]


def _body(arr, fmt, indent=1, per_line=6) -> str:
    """Brace-nested initializer contents of ``arr`` (without the outermost braces), written
    by ``fmt``, an array's formatter (:func:`c_floats`, :func:`_c_uints`)."""
    texts = np.empty(np.shape(arr), dtype=object)
    texts.flat[:] = fmt(arr)
    return _nested(texts, indent, per_line)


def _nested(texts, indent, per_line) -> str:
    pad = "    " * indent
    if texts.ndim == 1:
        vals = texts.tolist()
        lines = [", ".join(vals[i : i + per_line]) for i in range(0, len(vals), per_line)]
        return ",\n".join(pad + line for line in lines)
    parts = [f"{pad}{{\n{_nested(sub, indent + 1, per_line)}\n{pad}}}" for sub in texts]
    return ",\n".join(parts)


# --------------------------------------------------------------------------- header


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
        xi=_body(base.xi, c_floats),
        speed=_body(base.speed, c_floats),
        xi_dot=_body(base.xi_dot, c_floats),
        tilt=_body(base.tilt, c_floats),
        state_sign=_body(base.state_sign, c_floats, per_line=11),
        state_perm=_body(base.state_perm, _c_uints, per_line=11),
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
        K_tilt0=_body(data.K_tilt0.reshape(n_v, data.n_xi_tilt0, 4, n), c_floats),
        K=_body(K, c_floats),
        u_d=_body(data.u_d, c_floats, per_line=4),
        phi_d=_body(data.phi_d, c_floats),
        mask=_body(data.mask, _c_uints, per_line=18))
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
        mask=_body(data.mask, _c_uints, per_line=19),
        harmonics=_body(data.harmonics, _c_uints, per_line=25),
        coef_start=_body(data.start.reshape(n_a, n_v), _c_uints, per_line=10),
        coef=_body(data.coef if n_coef else np.zeros(1, np.float32), c_floats))
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
             f"    {{\n{_body(x, c_floats, 2, int(np.sqrt(x.size)))}\n    }}" for x in f.values()]
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
            f"{{\n{_body(data.offsets, c_floats, per_line=7)}\n}};\n")
    return dict(offset_harmonics=H, offsets_data=body, offsets_ref=f"&{name}_offsets[0][0][0][0]")


def firmware_data(table):
    """What a firmware holds of ``table``: its :class:`RuntimeData` or
    :class:`~gainsched.firmware.compact.CompactData` as given, else the dense form of a
    loaded table (:func:`runtime.runtime_data`)."""
    return table if isinstance(table, RuntimeData | CompactData) else runtime_data(table)


def header_name(data) -> str:
    return f"{data.name}_gains.h"


def _write(path: Path, text: str) -> Path:
    """Atomic write, then the usual permissions (the temp file is created 0600)."""
    write_atomic(path, text.encode())
    umask = os.umask(0)
    os.umask(umask)
    path.chmod(0o644 & ~umask)
    return path


def write_header(table, out_dir) -> Path:
    """Write ``OUT_DIR/<name>_gains.h`` for a loaded table (atomically); returns the path."""
    data = firmware_data(table)
    return _write(Path(out_dir) / header_name(data), render_header(data))


def copy_runtime(out_dir) -> list[Path]:
    """Copy :data:`RUNTIME_FILES` (``gainsched_runtime.[ch]``, ``gainsched_trig.h``) and
    :data:`CONTROL_FILES` (``gainsched_control.[ch]``) into ``out_dir`` (atomically);
    returns the paths: ``gainsched_runtime.h``, ``gainsched_runtime.c``,
    ``gainsched_control.h``, ``gainsched_control.c``, ``gainsched_trig.h``."""
    out = []
    # the original four first, so that a caller's index stays (``[1]`` the lookup's C,
    # ``[3]`` the controller's), then the headers added since
    for fname in (*RUNTIME_FILES[:2], *CONTROL_FILES, *RUNTIME_FILES[2:]):
        out.append(_write(Path(out_dir) / fname, _resource("c", fname)))
    return out


#: ``gs_ctrl_params`` fields: the comment each gets in ``<name>_control.h``
_PARAM_COMMENTS = {
    "dt": "control step, s", "rho": "tether length, m",
    "L_e": "attachment offset behind the COG, m", "thrust_min": "motor range, N",
    "thrust_max": "motor range, N", "thrust_idle": "idle thrust (GS_CTRL_IDLE), N",
    "int_limit": "rad s, each integral state's bound", "n_int": "integral states",
    "int_of": "the reduced state each integrates (0 delta, 1 xi)",
    "pose_delay": "s: SET it to your poses' latency (0: a lead that no status shows)",
    "pose_timeout": "s",
    "quat_tolerance": "| |q|^2 - 1 | of a usable pose", "gyro_range": "rad/s",
    "gyro_scale": "gyro reads scale * omega + bias ([sensors])",
    "gyro_bias": "rad/s, undone: omega = (gyro - bias) / scale",
    "accel_scale": "accelerometer reads scale * f + bias ([sensors])",
    "accel_bias": "m/s^2, undone: f = (accel - bias) / scale",
    "q_MB": "the body in the markers' frame: q_IB = q_pose (x) q_MB ([sensors])",
    "accel_range": "m/s^2", "k_pos": "estimator: position per pose",
    "k_vel": "estimator: velocity per pose", "k_att": "estimator: attitude per pose",
    "pose_period": "s between poses",
    "motor_slot": "output slot of T1..T4", "normalized": "1: commands 0..1, 0: N",
    "thr_mdl_fac": "thrust curve (PX4 THR_MDL_FAC)", "thrust_full": "N at command 1",
    "n_lag": "motor-lag thrusts at the LQR state's end (0 or 4)",
    "lag_keep": "exp(-dt / tau) of that motor lag",
}


def control_header_name(data) -> str:
    return f"{data.name}_control.h"


def render_control_header(data, params) -> str:
    """The text of ``<name>_control.h``: ``<name>_ctrl_params`` (the ``gs_ctrl_params`` of
    :class:`~gainsched.firmware.controller.ControllerParams`) and ``<name>_ctrl_init``."""
    from ..constants import INTEGRATORS
    from ..schedule.onboard import ACCEL_MARGIN, G0

    data = data.base if isinstance(data, CompactData) else data
    lines = []
    for key, ctype, v in params.c_fields():
        text = (c_decimal(v) if ctype == "float" else _c_uints(v)[0] if ctype == "uint32_t" else
                f"{{{', '.join(c_decimal(i) for i in v)}}}" if ctype.startswith("float") else
                f"{{{', '.join(_c_uints(v))}}}")
        note = _PARAM_COMMENTS[key]
        if key == "accel_range":
            note = f"m/s^2 = {v / G0:.3g} g, {ACCEL_MARGIN:g}x the table's largest specific force"
        elif key == "int_limit":
            by_state = {j: name for name, j in INTEGRATORS.items()}
            names = ", ".join(by_state[j] for j in params.int_of) or "none"
            note = f"rad s, bound of {names}: {_int_limit_source(data, params)}"
        lines.append(f"    {text}, /* {key}: {note} */")
    return render("control.in.h", name=data.name, NAME=data.name.upper(),
                  config_name=data.meta.get("config_name", data.name),
                  config_sha256=data.config_sha256 or "unknown",
                  tool_version=data.meta.get("tool_version", "?"),
                  dt_ms=f"{1000 * params.dt:g}",
                  fields="\n".join(lines), **_output_values(params))


def _int_limit_source(data, params) -> str:
    """Where the integral bounds of ``params`` come from, for the control header."""
    from .controller import INT_RANGE_FRACTION, int_limits_for

    if not params.int_of:
        return "unused"
    try:
        sized = int_limits_for(data, params.thrust_min, params.thrust_max, len(params.int_of))
    except (InputError, ValueError):
        sized = None
    if sized == tuple(params.int_limit):
        share = "" if INT_RANGE_FRACTION == 1 else f"{INT_RANGE_FRACTION:g}x "
        return f"{share}motor range / largest gain (sized from the table)"
    return "set, not sized from the table"


def _output_values(params) -> dict:
    """The control header's words for the controller's outputs."""
    from ..actuators import MOTOR_ORDERS, slots_from_order

    order = next((k for k, v in MOTOR_ORDERS.items()
                  if slots_from_order(v) == tuple(params.motor_slot)), "custom")
    slots = ", ".join(f"T{i + 1} -> out[{s}]" for i, s in enumerate(params.motor_slot))
    if params.normalized:
        unit = (f"commands 0..1 through the thrust curve T / {params.thrust_full:g} N = "
                f"(1 - f) u + f u^2, f = THR_MDL_FAC = {params.thr_mdl_fac:g}")
    else:
        unit = "thrusts in N"
    text = textwrap.fill(f"Outputs (out[4]): {order} order ({slots}), {unit}.", width=84,
                         subsequent_indent=" * ")
    return dict(motor_order=order, command="normalized" if params.normalized else "thrust",
                outputs=text)


def c_files(table, params=None) -> dict[str, bytes]:
    """The C outputs of a loaded table (or its :class:`RuntimeData`): file name -> bytes,
    header first, then the runtime and the controller, and with the controller's
    parameters ``params`` (:class:`~gainsched.firmware.controller.ControllerParams`)
    ``<name>_control.h``. Raises InputError if the table cannot be represented."""
    data = firmware_data(table)
    files = {header_name(data): render_header(data).encode()}
    if params is not None:
        files[control_header_name(data)] = render_control_header(data, params).encode()
    files.update((f, _resource("c", f).encode()) for f in RUNTIME_FILES + CONTROL_FILES)
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


# --------------------------------------------------------------------------- sizes


def code_bytes(*, cross: bool | None = None, opt: str = "-Os") -> tuple[int, str] | None:
    """Code bytes of the runtime (``.text*`` and ``.rodata*`` sections of its object file).

    Uses arm-none-eabi-gcc for Cortex-M4F when available (or ``cross=True``), else the
    host compiler. Returns ``(bytes, description)`` or None when no compiler works.
    """
    import tempfile

    use_cross = bool(find_cc(cross=True)) if cross is None else cross
    cc = find_cc(cross=use_cross)
    if cc is None:
        return None
    size_tool = shutil.which("arm-none-eabi-size" if use_cross else "size")
    flags = [*STRICT_CFLAGS, opt, "-ffunction-sections"] + (list(M4F_CFLAGS) if use_cross else [])
    with tempfile.TemporaryDirectory() as tmp:
        src = copy_runtime(tmp)[1]
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
    return total, f"{target} {Path(cc).name} {opt}"


def flash_summary(table, *, compile_code: bool = True) -> list[str]:
    """Lines describing the flash footprint: table bytes per array and runtime code bytes."""
    data = firmware_data(table)
    sizes = {k: len(b) for k, b in data.crc_chunks() if k not in ("dims", "xi_scale")}
    big = ", ".join(f"{k} {v}" for k, v in sizes.items() if v >= 1024)
    lines = [f"flash: table data {data.nbytes()} bytes ({data.nbytes() / 1024:.1f} KiB; {big})"]
    if compile_code:
        cb = code_bytes()
        if cb is None:
            lines.append("flash: runtime code size unknown (no working C compiler)")
        else:
            lines.append(f"flash: runtime code {cb[0]} bytes ({cb[1]}, .text + .rodata)")
    return lines


# --------------------------------------------------------------------------- host builds


def build_host(
    table, out_dir, *, cc=None, opt="-O2", sanitize=False, shared=True, extra=()
) -> Path:
    """Compile the table, the runtime and the batch shim for the host.

    ``shared``: a shared library for :class:`CRuntime`; otherwise the driver program
    (``batch``/``bench``/``verify`` modes, see ``templates/batch.in.c``). ``sanitize``
    adds AddressSanitizer + UndefinedBehaviorSanitizer (abort on the first report).
    Compiles with the strict warning set and -Werror. Returns the built file.
    """
    data = firmware_data(table)
    cc = cc or find_cc()
    if cc is None:
        raise RuntimeError("no C compiler found (set CC)")
    out_dir = Path(out_dir)
    header = write_header(data, out_dir)
    runtime_c = copy_runtime(out_dir)[1]
    shim = out_dir / f"{data.name}_batch.c"
    _write(
        shim,
        render(
            "batch.in.c",
            name=data.name,
            NAME=data.name.upper(),
            tool_version=data.meta.get("tool_version", "?"),
        ),
    )
    flags = [*STRICT_CFLAGS, opt, "-g", f"-I{out_dir}", *extra]
    if sanitize:
        flags += [
            "-fsanitize=address,undefined",
            "-fno-sanitize-recover=all",
            "-fno-omit-frame-pointer",
        ]
    suffix = "_san" if sanitize else ""
    if shared:
        out = out_dir / f"lib{data.name}_batch{suffix}.so"
        flags += ["-shared", "-fPIC"]
    else:
        out = out_dir / f"{data.name}_batch{suffix}"
        flags += ["-DGS_BATCH_MAIN"]
    cmd = [cc, *flags, "-o", str(out), str(shim), str(runtime_c)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{res.stderr}")
    assert header.exists()
    return out


class CRuntime:
    """The C runtime with one table, loaded through ctypes (a :func:`build_host` library)."""

    def __init__(self, lib_path, data: RuntimeData):
        self.data = data
        self.lib = lib = ctypes.CDLL(str(lib_path))
        nm = data.name
        self._batch = getattr(lib, f"{nm}_lookup_batch")
        self._batch.restype = None
        fp = np.ctypeslib.ndpointer(np.float32, flags="C_CONTIGUOUS")
        ip = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
        self._batch.argtypes = [ctypes.c_size_t, fp, fp, fp, fp, ip]
        self._verify = getattr(lib, f"{nm}_verify_table")
        self._verify.restype = ctypes.c_int
        self._crc = getattr(lib, f"{nm}_crc32")
        self._crc.restype = ctypes.c_uint32
        self._flip = getattr(lib, f"{nm}_verify_flipped")
        self._flip.argtypes = [ctypes.c_int, ctypes.c_size_t, ctypes.c_uint]
        self._flip.restype = ctypes.c_int
        self._bench = getattr(lib, f"{nm}_bench")
        self._bench.argtypes = [ctypes.c_size_t, fp, ctypes.c_int]
        self._bench.restype = ctypes.c_double
        self._nominal = getattr(lib, f"{nm}_nominal_batch")
        self._nominal.restype = None
        self._nominal.argtypes = [ctypes.c_size_t, fp, fp, fp, fp, fp, ip]
        self._trig = getattr(lib, f"{nm}_trig_batch")
        self._trig.restype = None
        self._trig.argtypes = [ctypes.c_size_t] + [fp] * 6
        self._bench_nominal = getattr(lib, f"{nm}_bench_nominal")
        self._bench_nominal.argtypes = [ctypes.c_size_t, fp, ctypes.c_int]
        self._bench_nominal.restype = ctypes.c_double
        self._ftz = getattr(lib, f"{nm}_flush_to_zero")
        self._ftz.argtypes = [ctypes.c_int]
        self._ftz.restype = ctypes.c_int
        self._queries = getattr(lib, f"{nm}_bench_queries")
        self._queries.argtypes = [ctypes.c_size_t, ctypes.c_uint32, fp]
        self._queries.restype = None

    def lookup(self, xi, xi_dot, alpha) -> Lookup:
        """Batched C lookups (one ctypes call); same shapes as the Python reference."""
        shape = np.broadcast_shapes(np.shape(xi), np.shape(xi_dot), np.shape(alpha))
        with np.errstate(over="ignore", invalid="ignore"):
            q = np.stack(
                [
                    np.broadcast_to(np.asarray(v, dtype=np.float32), shape).reshape(-1)
                    for v in (xi, xi_dot, alpha)
                ],
                axis=1,
            )
        q = np.ascontiguousarray(q)
        m, n = q.shape[0], self.data.dims[3]
        K = np.full((m, 4 * n), np.float32(12345.0))  # sentinel: must be overwritten
        U = np.full((m, 4), np.float32(12345.0))
        P = np.full(m, np.float32(12345.0))
        S = np.full(m, -1, dtype=np.int32)
        self._batch(m, q, K, U, P, S)
        return Lookup(
            K.reshape(shape + (4, n)), U.reshape(shape + (4,)), P.reshape(shape), S.reshape(shape)
        )

    __call__ = lookup

    def nominal(self, ref, alpha):
        """Batched ``gs_lookup_nominal``: references ``ref`` (m, 5) (xi rad, xi' rad/s,
        xi'' rad/s^2, xi''' rad/s^3, xi'''' rad/s^4) at tilts ``alpha`` (m,) or scalar, rad.

        Returns ``(K (m, 4, n), u_d (m, 4) N, x_d (m, 10), tension (m,) N, status (m,))``,
        float32 outputs of the runtime.
        """
        ref = np.asarray(ref, dtype=np.float64).reshape(-1, 5)
        m, n = ref.shape[0], self.data.dims[3]
        with np.errstate(over="ignore", invalid="ignore"):
            q = np.empty((m, 6), dtype=np.float32)
            q[:, :5] = ref
            q[:, 5] = np.broadcast_to(np.asarray(alpha, dtype=np.float64), (m,))
        K = np.full((m, 4 * n), np.float32(12345.0))  # sentinel: must be overwritten
        U = np.full((m, 4), np.float32(12345.0))
        X = np.full((m, 10), np.float32(12345.0))
        T = np.full(m, np.float32(12345.0))
        S = np.full(m, -1, dtype=np.int32)
        self._nominal(m, q, K, U, X, T, S)
        return K.reshape(m, 4, n), U, X, T, S

    def trig(self, x, y):
        """The runtime's ``gs_sincosf(x)``, ``gs_atan2f(y, x)``, ``gs_sqrtf(x)`` on float32
        arrays of one shape (m,): ``(sin, cos, atan2, sqrt)``."""
        x = np.ascontiguousarray(x, dtype=np.float32).reshape(-1)
        y = np.ascontiguousarray(y, dtype=np.float32).reshape(-1)
        out = [np.empty_like(x) for _ in range(4)]
        self._trig(x.size, x, y, *out)
        return tuple(out)
    def flush_to_zero(self, on: bool) -> bool:
        """Flush-to-zero and denormals-are-zero on or off for the calling thread (x86
        MXCSR, as FPSCR.FZ on a Cortex-M4F); False where the host has no such switch."""
        return bool(self._ftz(int(on)))

    def verify(self) -> int:
        return int(self._verify())

    def crc32(self) -> int:
        return int(self._crc())

    def verify_flipped(self, which: int, byte: int, flip: int = 0x01) -> int:
        """``gs_verify`` on a copy with one byte of array ``which`` (CRC order) flipped."""
        return int(self._flip(which, byte, flip))

    def bench_queries(self, m: int, seed: int = 12345) -> np.ndarray:
        q = np.zeros((m, 3), dtype=np.float32)
        self._queries(m, seed, q)
        return q

    def bench(self, q, reps: int = 1, *, nominal: bool = False) -> float:
        """``reps`` passes of lookups over queries ``q`` (m, 3); ``nominal``: with
        ``gs_lookup_nominal`` (derivatives of ``<name>_bench_reference``). Checksum."""
        q = np.ascontiguousarray(q, dtype=np.float32)
        fn = self._bench_nominal if nominal else self._bench
        return float(fn(q.shape[0], q, reps))


def check_runtime_data(table_path) -> RuntimeData:
    """Load a table file and convert it, raising InputError for problems."""
    from ..schedule.tables import load_table

    try:
        return runtime_data(load_table(table_path))
    except ValueError as exc:  # an InputError (a ValueError too) keeps its file and key
        raise exc if isinstance(exc, InputError) else InputError(table_path, "", f"{exc}") from None
