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
(:mod:`gainsched.analysis.logchecks`; thrust and tension with the ``config`` given);
``trust`` (or the metadata key ``trust``) skips a check by name.
"""

from __future__ import annotations

import dataclasses
import io
import math
import re
import stat
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...constants import MAX_LOG_BYTES
from ...errors import GainschedWarning, InputError
from ...textinput import _size, decode_text
from ..logchecks import _plane_angles, _plane_normal, check_log, thrust_units

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
#: largest plausible |value| per known column, with its unit (see the module docstring)
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


class LogWarning(GainschedWarning):
    """A log problem that is reported but not fatal (a gap, a dropped short segment)."""


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class FlightLog:
    """One gap-free segment of a flight log: pose, commanded thrusts, on-board sensors.

    What :func:`read_log` returns per segment (and :func:`log_from_arrays` builds, e.g.
    :func:`~gainsched.sim.loop.log_from_result` from a simulation). Frames and units of
    docs/conventions.md: inertial frame at the tether anchor, z up, SI units. The arrays
    are read-only; N is the number of samples (``len(log)``).

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    p_I : ndarray, shape (N, 3)
        COG position (x, y, z) in the inertial frame, m.
    q : ndarray, shape (N, 4)
        Attitude quaternion (w, x, y, z), Hamilton, body -> inertial; unit norm and
        sign-continuous (consecutive samples have a non-negative dot product).
    T_cmd : ndarray, shape (N, 4)
        Commanded motor thrusts T1..T4, N, each held over the interval before its sample.
    optional : dict of str to ndarray
        The known optional columns present, by name: ``omega_B`` shape (N, 3), the gyro
        (p, q, r) in the body frame, rad/s; ``f_B`` shape (N, 3), the accelerometer's
        specific force (ax, ay, az) at the COG in the body frame, m/s^2; ``tension``
        shape (N,), the tether load cell, N; ``vbat`` shape (N,), the battery voltage, V;
        ``xi_ref`` shape (N,), the reference azimuth in the circle frame, rad;
        ``xi_dot_ref`` shape (N,), its rate, rad/s. May hold NaN (a missing sample).
    extra : dict of str to ndarray
        Unknown columns by their name, each shape (N,) float (kept; the analysis ignores
        them).
    meta : dict of str to str
        The metadata as strings: ``schema``, ``alpha_c_deg`` and ``gamma_c_deg`` (the
        commanded circle plane, deg) and any other key (``flight_id``, ``vehicle``,
        ``notes``, ...).
    source : str
        The file the log came from (or the ``source`` of :func:`log_from_arrays`).
    segment : int
        Index of this segment among the pieces the file was split into at gaps (0-based;
        dropped short pieces keep their index).
    n_segments : int
        How many pieces the file was split into (dropped ones included).
    gaps : tuple of (float, float)
        Every gap of the source file as ``(t_before, t_after)``, s.
    rows : ndarray of int64, shape (N,), or None
        Where each sample is in the file, 1-based (see ``row_label``).
    row_label : str
        ``"line"`` (``rows`` are CSV line numbers) or ``"sample"`` (HDF5 or arrays:
        sample indices).
    alpha_c, gamma_c : float
        Properties: the commanded circle tilt alpha_C and heading gamma_C of the metadata,
        rad.
    duration : float
        Property: time from the first to the last sample, s.
    dt_median : float
        Property: the median sample interval, s (nan with fewer than two samples).

    Examples
    --------
    >>> log = gs.read_log("examples/flights/tilt20-v8.csv")[0]
    >>> round(float(np.rad2deg(log.alpha_c)), 6), log.p_I.shape, log.T_cmd.shape
    (20.0, (551, 3), (551, 4))
    >>> log.where(0), log.columns()["T1"].shape  # where sample 0 is in the file
    ('line 7', (551,))
    """

    t: np.ndarray
    p_I: np.ndarray
    q: np.ndarray
    T_cmd: np.ndarray
    optional: dict[str, np.ndarray] = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, str] = field(default_factory=dict)
    source: str = ""
    segment: int = 0
    n_segments: int = 1
    gaps: tuple[tuple[float, float], ...] = ()
    rows: np.ndarray | None = None
    row_label: str = "sample"

    @property
    def alpha_c(self) -> float:
        """Commanded circle tilt alpha_C, rad."""
        return math.radians(float(self.meta["alpha_c_deg"]))

    @property
    def gamma_c(self) -> float:
        """Commanded circle heading gamma_C, rad."""
        return math.radians(float(self.meta["gamma_c_deg"]))

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    @property
    def dt_median(self) -> float:
        """Median sample interval, s (nan with fewer than two samples)."""
        return float(np.median(np.diff(self.t))) if len(self) > 1 else math.nan

    def where(self, i: int) -> str:
        """``"line 17"`` / ``"sample 17"``: the file position of sample ``i`` (0-based)."""
        row = int(self.rows[i]) if self.rows is not None else i + 1
        return f"{self.row_label} {row}"

    def columns(self) -> dict[str, np.ndarray]:
        """All columns by their file name, in the canonical file order."""
        cols = {"t": self.t}
        for j, n in enumerate("xyz"):
            cols[n] = self.p_I[:, j]
        for j, n in enumerate(("qw", "qx", "qy", "qz")):
            cols[n] = self.q[:, j]
        for j in range(4):
            cols[f"T{j + 1}"] = self.T_cmd[:, j]
        for key, names in OPTIONAL_COLUMNS.items():
            if key in self.optional:
                arr = self.optional[key]
                if len(names) == 1:
                    cols[names[0]] = arr
                else:
                    for j, n in enumerate(names):
                        cols[n] = arr[:, j]
        for name in sorted(self.extra):
            cols[name] = self.extra[name]
        return cols


# ---------------------------------------------------------------------------
# reading


def _check_file(path: Path) -> None:
    """A log is a regular file or a folder (a rosbag2): a device, FIFO or socket (or a
    link to one, named ``.csv`` or ``.ulg``) is refused before it is read, as it may
    never end (``/dev/zero``) or block (a FIFO without a writer)."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return  # missing or unreadable: the reader says so, naming the file
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        kind = ("a FIFO" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
                else "a device")
        raise InputError(path, "", f"{kind}, not a log file: give a file")


