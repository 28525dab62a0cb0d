"""How a study shows what it does while it runs (progress bars, lines of chatter, its
result's lines as they come), and the one way a study takes a config.

A study (:mod:`gainsched.studies`) takes a :class:`Reporter`; the default shows nothing,
so a script that calls one sees only its result. The command line gives its terminal's
(progress on stderr when it is a terminal, none under ``--quiet``: gainsched/cli).
"""

from __future__ import annotations

__all__ = ["Reporter", "SILENT", "config_of", "teller", "on_bar", "stage"]


class _NoBar:
    """A progress bar that shows nothing: what :meth:`Reporter.bar` returns by default
    (``disable``, as tqdm's bar says it)."""

    disable = True

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> bool:
        return False

    def update(self, n: int = 1) -> None:
        """Count ``n`` more units done."""

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        """Name what runs now."""


class Reporter:
    """What a study tells while it runs; this base tells nothing (:data:`SILENT`).

    A subclass shows it: :meth:`bar` makes a progress bar (a context manager with
    ``update(n)`` and ``set_postfix_str(text)``, as tqdm's), :meth:`note` writes a line
    of chatter (what runs where, what was built on the way: not a result), :meth:`line`
    a line of the result as soon as it is known (a long study's verdict before its
    rebuild).

    Examples
    --------
    A reporter that prints its notes (and, as the base, draws no bar):

    >>> class Printing(gs.Reporter):
    ...     def note(self, text, bar=None):
    ...         print("note:", text)
    >>> r = Printing()
    >>> r.note("built tables/paper.h5")
    note: built tables/paper.h5
    >>> with r.bar("build paper", 7, "speed") as bar:
    ...     bar.update(7)
    """

    def bar(self, desc: str, total: int | None = None, unit: str = "it", *,
            show: bool = True):
        """A progress bar of ``total`` ``unit`` (None: counted without an end) named
        ``desc``; ``show`` false: a bar that shows nothing."""
        return _NoBar()

    def note(self, text: str, bar=None) -> None:
        """A line of chatter, written above a live ``bar`` when one is given."""

    def line(self, text: str) -> None:
        """A line of what the study found, as soon as it is known (the command line prints
        it on stdout); the result's ``lines()`` keeps them all."""


#: the reporter that tells nothing: the studies' default
SILENT = Reporter()


def config_of(config):
    """A study's config argument as a :class:`~gainsched.config.Config`: itself, or the
    TOML file (or shipped config's name) it names, loaded and validated."""
    from ..config import Config, load_config

    return config if isinstance(config, Config) else load_config(config)


def teller(reporter: Reporter):
    """``(said, say)``: the lines a study has told (a list, its result's ``lines()``) and
    ``say(lines)``, which tells each line to ``reporter`` as it comes and keeps it."""
    said: list[str] = []

    def say(lines) -> None:
        for line in lines:
            said.append(line)
            reporter.line(line)

    return said, say


def on_bar(bar):
    """The :func:`~gainsched.analysis.logs.reporting` callback that draws on a progress
    ``bar`` (tqdm's, or :meth:`Reporter.bar`'s): the stage as its label, a read's bytes or
    messages as its count; None for a disabled bar (off the terminal, ``--quiet``: nothing
    to watch)."""
    if bar.disable:
        return None

    def show(stage, done=None, total=None, unit=None):
        if total is not None and (bar.total != total or bar.unit != unit):
            bar.unit, bar.unit_scale = unit, unit == "B"
            bar.reset(total=total)
        if done is not None:
            bar.n = done
        bar.set_postfix_str(stage)

    return show


def stage(bar, name: str, fn, *args):
    """``fn(*args)`` as one counted step of a tqdm ``bar`` labelled ``name``: its result."""
    bar.set_postfix_str(name)
    out = fn(*args)
    bar.update()
    return out
