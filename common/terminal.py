"""Printing from a command that may sit in a pipe (``... | head -3``).

When the reader goes away, writing raises BrokenPipeError. The command should then stop as if
asked to and exit 0 without a traceback: Python would otherwise report the error again when it
flushes stdout at exit. ``balltrack``'s commands (``balltrack/cli/output.py``) print through
these; every module run with ``python -m`` ends through ``exit_with``.
"""

import os
import sys
from typing import Callable, NoReturn


def silence_closed_stdout() -> None:
    """After a BrokenPipeError, point stdout at /dev/null so the exit-time flush is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def print_lines(lines: list[str]) -> bool:
    """Print ``lines`` to stdout; False (quietly) when the reader has gone."""
    try:
        print("\n".join(lines), flush=True)
        return True
    except BrokenPipeError:
        silence_closed_stdout()
        return False


def exit_with(main: Callable[[], int]) -> NoReturn:
    """Run a command's ``main`` and exit with its status: what a module run with ``python -m``
    does under ``if __name__ == "__main__"``. A reader that went away (``| head``) ends the
    command quietly with status 0, wherever in ``main`` the write was."""
    try:
        status = main()
    except BrokenPipeError:
        silence_closed_stdout()
        status = 0
    sys.exit(status)
