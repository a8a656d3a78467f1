"""The service runner: everything a balltrack service does besides its own work.

``run_service`` parses the shared options, loads the config (a bad one exits 2 with one
line), opens the session, declares the liveliness token ``alive/<service>``, publishes
``<service>/stats`` at 1 Hz, answers ``<service>/config`` (read, change parameters live, or
``{"describe": true}`` for their declarations), and stops on SIGINT/SIGTERM by setting one
event, closing the session explicitly, exit 0.

A service module only says what it subscribes to and publishes::

    def build(service: ServiceContext):
        out = service.publisher(keys.DETECTED_BALL_3D, "Ball3D")
        service.subscribe(keys.DETECTED_BALL, "Ball2D", lambda ball: out.put(...))

    def main(argv=None):
        return run_service("locator", LocatorConfig, build, argv, __doc__)
"""

import argparse
import collections
import logging
import os
import sys
import threading
import time
import traceback
from typing import Any, Callable

import numpy as np
import zenoh

from balltrack.common import keys as key_table
from balltrack.common.clock import SimClock, TimerTicks, WallClock
from balltrack.common.config import (ConfigError, config_to_dict, describe_config, help_text, load_config,
                                     replace_config, settings_by_service)
from balltrack.common.keys import PROCESS_JOIN, Keys
from balltrack.common.messages import MessageError, decode, encode, shorten
from balltrack.common.session import (ArgumentParser, SessionOpenError, add_session_arguments, close_session,
                                      open_from_args, peer_conflict)
from balltrack.common.shutdown import stop_on_signals