def _format(path) -> str:
    fmt = _EXTENSIONS.get(Path(path).suffix.lower())
    if fmt is None:
        raise InputError(
            path,
            "",
            f"unknown log format ({Path(path).suffix or 'no extension'}): use .csv, .h5 or .hdf5",
        )
    return fmt


def _read_csv(path: Path):
    """-> (meta, columns {name: list[str]}, rows (N,) line numbers)."""
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_LOG_BYTES + 1)
    except OSError as exc:
        raise InputError(path, "", f"cannot read the file ({exc.strerror or exc})") from None
    if len(data) > MAX_LOG_BYTES:
        raise InputError(path, "", f"larger than {_size(MAX_LOG_BYTES)}: too large for a CSV "
                         "flight log (write a longer flight as HDF5, .h5)")
    text = decode_text(path, data)  # UTF-8 or refused with the line of the first bad byte
    lines = text.splitlines()
    meta: dict[str, str] = {}
    header = None
    i = 0
    for i, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            key, sep, value = s[1:].partition(":")
            key = key.strip()
            if sep and _KEY_RE.match(key):
                if key in meta:
                    raise InputError(path, f"metadata {key}, line {i + 1}", "given twice")
                meta[key] = value.strip()
            continue  # a '#' line that is not `key: value` is a comment
        header = [c.strip() for c in line.split(",")]
        break
    if header is None:
        raise InputError(path, "", "no header line (expected t,x,y,z,qw,qx,qy,qz,T1,...)")
    header_line = i + 1
    seen = set()
    for name in header:
        if not name:
            raise InputError(path, f"header, line {header_line}", "empty column name")
        if name in seen:
            raise InputError(path, f"column {name}, line {header_line}", "column given twice")
        seen.add(name)
    ncol = len(header)
    cells: list[list[str]] = []
    rows: list[int] = []
    for k in range(header_line, len(lines)):
        line = lines[k]
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            raise InputError(
                path, f"line {k + 1}", "comment or metadata lines must come before the header"
            )
        parts = line.split(",")
        if len(parts) != ncol:
            raise InputError(path, f"line {k + 1}", f"has {len(parts)} cells, header has {ncol}")
        cells.append(parts)
        rows.append(k + 1)
    columns = {name: [r[j] for r in cells] for j, name in enumerate(header)}
    return meta, columns, np.asarray(rows, dtype=np.int64), "line"


def _parse_column(path, name, strs, rows, label):
    joined = "".join(strs)
    if "_" not in joined and joined.isascii():
        try:
            return np.array(list(map(float, strs)), dtype=float)
        except ValueError:
            pass
    for k, s in enumerate(strs):
        try:
            float(s)
            ok = "_" not in s and s.isascii()  # float() also takes 1_0 and non-ASCII digits
        except ValueError:
            ok = False
        if not ok:
            what = "empty cell" if not s.strip() else f"not a number: {s.strip()!r}"
            raise InputError(path, f"column {name}, {label} {rows[k]}", what) from None
    raise AssertionError("unreachable")  # pragma: no cover


def _attr_str(v) -> str:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray) and v.ndim == 0:
        v = v[()]
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, np.integer):
        return str(int(v))
    return str(v)


