"""User-facing errors: one line naming the file and the key, exit code 2.

Every error a user can cause (bad config, bad log, bad CLI argument, bad table
file) is raised as :class:`InputError`. The CLI turns it into a single line on
stderr and exit code 2, with no traceback.

The classes are usable as the built-ins they are (python-control's habit, e.g.
``ControlArgument(TypeError)``): a bad value is a :class:`ValueError`, so
``except ValueError`` in a caller's code catches an :class:`InputError` too. Code in
this package that catches ``ValueError`` around something that may raise an
:class:`InputError` lets that one through first (``except InputError: raise``), so
that its message (file and key) is kept.
"""

from __future__ import annotations

__all__ = ["InputError", "GainschedError", "GainschedWarning"]


class GainschedError(Exception):
    """Base class of the errors gainsched raises on purpose.

    Each subclass is also the built-in it stands for: :class:`InputError` (a bad
    value) is a :class:`ValueError`.
    """


class InputError(GainschedError, ValueError):
    """Bad user input (config, log, table, argument): one line naming the file, key and fault.

    A bad config, flight log, scenario, table file or command-line argument raises this
    (never a traceback from deep inside): ``str(err)`` is ``"SOURCE: WHERE: MESSAGE"``
    (``"SOURCE: MESSAGE"`` without ``where``). The command line prints it as one line on
    stderr and exits with :attr:`exit_code` 2; from Python, catch it to report or fix
    the input.
    It is a :class:`ValueError` (and a :class:`GainschedError`): ``except ValueError``
    catches it.

    Parameters
    ----------
    source : str or path-like
        The file (or ``"command line"``) the bad value came from.
    where : str
        The key, column, row, dataset or argument that is wrong (e.g.
        ``"vehicle.mass"``, ``"gains/K"``); ``""`` when the whole source is bad (not
        readable, not TOML).
    message : str
        What is wrong, in a few words.

    Attributes
    ----------
    source : str
        ``str(source)``.
    where : str
        As given.
    message : str
        As given.
    exit_code : int
        2, the command line's exit code for it.

    Examples
    --------
    >>> err = gs.InputError("configs/paper.toml", "vehicle.mass", "must be > 0, got -0.5")
    >>> str(err)
    'configs/paper.toml: vehicle.mass: must be > 0, got -0.5'

    Catching it around a load, to report the key that is wrong:

    >>> try:
    ...     gs.config_from_text('name = "my config"', "mine.toml")
    ... except gs.InputError as exc:
    ...     print(exc.source, exc.where, exc.exit_code)
    mine.toml name 2
    """

    exit_code = 2

    def __init__(self, source, where: str, message: str):
        self.source = str(source)
        self.where = where
        self.message = message
        text = f"{self.source}: {where}: {message}" if where else f"{self.source}: {message}"
        super().__init__(text)


class GainschedWarning(UserWarning):
    """Something the user should know that does not stop the command (the CLI prints it
    as one line ``gainsched: warning: ...``)."""
