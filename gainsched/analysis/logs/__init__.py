"""Flight logs: read and write ``gainsched-flightlog/1`` (docs/flight-log.md).

A log is CSV (``# key: value`` metadata lines before the header) or HDF5 (root
attributes as metadata, one 1-D dataset per column), chosen by the file
extension (``.csv``, ``.h5``, ``.hdf5``). Frames and units are those of
docs/conventions.md: inertial frame at the anchor, z up, SI units, Hamilton
quaternions scalar first, body -> inertial.

Reading enforces every bad-data rule of the spec; each violation raises
:class:`~gainsched.errors.InputError` naming the file, the column and the row.
Rows are the line number in the file for CSV (``line 17``, counting the
metadata and header lines, 1-based) and the 1-based sample index for HDF5
(``sample 17``).

What the reader does to the data, and nothing else:

* **Quaternion norm.** ``|1 - |q|| > QUAT_NORM_TOL`` (0.01) is an error. Rows
  further than ``1e-12`` from unit norm are divided by their norm; rows closer
  than that are kept bit for bit, so ``write_log`` / ``read_log`` round trips
  are exact.
* **Quaternion sign continuity.** ``q`` and ``-q`` are the same attitude. Each
  sample is negated if needed so that consecutive quaternions have a
  non-negative dot product (the first sample is kept as given). Negation is
  exact, so this never costs precision; downstream finite differences of
  ``q`` are then meaningful.
* **Gaps.** A sample interval more than ``gap_factor`` (1.5) times the median
  interval of the file is a gap: the log is split there into separate
  :class:`FlightLog` segments (never interpolated), each segment lists every
  gap of the file in ``gaps``, and a :class:`LogWarning` is issued.
* **Short segments.** A segment with fewer than ``min_samples`` samples (the
  differentiation window) is dropped with a :class:`LogWarning` if another
  segment remains; if none remains it is an error.

Optional known columns may contain NaN (a missing sensor sample); required
columns may not. Every cell of every column (unknown ones included) must be
a number: the spec's "non-numeric cell" rule has no exception, and an empty
cell counts as non-numeric (write ``nan`` for a missing value). A number is
written in ASCII without digit separators: ``1_0`` and non-ASCII digits, which
Python's ``float`` would accept, are refused.

Values must be physically plausible (:data:`PLAUSIBLE`): ``|x|, |y|, |z| <=
1e3 m``, ``|T1..T4| <= 1e3 N``, ``|t| <= 1e10 s``, gyro ``<= 1e3 rad/s``,
accelerometer ``<= 1e4 m/s^2``, tension ``<= 1e4 N``, ``0 < vbat <= 1e3 V``,
``|xi_ref| <= 1e7 rad``, ``|xi_dot_ref| <= 1e3 rad/s``; a finite absurd value
(``x = 1e308``) would otherwise overflow later in the analysis. Unknown columns
are not bounded (the analysis ignores them).

**Declared circle plane.** The flown circle is a great circle around the anchor,
so its plane passes through the origin: a file whose positions span a plane
(:func:`fitted_plane`: enough arc, small out-of-plane spread) must lie in the
plane the metadata declare, ``R_IC = Rz(gamma_C) Rx(alpha_C)``, normal
``R_IC (0, 0, 1)``, within ``PLANE_TOL_DEG`` (10 deg); otherwise the metadata
``alpha_c_deg`` (or ``gamma_c_deg`` when the tilts agree) is an error. Files
only (:func:`read_log`); :func:`log_from_arrays` (simulations) is not checked.

**Consistency of the channels.** Files only, every format: the gyro, the quaternion
order, the commanded thrust, the load cell, the reference azimuth and the plane
normal's sign are checked against the pose and the model
(``_consistency``: :func:`check_log`; thrust and tension with the ``config`` given);
``trust`` (or the metadata key ``trust``) skips a check by name.

The package's modules, one concept each (private: this namespace is the API), top to
bottom of their imports (a module imports only from those below it):

- ``_read``: :func:`read_log`, :func:`convert_log` (the split at gaps,
  :class:`LogWarning`);
- ``_arrays``: :func:`log_from_arrays`;
- ``_write``: :func:`write_log`, :func:`log_bytes`;
- ``_files``: the CSV and HDF5 files read to columns;
- ``_cache``: a PX4 ULog or a ROS 2 bag converted once (the cache of converted logs);
- ``_ulogscan``: what a ULog declares, checked before pyulog parses it;
- ``_listing``: the topics of a ULog or a bag, for writing a map (``convert --list``);
- ``_clocks``: the offset and drift between two files' clocks, from the motion both hold;
- ``_pair``: a flight controller's log and a pose recorded apart made one log;
- ``_daycut``: a flight day cut into its circles and manoeuvres, the rest dropped;
- ``_foreign``: PX4 ULogs (pyulog) and ROS 2 bags (rosbags) to the flight-log columns
  (:data:`FOREIGN_FORMATS`, :func:`foreign_format`);
- ``_channelmap``: where a ULog or a bag holds each channel (:class:`ChannelMap`,
  :func:`load_channel_map`; the shipped maps in ``maps/``);
- ``_checks``: the bad-data rules (metadata, values, quaternions, the circle plane;
  :func:`fitted_plane`);
- ``_flightlog``: :class:`FlightLog`, :func:`describe`;
- ``_consistency``: the channels checked against each other and the model
  (:data:`CHECKS`, :func:`check_log`, :func:`figures`);
- ``_schema``: :data:`SCHEMA`, the columns, :data:`PLAUSIBLE` and the tolerances;
- ``_progress``: the stages of a foreign log's read and conversion, told to the
  callback of :func:`reporting` (``gainsched convert``'s progress line).

No other module of the package opens a log file: the readers, the channel maps, the
cache and the checks are here, behind these names (tests/test_architecture.py).
"""

from ._arrays import log_from_arrays
from ._channelmap import ChannelMap, load_channel_map
from ._checks import fitted_plane
from ._consistency import CHECKS, RATIO_TOL, Figures, check_log, figures
from ._daycut import DayCut, Piece, cut_day
from ._files import log_format
from ._flightlog import FlightLog, describe
from ._foreign import FOREIGN_FORMATS, foreign_format
from ._listing import LogListing, TopicInfo, list_topics
from ._progress import reporting
from ._read import Day, LogWarning, convert_log, read_day, read_log
from ._schema import (
    DEFAULT_MIN_SAMPLES,
    OPTIONAL_COLUMNS,
    PLANE_TOL_DEG,
    PLAUSIBLE,
    POSITIVE,
    QUAT_NORM_TOL,
    REQUIRED_COLUMNS,
    REQUIRED_META,
    SCHEMA,
)
from ._write import log_bytes, write_log

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
    "read_day",
    "Day",
    "DayCut",
    "Piece",
    "cut_day",
    "convert_log",
    "write_log",
    "log_bytes",
    "log_from_arrays",
    "describe",
    "fitted_plane",
    "ChannelMap",
    "load_channel_map",
    "FOREIGN_FORMATS",
    "foreign_format",
    "log_format",
    "list_topics",
    "LogListing",
    "TopicInfo",
    "CHECKS",
    "RATIO_TOL",
    "Figures",
    "figures",
    "check_log",
    "reporting",
]