def _read_hdf5(path: Path):
    import h5py

    if path.is_dir():
        raise InputError(path, "", "cannot read the file (Is a directory)")
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise InputError(path, "", "cannot read the file (no such file)") from None
    except (OSError, ValueError) as exc:
        raise InputError(path, "", f"not a readable HDF5 file ({exc})") from None
    with f:
        meta = {str(k): _attr_str(v) for k, v in f.attrs.items()}
        columns: dict[str, np.ndarray] = {}
        n = None
        for name in f:
            obj = f[name]
            if not isinstance(obj, h5py.Dataset) or obj.ndim != 1:
                raise InputError(path, f"column {name}", "must be a 1-D dataset")
            if obj.dtype.kind not in "fiub":
                raise InputError(path, f"column {name}", f"not numeric (HDF5 type {obj.dtype})")
            arr = np.asarray(obj[()], dtype=float)
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise InputError(
                    path, f"column {name}", f"has {arr.shape[0]} samples, other columns have {n}"
                )
            columns[name] = arr
    rows = np.arange(1, (n or 0) + 1, dtype=np.int64)
    return meta, columns, rows, "sample"


def _check_meta(path, meta: dict[str, str]) -> None:
    for key in REQUIRED_META:
        if key not in meta:
            raise InputError(path, f"metadata {key}", "missing required metadata key")
    if meta["schema"] != SCHEMA:
        raise InputError(path, "metadata schema", f"must be {SCHEMA!r}, got {meta['schema']!r}")
    for key in ("alpha_c_deg", "gamma_c_deg"):
        try:
            v = float(meta[key])
        except ValueError:
            v = math.nan
        if not math.isfinite(v):
            raise InputError(path, f"metadata {key}", f"must be a finite number, got {meta[key]!r}")


def _canonical(path, cols: dict[str, np.ndarray], rows, label, deferred=None):
    """Check the numeric bad-data rules and build the arrays -> dict of arrays.

    ``cols`` holds float arrays by column name (all columns the same length). With a
    list ``deferred``, the range error of a thrust column is appended to it instead of
    raised (the reader first asks whether the thrust is in other units).
    """
    for name in REQUIRED_COLUMNS:
        if name not in cols:
            raise InputError(path, f"column {name}", "missing required column")
    for names in OPTIONAL_COLUMNS.values():
        present = [n for n in names if n in cols]
        if present and len(present) != len(names):
            missing = ", ".join(n for n in names if n not in cols)
            raise InputError(
                path,
                f"column {missing}",
                f"columns {', '.join(names)} go together; {', '.join(present)} given without it",
            )
    for name in REQUIRED_COLUMNS:
        bad = np.flatnonzero(~np.isfinite(cols[name]))
        if bad.size:
            k = bad[0]
            raise InputError(
                path,
                f"column {name}, {label} {rows[k]}",
                f"{float(cols[name][k])!r} in a required column",
            )
    for name, (limit, unit) in PLAUSIBLE.items():
        if name in cols:
            with np.errstate(invalid="ignore"):
                bad = np.flatnonzero(np.abs(cols[name]) > limit)  # NaN (optional) passes
            if bad.size:
                k = bad[0]
                err = InputError(
                    path,
                    f"column {name}, {label} {rows[k]}",
                    f"{float(cols[name][k])!r} {unit} is not plausible (|{name}| <= {limit:g} "
                    f"{unit})",
                )
                if deferred is None or name[0] != "T" or not np.all(np.isfinite(cols[name])):
                    raise err
                if not deferred:
                    deferred.append(err)
    for name in POSITIVE:
        if name in cols:
            with np.errstate(invalid="ignore"):
                bad = np.flatnonzero(cols[name] <= 0)  # NaN (a missing sample) passes
            if bad.size:
                k = bad[0]
                limit, unit = PLAUSIBLE[name]
                raise InputError(
                    path,
                    f"column {name}, {label} {rows[k]}",
                    f"{float(cols[name][k])!r} {unit} is not plausible (0 < {name} <= "
                    f"{limit:g} {unit})",
                )
    t = cols["t"]
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        k = bad[0] + 1
        raise InputError(
            path,
            f"column t, {label} {rows[k]}",
            f"time {float(t[k])!r} does not increase (previous sample, {label} {rows[k - 1]}: "
            f"{float(t[k - 1])!r})",
        )
    q = np.stack([cols[n] for n in ("qw", "qx", "qy", "qz")], axis=-1)
    norm = np.sqrt(np.sum(q * q, axis=-1))
    off = np.abs(1.0 - norm)
    bad = np.flatnonzero(off > QUAT_NORM_TOL)
    if bad.size:
        k = bad[0]
        raise InputError(
            path,
            f"column qw (quaternion qw,qx,qy,qz), {label} {rows[k]}",
            f"quaternion norm {norm[k]:.6g} is off unit by more than {QUAT_NORM_TOL}",
        )
    fix = off > _QUAT_EXACT_TOL
    if np.any(fix):
        q = q.copy()
        q[fix] /= norm[fix, None]
    if q.shape[0] > 1:
        dots = np.sum(q[1:] * q[:-1], axis=-1)
        sign = np.cumprod(np.where(dots < 0, -1.0, 1.0))
        if np.any(sign < 0):
            q = q.copy()
            q[1:] *= sign[:, None]
    out = {
        "t": t,
        "p_I": np.stack([cols[n] for n in "xyz"], axis=-1),
        "q": q,
        "T_cmd": np.stack([cols[f"T{j}"] for j in range(1, 5)], axis=-1),
    }
    optional = {}
    for key, names in OPTIONAL_COLUMNS.items():
        if names[0] in cols:
            optional[key] = (
                cols[names[0]] if len(names) == 1 else np.stack([cols[n] for n in names], axis=-1)
            )
    extra = {n: cols[n] for n in cols if n not in _KNOWN}
    return out, optional, extra


