"""Commands that watch keys, as ``ros2 topic`` does: echo, hz.

Each works in a pipe (``balltrack echo detected_ball_3d | head -3`` prints three lines and exits
0) and stops within a second on SIGINT or SIGTERM.
"""

import json
import threading
import time

from balltrack.cli.output import Output, silence_closed_stdout
from balltrack.cli.session import networked, open_or_report
from balltrack.common.keys import Keys
from balltrack.common.messages import SCHEMAS, MessageError, decode
from balltrack.common.shutdown import stop_on_signals

POLL_SECONDS = 0.2  # how often a waiting command looks at its stop event


def printable(value):
    """A message with its bytes shown as their size (images would flood the terminal)."""
    if isinstance(value, (bytes, bytearray)):
        return f"<{len(value)} bytes>"
    if isinstance(value, dict):
        return {key: printable(item) for key, item in value.items()}
    if isinstance(value, list):
        return [printable(item) for item in value]
    return value


def _watch(args, on_sample, report=None, period: float = POLL_SECONDS) -> int:
    """Subscribe to ``args.key`` until stopped; ``report()`` runs every ``period`` seconds."""
    stop = stop_on_signals()
    session = open_or_report(args)
    if session is None:
        return 1
    out = Output(stop)
    try:
        subscriber = session.declare_subscriber(Keys(args.namespace)(args.key),
                                                lambda sample: on_sample(sample, out))
        while not stop.wait(period):
            if report is not None:
                report(out)
        subscriber.undeclare()
    finally:
        session.close()
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
    arrivals: list[float] = []
    lock = threading.Lock()
    reports = [0]
    key = Keys(args.namespace)(args.key)

    def on_sample(_sample, _out):
        with lock:
            arrivals.append(time.monotonic())

    def report(out: Output):
        now = time.monotonic()
        with lock:
            recent = [t for t in arrivals if t >= now - args.window]
            arrivals[:] = recent
        rate = (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 1 else 0.0
        out.line(f"{key}: {rate:.2f} Hz ({len(recent)} messages in {args.window:.1f} s)")
        reports[0] += 1
        if args.count and reports[0] >= args.count:
            out.stop.set()

    return _watch(args, on_sample, report, period=args.window)


def register(commands) -> None:
    echo = networked(commands, "echo", "print decoded messages of a key", command_echo)
    echo.add_argument("key")
    echo.add_argument("--count", type=int, default=0, help="stop after N messages")
    echo.add_argument("--type", choices=sorted(SCHEMAS),
                      help="message type (default: from the key table)")
    hz = networked(commands, "hz", "measure the rate of a key", command_hz)
    hz.add_argument("key")
    hz.add_argument("--window", type=float, default=2.0, help="seconds per report")
    hz.add_argument("--count", type=int, default=0, help="stop after N reports")
