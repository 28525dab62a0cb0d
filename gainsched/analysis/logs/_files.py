"""The project's own files, CSV and HDF5, read to columns: a file's bytes to metadata
strings and float columns with the file position of each row (line or sample).
"""

from __future__ import annotations

import stat
from pathlib import Path

import numpy as np

from ...constants import MAX_LOG_BYTES
from ...errors import InputError
from ...textinput import read_text
from ._checks import _check_meta
from ._schema import _EXTENSIONS, _KEY_RE, REQUIRED_COLUMNS


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


def log_format(path, where: str = "") -> str:
    """The project's flight-log format a file name asks for, ``"csv"`` or ``"hdf5"``.

    Raises
    ------
    InputError
        Naming ``path`` and ``where`` (an option: ``"-o"``): an extension of neither.
    """
    fmt = _EXTENSIONS.get(Path(path).suffix.lower())
    if fmt is None:
        ext = Path(path).suffix or "no extension"
        raise InputError(path, where, f"unknown log format ({ext}): use .csv, .h5 or .hdf5")
    return fmt


def _read_csv(path: Path):
    """-> (meta, columns {name: list[str]}, rows (N,) line numbers)."""
    # bounded by the bytes read, UTF-8 or refused with the line of the first bad byte
    text = read_text(path, what="CSV flight log", limit=MAX_LOG_BYTES,
                     advice="write a longer flight as HDF5, .h5")
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


def _read_file(path: Path):
    """A file of the project's own format, CSV or HDF5 (by extension), read and its
    metadata checked: ``(meta, columns, rows, label)``, the metadata as strings, the
    columns as (N,) float arrays by name, ``rows`` (N,) the file position of each sample
    and ``label`` its kind (``"line"`` in CSV, ``"sample"`` in HDF5)."""
    if path.is_dir() and path.suffix.lower() not in _EXTENSIONS:
        raise InputError(path, "", "a folder, not a log: give a log file (.csv, .h5, .ulg) "
                         "or a ROS 2 bag folder (with its metadata.yaml)")
    fmt = log_format(path)
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
    return meta, cols, rows, label
