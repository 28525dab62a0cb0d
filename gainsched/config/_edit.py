"""Config variants: the config text as a TOML document, edited and written back.

The one way gainsched makes a variant of a config (``diagnose --apply``, the
hidden-effect plants of ``campaign``, the variants of ``sweep``): the text is
parsed into a ``tomlkit`` document, the keys are set or removed, and the text is
written back with every comment, the order and the layout kept; floats are
written in full precision (shortest round-trip repr). The caller validates the
result with :func:`gainsched.config.config_from_text`, so a variant's ``text``
and ``sha256`` are always those of the config it is.

Sections are dotted table names (``"vehicle"``, ``"effects.rotor_drag"``); ``""``
is the root table.
"""

from __future__ import annotations

import math

import tomlkit
from tomlkit.container import OutOfOrderTableProxy
from tomlkit.items import Table

__all__ = ["get_value", "has_section", "set_value", "set_values", "remove_key", "set_section"]

#: comments start in this column, as in configs/paper.toml
_COMMENT_COL = 39


def _table(doc, section: str, create: bool):
    """The table ``[section]`` of ``doc`` (the document itself for ``""``), or None. A
    table written in pieces (``[effects.drag]`` near the top, ``[effects.rotor_drag]``
    at the end of the file: valid TOML) is tomlkit's proxy over its pieces, edited
    through it."""
    node = doc
    for part in [p for p in section.split(".") if p]:
        if part not in node:
            if not create:
                return None
            _add(node, part, tomlkit.table())
        node = node[part]
        if not isinstance(node, (Table, OutOfOrderTableProxy)):
            raise ValueError(f"[{section}]: {part!r} is not a table")
    return node


def _add(node, key: str, value) -> None:
    """Add ``key`` to a table at its end (a proxy over a table in pieces: to its pieces,
    as tomlkit places it)."""
    if isinstance(node, OutOfOrderTableProxy):
        node[key] = value
    else:
        node.append(key, value)


def _item(value, comment: str | None, key: str):
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"cannot write {value!r} to a config")
    it = tomlkit.item(value)
    if comment:
        it.comment(comment)
        width = len(f"{key} = {it.as_string()}")
        it.trivia.comment_ws = " " * max(2, _COMMENT_COL - width)
    return it


def has_section(text: str, section: str) -> bool:
    """True if ``[section]`` exists (``""``: the root, always)."""
    return _table(tomlkit.parse(text), section, create=False) is not None


def get_value(text: str, section: str, key: str):
    """The value of ``key`` in ``[section]`` (a Python number, string, list...), or None."""
    table = _table(tomlkit.parse(text), section, create=False)
    if table is None or key not in table:
        return None
    return table[key].unwrap() if hasattr(table[key], "unwrap") else table[key]


def set_value(text: str, section: str, key: str, value, comment: str | None = None) -> str:
    """Set ``key = value`` in ``[section]`` (creating both as needed), with a trailing
    comment; everything else is kept."""
    doc = tomlkit.parse(text)
    _table(doc, section, create=True)[key] = _item(value, comment, key)
    return tomlkit.dumps(doc)


def set_values(text: str, values: dict) -> str:
    """Set several dotted keys at once: ``{"vehicle.mass": 0.55, "effects.drag.mu1": 0.2}``.

    A trailing integer indexes a list (``"vehicle.inertia.2"``: Jzz of ``[Jxx, Jyy, Jzz]``;
    the diagonal entry of a 3x3 matrix).
    """
    doc = tomlkit.parse(text)
    for dotted, value in values.items():
        *path, last = dotted.split(".")
        if last.isdigit():
            key, i = path.pop(), int(last)
            table = _table(doc, ".".join(path), create=False)
            arr = table[key]
            if len(arr) and isinstance(arr[0], list):  # a matrix: its diagonal
                row = list(arr[i])
                row[i] = value
                arr[i] = row
            else:
                arr[i] = value
            continue
        _table(doc, ".".join(path), create=True)[last] = _item(value, None, last)
    return tomlkit.dumps(doc)


def remove_key(text: str, section: str, key: str) -> str:
    """Remove ``key`` from ``[section]`` if present."""
    doc = tomlkit.parse(text)
    table = _table(doc, section, create=False)
    if table is not None and key in table:
        del table[key]
    return tomlkit.dumps(doc)


def set_section(text: str, section: str, items, header_comment: str | None = None) -> str:
    """Replace (or add) ``[section]`` with ``items``: (key, value, comment) triples.

    A new ``[effects.NAME]`` table joins the other effect tables.
    """
    doc = tomlkit.parse(text)
    parent_name, _, name = section.rpartition(".")
    parent = _table(doc, parent_name, create=True)
    table = tomlkit.table()
    if header_comment:
        table.comment(header_comment)
        table.trivia.comment_ws = " " * max(2, _COMMENT_COL - len(f"[{section}]"))
    for key, value, comment in items:
        table.add(key, _item(value, comment, key))
    table.add(tomlkit.nl())
    if name in parent:
        parent[name] = table
    else:
        _add(parent, name, table)
    return tomlkit.dumps(doc)
