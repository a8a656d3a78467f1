"""One shutdown rule for every process: SIGINT and SIGTERM set one event. (A one-shot command
that has no event to watch lets SIGTERM interrupt it as Ctrl-C does: ``terminate_as_interrupt``.)"""

import contextlib
import signal
import sys
import threading

# An interrupt that Python swallowed is raised again this much later (see terminate_as_interrupt).
INTERRUPT_AGAIN_S = 0.05


def set_from_signal(event: threading.Event) -> None:
    """Set ``event`` from a signal handler.

    A handler runs in the main thread between two bytecodes, possibly while that thread holds
    the event's own lock inside ``event.wait()``; ``event.set()`` there would wait for that
    lock for ever (seen: a simulator that ignored SIGTERM until it was killed). A short thread
    sets it instead, once the main thread is back in its wait."""
    threading.Thread(target=event.set, name="signal-stop", daemon=True).start()


# SIGINT and SIGTERM that came while a process imported its code, before it had its stop
# event (see catch_early_stops).
_EARLY: list[int] = []


def catch_early_stops() -> None:
    """Keep SIGINT and SIGTERM from here until ``stop_on_signals``, which then sets its event
    at once. A service's entry point calls it before importing the service (0.3-0.6 s:
    zenoh, OpenCV, MuJoCo): a stop in that time killed it, status 143 in place of 0 (a
    supervisor stopping a process that has just started), and a SIGINT inherited as ignored
    (a process started in the background by a script) was lost. Call from the main thread."""
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, lambda number, _frame: _EARLY.append(number))


def stop_on_signals(stop: threading.Event | None = None) -> threading.Event:
    """Return an event that SIGINT and SIGTERM set (call from the main thread); already set
    when one came since ``catch_early_stops``."""
    stop = stop or threading.Event()
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, lambda *_: set_from_signal(stop))
    if _EARLY:
        stop.set()
    return stop


def ignore_stop_signals() -> None:
    """SIGINT and SIGTERM ignored from here on: for a command whose work is done, on its way
    out. Python sets its own handlers back to the default while the interpreter shuts down
    (imported libraries take a tenth of a second to unload), and a stop arriving then would
    kill the process, status 143 in place of its own; an ignored signal stays ignored."""
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, signal.SIG_IGN)


@contextlib.contextmanager
def terminate_as_interrupt():
    """Within the block, SIGTERM raises KeyboardInterrupt as SIGINT does, so a command ends
    the same way on either (its ``except KeyboardInterrupt``: one line, its status); the
    previous handlers are back afterwards. Call from the main thread.

    An interrupt raised where Python only reports an exception and goes on (an at-fork hook
    while a child process starts, a destructor) would be lost, and the command would run on:
    seen, frame_transport's run of 100,000 messages went on after a SIGTERM that landed in
    logging's at-fork hook. Such an interrupt is raised again INTERRUPT_AGAIN_S later (SIGALRM),
    once the main thread is back in the block's own code.

    A SIGINT inherited as ignored (a command started in the background by a script) raises
    KeyboardInterrupt within the block too, as it stops a service (``stop_on_signals``):
    left ignored, ``kill -INT`` did nothing."""
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler)
    previous_interrupt = signal.getsignal(signal.SIGINT)
    if previous_interrupt == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    previous_alarm = signal.signal(signal.SIGALRM, signal.default_int_handler)
    previous_hook = sys.unraisablehook
    armed = False

    def raise_again(unraisable) -> None:
        nonlocal armed
        if issubclass(unraisable.exc_type, KeyboardInterrupt):
            # (later, not now: raised inside this hook, it would be swallowed as well)
            signal.setitimer(signal.ITIMER_REAL, INTERRUPT_AGAIN_S)
            armed = True
        else:
            previous_hook(unraisable)

    sys.unraisablehook = raise_again
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        if armed:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous_alarm)
        signal.signal(signal.SIGTERM, previous)
        if previous_interrupt == signal.SIG_IGN:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
