"""Command-line interface (thin: parsing, printing; the logic lives in the modules).

Every user error is an :class:`~gainsched.errors.InputError`, printed as one
line ``gainsched: error: FILE: KEY: what is wrong`` with exit code 2.

One module per command group, each registering its commands on :data:`cli`
(:mod:`._base`, which holds what they share): :mod:`._build` (validate, nominal, build,
sweep), :mod:`._tables` (inspect, plot, export-c, check), :mod:`._flights` (simulate,
paper, campaign), :mod:`._logs` (compare, diagnose, improve, convert).
"""

from __future__ import annotations

from . import _build, _flights, _logs, _tables  # noqa: F401  (register the commands)
from ._base import _note, _outputs_apart, _progress, cli  # noqa: F401  (helpers of every group)

__all__ = ["main", "cli"]


def main():
    cli.main(prog_name="gainsched")


if __name__ == "__main__":
    main()
