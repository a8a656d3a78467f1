#!/usr/bin/env python3
"""Where is the ball? Subscribe to balltrack's ``detected_ball_3d`` from your own program.

    python examples/subscribe_ball3d.py                                   # the local router
    python examples/subscribe_ball3d.py --connect tcp/192.168.1.10:7447 --namespace robot1

Copy this file anywhere: it needs only ``pip install eclipse-zenoh msgpack``. Every balltrack
message is one msgpack map; a Ball3D (published by the locator for each detected ball) is::

    {"header": {"stamp": <capture time, ns>, "frame_id": "camera_optical", "seq": <frame number>},
     "x": <m, right>, "y": <m, down>, "z": <m, forward>, "distance": <m>}

in the camera's optical frame. By default the fields are read as they come (a missing one
raises KeyError, reported and skipped). With ``--validate``, and balltrack importable (run
from the repository or ``pip install -e .``), each message goes through
``common.messages.decode("Ball3D", ...)``: the services' own check of types, ranges and finite
numbers, which rejects a bad message with a one-line reason.
"""

import argparse
import json
import os
import signal
import sys
import threading

import msgpack
import zenoh


class ArgumentParser(argparse.ArgumentParser):
    def error(self, message: str):  # the reason in one line, not the usage block
        self.exit(2, f"{self.prog}: {message}\n")


def count(text: str) -> int:
    if not text.isdigit():
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return int(text)


def printed(line: str) -> bool:
    """Print ``line``; False when the reader of our output has gone (``| head``): stdout then
    points at /dev/null, so that the flush at exit does not fail again."""
    try:
        print(line, flush=True)
        return True
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return False


def zenoh_reason(error: Exception) -> str:
    """The first line of a Zenoh error, without the Rust source location it ends with or the
    wrapping of a configuration error (``Json5Err(Message { msg: "...``). A short cousin of
    ``balltrack.common.session.zenoh_reason``: this file imports only zenoh and msgpack."""
    line = (str(error).strip().splitlines() or [repr(error)])[0].split(" at /")[0]
    return line.split('msg: "', 1)[-1].rstrip('"')


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description="print the ball's 3D position")
    parser.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="router endpoint, repeatable (default tcp/127.0.0.1:7447)")
    parser.add_argument("--namespace", default="", help="the robot's key prefix, e.g. robot1")
    parser.add_argument("--count", type=count, default=0, help="stop after N messages (0: never)")
    parser.add_argument("--validate", action="store_true",
                        help="check each message with balltrack's common.messages")
    args = parser.parse_args(argv)

    if args.validate:
        from balltrack.common.messages import decode

        def read(payload: bytes) -> dict:
            return decode("Ball3D", payload)  # raises common.messages.MessageError (a ValueError)
    else:
        def read(payload: bytes) -> dict:
            return msgpack.unpackb(payload, raw=False)

    # A client of the router, as the balltrack services are; no multicast discovery.
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    try:
        config.insert_json5("connect/endpoints", json.dumps(args.connect or ["tcp/127.0.0.1:7447"]))
    except zenoh.ZError as error:  # not an endpoint (tcp/HOST:PORT)
        parser.error(f"--connect {' '.join(args.connect)}: {zenoh_reason(error)}")
    config.insert_json5("scouting/multicast/enabled", "false")
    key = f"{args.namespace.strip('/')}/detected_ball_3d" if args.namespace.strip("/") else "detected_ball_3d"

    stop = threading.Event()
    received = [0]

    def on_sample(sample) -> None:
        try:
            ball = read(sample.payload.to_bytes())
            line = (f"seq {ball['header']['seq']:>6}  x {ball['x']:+.3f}  y {ball['y']:+.3f}  "
                    f"z {ball['z']:.3f}  distance {ball['distance']:.3f} m")
        except (ValueError, KeyError, TypeError) as error:
            print(f"skipped a bad message: {error!r}", file=sys.stderr, flush=True)
            return
        if not printed(line):
            stop.set()  # nobody reads on: stop as if asked to
            return
        received[0] += 1
        if args.count and received[0] >= args.count:
            stop.set()

    # Ctrl-C (SIGINT) or SIGTERM: leave the loop, close the session, exit 0. The event is set
    # from a short thread: the handler interrupts the main thread, which may be holding the
    # event's own lock inside stop.wait(), where stop.set() would wait for ever.
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, lambda *_: threading.Thread(target=stop.set, daemon=True).start())
    try:
        session = zenoh.open(config)
    except Exception as error:  # no router at that endpoint
        print(f"cannot reach a router at {', '.join(args.connect or ['tcp/127.0.0.1:7447'])}: "
              f"{zenoh_reason(error)}", file=sys.stderr)
        return 1
    subscriber = session.declare_subscriber(key, on_sample)
    # (on stderr: stdout holds only the positions, for a pipe or a file)
    print(f"listening on {key} (Ctrl-C to stop)", file=sys.stderr, flush=True)
    while not stop.wait(0.2):
        pass
    subscriber.undeclare()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
