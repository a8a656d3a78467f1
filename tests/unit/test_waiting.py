"""common.waiting.poll_until: the one polling loop."""

import itertools
import threading

import pytest

from balltrack.common.waiting import poll_until


def test_returns_the_first_truthy_value():
    reads = itertools.count()
    assert poll_until(lambda: next(reads) >= 3 and "ready", timeout=60, interval=0.001) == "ready"
    assert next(reads) == 4  # read until it held, not after


def test_none_after_the_timeout_having_read_at_the_deadline_too():
    reads = []
    assert poll_until(lambda: reads.append(1), timeout=0.05, interval=0.01) is None
    assert len(reads) >= 2


def test_an_exception_ends_the_wait():
    def exited():
        raise RuntimeError("the process exited")

    with pytest.raises(RuntimeError, match="exited"):
        poll_until(exited, timeout=60)


def test_a_set_stop_event_ends_the_wait_at_once():
    stop = threading.Event()
    reads = itertools.count()

    def stopped_on_third_read():
        if next(reads) == 2:
            stop.set()
        return False

    assert poll_until(stopped_on_third_read, timeout=60, interval=0.001, stop=stop) is None
    assert next(reads) == 3  # not read again once stop was set