def fitted_plane(p_I) -> tuple[np.ndarray, np.ndarray]:
    """Plane through the origin (the anchor) that fits positions ``p_I`` (N, 3), m.

    Returns ``(normal, s)``: the unit normal (the right singular vector of the smallest
    singular value, oriented with ``normal[2] >= 0``) and the singular values
    ``s1 >= s2 >= s3`` (m sqrt(samples)), which say whether the points span a plane
    (``s2`` not small against ``s1``) and how flat it is (``s3`` against ``s2``).
    """
    p = np.asarray(p_I, dtype=float)
    _, s, vt = np.linalg.svd(p, full_matrices=False)
    n = vt[-1] if vt[-1, 2] >= 0 else -vt[-1]
    return n, s


def _check_plane(path, meta: dict[str, str], p_I: np.ndarray) -> None:
    """The positions' plane must be the declared circle plane (module docstring)."""
    if p_I.shape[0] < 3:
        return
    n, s = fitted_plane(p_I)
    if not (s[1] >= PLANE_SPREAD * s[0] and s[2] <= PLANE_FLAT * s[1]):
        return  # not a circle-like flight: too little arc, or not in a plane
    alpha, gamma = float(meta["alpha_c_deg"]), float(meta["gamma_c_deg"])
    d = _plane_normal(alpha, gamma)
    angle = math.degrees(math.acos(min(1.0, abs(float(n @ d)))))
    if angle <= PLANE_TOL_DEG:
        return
    tilt, heading = _plane_angles(n)
    declared_tilt = math.degrees(math.acos(min(1.0, abs(d[2]))))
    key = "alpha_c_deg" if abs(tilt - declared_tilt) > PLANE_TOL_DEG else "gamma_c_deg"
    plane = f"tilt {tilt:.1f} deg" + (f", gamma_c {heading:.1f} deg" if tilt > 0.5 else "")
    raise InputError(
        path,
        f"metadata {key}",
        f"declares the circle plane alpha_c_deg = {alpha:g}, gamma_c_deg = {gamma:g}, but the "
        f"logged positions lie in the plane through the anchor with {plane} ({angle:.1f} deg "
        f"apart, more than {PLANE_TOL_DEG:g})",
    )


def _make(arrays, optional, extra, meta, source, sl, **kw) -> FlightLog:
    def cut(a):
        return _readonly(np.array(a[sl], dtype=float))

    return FlightLog(
        t=cut(arrays["t"]),
        p_I=cut(arrays["p_I"]),
        q=cut(arrays["q"]),
        T_cmd=cut(arrays["T_cmd"]),
        optional={k: cut(v) for k, v in optional.items()},
        extra={k: cut(v) for k, v in extra.items()},
        meta=dict(meta),
        source=str(source),
        **kw,
    )


