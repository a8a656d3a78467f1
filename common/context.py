"""What a service's ``build`` function works with: ``ServiceContext`` (session, keys, config,
stats, clock, stop) and its publishers and subscribers, which decode, validate, count and time
every message; a malformed one is dropped, counted as rejected and logged (rate-limited), and
the next one served. ``runner.py`` opens the session and runs the services built on it.
"""

import collections
import logging
import threading
import time
import traceback
from typing import Any, Callable

import numpy as np
import zenoh

from balltrack.common import keys as key_table
from balltrack.common.clock import SimClock, TimerTicks, WallClock, wait_out
from balltrack.common.config import ConfigError, replace_config
from balltrack.common.keys import Keys
from balltrack.common.latest import LatestSlots
from balltrack.common.messages import MessageError, decode, encode, shorten

# Samples Zenoh holds for ``subscribe_latest``'s worker while it is busy (RingChannel: when
# full, the oldest goes, uncounted): a call would have to last as long as this many frames of
# the camera (0.27 s at 30 Hz) to lose one from ``dropped``. The worker waits on Zenoh's channel
# itself: a hand-over from a callback would add a thread wake-up to every frame's path.
LATEST_RING = 8
# Seconds spent, on this thread, in handlers that the current handler's puts called: with
# several services in one process a put runs a subscriber of the same session at once, and
# each service's processing time is its own (ServiceContext.process).
_NESTED = threading.local()


class RateLimitedLog:
    """Logs a (key, kind) at most once per ``period`` seconds, counting what it held back."""

    # Kinds come from peers' payloads: past this many, every new kind shares one slot per key,
    # so neither the table nor the log grows with what a fuzzer sends.
    MAX_KINDS = 256

    def __init__(self, logger: logging.Logger, period: float = 5.0):
        self.logger = logger
        self.period = period
        self._last: dict[tuple, float] = {}
        self._suppressed: collections.Counter = collections.Counter()
        self._lock = threading.Lock()

    def warning(self, key: str, reason: str, what: str = "rejected message") -> None:
        kind = (key, shorten(reason.split(":")[0], 40))
        now = time.monotonic()
        with self._lock:
            if kind not in self._last and len(self._last) >= self.MAX_KINDS:
                kind = (key, "other")
            if now - self._last.get(kind, -1e9) < self.period:
                self._suppressed[kind] += 1
                return
            self._last[kind] = now
            held_back = self._suppressed.pop(kind, 0)
        suffix = f" ({held_back} similar suppressed)" if held_back else ""
        self.logger.warning("%s on %s: %s%s", what, key, shorten(reason, 300), suffix)


# Stats describe the process (counts, processing times in wall milliseconds, a 1 Hz heartbeat
# that goes on while a simulation is paused), not frames: their ``stamp`` is the wall clock's,
# and every snapshot says so in ``stamp_clock``, for a reader that puts all keys on one timeline.
STATS_CLOCK = "wall"


class Stats:
    """Counters and processing-time percentiles for ``<service>/stats``."""

    def __init__(self, service: str):
        self.service = service
        self.received = self.published = self.rejected = self.dropped = 0
        self._durations = collections.deque(maxlen=1000)
        self._lock = threading.Lock()
        # A service's own figures, added to every snapshot (the Stats schema allows extra fields).
        self.extra: Callable[[], dict] | None = None

    def count(self, field: str, amount: int = 1) -> None:
        with self._lock:
            setattr(self, field, getattr(self, field) + amount)

    def record_duration(self, seconds: float) -> None:
        with self._lock:
            self._durations.append(seconds * 1000.0)

    def snapshot(self, stamp_ns: int) -> dict:
        """The Stats message at wall-clock time ``stamp_ns`` (see STATS_CLOCK)."""
        with self._lock:
            durations = np.array(self._durations) if self._durations else np.zeros(1)
            figures = {"service": self.service, "stamp": int(stamp_ns), "stamp_clock": STATS_CLOCK,
                       "received": self.received, "published": self.published,
                       "rejected": self.rejected, "dropped": self.dropped,
                       "p50_ms": float(np.percentile(durations, 50)),
                       "p99_ms": float(np.percentile(durations, 99))}
        return {**figures, **(self.extra() if self.extra else {})}


