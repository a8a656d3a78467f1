"""Commands that watch keys, as ``ros2 topic`` does: echo, hz, bw, delay.

Each works in a pipe (``balltrack echo detected_ball_3d | head -3`` prints three lines and exits
0) and stops within a second on SIGINT or SIGTERM.
"""

import json
import statistics
import threading
import time

import msgpack

from balltrack.cli.output import Output
from balltrack.common.terminal import silence_closed_stdout
from balltrack.cli.session import close_or_report, networked, open_or_report
from balltrack.common.arguments import integer, seconds
from balltrack.common import keys as key_table
from balltrack.common.keys import Keys
from balltrack.common.messages import SCHEMAS, MessageError, decode
from balltrack.common.shutdown import stop_on_signals

POLL_SECONDS = 0.2  # how often a waiting command looks at its stop event
# A median delay past this (a day, in ms) says the stamps are on another clock than the wall's:
# the simulator's, which starts at 0.
NOT_WALL_CLOCK_MS = 86_400_000.0


def printable(value):
    """A message with its bytes shown as their size (images would flood the terminal); large
    byte fields come out of ``decode`` as memoryviews of the payload."""
    if isinstance(value, (bytes, bytearray)):
        return f"<{len(value)} bytes>"
    if isinstance(value, memoryview):
        return f"<{value.nbytes} bytes>"
    if isinstance(value, dict):
        return {key: printable(item) for key, item in value.items()}
    if isinstance(value, list):
        return [printable(item) for item in value]
    return value


def _watch(args, on_sample, report=None, period: float = POLL_SECONDS, on_open=None) -> int:
    """Subscribe to ``args.key`` until stopped; ``report()`` runs every ``period`` seconds."""
    stop = stop_on_signals()
    session = open_or_report(args, stop)
    if session is None:
        return 1
    out = Output(stop)
    try:
        if on_open is not None:
            on_open(session)
        subscriber = session.declare_subscriber(Keys(args.namespace)(args.key),
                                                lambda sample: on_sample(sample, out))
        while not stop.wait(period):
            if report is not None:
                report(out)
        subscriber.undeclare()
    finally:
        close_or_report(args, session)
    if out.closed:
        silence_closed_stdout()
    return 0


def command_echo(args) -> int:
    message_name = args.type or Keys(args.namespace).message_of(args.key)
    printed = [0]

    def on_sample(sample, out: Output):
        payload = sample.payload.to_bytes()
        try:
            message = printable(decode(message_name, payload)) if message_name else payload.hex()
        except MessageError as error:
            message = {"error": str(error)}
        if out.line(json.dumps({"key": str(sample.key_expr), "message": message})):
            printed[0] += 1
            if args.count and printed[0] >= args.count:
                out.stop.set()

    return _watch(args, on_sample)


def command_hz(args) -> int:
    key = Keys(args.namespace)(args.key)
    window = Window(args.window)

    def describe(items):
        arrivals = [arrival for arrival, _ in items]
        rate = (len(arrivals) - 1) / (arrivals[-1] - arrivals[0]) if len(arrivals) > 1 else 0.0
        return f"{key}: {rate:.2f} Hz ({len(arrivals)} messages in {args.window:.1f} s)"

    report = _reporter(args, describe)
    return _watch(args, lambda _sample, _out: window.add(0.0), lambda out: report(out, window),
                  period=args.window)


class Window:
    """Per-sample figures of the last ``seconds``, reported and forgotten each period."""

    def __init__(self, seconds: float):
        self.seconds = seconds
        self._items: list[tuple[float, float]] = []
        self._lock = threading.Lock()

    def add(self, value: float) -> None:
        with self._lock:
            self._items.append((time.monotonic(), value))

    def take(self) -> list[tuple[float, float]]:
        now = time.monotonic()
        with self._lock:
            recent = [item for item in self._items if item[0] >= now - self.seconds]
            self._items = []
        return recent


def spread(values: list[float], unit: str, digits: int) -> str:
    """``mean 3.10 ms, min 2.00, max 4.00, std 0.50 (12 messages)``."""
    return (f"mean {statistics.fmean(values):.{digits}f} {unit}, min {min(values):.{digits}f}, "
            f"max {max(values):.{digits}f}, std {statistics.pstdev(values):.{digits}f} "
            f"({len(values)} messages)")