def read_log(
    path, *, channel_map=None, thrust_max: float | None = None,
    min_samples: int = DEFAULT_MIN_SAMPLES, gap_factor: float = GAP_FACTOR,
    config=None, trust=(),
) -> list[FlightLog]:
    """Read a flight log file into its gap-free segments, checked against the spec.

    The format is docs/flight-log.md (``gainsched-flightlog/1``, CSV or HDF5), chosen by
    the file extension; a PX4 ULog (``.ulg``) or a ROS 2 bag (a rosbag2 folder, or its
    ``.mcap`` / ``.db3`` file) is converted to it first through a channel map
    (:mod:`gainsched.analysis.foreign`). Every bad-data rule of the spec is enforced; the
    reader normalises only the quaternions (rows off unit norm by more than 1e-12
    divided by their norm, signs made continuous) and splits the log at gaps, never
    interpolating across them (the module docstring has the details).

    Parameters
    ----------
    path : str or path-like
        The log file: ``.csv``, ``.h5``, ``.hdf5``, ``.ulg``, ``.mcap``, ``.db3`` or a
        rosbag2 folder.
    channel_map : ChannelMap, str or path-like, optional
        How a ULog or a bag holds the channels (:func:`gainsched.analysis.channelmap.
        load_channel_map`: a file or a shipped map's name). Default for a ULog: the
        shipped ``px4``; a bag needs one.
    thrust_max : float, optional
        A motor's thrust at full command, N, for normalised or PWM commands when the map
        does not give it (the analysis config's ``vehicle.thrust_max``).
    min_samples : int, default 31
        Fewest samples of a segment (the differentiation window): shorter segments are
        dropped with a warning (:data:`DEFAULT_MIN_SAMPLES`).
    gap_factor : float, default 1.5
        A sample interval more than ``gap_factor`` times the file's median interval is a
        gap: the log is split there.
    config : Config, optional
        The config of the analysis: its vehicle (mass, g, thrust scale) is what the
        commanded thrust and the load cell are checked against
        (:mod:`gainsched.analysis.logchecks`); without it those two checks are skipped.
    trust : iterable of str, default ()
        Consistency checks to skip, by name (:data:`~gainsched.analysis.logchecks.
        CHECKS`: ``plane``, ``quaternion``, ``gyro``, ``thrust``, ``tension``,
        ``xi_ref``), where the user knows the log is right; the log's metadata ``trust``
        adds to them.

    Returns
    -------
    list of FlightLog
        The segments kept, in time order: one for a log without gaps.

    Raises
    ------
    InputError
        Naming the file, the column or key and the row (``line 17`` in CSV, ``sample 17``
        in HDF5): an unknown extension, an unreadable file, a missing required column or
        metadata key, an unknown schema, an incomplete group of optional columns (``p``,
        ``q`` without ``r``), a cell that is not a number, NaN or inf in a required
        column, a value outside the plausible range (:data:`PLAUSIBLE`), time that does not
        strictly increase, a quaternion norm off unit by more than 0.01, a declared
        circle plane the positions do not lie in, channels that contradict each other
        or the model (:func:`~gainsched.analysis.logchecks.check_log`), fewer than
        ``min_samples`` samples, or no segment left after splitting.

    Warns
    -----
    LogWarning
        For each gap (the log is split there) and each dropped short segment.

    Examples
    --------
    >>> segs = gs.read_log("examples/flights/v9.csv")
    >>> log = segs[0]
    >>> len(segs), len(log), log.duration, round(1 / log.dt_median)
    (1, 551, 2.75, 200)
    >>> sorted(log.optional)  # gyro, load cell, reference azimuth
    ['omega_B', 'tension', 'xi_dot_ref', 'xi_ref']
    >>> speed = np.linalg.norm(np.diff(log.p_I, axis=0), axis=1) / np.diff(log.t)
    >>> print(f"mean COG speed {speed.mean():.1f} m/s, "
    ...       f"tension {np.mean(log.optional['tension']):.0f} N")
    mean COG speed 8.9 m/s, tension 25 N
    """
    path = Path(path)
    _check_file(path)
    foreign = _foreign(path, channel_map, thrust_max)
    if foreign is not None:
        return _segments(path, foreign.meta, foreign.columns, foreign.rows, foreign.label,
                         min_samples, gap_factor, config=config, trust=trust)
    if path.is_dir() and path.suffix.lower() not in _EXTENSIONS:
        raise InputError(path, "", "a folder, not a log: give a log file (.csv, .h5, .ulg) "
                         "or a ROS 2 bag folder (with its metadata.yaml)")
    fmt = _format(path)
    if fmt == "csv":
        meta, raw, rows, label = _read_csv(path)
    else:
        meta, raw, rows, label = _read_hdf5(path)
    _check_meta(path, meta)
    for name in REQUIRED_COLUMNS:  # before parsing, so a missing column is named first
        if name not in raw:
            raise InputError(path, f"column {name}", "missing required column")
    if fmt == "csv":
        cols = {name: _parse_column(path, name, s, rows, label) for name, s in raw.items()}
    else:
        cols = raw
    return _segments(path, meta, cols, rows, label, min_samples, gap_factor, config=config,
                     trust=trust)


