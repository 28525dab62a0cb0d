"""The bad-data rules of the format (module docstring of :mod:`gainsched.analysis.logs`):
the metadata, the columns' values, the quaternions and the declared circle plane.
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import InputError
from ._consistency import _plane_angles, _plane_normal
from ._schema import (
    _KNOWN,
    _QUAT_EXACT_TOL,
    OPTIONAL_COLUMNS,
    PLANE_FLAT,
    PLANE_SPREAD,
    PLANE_TOL_DEG,
    PLAUSIBLE,
    POSITIVE,
    QUAT_NORM_TOL,
    REQUIRED_COLUMNS,
    REQUIRED_META,
    SCHEMA,
)

#: the pulse widths of an RC or PWM channel, us: a "thrust" in this range is one
PWM_US = (800.0, 2200.0)


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


def _check_values(path, cols: dict[str, np.ndarray], rows, label, deferred=None,
                  sources=None) -> None:
    """The bad-data rules of the columns' values (module docstring of
    :mod:`gainsched.analysis.logs`), in this order: required columns present, groups of
    optional columns complete, required columns finite, every known column plausible,
    positive columns positive, time strictly increasing.

    ``cols`` holds float arrays by column name (all columns the same length); ``rows``
    (N,) the file position of each sample, ``label`` its kind (``"line"`` or
    ``"sample"``). With a list ``deferred``, the range error of a thrust column is
    appended to it instead of raised (the reader first asks whether the thrust is in
    other units). ``sources``: per column of a converted log the topic it came from,
    named in its errors (the rows are the position topic's samples).
    """
    sources = sources or {}

    def where(name: str, k: int) -> str:
        src = f" (from topic {sources[name]})" if name in sources else ""
        return f"column {name}{src}, {label} {rows[k]}"

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
            raise InputError(path, where(name, k),
                             f"{float(cols[name][k])!r} in a required column")
    for name, (limit, unit) in PLAUSIBLE.items():
        if name in cols:
            with np.errstate(invalid="ignore"):
                bad = np.flatnonzero(np.abs(cols[name]) > limit)  # NaN (optional) passes
            if bad.size:
                k = bad[0]
                v = float(cols[name][k])
                err = InputError(path, where(name, k), f"{v!r} {unit} is not plausible "
                                 f"(|{name}| <= {limit:g} {unit})" + _pwm_hint(name, v))
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
                raise InputError(path, where(name, k), f"{float(cols[name][k])!r} {unit} is "
                                 f"not plausible (0 < {name} <= {limit:g} {unit})")
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


def _pwm_hint(name: str, value: float) -> str:
    """For a thrust of 800-2200: it looks like a PWM pulse width in microseconds."""
    if name[0] != "T" or not PWM_US[0] <= value <= PWM_US[1]:
        return ""
    return (f": it looks like a PWM pulse width in microseconds ({PWM_US[0]:g}-{PWM_US[1]:g}"
            " us), not newtons: a channel map reads PWM with [motors] unit = \"pwm\" "
            "(pwm_min, pwm_max)")


def _unit_quaternions(path, cols: dict[str, np.ndarray], rows, label) -> np.ndarray:
    """The quaternion columns (qw, qx, qy, qz) as (N, 4): an error when a row is off unit
    norm by more than :data:`QUAT_NORM_TOL`, rows off by more than ``1e-12`` divided by
    their norm, signs made continuous (module docstring of :mod:`gainsched.analysis.logs`).
    """
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
    return q


def _canonical(path, cols: dict[str, np.ndarray], rows, label, deferred=None, sources=None):
    """Check the numeric bad-data rules and build the arrays -> dict of arrays.

    ``cols`` holds float arrays by column name (all columns the same length). With a
    list ``deferred``, the range error of a thrust column is appended to it instead of
    raised (the reader first asks whether the thrust is in other units). ``sources``:
    per column of a converted log the topic it came from.
    """
    _check_values(path, cols, rows, label, deferred, sources)
    t = cols["t"]
    q = _unit_quaternions(path, cols, rows, label)
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
    """The positions' plane must be the declared circle plane (the module docstring of
    :mod:`gainsched.analysis.logs`)."""
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
