"""User-facing errors: one line naming the file and the key, exit code 2.

Every error a user can cause (bad config, bad log, bad CLI argument, bad table
file) is raised as :class:`InputError`. The CLI turns it into a single line on
stderr and exit code 2, with no traceback.
"""

from __future__ import annotations

__all__ = ["InputError", "GainschedError", "GainschedWarning"]


class GainschedError(Exception):
    """Base class of the errors gainsched raises on purpose."""


class InputError(GainschedError):
    """Bad user input.

    Parameters
    ----------
    source : str or path-like
        The file (or ``"command line"``) the bad value came from.
    where : str
        The key, column, row or argument that is wrong (e.g. ``"vehicle.mass"``).
    message : str
        What is wrong, in a few words.
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
