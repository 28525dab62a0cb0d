"""Named constants shared across the layers: dimensions, feasibility bits, runtime limits.

The lowest layer of the package (imports nothing of it), so that the config
checks, the schedule, the tables and the runtime read one definition each.
"""

from __future__ import annotations

from enum import IntFlag

__all__ = [
    "COMPLEX_STEP",
    "N_STATE",
    "N_INPUT",
    "INTEGRATORS",
    "REDUCED_NAMES",
    "CONTROL_LAW",
    "Reason",
    "REASONS",
    "MASK_NO_GAINS",
    "MAX_XI",
    "XI_LIMIT",
    "XI_DOT_LIMIT",
    "TILT_LIMIT",
    "TILT_BATCH",
    "BIN_VARIABLES",
    "MAX_FLIGHT_S",
    "MAX_FLIGHT_STEPS",
    "MAX_SEED",
    "MAX_SWEEP_VARIANTS",
    "MAX_JOBS",
    "MAX_LOG_BYTES",
    "MARGIN_GAIN_MAX",
    "MARGIN_DELAY_MAX_S",
]

#: reduced state (delta, xi, delta', xi', phi, theta, chi, omega_x, omega_y, omega_z)
N_STATE = 10
#: the imaginary step of every complex-step derivative (the model's Jacobians, the trim's
#: local partials, the thrust modifiers' partials): exact to rounding for any step this
#: small, since no subtraction cancels
COMPLEX_STEP = 1e-30
#: names of the reduced state entries (LQR state columns 0-9)
REDUCED_NAMES = ("delta", "xi", "delta_dot", "xi_dot", "phi", "theta", "chi",
                 "omega_x", "omega_y", "omega_z")
#: the control law the gains are for (stored in the tables and the C headers)
CONTROL_LAW = ("u = u_d - K (x - x_d); the azimuth error from continuous (unwrapped) "
               "azimuths, never wrapped at +-pi; integral states integrate their errors")
#: inputs: the four motor thrusts (T1, T2, T3, T4), N
N_INPUT = 4
#: the stability margins' search ranges (gainsched.schedule.margins): the largest factor
#: on the commands (+20 dB) and the longest extra delay, s; beyond them a margin is
#: reported infinite, and a build bound cannot ask for more
MARGIN_GAIN_MAX = 10.0
MARGIN_DELAY_MAX_S = 0.05
#: the LQR's optional integral states, in their order after the reduced state (before
#: the effect states): name -> index of the reduced state whose error each integrates.
#: ``int_delta`` is the paper's (Sec. IV.B, ``[control] integrator``); ``int_xi``, the
#: along-track integral, holds the place on the circle (``[control] azimuth_integral``)
INTEGRATORS = {"int_delta": 0, "int_xi": 1}


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

#: the variables model-vs-measurement residuals are binned against: (unit, meaning)
#: (gainsched.analysis.compare where it fails, gainsched.analysis.structure)
BIN_VARIABLES = {
    "airspeed": ("m/s", "airspeed |v|"),
    "tilt": ("deg", "circle tilt alpha_C"),
    "azimuth": ("deg", "azimuth xi"),
    "tension": ("N", "tether tension"),
    "thrust": ("N", "commanded collective thrust"),
    "time": ("s", "time in flight"),
}

# ------------------------------------------------------------------------ input limits
# Every count and duration a user gives is bounded where it comes in (scenario files,
# command-line options), so that no input asks for more memory or time than a machine has.

#: longest simulated flight, s (a scenario's ``duration``, ``campaign --duration``): a
#: tethered flight at 15 m/s laps its circle every second and the paper's experiments
#: last seconds; 600 s at the paper's 1 kHz control rate is 600,000 control steps
MAX_FLIGHT_S = 600.0
#: most control steps of one simulated flight (duration x control rate): each step records
#: some 70 numbers (true and estimated state, nominal, thrusts, pose, status) and the log
#: made of them, about 1 KiB a step, so 1,000,000 steps is about 1 GB of memory
MAX_FLIGHT_STEPS = 1_000_000
#: largest seed of the noise (``--seed``, a scenario's ``[sensing] seed``): numpy takes
#: any non-negative integer; a TOML integer is 64-bit signed, so both sides share this
MAX_SEED = 2**63 - 1
#: most variants of one sweep (``--vary`` values multiplied, times ``--monte-carlo``):
#: each is a whole table build (a second for a small grid, half a minute for the paper's)
#: and a table on disk (up to a few MB), so 1000 variants are hours and gigabytes
MAX_SWEEP_VARIANTS = 1000
#: most parallel workers (``-j``): beyond the cores of any machine or cluster we run on,
#: more only costs memory (-1: all cores)
MAX_JOBS = 1024
#: largest CSV flight log, bytes: the reader holds the text and its fields (several
#: times the size) in memory; a 600 s flight at 1 kHz is about 100 MB of CSV, and a
#: longer one goes as HDF5 (read by column). Bounds a ``.csv`` that is a device or a
#: link to one (``/dev/zero`` never ends)
MAX_LOG_BYTES = 256 * 2**20
