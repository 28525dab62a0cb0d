"""Small, comment-preserving edits of config TOML text (used by ``diagnose --apply``).

Only single-line ``key = value`` entries are edited; everything else (comments,
order, multi-line arrays) is kept byte for byte. A section is the run of lines
from its ``[header]`` to the next header. The caller validates the result with
:func:`gainsched.config.config_from_text`.
"""

from __future__ import annotations

import math
import re

__all__ = ["fmt_value", "get_value", "set_value", "remove_key", "has_section", "set_section"]

_HEADER = re.compile(r"^\s*\[\s*([A-Za-z_\"][A-Za-z0-9_.\-\"]*)\s*\]\s*(#.*)?$")
_COMMENT_COL = 39  # comments aligned like configs/paper.toml


def fmt_value(v) -> str:
    """TOML literal for a Python value: shortest round-trip float, quoted string, bool, int."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write {v!r} to a config")
        s = repr(float(f"{v:.6g}"))
        return s
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    raise TypeError(f"cannot write {type(v).__name__} to a config")


def _line(key: str, value, comment: str | None) -> str:
    s = f"{key} = {fmt_value(value)}"
    if comment:
        s = s.ljust(_COMMENT_COL) + f"# {comment}"
    return s


def _sections(lines: list[str]) -> list[tuple[str, int, int]]:
    """(name, first line index after the header or 0 for the root, end index) per section."""
    out = []
    name, start = "", 0
    for i, ln in enumerate(lines):
        m = _HEADER.match(ln)
        if m:
            out.append((name, start, i))
            name, start = m.group(1), i + 1
    out.append((name, start, len(lines)))
    return out


def _find(lines, section):
    for name, a, b in _sections(lines):
        if name == section:
            return a, b
    return None


def _key_index(lines, a, b, key):
    pat = re.compile(rf"^\s*{re.escape(key)}\s*=")
    for i in range(a, b):
        if pat.match(lines[i]):
            return i
    return None


def has_section(text: str, section: str) -> bool:
    """True if ``[section]`` exists (``""``: the root, always)."""
    return _find(text.splitlines(), section) is not None


def get_value(text: str, section: str, key: str) -> str | None:
    """The raw value text of ``key`` in ``[section]`` (comment stripped), or None."""
    lines = text.splitlines()
    loc = _find(lines, section)
    if loc is None:
        return None
    i = _key_index(lines, *loc, key)
    if i is None:
        return None
    v = lines[i].split("=", 1)[1]
    return v.split("#", 1)[0].strip() if '"' not in v else v.strip()


def set_value(text: str, section: str, key: str, value, comment: str | None = None) -> str:
    """Set ``key = value`` in ``[section]`` (creating both as needed), with a trailing comment."""
    lines = text.splitlines()
    loc = _find(lines, section)
    new = _line(key, value, comment)
    if loc is None:
        if lines and lines[-1].strip():
            lines.append("")
        lines += [f"[{section}]", new]
    else:
        a, b = loc
        i = _key_index(lines, a, b, key)
        if i is not None:
            lines[i] = new
        else:
            j = b
            while j > a and not lines[j - 1].strip():  # before trailing blank lines
                j -= 1
            lines.insert(j, new)
    return "\n".join(lines) + "\n"


def remove_key(text: str, section: str, key: str) -> str:
    """Remove ``key`` from ``[section]`` if present."""
    lines = text.splitlines()
    loc = _find(lines, section)
    if loc is not None:
        i = _key_index(lines, *loc, key)
        if i is not None:
            del lines[i]
    return "\n".join(lines) + "\n"


def set_section(text: str, section: str, items, header_comment: str | None = None) -> str:
    """Replace (or append) ``[section]`` with ``items``: (key, value, comment) triples."""
    lines = text.splitlines()
    loc = _find(lines, section)
    header = f"[{section}]"
    if header_comment:
        header = header.ljust(_COMMENT_COL) + f"# {header_comment}"
    body = [header] + [_line(k, v, c) for k, v, c in items]
    if loc is None:
        # effects tables go after the last [effects.*] table, else at the end
        secs = _sections(lines)
        prefix = section.split(".")[0] + "."
        same = [b for name, _, b in secs if name.startswith(prefix)]
        if same:
            at = same[-1]
            while at > 0 and not lines[at - 1].strip():
                at -= 1
            lines[at:at] = ["", *body]
        else:
            if lines and lines[-1].strip():
                lines.append("")
            lines += body
    else:
        a, b = loc
        end = b
        while end > a and not lines[end - 1].strip():
            end -= 1
        lines[a - 1 : end] = body
    return "\n".join(lines) + "\n"