def convert_log(path, out, *, channel_map=None, thrust_max: float | None = None,
                config=None, trust=()) -> tuple[tuple[str, ...], list[FlightLog]]:
    """Convert a PX4 ULog or a ROS 2 bag to ``gainsched-flightlog/1`` at ``out``.

    The whole converted log is written (gaps included, as the format allows), after it
    passed every rule :func:`read_log` applies; nothing is written otherwise.

    Parameters
    ----------
    path : str or path-like
        The ULog (``.ulg``) or bag (a rosbag2 folder, ``.mcap`` or ``.db3``).
    out : str or path-like
        ``.csv``, ``.h5`` or ``.hdf5``.
    channel_map, thrust_max, config
        As for :func:`read_log`.
    trust : iterable of str, default ()
        Consistency checks to skip (:func:`read_log`); written to the converted log's
        metadata ``trust``, so that it is read as it was converted.

    Returns
    -------
    (tuple of str, list of FlightLog)
        What was mapped to what (one line per channel, the plane, the left-out samples),
        and the segments as :func:`read_log` gives them.
    """
    path, out = Path(path), Path(out)
    _format(out)  # a bad output name fails before any reading
    _check_file(path)
    conv = _foreign(path, channel_map, thrust_max)
    if conv is None:
        raise InputError(path, "", "not a PX4 ULog (.ulg) or a ROS 2 bag (.mcap, .db3, or a "
                         "rosbag2 folder): nothing to convert")
    meta = dict(conv.meta)
    if trust:
        meta["trust"] = ", ".join(dict.fromkeys(trust))
    segs = _segments(path, meta, conv.columns, conv.rows, conv.label,
                     DEFAULT_MIN_SAMPLES, GAP_FACTOR, config=config, trust=trust)
    write_log(out, conv.columns, meta)
    return conv.report, segs


def _foreign(path: Path, channel_map, thrust_max):
    """The converted columns of a ULog or a bag (None for the project's own formats)."""
    from ..foreign import foreign_format

    fmt = foreign_format(path)
    if fmt is None:
        return None
    from ..channelmap import ChannelMap, load_channel_map

    if channel_map is None:
        if fmt != "ulog":
            raise InputError(path, "", "a ROS 2 bag needs a channel map (--map; the "
                             "shipped ros2 map is a template to copy)")
        channel_map = "px4"
    cmap = channel_map if isinstance(channel_map, ChannelMap) else load_channel_map(
        channel_map)
    if not path.exists():
        raise InputError(path, "", "cannot read (No such file or directory)")
    from ..logcache import converted_log

    conv = converted_log(path, cmap, thrust_max)
    if "alpha_c_deg" in conv.meta:
        return conv
    alpha, gamma = _plane_angles(fitted_plane(np.stack([conv.columns[c] for c in "xyz"],
                                                       -1))[0])
    meta = {**conv.meta, "alpha_c_deg": repr(alpha), "gamma_c_deg": repr(gamma),
            "plane_source": "estimated from the logged positions"}
    line = (f"circle plane: alpha_c {alpha:.2f} deg, gamma_c {gamma:.2f} deg, estimated "
            "from the positions")
    return dataclasses.replace(conv, meta=meta, report=(*conv.report, line))


def _segments(path, meta, cols, rows, label, min_samples, gap_factor, *, config=None,
              trust=()) -> list[FlightLog]:
    """The common half of reading: the numeric rules, the plane, the channels' consistency
    (:mod:`.logchecks`), the split at gaps."""
    deferred: list[InputError] = []
    arrays, optional, extra = _canonical(path, cols, rows, label, deferred)
    if deferred:  # thrust out of range: in other units? (else the range error as such)
        thrust_units(path, arrays, optional, meta, config=config, trust=trust,
                     gap_factor=gap_factor)
        raise deferred[0]
    t = arrays["t"]
    n = t.shape[0]
    if n == 0:
        raise InputError(path, "column t", "no data rows")
    if n < min_samples:
        raise InputError(
            path,
            f"column t, {label}s {rows[0]}-{rows[-1]}",
            f"{n} samples, fewer than the differentiation window ({min_samples})",
        )
    _check_plane(path, meta, arrays["p_I"])
    check_log(path, t, arrays["p_I"], arrays["q"], arrays["T_cmd"], optional, meta,
              config=config, trust=trust, gap_factor=gap_factor)
    dt = np.diff(t)
    med = float(np.median(dt)) if dt.size else 0.0
    cuts = np.flatnonzero(dt > gap_factor * med) + 1
    gaps = tuple((float(t[k - 1]), float(t[k])) for k in cuts)
    for k in cuts:
        warnings.warn(
            f"{path}: column t, {label} {rows[k]}: gap of {t[k] - t[k - 1]:.6g} s "
            f"(median interval {med:.6g} s) from t = {float(t[k - 1])!r} to {float(t[k])!r}; "
            "log split there",
            LogWarning,
            stacklevel=2,
        )
    bounds = [0, *cuts.tolist(), n]
    pieces = list(zip(bounds[:-1], bounds[1:], strict=True))
    keep = [(i, a, b) for i, (a, b) in enumerate(pieces) if b - a >= min_samples]
    if not keep:
        i, (a, b) = max(enumerate(pieces), key=lambda p: p[1][1] - p[1][0])
        raise InputError(
            path,
            f"column t, {label}s {rows[a]}-{rows[b - 1]}",
            f"after splitting at {len(gaps)} gap(s) no segment has {min_samples} samples "
            f"(the differentiation window); the longest has {b - a}",
        )
    for i, (a, b) in enumerate(pieces):
        if b - a < min_samples:
            warnings.warn(
                f"{path}: column t, {label}s {rows[a]}-{rows[b - 1]}: segment {i} has "
                f"{b - a} samples, fewer than the differentiation window ({min_samples}); "
                "dropped",
                LogWarning,
                stacklevel=2,
            )
    return [
        _make(
            arrays,
            optional,
            extra,
            meta,
            path,
            slice(a, b),
            segment=i,
            n_segments=len(pieces),
            gaps=gaps,
            rows=_readonly(rows[a:b].copy()),
            row_label=label,
        )
        for i, a, b in keep
    ]