LOG_FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"
# Samples Zenoh holds for ``subscribe_latest``'s worker while it is busy (RingChannel: when
# full, the oldest goes, uncounted): a call would have to last as long as this many frames of
# the camera (0.27 s at 30 Hz) to lose one from ``dropped``. The worker's direct wake-up served
# frames ~0.2 ms sooner than a hand-over from a callback (demo, frame -> detected_ball p50 3.7
# and 3.7 ms against 3.9 and 3.9, two runs each).
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
        with self._lock:
            durations = np.array(self._durations) if self._durations else np.zeros(1)
            figures = {"service": self.service, "stamp": int(stamp_ns),
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
                 stop: threading.Event | None = None):
        self.name = name
        self.session = session
        self.keys = Keys(namespace)
        self.stats = Stats(name)
        self.stop = stop or threading.Event()
        self.log = logging.getLogger(name)
        self.rejections = RateLimitedLog(self.log)
        self._config = config
        self._config_listeners: list[Callable[[Any], None]] = []
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
        new_config = replace_config(self._config, changes)
        if getattr(new_config, "use_sim_time", None) != getattr(self._config, "use_sim_time", None):
            raise ConfigError("use_sim_time: can only be set at start")
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
        """
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
                self.stats.count("received", arrived)
                if arrived > 1:
                    self.stats.count("dropped", arrived - 1)
                self.process(full_key, message_name, sample.payload.to_bytes(), handler, True)

        self.start_thread(worker, f"{self.name}-{key}")

    def start_thread(self, target: Callable[[], None], name: str) -> None:
        """A worker that must return soon after ``stop`` is set; joined before the session closes
        (a thread still inside native code at interpreter exit aborts the process)."""
        thread = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(thread)
        thread.start()

    def release_waiting(self) -> None:
        """Undeclare the subscribers whose workers wait in their ``recv`` (``subscribe_latest``):
        the wait ends with an error, and the worker returns once done with a sample in hand."""
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
            next_tick = time.monotonic()
            while not self.stop.is_set():
                run(callback)
                next_tick = max(next_tick + period(), time.monotonic() - period())
                self.stop.wait(max(0.0, next_tick - time.monotonic()))

        loop = sim_loop if isinstance(self.clock, SimClock) else wall_loop
        self.start_thread(loop, f"{self.name}-timer")


def _serve_config(context: ServiceContext, query) -> None:
    """Answer one ``<service>/config`` query; every request gets a reply, a bad one ``ok:
    false`` with a short reason (counted and logged, rate-limited, like a rejected message)."""
    key = context.keys(key_table.config_key(context.name))
    try:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        request = decode("ConfigRequest", payload) if payload else {}
        if request.get("set"):
            context.set_config(request["set"])
            context.log.info("config changed: %s", shorten(request["set"], 300))
        reply = {"ok": True, "config": config_to_dict(context.config)}
        if request.get("describe"):
            reply["parameters"] = describe_config(type(context.config))
    except (MessageError, ConfigError) as error:
        reply = {"ok": False, "error": shorten(str(error), 300)}
    except Exception as error:  # e.g. a value too deep to format: still an answer, not silence
        reply = {"ok": False, "error": f"bad request ({shorten(error, 300)})"}
    if not reply["ok"]:
        context.reject(key, reply["error"])
    try:
        answer = encode("ConfigReply", reply)
    except MessageError as error:  # our own reply is invalid: say so rather than stay silent
        context.log.error("config reply not encodable: %s", shorten(str(error)))
        answer = encode("ConfigReply", {"ok": False, "error": "internal error: reply not encodable"})
    query.reply(query.key_expr, answer)


def build_parser(name: str, description: str | None, config_class=None) -> argparse.ArgumentParser:
    """The service's options; with ``config_class``, ``--help`` ends with every parameter."""
    parser = ArgumentParser(prog=f"balltrack run {name}", description=description,
                            epilog=help_text(config_class) if config_class else None,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    add_session_arguments(parser, role=name, peer=True)
    parser.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    return parser


def run_service(name: str, config_class, build: Callable[[ServiceContext], Callable | None],
                argv: list[str] | None = None, description: str | None = None) -> int:
    """Run a service until SIGINT/SIGTERM. ``build`` declares its keys and may return a
    blocking ``loop(context)`` to run in the main thread (it must return once ``stop`` is set)."""
    parser = build_parser(name, description, config_class)
    args = parser.parse_args(argv)
    conflict = peer_conflict(args)
    if conflict:
        parser.error(conflict)
    logging.basicConfig(level=args.log_level, format=LOG_FORMAT, stream=sys.stderr)
    try:
        config = load_config(config_class, args.config, args.overrides, section=name)
        Keys(args.namespace)
    except (ConfigError, ValueError) as error:
        print(f"{name}: {error}", file=sys.stderr)
        return 2
    return serve(name, args, [(name, config, build)])


def run_services(services: list[tuple[str, Any, Callable[[ServiceContext], Callable | None]]],
                 argv: list[str] | None = None, description: str | None = None) -> int:
    """Run several services in one process, on one session, until SIGINT/SIGTERM
    (``balltrack run detector+locator``): ``services`` are (name, config class, build), each
    as ``run_service`` takes them. A message from one to another is then a call in this
    process (Zenoh delivers a put to its own session's subscribers at once), not a hop to
    another process that must wake up; every key and message stays as it is, for anyone else."""
    names = [name for name, _, _ in services]
    label = PROCESS_JOIN.join(names)
    parser = ArgumentParser(prog=f"balltrack run {label}", description=description,
                            epilog="Each service's parameters, given here as --set SERVICE.NAME=VALUE or in "
                                   "the file of --config SERVICE=FILE:\n\n"
                                   + "\n\n".join(f"{name} {help_text(config_class)}" for name, config_class, _ in services),
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    add_session_arguments(parser, config_file=False, role=label, peer=True)
    parser.add_argument("--config", action="append", default=[], metavar="SERVICE=FILE", dest="configs",
                        help="a service's TOML parameter file, repeatable")
    parser.add_argument("--set", action="append", default=[], metavar="SERVICE.KEY=VALUE",
                        dest="overrides", help="override a service's parameter, repeatable")
    parser.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    args = parser.parse_args(argv)
    if args.secure:
        parser.error("--secure: a secure setup gives each service its own certificate and role; "
                     "run these services as processes of their own")
    conflict = peer_conflict(args)
    if conflict:
        parser.error(conflict)
    logging.basicConfig(level=args.log_level, format=LOG_FORMAT, stream=sys.stderr)
    try:
        files: dict[str, str] = {}
        for item in args.configs:
            service, separator, path = item.partition("=")
            if not separator or service not in names:
                raise ConfigError(f"--config {item}: expected SERVICE=FILE, SERVICE one of {', '.join(names)}")
            files[service] = path
        overrides = settings_by_service(args.overrides, names, f"this process's {', '.join(names)}")
        configs = [load_config(config_class, files.get(name), overrides[name], section=name)
                   for name, config_class, _ in services]
        Keys(args.namespace)
    except (ConfigError, ValueError) as error:
        print(f"{label}: {error}", file=sys.stderr)
        return 2
    return serve(label, args, [(name, config, build) for (name, _, build), config in zip(services, configs)])


def serve(label: str, args, services: list[tuple[str, Any, Callable[[ServiceContext], Callable | None]]]) -> int:
    """Open the session of ``args`` and run ``services`` ((name, config, build) each) on it
    until SIGINT/SIGTERM: one process, one session, each service with its own context (stats,
    config queryable, liveliness token) as if it ran alone. ``label`` names the process in
    its messages. Every ``loop`` a build returns runs (the last in the main thread)."""
    # The session opens in a thread so that SIGINT/SIGTERM while the router is still
    # unreachable ends the service at once with status 0, as when it is running.
    stop = stop_on_signals()
    opened: dict[str, Any] = {}

    def open_session():
        try:
            opened["session"] = open_from_args(args)
        except SessionOpenError as error:
            opened["error"] = error
        opened["done"] = True

    threading.Thread(target=open_session, name=f"{label}-open", daemon=True).start()
    while "done" not in opened and not stop.wait(0.1):
        pass
    if "error" in opened:
        print(f"{label}: {opened['error']}", file=sys.stderr)
        return 1
    if "session" not in opened:
        logging.getLogger(label).info("stopped before a router answered")
        os._exit(0)  # nothing to close; the opening thread is inside Zenoh and cannot be joined
    session = opened["session"]

    contexts = [ServiceContext(name, session, args.namespace, config, stop) for name, config, _ in services]
    status = 0
    try:
        loops = []
        tokens = []
        for context, (_, _, build) in zip(contexts, services):
            loop = build(context)
            if loop is not None:
                loops.append((context, loop))
            tokens.append(_announce(context))
        for context, loop in loops[:-1]:
            context.start_thread(lambda context=context, loop=loop: loop(context), f"{context.name}-loop")
        if loops:
            loops[-1][1](loops[-1][0])
        # A timed wait keeps the main thread responsive to signals on every platform.
        while not stop.wait(0.5):
            pass
        for token in tokens:
            token.undeclare()
    except (ConfigError, ValueError) as error:
        print(f"{label}: {error}", file=sys.stderr)
        status = 2
    finally:
        stop.set()
        for context in reversed(contexts):
            context.release_waiting()
            context.join_threads()
            for entity in reversed(context._declared):
                try:
                    entity.undeclare()
                except Exception:
                    pass
        reason = close_session(session)
        if reason:
            logging.getLogger(label).warning("%s", reason)
    for context in contexts:
        context.log.info("stopped")
    return status


def _announce(context: ServiceContext):
    """Publish a built service's stats at 1 Hz, answer its config queries and declare it
    alive; returns its liveliness token."""
    name = context.name
    stats_publisher = context.session.declare_publisher(context.keys(key_table.stats_key(name)))
    context._declared.append(stats_publisher)
    context._declared.append(context.session.declare_queryable(
        context.keys(key_table.config_key(name)), lambda query: _serve_config(context, query)))
    token = context.session.liveliness().declare_token(context.keys(key_table.alive_key(name)))

    def publish_stats():
        while not context.stop.wait(1.0):
            stats_publisher.put(encode("Stats", context.stats.snapshot(time.time_ns())))

    context.start_thread(publish_stats, f"{name}-stats")
    context.log.info("running (namespace %r)", context.keys.namespace)
    return token
