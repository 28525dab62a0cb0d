"""Writing a flight log, CSV or HDF5, deterministic and exact (:func:`write_log`,
:func:`log_bytes`).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ._files import log_format
from ._flightlog import FlightLog
from ._schema import _KEY_RE, _META_ORDER, OPTIONAL_COLUMNS, REQUIRED_COLUMNS, SCHEMA


def _meta_str(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return str(v)


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

    data = log_bytes(log_format(path), log_or_columns, meta, name=Path(path).name)
    write_atomic(path, data)
    return len(data)
