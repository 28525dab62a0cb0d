"""``python -m gainsched`` and the ``gainsched`` command.

The process is pinned to the reproducible numerics (:mod:`gainsched.native.reproducible`)
before anything imports numpy, so every backend of ``gainsched build`` gives the
same table bits on every x86-64-v3 machine.
"""

from __future__ import annotations

import signal


def main() -> None:
    """Pin the numerics of this process, then run the command line."""
    from .native.reproducible import pin_environ

    pin_environ()
    from .cli import main as cli_main

    try:
        cli_main()
    finally:
        # the command is done (or has reported its interruption): a Ctrl-C while the
        # interpreter shuts down its worker pools would only print a traceback
        signal.signal(signal.SIGINT, signal.SIG_IGN)


if __name__ == "__main__":
    main()