# ---------------------------------------------------------------------------
# building and writing


def _meta_str(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return str(v)


def log_from_arrays(
    t, p_I, q, T_cmd, meta, *, extra=None, source: str = "<arrays>", **optional
) -> FlightLog:
    """Build one :class:`FlightLog` from arrays (e.g. a simulation), with the reader's checks.

    ``meta`` needs ``alpha_c_deg`` and ``gamma_c_deg`` (numbers or strings);
    ``schema`` is filled in. ``optional`` takes the keys of ``OPTIONAL_COLUMNS``
    (``omega_B`` and ``f_B`` as (N, 3), the others (N,)); ``extra`` maps unknown
    column names to (N,) arrays. Time gaps are not split here. Bad values raise
    :class:`InputError` with ``source`` and ``sample N`` (1-based).
    """
    meta = {"schema": SCHEMA, **{str(k): _meta_str(v) for k, v in dict(meta).items()}}
    _check_meta(source, meta)
    t = np.asarray(t, dtype=float)
    n = t.shape[0] if t.ndim == 1 else -1
    shapes = {"t": (t, (n,)), "p_I": (p_I, (n, 3)), "q": (q, (n, 4)), "T_cmd": (T_cmd, (n, 4))}
    for key, value in optional.items():
        if key not in OPTIONAL_COLUMNS:
            raise TypeError(
                f"unknown optional array {key!r}; known: {', '.join(OPTIONAL_COLUMNS)} "
                "(pass other columns in extra=)"
            )
        names = OPTIONAL_COLUMNS[key]
        shapes[key] = (value, (n,) if len(names) == 1 else (n, len(names)))
    for key, value in (extra or {}).items():
        if key in _KNOWN or not _KEY_RE.match(str(key)):
            raise ValueError(f"extra column name {key!r} is a known column or not a valid name")
        shapes[key] = (value, (n,))
    cols: dict[str, np.ndarray] = {}
    for key, (value, shape) in shapes.items():
        a = np.asarray(value, dtype=float)
        if n < 0 or a.shape != shape:
            raise ValueError(f"{key} has shape {a.shape}, expected {shape} (t must be 1-D)")
        if key == "p_I":
            cols.update(zip("xyz", a.T, strict=True))
        elif key == "q":
            cols.update(zip(("qw", "qx", "qy", "qz"), a.T, strict=True))
        elif key == "T_cmd":
            cols.update(zip(("T1", "T2", "T3", "T4"), a.T, strict=True))
        elif key in OPTIONAL_COLUMNS and len(OPTIONAL_COLUMNS[key]) > 1:
            cols.update(zip(OPTIONAL_COLUMNS[key], a.T, strict=True))
        else:
            cols[key] = a
    rows = np.arange(1, n + 1, dtype=np.int64)
    arrays, opt, ext = _canonical(source, cols, rows, "sample")
    return _make(arrays, opt, ext, meta, source, slice(None), rows=_readonly(rows))


def _ordered_columns(log_or_columns) -> dict[str, np.ndarray]:
    if isinstance(log_or_columns, FlightLog):
        return log_or_columns.columns()
    cols = {str(k): np.asarray(v, dtype=float) for k, v in dict(log_or_columns).items()}
    order = [*REQUIRED_COLUMNS, *(n for names in OPTIONAL_COLUMNS.values() for n in names)]
    known = [n for n in order if n in cols]
    return {n: cols[n] for n in known + sorted(set(cols) - set(order))}


def _ordered_meta(log_or_columns, meta) -> dict[str, str]:
    base = dict(log_or_columns.meta) if isinstance(log_or_columns, FlightLog) else {}
    base.update({str(k): _meta_str(v) for k, v in dict(meta or {}).items()})
    base.setdefault("schema", SCHEMA)
    return {
        **{k: base[k] for k in _META_ORDER if k in base},
        **{k: base[k] for k in sorted(base) if k not in _META_ORDER},
    }


def log_bytes(fmt: str, log_or_columns, meta=None, *, name: str = "flightlog") -> bytes:
    """The bytes :func:`write_log` writes, for ``fmt`` ``"csv"`` or ``"hdf5"``.

    Deterministic: the same input gives the same bytes (no timestamps in HDF5).
    """
    cols = _ordered_columns(log_or_columns)
    meta = _ordered_meta(log_or_columns, meta)
    lengths = {a.shape for a in cols.values()}
    if len(lengths) > 1 or any(len(s) != 1 for s in lengths):
        raise ValueError(f"columns must be 1-D and of equal length, got shapes {lengths}")
    for k, v in meta.items():
        if not _KEY_RE.match(k) or "\n" in v or "\r" in v:
            raise ValueError(f"metadata {k!r}: {v!r} cannot be written (bad key or newline)")
    for k in cols:
        if not _KEY_RE.match(k):
            raise ValueError(f"column name {k!r} cannot be written")
    if fmt == "csv":
        buf = io.StringIO()
        for k, v in meta.items():
            buf.write(f"# {k}: {v}\n")
        buf.write(",".join(cols) + "\n")
        # repr(float) is the shortest string that parses back to the same double
        text = [list(map(repr, a.tolist())) for a in cols.values()]
        for row in zip(*text, strict=True):
            buf.write(",".join(row) + "\n")
        return buf.getvalue().encode("utf-8")
    if fmt != "hdf5":
        raise ValueError(f"unknown format {fmt!r}")
    import h5py

    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fapl_core(backing_store=False)
    fapl.set_libver_bounds(h5py.h5f.LIBVER_V18, h5py.h5f.LIBVER_V18)
    fcpl = h5py.h5p.create(h5py.h5p.FILE_CREATE)
    fcpl.set_obj_track_times(False)  # the root group would carry the wall-clock second
    fid = h5py.h5f.create(name.encode(), h5py.h5f.ACC_TRUNC, fapl=fapl, fcpl=fcpl)
    with h5py.File(fid) as f:
        for k, v in meta.items():
            f.attrs[k] = v
        for k, a in cols.items():
            f.create_dataset(k, data=np.asarray(a, dtype=np.float64), track_times=False)
        f.flush()
        return f.id.get_file_image()


def write_log(path, log_or_columns, meta=None) -> int:
    """Write a log atomically as CSV or HDF5 (by extension); returns the size in bytes.

    ``log_or_columns`` is a :class:`FlightLog` (its ``meta`` updated by
    ``meta``) or a mapping of column name -> (N,) array, written as given
    (no checks on the values, so bad files can be made on purpose). CSV column
    order: t, x, y, z, qw..qz, T1..T4, the optional known columns present,
    then unknown ones sorted. Floats are written with the shortest exact
    representation, so a round trip is lossless. ``schema`` is added if absent.
    """
    from ...publish import write_atomic

    data = log_bytes(_format(path), log_or_columns, meta, name=Path(path).name)
    write_atomic(path, data)
    return len(data)


# ---------------------------------------------------------------------------


def describe(log) -> str:
    """One-line summary of a log segment or a list of segments (as :func:`read_log` returns)."""
    logs = [log] if isinstance(log, FlightLog) else list(log)
    if not logs:
        return "empty log"
    first = logs[0]
    name = first.meta.get("flight_id") or Path(first.source).name or "log"
    samples = sum(len(lg) for lg in logs)
    duration = sum(lg.duration for lg in logs)
    dts = np.concatenate([np.diff(lg.t) for lg in logs])
    rate = 1.0 / float(np.median(dts)) if dts.size else math.nan
    if isinstance(log, FlightLog):
        seg = f"segment {first.segment + 1} of {first.n_segments}"
    else:
        seg = f"{len(logs)} of {first.n_segments} segment{'s' * (first.n_segments != 1)} kept"
    ngaps = len(first.gaps)
    return (
        f"{name}: {duration:.3f} s, {rate:.1f} Hz, {samples} samples, {seg}, "
        f"{ngaps} gap{'s' * (ngaps != 1)}, tilt {float(first.meta['alpha_c_deg']):g} deg"
    )
