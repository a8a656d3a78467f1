"""The one polling loop, for conditions that have no event to wait on: a file another process
rewrites, a pid that is not our child, a log, a Zenoh matching status.

Example::

    from balltrack.common.waiting import poll_until

    status = poll_until(lambda: read_status(run_dir), timeout=30.0)
    if status is None:
        ...  # not there in 30 s
"""

import threading
import time
from typing import Callable, TypeVar

T = TypeVar("T")
# How often a condition is read again by default: what is polled changes on a scale of tens of
# milliseconds (a status file rewritten, a process starting), and the deadline, not the
# interval, bounds the wait.
POLL_INTERVAL = 0.05


def poll_until(condition: Callable[[], T], timeout: float, interval: float = POLL_INTERVAL,
               stop: threading.Event | None = None) -> T | None:
    """``condition()``'s first truthy value, read every ``interval`` seconds (and once more at
    the deadline); None when ``timeout`` seconds pass first, or as soon as ``stop`` is set (a
    Ctrl-C while waiting). An exception from ``condition`` ends the wait (a way to give up
    early: the process being waited for has exited)."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if result:
            return result
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return None
        if stop is None:
            time.sleep(min(interval, remaining))
        elif stop.wait(min(interval, remaining)):
            return None
