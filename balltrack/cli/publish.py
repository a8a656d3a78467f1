"""``balltrack pub KEY MESSAGE [--rate R]``: publish a message written as YAML or JSON.

    balltrack pub cmd_vel '{linear: [0.1, 0, 0], angular: [0, 0, 0.5]}'          # once
    balltrack pub cmd_vel '{"linear": [0, 0, 0], "angular": [0, 0, 0.3]}' --rate 10

The message is validated against the key's schema (or ``--type``) before anything is sent; a
missing ``header`` is filled in (stamp = now, seq counting from 0), as ``ros2 topic pub`` does.
"""

import sys
import time

import yaml

from balltrack.cli.session import close_or_report, networked, open_or_report, refused_for_role
from balltrack.common.arguments import integer, zero_or
from balltrack.common.keys import Keys
from balltrack.common.messages import SCHEMAS, MessageError, encode, header, shorten
from balltrack.common.shutdown import stop_on_signals


def _parse(text: str) -> dict:
    try:
        message = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise MessageError(f"not YAML or JSON ({shorten(str(error).splitlines()[0], 100)})") from None
    if not isinstance(message, dict):
        raise MessageError(f"a message is a map, got {type(message).__name__}")
    return message


def payload_maker(message_name: str, message: dict):
    """``make(seq) -> bytes``; raises MessageError when the message does not validate."""
    try:
        encode(message_name, message)
        return lambda seq: encode(message_name, message)
    except MessageError as error:
        if "header" in message or not str(error).startswith("header:"):
            raise
    # A stamped message written without its header: one is filled in for every send.
    def stamped(seq: int) -> bytes:
        return encode(message_name, {**message, "header": header(time.time_ns(), seq, "")})

    stamped(0)
    return stamped


def command_pub(args) -> int:
    keys = Keys(args.namespace)
    message_name = args.type or keys.message_of(keys(args.key))
    if message_name is None:
        print(f"balltrack pub: {args.key} has no message type in the key table; give --type",
              file=sys.stderr)
        return 2
    try:
        make = payload_maker(message_name, _parse(args.message))
    except MessageError as error:
        print(f"balltrack pub: {message_name}: {error}", file=sys.stderr)
        return 2
    if refused_for_role(args, "puts", [args.key]):
        return 2
    stop = stop_on_signals()
    session = open_or_report(args, stop)
    if session is None:
        return 1
    try:
        publisher = session.declare_publisher(keys(args.key))
        sent = 0
        next_send = time.monotonic()
        while not stop.is_set():
            publisher.put(make(sent))
            sent += 1
            if args.rate == 0 or (args.count and sent >= args.count):
                break
            next_send += 1.0 / args.rate
            stop.wait(max(0.0, next_send - time.monotonic()))
        publisher.undeclare()
    finally:
        close_or_report(args, session)
    print(f"published {sent} {message_name} on {keys(args.key)}", file=sys.stderr)
    return 0


def register(commands) -> None:
    pub = networked(commands, "pub", "publish a YAML or JSON message (validated) once or at a rate",
                    command_pub)
    pub.add_argument("key")
    pub.add_argument("message", metavar="MESSAGE", help="the message as YAML or JSON")
    pub.add_argument("--type", choices=sorted(SCHEMAS), help="message type (default: from the key table)")
    pub.add_argument("--rate", type=zero_or(0.001, 10_000, "once"), default=0.0, metavar="HZ",
                     help="publish repeatedly at this rate until stopped (default: once)")
    pub.add_argument("--count", type=integer(minimum=0), default=0, help="with --rate: stop after N messages")
