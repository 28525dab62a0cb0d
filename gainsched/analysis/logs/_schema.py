"""The names and limits of ``gainsched-flightlog/1`` (docs/flight-log.md): the columns, the
metadata keys, the plausible ranges and the tolerances the reader applies.
"""

from __future__ import annotations

import re

SCHEMA = "gainsched-flightlog/1"
REQUIRED_COLUMNS = ("t", "x", "y", "z", "qw", "qx", "qy", "qz", "T1", "T2", "T3", "T4")
#: Optional known columns, grouped into the arrays of ``FlightLog.optional``.
OPTIONAL_COLUMNS = {
    "omega_B": ("p", "q", "r"),
    "f_B": ("ax", "ay", "az"),
    "tension": ("tension",),
    "vbat": ("vbat",),
    "xi_ref": ("xi_ref",),
    "xi_dot_ref": ("xi_dot_ref",),
}
REQUIRED_META = ("schema", "alpha_c_deg", "gamma_c_deg")
_META_ORDER = ("schema", "alpha_c_deg", "gamma_c_deg", "flight_id", "vehicle", "notes")
QUAT_NORM_TOL = 0.01
_QUAT_EXACT_TOL = 1e-12
DEFAULT_MIN_SAMPLES = 31
GAP_FACTOR = 1.5
_EXTENSIONS = {".csv": "csv", ".h5": "hdf5", ".hdf5": "hdf5"}
_KEY_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_KNOWN = frozenset(REQUIRED_COLUMNS).union(*OPTIONAL_COLUMNS.values())
#: largest plausible |value| per known column, with its unit (the docstring of
#: :mod:`gainsched.analysis.logs`)
PLAUSIBLE = {
    "t": (1e10, "s"),
    **{c: (1e3, "m") for c in "xyz"},
    **{f"T{j}": (1e3, "N") for j in range(1, 5)},
    **{c: (1e3, "rad/s") for c in "pqr"},
    **{c: (1e4, "m/s^2") for c in ("ax", "ay", "az")},
    "tension": (1e4, "N"),
    "vbat": (1e3, "V"),
    "xi_ref": (1e7, "rad"),
    "xi_dot_ref": (1e3, "rad/s"),
}
#: known columns whose values must be positive (NaN, a missing sample, passes): a battery
#: voltage of 0 or less is no measurement (PX4 writes 0 when it does not know it)
POSITIVE = ("vbat",)
#: largest angle between the declared circle plane and the plane of the positions, deg.
#: Not 3: a closed-loop flight on a plant the model misses really leaves its plane (the
#: example flights by up to 6.3 deg, simulated campaigns with a hidden effect up to 7.1 deg,
#: braking and tilted circles), and those are the flights compare and diagnose are for.
PLANE_TOL_DEG = 10.0
#: a file's positions span a plane when s2 >= PLANE_SPREAD s1 (enough arc: about 1 rad)
#: and s3 <= PLANE_FLAT s2 (s1 >= s2 >= s3: singular values of the positions)
PLANE_SPREAD = 0.3
PLANE_FLAT = 0.2
