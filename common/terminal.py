"""Printing from a command that may sit in a pipe (``... | head -3``), and ending a command that a
signal stops.

When the reader goes away, writing raises BrokenPipeError. The command should then stop as if
asked to and exit 0 without a traceback: Python would otherwise report the error again when it
flushes stdout at exit. ``balltrack``'s commands (``balltrack/cli/output.py``) print through
these; every module run with ``python -m`` ends through ``exit_with``, ``balltrack experiment``
through ``interruptible``.
"""

import os
import sys
from pathlib import Path
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


def interruptible(main: Callable[[], int], name: str) -> int:
    """``main()``'s status, for a command that may sit in a pipe and may be stopped by a signal.

    A reader that went away (``| head``) ends the command quietly with status 0, wherever in
    ``main`` the write was. SIGTERM ends it as Ctrl-C does (``shutdown.terminate_as_interrupt``):
    the cleanup on the way out runs (child processes stopped, sessions closed, temporary
    folders removed), then one line ``NAME: stopped by a signal`` and status 1, no result."""
    from balltrack.common.shutdown import terminate_as_interrupt

    try:
        with terminate_as_interrupt():
            return main()
    except BrokenPipeError:
        silence_closed_stdout()
        return 0
    except KeyboardInterrupt:
        print(f"{name}: stopped by a signal", file=sys.stderr)
        return 1


def exit_with(main: Callable[[], int]) -> NoReturn:
    """Run a command's ``main`` (see ``interruptible``) and exit with its status: what a module
    run with ``python -m`` does under ``if __name__ == "__main__"``."""
    from balltrack.common.shutdown import ignore_stop_signals

    status = interruptible(main, Path(sys.argv[0]).stem)
    ignore_stop_signals()  # (done: a late stop must not replace the status)
    sys.exit(status)
