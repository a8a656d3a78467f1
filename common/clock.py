"""Time sources: wall time by default, simulation time from ``clock`` with use_sim_time.

As in ROS, a node with ``use_sim_time`` reads time only from the simulator's clock messages,
so its timeouts and timers follow simulated time (a paused or slowed simulation pauses them
too). Times are integer nanoseconds on the wire; ``now()`` gives float seconds for cores.
"""

import threading
import time
from typing import Callable

# A wait on the wall clock whose length a setting changed live may alter (a timer's period, a
# camera's rate, a simulator's real-time factor) reads it again at least this often, so that
# the change applies within it, not after the old wait has run out.
TIMER_SLICE_S = 0.5


def wait_out(stop: threading.Event, remaining: Callable[[], float]) -> bool:
    """Wait until ``remaining()`` (seconds, read again at least every TIMER_SLICE_S) is no
    longer positive; True when ``stop`` was set first."""
    while (left := remaining()) > 0:
        if stop.wait(min(left, TIMER_SLICE_S)):
            return True
    return stop.is_set()


class WallClock:
    is_sim = False

    def now_ns(self) -> int:
        return time.time_ns()

    def now(self) -> float:
        return self.now_ns() / 1e9

    def has_time(self) -> bool:
        return True


class SimClock:
    """Time last published on ``clock``; 0 until the first message, as in ROS."""

    is_sim = True

    def __init__(self):
        self._stamp_ns = 0
        self._updates = 0
        self._received = False
        self._changed = threading.Condition()

    def update(self, stamp_ns: int) -> None:
        with self._changed:
            self._stamp_ns = int(stamp_ns)
            self._updates += 1
            self._received = True
            self._changed.notify_all()

    def now_ns(self) -> int:
        return self._stamp_ns

    def now(self) -> float:
        return self._stamp_ns / 1e9

    def has_time(self) -> bool:
        return self._received

    def wait_for_update(self, seen_updates: int, timeout: float) -> tuple[int, int]:
        """Block until a clock message newer than update number ``seen_updates`` has arrived
        (or ``timeout`` wall seconds pass); returns (update number, stamp in ns)."""
        with self._changed:
            self._changed.wait_for(lambda: self._updates != seen_updates, timeout)
            return self._updates, self._stamp_ns


def make_clock(use_sim_time: bool):
    return SimClock() if use_sim_time else WallClock()


class TimerTicks:
    """When a timer on simulated time fires: on the first clock, on a clock at or past the next
    whole multiple of the period, and when the clock went back (a simulation reset).

    Ticks on whole multiples let a lockstep simulator predict which frames owe a command; it
    uses this same class, so the rule cannot drift apart. Integer nanoseconds with a 1 us
    tolerance keep float rounding from moving a tick by a frame.
    """

    TOLERANCE_NS = 1_000

    def __init__(self):
        self.next_tick_ns: int | None = None

    def reset(self) -> None:
        """A new timer (e.g. a follower that just started): it fires on the next clock."""
        self.next_tick_ns = None

    def fires(self, stamp_ns: int, period: float) -> bool:
        period_ns = max(1, round(period * 1e9))
        due = (self.next_tick_ns is None or stamp_ns >= self.next_tick_ns - self.TOLERANCE_NS
               or stamp_ns < self.next_tick_ns - 2 * period_ns)
        if due:
            self.next_tick_ns = ((stamp_ns + self.TOLERANCE_NS) // period_ns + 1) * period_ns
        return due
