"""The one reader of the text files a user gives: configs, scenarios, channel maps.

Every TOML input comes in through :func:`read_text` and :func:`parse_toml` (or both
at once, :func:`load_toml`), so each gets the same front door, each fault as one
:class:`~gainsched.errors.InputError` naming the file:

- the size is bounded by the bytes actually read (at most ``limit + 1``), not by
  ``st_size``: a device such as ``/dev/zero`` says 0 and never ends;
- a binary file a user may mix up with it (a ULog, a bag, an HDF5 table or log) is named
  as what it is;
- the bytes must be UTF-8 (a UTF-8 byte-order mark is dropped); UTF-16, UTF-32,
  NUL bytes and any other encoding are refused with the line (and column) of the
  first bad byte; newlines are normalised to ``\\n``;
- the TOML must parse, its numbers must be numbers Python can hold, and its arrays
  and tables may nest at most :data:`MAX_NESTING` deep (``tomllib`` recurses once per
  level: 100,000 nested brackets would otherwise end in a RecursionError).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from .errors import InputError

__all__ = ["MAX_TEXT_BYTES", "MAX_NESTING", "read_text", "decode_text", "parse_toml",
           "load_toml"]

#: largest scenario or channel map, bytes: a hand-written one is well under 10 KiB (1 MiB
#: still parses in a fraction of a second). Configs set their own bound (config/_reader.py).
MAX_TEXT_BYTES = 2**20
#: deepest nesting of arrays and tables: a config's deepest key is 3 tables down
#: (``effects.motor_lag.tau``) and its deepest value a list of rows (Q, R); 32 leaves
#: room for anything written by hand and stays far below Python's recursion limit
MAX_NESTING = 32

#: the files a user may give where text belongs, by their first bytes: what each is
_BINARY = ((b"ULog\x01\x12\x35", "a PX4 ULog flight log"),
           (b"\x89MCAP", "an MCAP file (a ROS 2 bag)"),
           (b"SQLite format 3\x00", "an SQLite database (a ROS 2 bag's .db3)"),
           (b"\x89HDF\r\n\x1a\n", "an HDF5 file (a gain table or a flight log)"),
           (b"PK\x03\x04", "a ZIP archive"), (b"\x7fELF", "a program (ELF)"))
_UTF32_BOMS = (b"\xff\xfe\x00\x00", b"\x00\x00\xfe\xff")
_UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")


def _size(n: int) -> str:
    return f"{n / 2**20:g} MiB" if n >= 2**20 else f"{n / 2**10:g} KiB"


def read_text(path, *, what: str = "file", limit: int = MAX_TEXT_BYTES,
              allowed: str | None = None, hint: str = "", advice: str = "") -> str:
    """The text of a user's file: at most ``limit`` bytes, UTF-8, newlines as ``\\n``.

    Parameters
    ----------
    path : str or path-like
    what : str
        What the file is (``"config"``, ``"scenario"``), for the message.
    limit : int
        Most bytes accepted; no more than ``limit + 1`` are ever read.
    allowed : str, optional
        The size limit as the message states it (default: ``limit`` in KiB or MiB).
    hint : str
        Appended to the "cannot read" message (e.g. the shipped names).
    advice : str
        What the "too large" message advises (default: the size a ``what`` may have).

    Raises
    ------
    InputError
        Naming the file: it cannot be read, is a binary file of a known kind (a ULog, a
        bag, HDF5: named), is larger than ``limit`` or is not UTF-8 text
        (:func:`decode_text`).
    """
    p = Path(path)
    try:
        with open(p, "rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise InputError(p, "", f"cannot read ({exc.strerror or exc}){hint}") from None
    for magic, kind in _BINARY:  # a log given for a map: say so, not "too large"
        if data.startswith(magic):
            raise InputError(p, "", f"{kind}, not a {what} (a {what} is TOML text)")
    if len(data) > limit:
        advice = advice or f"a {what} may have at most {allowed or _size(limit)}"
        raise InputError(p, "", f"larger than {_size(limit)}: too large for a {what} "
                         f"({advice})")
    return decode_text(p, data)


def decode_text(source, data: bytes) -> str:
    """Bytes -> text: UTF-8 (a UTF-8 byte-order mark is dropped), newlines as ``\\n``.

    Raises InputError naming ``source`` for UTF-16/UTF-32 text (with or without a
    byte-order mark), NUL bytes, and bytes that are not UTF-8 (e.g. latin-1), with the
    line and column of the first bad byte.
    """
    if data.startswith(_UTF32_BOMS):
        raise InputError(source, "", "UTF-32 text (byte-order mark); save it as UTF-8")
    if data.startswith(_UTF16_BOMS):
        raise InputError(source, "", "UTF-16 text (byte-order mark); save it as UTF-8")
    if b"\x00" in data:
        # TOML text never holds NUL; ASCII text in UTF-16 without a BOM is half NULs
        even, odd = data[0::2].count(0), data[1::2].count(0)
        if max(even, odd) > len(data) // 8:
            raise InputError(source, "", "looks like UTF-16 text (NUL bytes between the "
                             "characters); save it as UTF-8")
        line = data[: data.index(b"\x00")].count(b"\n") + 1
        raise InputError(source, "", f"not a text file (NUL byte on line {line})")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise InputError(
            source, "", f"not UTF-8 text (byte 0x{data[exc.start]:02x} at line {line}, column "
            f"{col}: {exc.reason}); save it as UTF-8"
        ) from None
    # as text-mode reading does: universal newlines, so a hash does not depend on them
    return text.replace("\r\n", "\n").replace("\r", "\n")


def parse_toml(text: str, source, *, max_nesting: int = MAX_NESTING) -> dict:
    """TOML text -> dict, nested at most ``max_nesting`` deep.

    Raises
    ------
    InputError
        Naming ``source``: not valid TOML (with the parser's line and column), a
        number Python cannot hold, or nesting deeper than ``max_nesting`` (named by
        the dotted key where it is too deep).
    """
    deep = f"nested deeper than {max_nesting} levels of arrays and tables"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(source, "", f"not valid TOML ({exc})") from None
    except RecursionError:  # tomllib recurses once per nested array or inline table
        raise InputError(source, "", deep) from None
    except ValueError as exc:  # an integer of more than 4300 digits
        raise InputError(source, "", f"not valid TOML ({' '.join(str(exc).split())})") from None
    key = _too_deep(data, max_nesting)
    if key is not None:
        raise InputError(source, key, deep)
    return data


def _too_deep(data: dict, max_nesting: int) -> str | None:
    """The dotted key of the first value nested deeper than ``max_nesting``, or None
    (iterative: no recursion however deep the data)."""
    stack = [(data, "", 0)]
    while stack:
        node, key, depth = stack.pop()
        if depth > max_nesting:
            return key or "(top)"
        if isinstance(node, dict):
            stack.extend((v, f"{key}.{k}" if key else str(k), depth + 1) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, f"{key}[{i}]", depth + 1) for i, v in enumerate(node))
    return None


def load_toml(path, *, what: str = "file", limit: int = MAX_TEXT_BYTES,
              hint: str = "") -> dict:
    """:func:`read_text` then :func:`parse_toml`: a user's TOML file as a dict."""
    return parse_toml(read_text(path, what=what, limit=limit, hint=hint), path)
