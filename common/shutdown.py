"""One shutdown rule for every process: SIGINT and SIGTERM set one event. (A one-shot command
that has no event to watch lets SIGTERM interrupt it as Ctrl-C does: ``terminate_as_interrupt``.)"""

import contextlib
import signal
import threading


def set_from_signal(event: threading.Event) -> None:
    """Set ``event`` from a signal handler.

    A handler runs in the main thread between two bytecodes, possibly while that thread holds
    the event's own lock inside ``event.wait()``; ``event.set()`` there would wait for that
    lock for ever (seen: a simulator that ignored SIGTERM until it was killed). A short thread
    sets it instead, once the main thread is back in its wait."""
    threading.Thread(target=event.set, name="signal-stop", daemon=True).start()


def stop_on_signals(stop: threading.Event | None = None) -> threading.Event:
    """Return an event that SIGINT and SIGTERM set (call from the main thread)."""
    stop = stop or threading.Event()
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, lambda *_: set_from_signal(stop))
    return stop


@contextlib.contextmanager
def terminate_as_interrupt():
    """Within the block, SIGTERM raises KeyboardInterrupt as SIGINT does, so a command ends
    the same way on either (its ``except KeyboardInterrupt``: one line, its status); the
    previous handler is back afterwards. Call from the main thread."""
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
