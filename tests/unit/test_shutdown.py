"""SIGINT/SIGTERM set the one stop event without ever blocking the thread they interrupt."""

import signal
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from balltrack.common.shutdown import stop_on_signals, terminate_as_interrupt
from tests.harness import REPO, process_environment


def test_a_signal_landing_inside_stop_wait_does_not_deadlock():
    saved = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        stop = stop_on_signals(threading.Event())
        handler = signal.getsignal(signal.SIGTERM)
        # A handler runs in the main thread, which may be inside stop.wait() holding the
        # event's own lock (CPython's Event._cond) at that moment: hold it, and run the handler.
        with stop._cond:
            caller = threading.Thread(target=handler, args=(signal.SIGTERM, None))
            caller.start()
            caller.join(5)
            assert not caller.is_alive(), "the handler blocked on the event's lock"
            assert not stop.is_set()
        assert stop.wait(5)  # set as soon as the lock is free
    finally:
        for number, previous in saved.items():
            signal.signal(number, previous)



def test_terminate_as_interrupt_raises_keyboard_interrupt_then_restores_the_handler():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt):
        with terminate_as_interrupt():
            assert signal.getsignal(signal.SIGTERM) is signal.default_int_handler
            signal.raise_signal(signal.SIGTERM)  # (its handler runs before this returns)
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_sigint_inherited_as_ignored_interrupts_the_block_and_is_ignored_again_after():
    # (balltrack experiment started in the background by a script: kill -INT did nothing)
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with pytest.raises(KeyboardInterrupt):
            with terminate_as_interrupt():
                signal.raise_signal(signal.SIGINT)
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


class InterruptedDestructor:
    """An object whose destructor is interrupted: Python reports that and goes on."""

    def __del__(self):
        raise KeyboardInterrupt


def test_an_interrupt_that_python_swallows_is_raised_again_in_the_block():
    before, alarm_before = sys.unraisablehook, signal.getsignal(signal.SIGALRM)
    with pytest.raises(KeyboardInterrupt):
        with terminate_as_interrupt():
            InterruptedDestructor()  # (dropped at once: its interrupt goes to sys.unraisablehook)
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                time.sleep(0.01)
    assert sys.unraisablehook is before
    assert signal.getsignal(signal.SIGALRM) is alarm_before


LATE_STOP = """
import os, signal, sys
from balltrack.common.shutdown import ignore_stop_signals, stop_on_signals

stop = stop_on_signals()


class Late:
    def __del__(self):  # (run as the interpreter clears its modules: Python's handlers are gone)
        # (a signal a process sends itself is acted on before kill returns: a default
        # SIGTERM ends it there, an ignored one is dropped)
        os.kill(os.getpid(), signal.SIGTERM)


late = Late()
if sys.argv[1] == "ignore":
    ignore_stop_signals()
sys.exit(3)
"""


@pytest.mark.parametrize("ignoring, status", [("ignore", 3), ("no", -signal.SIGTERM)])
def test_a_stop_while_the_interpreter_shuts_down_keeps_the_status_once_ignored(ignoring, status):
    # (balltrack detect, SIGTERM in the tenth of a second after its last image: status 143)
    finished = subprocess.run([sys.executable, "-c", LATE_STOP, ignoring], capture_output=True, timeout=60)
    assert finished.returncode == status, finished.stderr


@pytest.mark.parametrize("signal_name", ["SIGTERM", "SIGINT"])
def test_a_stop_while_a_service_imports_its_code_sets_its_event_once_it_has_one(signal_name):
    # (it killed the process, status 143, or with SIGINT inherited as ignored was lost)
    script = textwrap.dedent(f"""
        import os, signal
        from balltrack.common.shutdown import catch_early_stops, stop_on_signals
        catch_early_stops()
        os.kill(os.getpid(), signal.{signal_name})
        print(stop_on_signals().wait(5))
    """)
    ignored = signal.SIG_IGN if signal_name == "SIGINT" else signal.SIG_DFL
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                            cwd=REPO, env=process_environment(),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, ignored))
    assert (result.returncode, result.stdout) == (0, "True\n"), result.stderr
