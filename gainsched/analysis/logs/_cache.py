"""A foreign log converted once: the columns of a PX4 ULog or a ROS 2 bag kept in the
cache, so that the model loop (``compare``, ``diagnose``, ``compare`` again after an
effect was added) parses each log once.

Parsing is what a ULog costs: pyulog reads it message by message in Python, about
2 us per message, 3 s for 10 minutes of a 1 kHz log (docs/performance.md); the
conversion after it takes a tenth of that. The converted columns
(:class:`~gainsched.analysis.logs._foreign.ConvertedLog`) are kept in the cache folder
(``$GAINSCHED_CACHE``, default ``~/.cache/gainsched``) as
``logs/<key>.npz``, the key a SHA-256 of:

* the log's bytes (a bag folder: its files, by name);
* the channel map's values (not where it was read from);
* the full-command thrust the reader was given;
* the converter's own source (``foreign.py``, ``channelmap.py``, ``actuators.py``)
  and the pyulog and rosbags versions, so that a changed converter converts again.

Only successful conversions are kept (an error is raised again on every read, naming
the file as before), written atomically; an unreadable entry is converted again.
Delete the folder to clear it; ``GAINSCHED_LOG_CACHE=0`` turns it off.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import zipfile
from importlib import metadata
from pathlib import Path

import numpy as np

from ...errors import InputError
from ...native import cache_dir
from ...publish import write_atomic
from ._channelmap import ChannelMap
from ._foreign import ConvertedLog, convert_topics, read_topics
from ._progress import report

__all__ = ["converted_log", "log_cache_key"]

_CODE = ("_foreign.py", "_channelmap.py", "../../actuators.py")
_BLOCK = 1 << 22


def _enabled() -> bool:
    return os.environ.get("GAINSCHED_LOG_CACHE", "1") not in ("0", "false", "no", "off")


def _hash_file(h, path: Path) -> None:
    with open(path, "rb") as f:
        while block := f.read(_BLOCK):
            h.update(block)


def log_cache_key(path, cmap: ChannelMap, thrust_max: float | None, day: bool = False) -> str:
    """The cache key of a log converted with a map (module docstring): 64 hex digits.

    Parameters
    ----------
    path : path-like
        A ULog file, an MCAP or SQLite bag file, or a bag folder.
    cmap : ChannelMap
        The validated channel map.
    thrust_max : float or None, N
        The full-command thrust the reader was given (the config's), or None.

    Returns
    -------
    str
    """
    h = hashlib.sha256()
    here = Path(__file__).parent
    for name in _CODE:
        h.update((here / name).read_bytes())
    for dist in ("pyulog", "rosbags"):
        h.update(metadata.version(dist).encode())
    h.update(repr(dataclasses.replace(cmap, source="")).encode())
    h.update(repr(thrust_max).encode() + (b"day" if day else b""))
    path = Path(path)
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for p in files:
        h.update(str(p.relative_to(path) if path.is_dir() else p.name).encode() + b"\0")
        _hash_file(h, p)
    return h.hexdigest()


def _load(entry: Path) -> ConvertedLog | None:
    try:
        with np.load(entry, allow_pickle=False) as z:
            head = json.loads(bytes(z["head"]).decode())
            columns = {k: z[f"c_{k}"] for k in head["columns"]}
            return ConvertedLog(columns, head["meta"], z["rows"], head["label"],
                                tuple(head["report"]), head["sources"])
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None


def _store(entry: Path, conv: ConvertedLog) -> None:
    from io import BytesIO

    head = json.dumps({"columns": list(conv.columns), "meta": conv.meta,
                       "label": conv.label, "report": list(conv.report),
                       "sources": conv.sources}).encode()
    buf = BytesIO()
    np.savez(buf, head=np.frombuffer(head, dtype=np.uint8), rows=conv.rows,
             **{f"c_{k}": v for k, v in conv.columns.items()})
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(entry, buf.getvalue())
    except (OSError, InputError):  # a cache that cannot be written: convert next time
        pass


def converted_log(path, cmap: ChannelMap, thrust_max: float | None = None,
                  day: bool = False) -> ConvertedLog:
    """The flight-log columns of a ULog or a bag (:func:`~._foreign.read_topics` and
    :func:`~._foreign.convert_topics`), from the cache when this log was converted with
    this map before.

    Parameters
    ----------
    path : path-like
        A ULog file, an MCAP or SQLite bag file, or a bag folder.
    cmap : ChannelMap
        The validated channel map.
    thrust_max : float or None, N
        A motor's thrust at full command when the map does not give it.

    Returns
    -------
    ConvertedLog

    Raises
    ------
    InputError
        As :func:`~._foreign.read_topics` and :func:`~._foreign.convert_topics`.
    """
    entry = None
    if _enabled():
        entry = cache_dir() / "logs" / f"{log_cache_key(path, cmap, thrust_max, day)}.npz"
        if entry.is_file() and (conv := _load(entry)) is not None:
            return conv
    topics, params = read_topics(path, cmap)
    report("convert")
    conv = convert_topics(path, topics, params, cmap, thrust_max=thrust_max, day=day)
    if entry is not None:
        _store(entry, conv)
    return conv
