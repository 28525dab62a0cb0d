"""A flight log built from arrays (a simulation), with the reader's checks
(:func:`log_from_arrays`).
"""

from __future__ import annotations

import numpy as np

from ._checks import _canonical, _check_meta
from ._flightlog import FlightLog, _make, _readonly
from ._schema import _KEY_RE, _KNOWN, OPTIONAL_COLUMNS, SCHEMA
from ._write import _meta_str


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
