"""What a PX4 ULog declares, read before ``pyulog`` parses it: the message formats of its
definitions section and the bytes one sample of each needs.

Why by hand: ``pyulog`` trusts the formats a file declares. A format is text
(``"name:uint64_t timestamp;float[4] q;"``) that may nest other formats and arrays, so
100 bytes can declare a topic of 65535 x 65535 fields; ``pyulog`` then builds the record
type field by field and never answers. A ULog data message carries its sample in at most
65,535 bytes (its size is a 16-bit number, the message id included: ULog file format,
docs.px4.io "ULog File Format"), so no sample of a real log is larger:
:func:`check_ulog_formats` refuses a format whose sample exceeds it, in one line naming
the format, before any parsing. The scan reads the file header and the definitions
section only (each message at most 65,535 bytes, and it stops at the first data-section
message).
"""

from __future__ import annotations

import struct
from pathlib import Path

from ...errors import InputError

__all__ = ["ULOG_MAGIC", "MAX_SAMPLE_BYTES", "ulog_formats", "check_ulog_formats"]

#: the first 7 bytes of every ULog (``"ULog"`` and the magic 0x01 0x12 0x35)
ULOG_MAGIC = b"ULog\x01\x12\x35"
#: most bytes one sample of a topic can have: a data message's size is 16 bits and holds
#: the 2-byte message id
MAX_SAMPLE_BYTES = 65535 - 2
#: bytes of ULog's primitive types
_PRIMITIVE = {"int8_t": 1, "uint8_t": 1, "bool": 1, "char": 1, "int16_t": 2, "uint16_t": 2,
              "int32_t": 4, "uint32_t": 4, "float": 4, "int64_t": 8, "uint64_t": 8,
              "double": 8}
#: the message types of the definitions section (flag bits, format, info, info multiple,
#: parameter, parameter default); any other ends it
_DEFINITIONS = frozenset(b"BFIMPQ")
#: deepest nesting of formats followed (PX4's deepest is 2 or 3)
_MAX_DEPTH = 16


def ulog_formats(path) -> dict[str, list[tuple[str, str, int]]]:
    """The formats a ULog's definitions section declares: name -> fields ``(type, name,
    array length or 0)``, in the file's order. Text that is not a format is skipped
    (pyulog reports a damaged file)."""
    formats: dict[str, list[tuple[str, str, int]]] = {}
    with open(path, "rb") as f:
        if f.read(16)[:7] != ULOG_MAGIC:
            return formats
        while len(head := f.read(3)) == 3:
            size, kind = struct.unpack("<HB", head)
            if kind not in _DEFINITIONS:
                break
            data = f.read(size)
            if kind == ord("F"):
                name, fields = _parse_format(data)
                if name:
                    formats[name] = fields
    return formats


def _parse_format(data: bytes) -> tuple[str, list[tuple[str, str, int]]]:
    text = data.decode("utf-8", "replace")
    name, sep, rest = text.partition(":")
    if not sep:
        return "", []
    fields = []
    for item in filter(None, (s.strip() for s in rest.split(";"))):
        kind, _, fname = item.partition(" ")
        base, _, count = kind.partition("[")
        try:
            n = int(count.rstrip("]")) if count else 0
        except ValueError:
            n = 0
        fields.append((base, fname, n))
    return name, fields


def check_ulog_formats(path) -> None:
    """Refuse, in one line, a ULog whose declared formats no real log can hold.

    Raises
    ------
    InputError
        Naming the file and the format: one sample of it needs more than
        :data:`MAX_SAMPLE_BYTES` bytes (what one ULog message can carry), or its formats
        nest deeper than 16 levels or in a circle.
    """
    formats = ulog_formats(path)
    sizes: dict[str, int] = {}

    def size(name: str, depth: int) -> int:
        if name in sizes:
            return sizes[name]
        if depth > _MAX_DEPTH:
            raise InputError(Path(path), f"format {name}", "formats nested deeper than "
                             f"{_MAX_DEPTH} levels, or in a circle: not a ULog a flight "
                             "stack writes")
        total = 0
        for kind, _, n in formats[name]:
            one = _PRIMITIVE.get(kind)
            if one is None:
                one = size(kind, depth + 1) if kind in formats else 0
            total += one * max(n, 1)
            if total > MAX_SAMPLE_BYTES:  # stop counting: 65535 x 65535 never multiplied out
                raise InputError(
                    Path(path), f"format {name}",
                    f"declares more than {MAX_SAMPLE_BYTES:,} bytes per sample, more than a "
                    "ULog message can carry: a damaged or forged header, not read")
        sizes[name] = total
        return total

    for name in formats:
        size(name, 0)
