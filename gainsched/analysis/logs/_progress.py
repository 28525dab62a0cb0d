"""Progress of reading and converting a foreign log (PX4 ULog, ROS 2 bag), for a caller
that shows it (``gainsched convert``'s progress line: gainsched.studies' ``on_bar``).

A callback in a context variable, so that the library functions keep their signatures
and report nothing when no one listens: the ULog parse reports the bytes read (watched
from a thread every 0.1 s: pyulog parses in one call), a bag's read the messages, the
conversion and the consistency checks their start.
"""

from __future__ import annotations

import contextlib
import threading
from contextvars import ContextVar

__all__ = ["reporting", "report", "listener", "watch_file"]

_LISTENER: ContextVar = ContextVar("gainsched_log_progress", default=None)


@contextlib.contextmanager
def reporting(callback):
    """While inside, the log reading and conversion report to ``callback(stage, done,
    total, unit)``.

    Parameters
    ----------
    callback : callable or None
        Called with the stage's name (str), its progress ``done`` of ``total`` (numbers
        in ``unit``: ``"B"`` bytes, ``"msg"`` messages; None for a stage without). None:
        no one listens.
    """
    token = _LISTENER.set(callback)
    try:
        yield
    finally:
        _LISTENER.reset(token)


def listener():
    """The callback of :func:`reporting` in this context, or None."""
    return _LISTENER.get()


def report(stage: str, done=None, total=None, unit=None) -> None:
    """Tell the listener (if any) that ``stage`` runs, ``done`` of ``total`` ``unit``."""
    cb = _LISTENER.get()
    if cb is not None:
        cb(stage, done, total, unit)


@contextlib.contextmanager
def watch_file(handle, total: int, stage: str, every: float = 0.1):
    """Report ``handle``'s read position (bytes of ``total``) as ``stage`` every ``every``
    seconds from a thread while inside, and ``total`` at the end; nothing without a
    listener. The handle is a binary buffered file (safe to ask from a second thread)."""
    cb = _LISTENER.get()
    if cb is None:
        yield
        return
    stop = threading.Event()

    def poll():
        while not stop.wait(every):
            try:
                pos = handle.tell()
            except (ValueError, OSError):  # closed by the reader: done
                return
            cb(stage, pos, total, "B")

    cb(stage, 0, total, "B")
    thread = threading.Thread(target=poll, name="gainsched-read-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
    cb(stage, total, total, "B")
