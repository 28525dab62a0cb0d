"""Reading a TOML table key by key (:class:`Section`) and the checks several sections
share (``check_*``): each raises an :class:`~gainsched.errors.InputError` naming the
source and the dotted key.

:class:`Section` tracks the keys read, so that an unknown key is refused (with the
likely meant key when one is close: ``arm_lenght`` -> ``arm_length``, difflib).
"""

from __future__ import annotations

import difflib
import math
import re

import numpy as np

from ..errors import InputError
from ._schema import AxisRange, Control, Grid

#: ``name``: 1..64 characters of [A-Za-z0-9_.-], the first a letter or a digit (a file name
#: that stays inside the output folder, is never hidden, and maps to a C identifier)
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}")
NAME_RULE = "1-64 characters from A-Z a-z 0-9 _ - . starting with a letter or a digit"
MIN_STEPS_PER_PERIOD = 32  # control steps over the fastest circle of the grid


def _numeric_list(v) -> bool:
    """A (nested) list whose leaves are all ints or floats (TOML booleans and strings are not)."""
    return isinstance(v, list) and all(
        (isinstance(x, int | float) and not isinstance(x, bool)) or _numeric_list(x) for x in v
    )


#: how alike a written key and a known one must be to be named as its likely meaning
#: (difflib's ratio: ``arm_lenght`` and ``arm_length`` 0.9, ``mass`` and ``max`` 0.57)
_TYPO_CUTOFF = 0.8


class Section:
    """A TOML table being consumed: tracks which keys were read, to reject unknown ones."""

    def __init__(self, source: str, prefix: str, data):
        if not isinstance(data, dict):
            raise InputError(source, prefix, "must be a table")
        self.source, self.prefix, self.data = source, prefix, data
        self.used: set[str] = set()

    def key(self, k: str) -> str:
        return f"{self.prefix}.{k}" if self.prefix else k

    def error(self, k: str, msg: str) -> InputError:
        return InputError(self.source, self.key(k), msg)

    def get(self, k: str, default=...):
        self.used.add(k)
        if k not in self.data:
            if default is ...:
                # a misspelt key reads as a missing one: name the key that was written
                typo = difflib.get_close_matches(k, [d for d in self.data if d not in self.used],
                                                 n=1, cutoff=_TYPO_CUTOFF)
                if typo:
                    raise self.error(typo[0], f"unknown key (did you mean {k}?)")
                raise self.error(k, "missing required key")
            return default
        return self.data[k]

    def number(self, k, default=..., *, positive=False, nonneg=False) -> float:
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.error(k, f"must be a number, got {type(v).__name__}")
        try:
            v = float(v)
        except OverflowError:  # an integer beyond the floats (TOML integers are unbounded)
            raise self.error(k, "must be finite") from None
        if not math.isfinite(v):
            raise self.error(k, "must be finite")
        if positive and v <= 0:
            raise self.error(k, f"must be > 0, got {v:g}")
        if nonneg and v < 0:
            raise self.error(k, f"must be >= 0, got {v:g}")
        return v

    def bounded(self, k, default=..., *, lo: float, hi: float, unit: str,
                lo_open: bool = False) -> float:
        """A finite number in ``[lo, hi]`` (``lo_open``: ``(lo, hi]``); the message gives
        the range and the unit."""
        v = self.number(k, default)
        if (v <= lo if lo_open else v < lo) or v > hi:
            raise self.error(k, f"must be in {'(' if lo_open else '['}{lo:g}, {hi:g}] {unit}, "
                             f"got {v:g}")
        return v

    def integer(self, k, default=..., *, lo: int, hi: int, what: str = "") -> int:
        """An integer (not a float, not a boolean) in ``[lo, hi]``."""
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            shown = repr(v) if isinstance(v, int | float | bool) else type(v).__name__
            raise self.error(k, f"must be an integer in [{lo}, {hi}]{what}, got {shown}")
        return v

    def string(self, k, default=..., choices=None) -> str:
        v = self.get(k, default)
        if not isinstance(v, str):
            raise self.error(k, f"must be a string, got {type(v).__name__}")
        if choices is not None and v not in choices:
            raise self.error(k, f"must be one of {', '.join(choices)}; got {v!r}")
        return v

    def boolean(self, k, default=...) -> bool:
        v = self.get(k, default)
        if not isinstance(v, bool):
            raise self.error(k, f"must be true or false, got {type(v).__name__}")
        return v

    def array(self, k, default=...) -> np.ndarray:
        v = self.get(k, default)
        if not _numeric_list(v):
            raise self.error(k, "must be a list of numbers (or a list of rows)")
        try:
            a = np.array(v, dtype=float)
        except (TypeError, ValueError, OverflowError):  # ragged rows, integers beyond floats
            raise self.error(k, "must be a list of numbers (or a list of rows)") from None
        if not np.all(np.isfinite(a)):
            raise self.error(k, "entries must be finite")
        return a

    def sub(self, k, default=...) -> Section:
        return Section(self.source, self.key(k), self.get(k, default))

    def done(self):
        extra = sorted(set(self.data) - self.used)
        if extra:
            near = difflib.get_close_matches(extra[0], sorted(self.used), n=1,
                                             cutoff=_TYPO_CUTOFF)
            raise self.error(extra[0], "unknown key" + (f" (did you mean {near[0]}?)"
                                                        if near else ""))


