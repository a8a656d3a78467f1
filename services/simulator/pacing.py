"""How the simulator service paces its frames: wall deadlines, lockstep waits, the achieved rate.

Pure helpers (threading and arithmetic, no Zenoh), used by :mod:`services.simulator.service`:

* :class:`RealtimePacer`: the wall time at which a frame is due in ``realtime`` pacing, and
  when to start making it (:class:`WorkEstimate`: how long making one takes).
* :class:`TimerTicks` (from common.clock): which clock values make the follower's timer fire.
* :class:`LockstepGate`: what the frame loop waits for in ``lockstep`` pacing (the detector's
  answer to a frame, the follower's command of a tick), fed by subscriber callbacks; one per
  robot, and :func:`wait_together` waits for several robots' under one deadline.
* :class:`RateMeter`: the real-time factor actually reached.
"""

import collections
import threading
import time
from typing import Callable

from balltrack.common.clock import TimerTicks


class RealtimePacer:
    """Frame at simulated time ``t`` is due at ``start + (t - t_start) / real_time_factor``.

    A frame that is late is published at once; when the loop falls more than one frame behind
    (an overloaded machine), the schedule restarts from now instead of bursting to catch up,
    so simulated time slows down rather than running in jumps.
    """

    def __init__(self):
        self._anchor: tuple[float, float, float] | None = None  # (wall, sim, factor)
        self.slips = 0

    def reset(self) -> None:
        self._anchor = None

    def start_delay(self, sim_time: float, factor: float, now: float, lead: float) -> float:
        """Wall seconds to wait before starting to make the frame at ``sim_time`` so that it is
        ready ``lead`` seconds before it is due (0 when already that close, or with no schedule
        yet). Unlike :meth:`delay` it neither anchors the schedule nor counts slips."""
        if self._anchor is None or self._anchor[2] != factor or sim_time < self._anchor[1]:
            return 0.0
        wall, start, _ = self._anchor
        return max(0.0, wall + (sim_time - start) / factor - now - lead)

    def delay(self, sim_time: float, factor: float, period: float, now: float) -> float:
        """Wall seconds to wait before publishing the frame at ``sim_time`` (0 when due)."""
        if self._anchor is None or self._anchor[2] != factor or sim_time < self._anchor[1]:
            self._anchor = (now, sim_time, factor)
            return 0.0
        wall, start, _ = self._anchor
        remaining = wall + (sim_time - start) / factor - now
        if remaining < -period / factor:
            self.slips += 1
            self._anchor = (now, sim_time, factor)
            return 0.0
        return max(0.0, remaining)


class WorkEstimate:
    """A high percentile of how long recent frames took to make (step and render), the lead
    with which a realtime frame is started before it is due."""

    def __init__(self, window: int = 100, quantile: float = 0.9, margin: float = 0.002):
        self._seconds: collections.deque = collections.deque(maxlen=window)
        self._quantile, self._margin = quantile, margin

    def add(self, seconds: float) -> None:
        self._seconds.append(seconds)

    def lead(self) -> float:
        if not self._seconds:
            return self._margin
        ordered = sorted(self._seconds)
        return ordered[min(len(ordered) - 1, int(self._quantile * len(ordered)))] + self._margin


class LockstepGate:
    """Shared state between subscriber callbacks and the frame loop, with bounded waits.

    A wait ends when its condition holds, when the peer it waits for is no longer alive, when
    ``stop`` is set, or at the timeout; only the timeout returns False (counted in ``timeouts``).
    """

    def __init__(self, stop: threading.Event):
        self._stop = stop
        self._changed = threading.Condition()
        self._alive: set[str] = set()
        self._arrivals: collections.Counter = collections.Counter()
        self._ticks = TimerTicks()
        self._follower_seen = 0
        self.timeouts = 0
        self._answered_seq: int | None = None
        self._command_time: int | None = None

    def set_alive(self, service: str, alive: bool) -> None:
        with self._changed:
            if alive and service not in self._alive:
                self._arrivals[service] += 1
            (self._alive.add if alive else self._alive.discard)(service)
            self._changed.notify_all()

    def alive(self, service: str) -> bool:
        with self._changed:
            return service in self._alive

    def follower_fires(self, stamp_ns: int, period: float) -> bool:
        """Whether a live follower's timer fires on the clock ``stamp_ns`` just published
        (call once per clock). A follower that (re)appeared is a new timer."""
        with self._changed:
            if "follower" not in self._alive or self._arrivals["follower"] != self._follower_seen:
                self._follower_seen = self._arrivals["follower"]
                self._ticks.reset()
            return "follower" in self._alive and self._ticks.fires(stamp_ns, period)

    def answered(self, seq: int) -> None:
        with self._changed:
            self._answered_seq = seq
            self._changed.notify_all()

    def commanded(self, time_ns: int) -> None:
        with self._changed:
            self._command_time = time_ns
            self._changed.notify_all()

    def wake(self) -> None:
        """Re-check the waits now (after ``stop`` was set)."""
        with self._changed:
            self._changed.notify_all()

    def wait_answer(self, seq: int, timeout: float | Callable[[], float]) -> bool:
        return self._wait("detector", lambda: self._answered_seq == seq, timeout)

    def wait_command(self, time_ns: int, timeout: float | Callable[[], float]) -> bool:
        return self._wait("follower", lambda: self._command_time == time_ns, timeout)

    def _wait(self, service: str, done: Callable[[], bool], timeout: float | Callable[[], float]) -> bool:
        """``timeout``: seconds from the start of the wait, or a function giving them, read again
        in every slice (``lockstep_timeout`` changed live applies to the wait under way)."""
        started = time.monotonic()
        limit = timeout if callable(timeout) else (lambda: timeout)
        with self._changed:
            while not (done() or service not in self._alive or self._stop.is_set()):
                remaining = started + limit() - time.monotonic()
                if remaining <= 0:
                    self.timeouts += 1
                    return False
                # Bounded slices: a stop from a signal handler does not notify the condition.
                self._changed.wait(min(remaining, 0.1))
        return True


def wait_together(waits: list[Callable[[Callable[[], float]], bool]],
                  timeout: Callable[[], float]) -> int:
    """Run one frame's lockstep waits of several robots (each a ``LockstepGate`` wait given its
    timeout) one after the other under one deadline, ``timeout()`` wall seconds from the start,
    so a frame waits at most as long with many robots as with one. Returns how many timed out."""
    started = time.monotonic()
    missed = 0
    for wait in waits:
        spent = time.monotonic() - started
        missed += not wait(lambda spent=spent: timeout() - spent)
    return missed


class RateMeter:
    """Simulated seconds per wall second over the last ``window`` wall seconds."""

    def __init__(self, window: float = 5.0):
        self.window = window
        self._samples: collections.deque = collections.deque()
        self._lock = threading.Lock()

    def add(self, wall: float, sim_time: float) -> None:
        with self._lock:
            self._samples.append((wall, sim_time))
            while len(self._samples) > 2 and wall - self._samples[1][0] >= self.window:
                self._samples.popleft()

    def factor(self) -> float:
        with self._lock:
            if len(self._samples) < 2:
                return 0.0
            (wall_0, sim_0), (wall_1, sim_1) = self._samples[0], self._samples[-1]
        return (sim_1 - sim_0) / (wall_1 - wall_0) if wall_1 > wall_0 else 0.0

    def frames_per_second(self) -> float:
        with self._lock:
            if len(self._samples) < 2:
                return 0.0
            span = self._samples[-1][0] - self._samples[0][0]
            return (len(self._samples) - 1) / span if span > 0 else 0.0
