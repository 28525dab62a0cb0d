"""``<name>_control.h``: the controller's parameters of a table, rendered from
``templates/control.in.h``.

``<name>_ctrl_params`` is the ``gs_ctrl_params`` of a
:class:`~gainsched.firmware.controller.ControllerParams` (each field with a comment
saying what it is and, for the integral bounds and the accelerometer range, where it
comes from) and ``<name>_ctrl_init`` sets a controller up with it.
"""

from __future__ import annotations

import textwrap

from ..errors import InputError
from .cformat import c_decimal, c_uints
from .compact import CompactData
from .sources import render

__all__ = ["control_header_name", "render_control_header"]


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
        text = (c_decimal(v) if ctype == "float" else c_uints(v)[0] if ctype == "uint32_t" else
                f"{{{', '.join(c_decimal(i) for i in v)}}}" if ctype.startswith("float") else
                f"{{{', '.join(c_uints(v))}}}")
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
