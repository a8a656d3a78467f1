"""Printing from a command that may sit in a pipe (``balltrack echo KEY | head -3``).

When the reader goes away, writing raises BrokenPipeError. The command should then stop as if
asked to (its stop event is set), close its session, and exit 0 without a traceback: Python
would otherwise report the error again when it flushes stdout at exit
(``common.terminal.silence_closed_stdout``).
"""

import sys
import threading


class Output:
    """Thread-safe line printer for Zenoh callbacks; a closed pipe sets ``stop``."""

    def __init__(self, stop: threading.Event, stream=None):
        self.stop = stop
        self.stream = stream or sys.stdout
        self.closed = False
        self._lock = threading.Lock()

    def line(self, text: str) -> bool:
        """Print one line; False once the reader has gone (and from then on)."""
        with self._lock:
            if self.closed:
                return False
            try:
                self.stream.write(text + "\n")
                self.stream.flush()
                return True
            except (BrokenPipeError, ValueError):  # ValueError: stdout already closed
                self.closed = True
                self.stop.set()
                return False
