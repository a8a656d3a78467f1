"""Time sources: wall time by default, simulation time from ``clock`` with use_sim_time.

As in ROS, a node with ``use_sim_time`` reads time only from the simulator's clock messages,
so its timeouts and timers follow simulated time (a paused or slowed simulation pauses them
too). Times are integer nanoseconds on the wire; ``now()`` gives float seconds for cores.
"""

import threading
import time


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
