"""``python -m gainsched`` and the ``gainsched`` command.

The process is pinned to the reproducible numerics (:mod:`gainsched.native.reproducible`)
before anything imports numpy, so every backend of ``gainsched build`` gives the
same table bits on every x86-64-v3 machine.

A Ctrl-C at any moment, the imports included (numpy, click and the command's modules
take a quarter of a second), prints ``gainsched: interrupted`` and exits with 130: this
module imports nothing heavy before :func:`main` holds the handler (``import
gainsched`` itself is a few milliseconds: every name of it loads on first use).
"""

from __future__ import annotations

import signal
import sys

#: the exit code of a command stopped by Ctrl-C (128 + SIGINT), as a shell's
INTERRUPTED = 130


def _ctrl_c_in_a_callback(unraisable) -> None:
    """``sys.unraisablehook`` of the command: a Ctrl-C that lands where Python cannot raise
    (a weakref callback such as a ``WeakValueDictionary``'s, a ``__del__``, a ctypes
    callback) would be printed as "Exception ignored" with its traceback and lost, the
    command going on. It is delivered again to the main thread once the callback is
    over, from a timer thread (raised inside this hook it would be lost the same way);
    every other unraisable exception is shown as Python shows it."""
    if issubclass(unraisable.exc_type, KeyboardInterrupt):
        import _thread
        import threading

        timer = threading.Timer(0.005, _thread.interrupt_main)
        timer.daemon = True
        timer.start()
        return
    sys.__unraisablehook__(unraisable)


def main() -> None:
    """Pin the numerics of this process, then run the command line."""
    sys.unraisablehook = _ctrl_c_in_a_callback
    try:
        from .native.reproducible import pin_environ

        pin_environ()
        from .cli import main as cli_main

        cli_main()
    except KeyboardInterrupt:  # before the command line's own handler is in place
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        sys.stderr.write("gainsched: interrupted\n")
        sys.exit(INTERRUPTED)
    finally:
        # the command is done (or has reported its interruption): a Ctrl-C while the
        # interpreter shuts down its worker pools would only print a traceback
        signal.signal(signal.SIGINT, signal.SIG_IGN)


if __name__ == "__main__":
    main()
