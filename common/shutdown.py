"""One shutdown rule for every process: SIGINT and SIGTERM set one event."""

import signal
import threading


def stop_on_signals(stop: threading.Event | None = None) -> threading.Event:
    """Return an event that SIGINT and SIGTERM set (call from the main thread)."""
    stop = stop or threading.Event()
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, lambda *_: stop.set())
    return stop