class Publisher:
    """Validates, encodes and counts; ``wanted`` tells whether anyone subscribes."""

    def __init__(self, context: "ServiceContext", key: str, message: str, **options):
        self._context = context
        self.key = context.keys(key)
        self.message = message
        self._publisher = context.session.declare_publisher(self.key, **options)

    @property
    def wanted(self) -> bool:
        return self._publisher.matching_status.matching

    def put(self, message: dict) -> None:
        self._publisher.put(encode(self.message, message))
        self._context.stats.count("published")


def in_order(callback: Callable) -> "zenoh.handlers.Callback":
    """Run a subscriber callback on Zenoh's network thread, so one service's callbacks run one
    at a time in arrival order. (zenoh-python's default gives each subscriber its own thread:
    a ``clock`` could then overtake the ``detected_ball`` the router sent before it, and a
    lockstep simulation would not be reproducible.) Callbacks must therefore be short."""
    return zenoh.handlers.Callback(callback, indirect=False)


class ServiceContext:
    """What a service's ``build`` function uses: session, keys, config, stats, clock, stop."""

    def __init__(self, name: str, session, namespace: str, config,
                 stop: threading.Event | None = None, shared_worker: "SharedLatestWorker | None" = None):
        self.name = name
        self.session = session
        self.keys = Keys(namespace)
        self.stats = Stats(name)
        self.stop = stop or threading.Event()
        # Serving several robots, one logger each: which robot a line is about is the news.
        self.log = logging.getLogger(self.keys(name) if shared_worker is not None else name)
        # Serving several robots: the worker that serves every robot's ``subscribe_latest`` in turn.
        self.shared_worker = shared_worker
        self.rejections = RateLimitedLog(self.log)
        self._config = config
        self._config_listeners: list[Callable[[Any], None]] = []
        # The settings a running service applies when changed (its ``<service>/config``); a
        # change to any other is refused, as ROS 2 refuses a read-only parameter: accepted, it
        # would be reported as set and never take effect. None: every setting.
        self.live_settings: set[str] | None = None
        self._declared: list = []
        # Subscribers whose worker waits in their ``recv``: undeclared to let it return.
        self._waited_on: list = []
        self._threads: list[threading.Thread] = []
        self.clock = SimClock() if getattr(config, "use_sim_time", False) else WallClock()
        if isinstance(self.clock, SimClock):
            self.subscribe(key_table.CLOCK, "Clock", lambda tick: self.clock.update(tick["stamp"]),
                           count=False)

    @property
    def config(self):
        return self._config

    def on_config_change(self, listener: Callable[[Any], None]) -> None:
        self._config_listeners.append(listener)

    def set_config(self, changes: dict) -> Any:
        live = "" if self.live_settings is None else f" (live: {', '.join(sorted(self.live_settings))})"

        def start_only(name: str) -> bool:  # (use_sim_time never: the clock is chosen at start)
            return name == "use_sim_time" or self.live_settings is not None and name not in self.live_settings

        try:
            new_config = replace_config(self._config, changes)
        except ConfigError:
            # (a start-only setting that is also invalid with the rest, width=320 without its
            # height: that it cannot be changed here is the news)
            fixed = [name for name in changes if name in vars(self._config) and start_only(name)]
            if fixed:
                raise ConfigError(f"{', '.join(fixed)}: can only be set at start{live}") from None
            raise
        fixed = [name for name in vars(new_config)
                 if start_only(name) and getattr(new_config, name) != getattr(self._config, name)]
        if fixed:
            raise ConfigError(f"{', '.join(fixed)}: can only be set at start{live}")
        self._config = new_config
        for listener in self._config_listeners:
            listener(new_config)
        return new_config

    def publisher(self, key: str, message: str, **options) -> Publisher:
        publisher = Publisher(self, key, message, **options)
        self._declared.append(publisher._publisher)
        return publisher

    def queryable(self, key: str, handler: Callable) -> None:
        """Answer queries on ``key`` (namespaced) with ``handler(query)`` until shutdown."""
        self._declared.append(self.session.declare_queryable(self.keys(key), handler))

    def reject(self, key: str, reason: str) -> None:
        self.stats.count("rejected")
        self.rejections.warning(key, reason)

    def process(self, key: str, message_name: str, payload: bytes, handler, count: bool) -> None:
        """Decode, validate and handle one message; a bad one is rejected (counted, logged).
        The handling time recorded is this service's own: without that of other services'
        handlers that its puts called in this process (``run_services``)."""
        started = time.perf_counter()
        outer_nested = getattr(_NESTED, "seconds", 0.0)
        _NESTED.seconds = 0.0
        try:
            try:
                message = decode(message_name, payload)
                handler(message)
            except MessageError as error:
                self.reject(key, str(error))
                return
            except Exception as error:  # a bug must not kill the service; it is logged loudly
                self.reject(key, f"internal error: {shorten(error)}")
                self.log.debug("%s", traceback.format_exc())
                return
            if count:
                self.stats.record_duration(time.perf_counter() - started - _NESTED.seconds)
        finally:
            # (to the handler that called this one, all of this call is nested time)
            _NESTED.seconds = outer_nested + time.perf_counter() - started

    def subscribe(self, key: str, message_name: str, handler: Callable[[dict], None],
                  count: bool = True):
        """Decode each sample on ``key`` as ``message_name`` and call ``handler`` in order;
        returns the subscriber, for ``unsubscribe``."""
        full_key = self.keys(key)

        def on_sample(sample):
            if count:
                self.stats.count("received")
            self.process(full_key, message_name, sample.payload.to_bytes(), handler, count)

        subscriber = self.session.declare_subscriber(full_key, in_order(on_sample))
        self._declared.append(subscriber)
        return subscriber

    def unsubscribe(self, subscriber) -> None:
        """Undeclare a subscriber that ``subscribe`` returned."""
        self._declared.remove(subscriber)
        subscriber.undeclare()

    def subscribe_latest(self, key: str, message_name: str, handler: Callable[[dict], None]) -> None:
        """Like ``subscribe`` but a worker thread serves only the newest sample: under
        overload stale samples are dropped (counted in ``dropped``), never queued.

        Zenoh keeps what arrives while the worker is busy in a ring of LATEST_RING samples; the
        worker takes them all, serves the newest and counts the others as dropped. It waits
        in Zenoh's own ``recv``, which wakes it directly. (Before, a callback on Zenoh's thread
        handed each sample to it through a ``threading.Condition``: the worker then woke
        only to wait again until that thread let go of the GIL, and served a frame ~0.2 ms
        later, see LATEST_RING.)

        With a ``shared_worker`` (one process serving several robots) that worker serves this
        robot's newest sample in turn with the other robots' instead (``SharedLatestWorker``).
        """
        if self.shared_worker is not None:
            self.shared_worker.subscribe(self, key, message_name, handler)
            return
        full_key = self.keys(key)
        subscriber = self.session.declare_subscriber(full_key, zenoh.handlers.RingChannel(LATEST_RING))
        self._declared.append(subscriber)
        self._waited_on.append(subscriber)
        samples = subscriber.handler

        def worker():
            while True:
                try:
                    sample = samples.recv()
                except zenoh.ZError:  # the subscriber was undeclared: the service stops
                    return
                arrived = 1
                while (newer := samples.try_recv()) is not None:
                    sample, arrived = newer, arrived + 1
                self.serve_newest(full_key, message_name, sample, arrived, handler)

        self.start_thread(worker, f"{self.name}-{key}")

    def serve_newest(self, full_key: str, message_name: str, sample, arrived: int, handler) -> None:
        """Handle ``sample``, the newest of ``arrived`` on ``full_key``: the others are dropped."""
        self.stats.count("received", arrived)
        if arrived > 1:
            self.stats.count("dropped", arrived - 1)
        self.process(full_key, message_name, sample.payload.to_bytes(), handler, True)

    def start_thread(self, target: Callable[[], None], name: str) -> None:
        """A worker that must return soon after ``stop`` is set; joined before the session closes
        (a thread still inside native code at interpreter exit aborts the process)."""
        thread = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(thread)
        thread.start()

    def release_waiting(self) -> None:
        """Undeclare the subscribers whose workers wait in their ``recv`` (``subscribe_latest``):
        the wait ends with an error, and the worker returns once done with a sample in hand.
        A shared worker is stopped and joined here, before any robot's entities go."""
        if self.shared_worker is not None:
            self.shared_worker.close()
        for subscriber in self._waited_on:
            self._declared.remove(subscriber)
            try:
                subscriber.undeclare()
            except Exception:  # (as for every entity at stop; closing the session ends the wait then)
                pass
        self._waited_on.clear()

    def join_threads(self, timeout: float = 5.0) -> None:
        deadline = time.monotonic() + timeout
        for thread in self._threads:
            thread.join(max(0.0, deadline - time.monotonic()))

    def declare(self, entity):
        """Keep a Zenoh entity the service declared itself (a publisher it encodes for), to be
        undeclared by ``close``; returns it."""
        self._declared.append(entity)
        return entity

    def close(self) -> None:
        """Once ``stop`` is set: let waiting workers return, join every thread, then undeclare
        every entity, newest first (errors ignored: the session closes next anyway)."""
        self.release_waiting()
        self.join_threads()
        for entity in reversed(self._declared):
            try:
                entity.undeclare()
            except Exception:
                pass

    def every(self, period: Callable[[], float], callback: Callable[[], None]) -> None:
        """Call ``callback`` every ``period()`` seconds of the service's clock, in a thread.

        On simulated time the ticks fall on whole multiples of the period and happen when a
        ``clock`` message crosses one, so a lockstep simulator knows which frames owe a tick."""

        def run(callback):
            try:
                callback()
            except Exception:
                self.log.error("timer callback failed:\n%s", traceback.format_exc())

        def sim_loop():
            seen_updates, ticks = 0, TimerTicks()
            while not self.stop.is_set():
                updates, now_ns = self.clock.wait_for_update(seen_updates, 0.2)
                if updates != seen_updates:
                    seen_updates = updates
                    if ticks.fires(now_ns, period()):
                        run(callback)

        def wall_loop():
            last_tick = time.monotonic()
            run(callback)
            # (the period is read again while waiting: a rate changed live takes effect within
            # TIMER_SLICE_S, not after the old period has run out)
            while not wait_out(self.stop, lambda: last_tick + period() - time.monotonic()):
                current, now = period(), time.monotonic()
                # (on schedule; more than a period behind, the schedule starts again from now)
                last_tick = last_tick + current if now - last_tick < 2 * current else now
                run(callback)

        loop = sim_loop if isinstance(self.clock, SimClock) else wall_loop
        self.start_thread(loop, f"{self.name}-timer")


