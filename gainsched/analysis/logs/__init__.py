"""Flight logs: read and write ``gainsched-flightlog/1`` (docs/flight-log.md; a package
being split into one private module per concept; this namespace is the API)."""

from ._read import (
    DEFAULT_MIN_SAMPLES,
    OPTIONAL_COLUMNS,
    PLANE_TOL_DEG,
    PLAUSIBLE,
    POSITIVE,
    QUAT_NORM_TOL,
    REQUIRED_COLUMNS,
    REQUIRED_META,
    SCHEMA,
    FlightLog,
    LogWarning,
    convert_log,
    describe,
    fitted_plane,
    log_bytes,
    log_from_arrays,
    read_log,
    write_log,
)

__all__ = [
    "SCHEMA",
    "REQUIRED_COLUMNS",
    "OPTIONAL_COLUMNS",
    "REQUIRED_META",
    "QUAT_NORM_TOL",
    "PLAUSIBLE",
    "POSITIVE",
    "PLANE_TOL_DEG",
    "DEFAULT_MIN_SAMPLES",
    "LogWarning",
    "FlightLog",
    "read_log",
    "convert_log",
    "write_log",
    "log_bytes",
    "log_from_arrays",
    "describe",
    "fitted_plane",
]
