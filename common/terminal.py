"""Printing from a command that may sit in a pipe (``... | head -3``).

When the reader goes away, writing raises BrokenPipeError. The command should then stop as if
asked to and exit 0 without a traceback: Python would otherwise report the error again when it
flushes stdout at exit. ``balltrack``'s commands (``balltrack/cli/output.py``) and the
experiments run as modules print through these.
"""

import os
import sys


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