class SharedLatestWorker:
    """One worker for one service's ``subscribe_latest`` in every robot a process serves
    (``--namespaces``): each robot's subscriber keeps its newest sample in a slot of its own,
    and the worker serves the slots in turn (``latest.LatestSlots``), counting what a robot's
    slot dropped in that robot's stats. The newest sample per robot, as ``subscribe_latest``
    keeps per key; its Zenoh ring cannot be used here, as a worker waits on one channel only.
    """

    def __init__(self, name: str):
        self.name = name
        self.slots: LatestSlots = LatestSlots()
        # full key -> (the robot's context, message name, handler)
        self._served: dict[str, tuple["ServiceContext", str, Callable]] = {}
        self._thread: threading.Thread | None = None

    def subscribe(self, context: "ServiceContext", key: str, message_name: str, handler: Callable) -> None:
        full_key = context.keys(key)
        self._served[full_key] = (context, message_name, handler)
        self.slots.add(full_key)
        # (on Zenoh's thread, in arrival order: it only fills the slot)
        context.declare(context.session.declare_subscriber(
            full_key, in_order(lambda sample: self.slots.put(full_key, sample))))
        if self._thread is None:
            self._thread = threading.Thread(target=self._work, name=f"{self.name}-shared", daemon=True)
            self._thread.start()

    def _work(self) -> None:
        while (taken := self.slots.take()) is not None:
            context, message_name, handler = self._served[taken.source]
            context.serve_newest(taken.source, message_name, taken.item, taken.arrived, handler)

    def close(self, timeout: float = 5.0) -> None:
        """Stop serving: the worker returns once done with the sample in hand; joined."""
        self.slots.close()
        if self._thread is not None:
            self._thread.join(timeout)
