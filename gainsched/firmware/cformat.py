"""C literals and initializers of arrays, as the generated headers write them.

Float32 values are hexadecimal float literals (:func:`c_float`, :func:`c_floats`:
exact, so every compiler reproduces the same bytes and the embedded CRC-32 holds);
macros meant to be read take the shortest decimal (:func:`c_decimal`); counts and
indices are unsigned literals (:func:`c_uints`); :func:`c_initializer` nests an
array's literals in braces.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["c_float", "c_decimal", "c_floats", "c_uints", "c_initializer"]


def c_float(x) -> str:
    """Exact C99 float literal of a float32 value (hexadecimal, ``0x1.8p+1f``)."""
    f = float(np.float32(x))
    if not np.isfinite(f):
        raise ValueError(f"non-finite value {f} cannot be emitted")
    if f == 0:
        return "-0.0f" if np.signbit(f) else "0.0f"
    mant, exp = f.hex().split("p")
    mant = mant.rstrip("0").rstrip(".")
    return f"{mant}p{exp}f"


def c_decimal(x) -> str:
    """Shortest decimal C float literal of a float32 value (for macros meant to be read)."""
    return np.format_float_positional(np.float32(x), unique=True, trim="0") + "f"


@lru_cache(maxsize=1)
def _hex_tables():
    """Text pieces of :func:`c_floats`: three hex digits of a 12-bit half of the mantissa,
    with and without their trailing zeros, and ``p<exponent>f`` per biased exponent."""
    full = np.array([f"{h:03x}" for h in range(4096)], dtype=object)
    stripped = np.array([t.rstrip("0") for t in full.tolist()], dtype=object)
    power = np.array([f"p{e - 127:+d}f" for e in range(256)], dtype=object)
    return full, stripped, power


def c_floats(values) -> list[str]:
    """:func:`c_float` of every value of an array, the same text, ~10x faster (a table's
    header has 10^5 to 10^6 values): a normal float32 is ``0x1.`` and its 23 mantissa
    bits as six hex digits without their trailing zeros, then ``p`` and the unbiased
    exponent (``float.hex``); the pieces come from tables indexed by the bits, joined
    in numpy's object loops. Zeros are ``0.0f``; subnormals take :func:`c_float`."""
    full, stripped, power = _hex_tables()
    f = np.asarray(values, dtype=np.float32).ravel()
    if not np.all(np.isfinite(f)):
        c_float(f[~np.isfinite(f)][0])  # raises, naming the value
    bits = f.view(np.uint32)
    exp = (bits >> 23) & 0xFF
    mant = (bits & 0x7FFFFF) << 1  # 24 bits: six hex digits
    hi, lo = mant >> 12, mant & 0xFFF
    digits = np.where(lo == 0, stripped[hi], full[hi] + stripped[lo])
    head = np.where(bits >> 31 == 1, "-0x1", "0x1").astype(object)
    text = head + np.where(digits == "", "", ".").astype(object) + digits + power[exp]
    zero = (bits & 0x7FFFFFFF) == 0
    text[zero] = np.where(bits[zero] >> 31 == 1, "-0.0f", "0.0f")
    for i in np.flatnonzero((exp == 0) & ~zero).tolist():
        text[i] = c_float(f[i])
    return text.tolist()


def c_uints(values) -> list[str]:
    """C unsigned literals (``3u``) of an array's values (or of one value)."""
    return [f"{int(x)}u" for x in np.ravel(values)]


def c_initializer(arr, fmt, indent=1, per_line=6) -> str:
    """Brace-nested initializer contents of ``arr`` (without the outermost braces), written
    by ``fmt``, an array's formatter (:func:`c_floats`, :func:`c_uints`)."""
    texts = np.empty(np.shape(arr), dtype=object)
    texts.flat[:] = fmt(arr)
    return _nested(texts, indent, per_line)


def _nested(texts, indent, per_line) -> str:
    pad = "    " * indent
    if texts.ndim == 1:
        vals = texts.tolist()
        lines = [", ".join(vals[i : i + per_line]) for i in range(0, len(vals), per_line)]
        return ",\n".join(pad + line for line in lines)
    parts = [f"{pad}{{\n{_nested(sub, indent + 1, per_line)}\n{pad}}}" for sub in texts]
    return ",\n".join(parts)
