"""Named constants shared across the layers: dimensions, feasibility bits, runtime limits.

The lowest layer of the package (imports nothing of it), so that the config
checks, the schedule, the tables and the runtime read one definition each.
"""

from __future__ import annotations

from enum import IntFlag

__all__ = [
    "N_STATE",
    "N_INPUT",
    "N_LQR",
    "Reason",
    "REASONS",
    "MASK_NO_GAINS",
    "MAX_XI",
    "XI_LIMIT",
    "XI_DOT_LIMIT",
    "TILT_LIMIT",
    "TILT_BATCH",
]

#: reduced state (delta, xi, delta', xi', phi, theta, chi, omega_x, omega_y, omega_z)
N_STATE = 10
#: inputs: the four motor thrusts (T1, T2, T3, T4), N
N_INPUT = 4
#: LQR state: the reduced state plus the integral of the delta error (paper Sec. IV.B)
N_LQR = 11


class Reason(IntFlag):
    """Why a grid point is infeasible (uint8 bits stored in ``feasibility/reasons``)."""

    SLACK = 0x01
    THRUST_LOW = 0x02
    THRUST_HIGH = 0x04
    TRIM_FAILED = 0x08
    ELSEWHERE = 0x10


#: the text of each reason bit, as stored in the tables' ``bit_N`` attributes
REASONS = {
    int(Reason.SLACK): "tether slack",
    int(Reason.THRUST_LOW): "thrust below minimum",
    int(Reason.THRUST_HIGH): "thrust above maximum",
    int(Reason.TRIM_FAILED): "trim failed",
    int(Reason.ELSEWHERE): "circle infeasible elsewhere",
}
#: mask bit of the C tables for a point without gains (above every Reason bit)
MASK_NO_GAINS = 0x80

# limits of the C runtime's queries (gainsched_runtime.h; the Python reference and the
# config checks read these)
#: largest azimuth axis the runtime accepts (exact float <-> int wraps)
MAX_XI = 4096
#: |xi| above this is a bad query, rad
XI_LIMIT = 1.0e4
#: |xi_dot| above this is a bad query, rad/s
XI_DOT_LIMIT = 1.0e3
#: |alpha| above this is a bad query, rad (pi / 2)
TILT_LIMIT = 1.5707963267948966

#: tilts solved together in one job of the grid sweep: bounds a job's working set (the
#: A_k, B_k of a batch: 8 x N x 165 doubles, 20 MB at 1 kHz), so build time and memory
#: grow linearly with the number of tilts
TILT_BATCH = 8