def _reporter(args, describe):
    """A ``report`` for _watch that prints ``describe(window items)`` and honours --count."""
    reports = [0]

    def report(out: Output, window: Window):
        out.line(describe(window.take()))
        reports[0] += 1
        if args.count and reports[0] >= args.count:
            out.stop.set()
    return report


def command_bw(args) -> int:
    key = Keys(args.namespace)(args.key)
    window = Window(args.window)

    def describe(items):
        sizes = [size for _, size in items]
        if not sizes:
            return f"{key}: no messages in {args.window:.1f} s"
        return f"{key}: {sum(sizes) / args.window / 1e3:.1f} kB/s, {spread(sizes, 'B', 0)}"

    report = _reporter(args, describe)
    return _watch(args, lambda sample, _out: window.add(len(sample.payload)),
                  lambda out: report(out, window), period=args.window)


def header_stamp(payload: bytes) -> int | None:
    """The header stamp (ns) of any balltrack data message, or None."""
    try:
        message = msgpack.unpackb(payload, raw=False, max_array_len=1 << 16, max_map_len=1 << 12)
    except Exception:  # any malformed payload simply has no stamp
        return None
    if not isinstance(message, dict):
        return None
    head = message.get("header")
    stamp = head.get("stamp") if isinstance(head, dict) else message.get("stamp")
    return stamp if isinstance(stamp, int) and not isinstance(stamp, bool) else None


def command_delay(args) -> int:
    keys = Keys(args.namespace)
    key = keys(args.key)
    window = Window(args.window)
    sim_now = [None]  # the newest `clock` stamp, with --use-sim-time
    clock_subscription = []

    def now_ns() -> int | None:
        return sim_now[0] if args.use_sim_time else time.time_ns()

    def on_sample(sample, _out):
        stamp = header_stamp(sample.payload.to_bytes())
        now = now_ns()
        if stamp is not None and now is not None:
            window.add((now - stamp) / 1e6)

    def describe(items):
        delays = [delay for _, delay in items]
        if not delays:
            return f"{key}: no stamped messages in {args.window:.1f} s"
        line = f"{key}: delay {spread(delays, 'ms', 2)}"
        if not args.use_sim_time and abs(statistics.median(delays)) > NOT_WALL_CLOCK_MS:
            line += " (the stamps are not wall-clock time: a simulator's? try --use-sim-time)"
        return line

    report = _reporter(args, describe)

    def start_clock(session):
        def on_clock(sample):
            stamp = header_stamp(sample.payload.to_bytes())
            if stamp is not None:
                sim_now[0] = stamp
        clock_subscription.append(session.declare_subscriber(keys(key_table.CLOCK), on_clock))

    return _watch(args, on_sample, lambda out: report(out, window), period=args.window,
                  on_open=start_clock if args.use_sim_time else None)


def register(commands) -> None:
    echo = networked(commands, "echo", "print decoded messages of a key", command_echo)
    echo.add_argument("key")
    echo.add_argument("--count", type=integer(minimum=0), default=0, help="stop after N messages")
    echo.add_argument("--type", choices=sorted(SCHEMAS),
                      help="message type (default: from the key table)")
    hz = networked(commands, "hz", "measure the rate of a key", command_hz)
    hz.add_argument("key")
    hz.add_argument("--window", type=seconds(minimum=0.01), default=2.0, help="seconds per report")
    hz.add_argument("--count", type=integer(minimum=0), default=0, help="stop after N reports")
    for name, help_text, handler in (("bw", "measure a key's bandwidth, as ros2 topic bw", command_bw),
                                     ("delay", "age of a key's header stamps, as ros2 topic delay",
                                      command_delay)):
        sub = networked(commands, name, help_text, handler)
        sub.add_argument("key")
        sub.add_argument("--window", type=seconds(minimum=0.01), default=2.0, help="seconds per report")
        sub.add_argument("--count", type=integer(minimum=0), default=0, help="stop after N reports")
        if name == "delay":
            sub.add_argument("--use-sim-time", action="store_true",
                             help="compare with the newest `clock` message (simulated stamps)")