def check_square_weight(sec: Section, k: str, n: int, *, definite: bool,
                        names: tuple[str, ...] = ()) -> np.ndarray:
    """Q or R: n diagonal entries or an n x n symmetric matrix; PSD (Q) or PD (R).
    ``names`` (n entries) are quoted when the size is wrong."""
    a = sec.array(k)
    order = f" ({', '.join(names)})" if names else ""
    if a.ndim == 1:
        if a.shape != (n,):
            raise sec.error(k, f"must have {n} diagonal entries{order} or be {n}x{n}, "
                            f"got {a.size}")
        a = np.diag(a)
    elif a.shape != (n, n):
        raise sec.error(k, f"must be {n}x{n}, got {'x'.join(map(str, a.shape))}")
    if not np.allclose(a, a.T, rtol=0, atol=1e-12 * max(1.0, np.abs(a).max())):
        raise sec.error(k, "must be symmetric")
    lam = np.linalg.eigvalsh(a).min()
    tol = 1e-12 * max(1.0, np.abs(a).max())
    if definite and lam <= tol:
        raise sec.error(k, f"must be positive definite (smallest eigenvalue {lam:.3g})")
    if not definite and lam < -tol:
        raise sec.error(k, f"must be positive semidefinite (smallest eigenvalue {lam:.3g})")
    return a


def check_axis(sec: Section, k: str, *, nonneg: bool, positive: bool) -> np.ndarray:
    a = sec.array(k)
    if a.ndim != 1 or a.size == 0:
        raise sec.error(k, "must be a non-empty list of numbers")
    if np.any(np.diff(a) <= 0):
        raise sec.error(k, "must be strictly increasing")
    if positive and a[0] <= 0:
        raise sec.error(k, f"must be > 0, got {a[0]:g}")
    if nonneg and a[0] < 0:
        raise sec.error(k, f"must be >= 0 (negative values come from the symmetry), got {a[0]:g}")
    return a


def check_float32_axis(sec: Section, k: str, values: np.ndarray, what: str) -> None:
    """The tables store axes as float32: ``values`` must stay finite and strictly increasing.

    ``values`` is the axis as stored (e.g. speeds / r for ``xi_dot``, rad for tilts);
    ``what`` names it in the message. Raises InputError naming ``k``.
    """
    with np.errstate(over="ignore"):
        f = values.astype(np.float32)
    if not np.all(np.isfinite(f)):
        raise sec.error(k, f"{what} overflows float32 (the C tables store float32)")
    same = np.flatnonzero(np.diff(f) <= 0)
    if same.size:
        i = int(same[0])
        raise sec.error(
            k,
            f"entries {i + 1} and {i + 2} are equal in float32 ({what} {float(values[i])!r} "
            f"and {float(values[i + 1])!r}; the C tables store float32): space them further "
            "apart",
        )


def check_name(source, name: str, *, from_file: bool = False) -> str:
    """``name``: the output file stem (``OUT/NAME.h5``, ``OUT/NAME_gains.h``) and the C prefix.

    Rule: 1-64 characters from ``A-Z a-z 0-9 _ - .``, the first a letter or a digit (so
    it stays inside the output folder, is never a hidden file, and
    :func:`gainsched.firmware.runtime.c_identifier` maps it to a C identifier). With
    ``from_file`` the name is the default taken from the config file's name, and the
    message says to set ``name``. Raises InputError naming the key ``name``.
    """
    if NAME_RE.fullmatch(name):
        return name
    shown = name if len(name) <= 80 else name[:77] + "..."
    if from_file:
        fix = re.sub(r"[^A-Za-z0-9_.\-]", "_", name).lstrip("._-")[:64] or "config"
        raise InputError(
            source,
            "name",
            f"not set, and the default from the file name {shown!r} is not a valid name "
            f"({NAME_RULE}); set name = {fix!r} in the file",
        )
    raise InputError(
        source,
        "name",
        f"must be {NAME_RULE} (it names the output files NAME.h5, NAME_gains.h and "
        f"the C symbols); got {shown!r}",
    )


#: most breakpoints an automatic axis may be given (``max_count``)
MAX_AUTO_COUNT = 1024


def check_axis_range(sec: Section, k: str) -> AxisRange:
    """``grid.<k> = {min = .., max = .., max_count = ..}``: finite ends ``min < max`` and an
    integer ``2 <= max_count <= MAX_AUTO_COUNT``; errors name ``grid.<k>.<field>``."""
    sub = sec.sub(k)
    lo, hi = sub.number("min"), sub.number("max")
    n = sub.get("max_count")
    if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= MAX_AUTO_COUNT:
        raise sub.error("max_count", f"must be an integer in [2, {MAX_AUTO_COUNT}], got {n!r}")
    if not lo < hi:
        raise sub.error("max", f"must be > min ({lo:g}), got {hi:g}")
    sub.done()
    return AxisRange(lo, hi, n)


def check_rate(source, control: Control, grid: Grid, radius: float) -> None:
    """The control rate must resolve the fastest circle: at least ``MIN_STEPS_PER_PERIOD``
    steps over its period T = 2 pi r / v (r = rho + L_e, m; v the largest grid speed, m/s).
    Raises InputError naming ``control.rate_hz``."""
    v = float(grid.speeds[-1])
    T = 2 * math.pi * radius / v
    steps = 2 * round(T * control.rate_hz / 2)
    if steps < MIN_STEPS_PER_PERIOD:
        need = MIN_STEPS_PER_PERIOD / T
        raise InputError(
            source,
            "control.rate_hz",
            f"{control.rate_hz:g} Hz gives {steps} steps over the fastest circle "
            f"({v:g} m/s, period {T:.3g} s); needs >= {MIN_STEPS_PER_PERIOD}, i.e. "
            f"rate_hz >= {need:.3g}",
        )
