"""The ``balltrack`` command: a router, offline detection, and ros2-topic-like inspection.

    balltrack router --listen tcp/0.0.0.0:7447
    balltrack detect photo1.jpg photo2.jpg --set param2=20
    balltrack status
    balltrack echo detected_ball_3d --count 5
    balltrack hz camera/image_raw
    balltrack config detector                 # read parameters
    balltrack config detector v_min=30        # change them live
    balltrack sim set_light diffuse=0.1       # drive the simulator
    balltrack experiment range --quick --out runs/range
"""

import argparse
import json
import signal
import sys
import threading
import time

from balltrack.common import keys as key_table
from balltrack.common.config import ConfigError, load_config, parse_overrides
from balltrack.common.keys import Keys
from balltrack.common.messages import SCHEMAS, SIM_OPS, MessageError, decode, encode
from balltrack.common.status import service_status
from balltrack.common.session import (DEFAULT_PORT, ArgumentParser, SessionOpenError, add_session_arguments,
                            first_error_line, open_from_args, router_config)


def _printable(value):
    if isinstance(value, (bytes, bytearray)):
        return f"<{len(value)} bytes>"
    if isinstance(value, dict):
        return {key: _printable(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_printable(item) for item in value]
    return value


def _stop_event() -> threading.Event:
    stop = threading.Event()
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, lambda *_: stop.set())
    return stop


def command_router(args) -> int:
    import zenoh

    listen = args.listen or [f"tcp/0.0.0.0:{DEFAULT_PORT}"]
    try:
        session = zenoh.open(router_config(listen, args.connect, args.zenoh_config))
    except Exception as error:
        print(f"balltrack router: cannot listen on {', '.join(listen)}: {first_error_line(error)}",
              file=sys.stderr)
        return 1
    print(f"router {session.zid()} listening on {', '.join(listen)}", flush=True)
    stop = _stop_event()
    while not stop.wait(0.5):
        pass
    session.close()
    return 0


def command_detect(args) -> int:
    import cv2

    from balltrack.services.detector.config import DetectorConfig
    from balltrack.services.detector.pipeline import BallDetector

    try:
        config = load_config(DetectorConfig, args.config, args.overrides, section="detector")
    except ConfigError as error:
        print(f"balltrack detect: {error}", file=sys.stderr)
        return 2
    detector = BallDetector(config)
    status = 0
    for path in args.images:
        image = cv2.imread(path, cv2.IMREAD_COLOR)
        if image is None:
            print(json.dumps({"file": path, "error": "cannot read image"}), flush=True)
            status = 1
            continue
        detections = detector.detect(image).detections
        balls = [{"u": round(d.u, 2), "v": round(d.v, 2), "radius_px": round(d.radius_px, 2),
                  "score": round(d.score, 3)} for d in detections]
        print(json.dumps({"file": path, "balls": balls}), flush=True)
    return status


def _open(args):
    try:
        return open_from_args(args, open_timeout=args.timeout)
    except SessionOpenError as error:
        print(f"balltrack {args.command}: {error}", file=sys.stderr)
        return None


def command_status(args) -> int:
    session = _open(args)
    if session is None:
        return 1
    alive, stats = service_status(session, args.namespace, args.timeout)
    session.close()
    print(f"{'service':<10} {'alive':<6} {'received':>9} {'published':>9} {'rejected':>8} "
          f"{'dropped':>8} {'p50_ms':>7} {'p99_ms':>7}")
    for service in key_table.SERVICES:
        row = stats.get(service)
        figures = (f"{row['received']:>9} {row['published']:>9} {row['rejected']:>8} "
                   f"{row['dropped']:>8} {row['p50_ms']:>7.2f} {row['p99_ms']:>7.2f}") if row else ""
        print(f"{service:<10} {'yes' if service in alive else 'no':<6} {figures}")
    return 0


def command_echo(args) -> int:
    names = Keys(args.namespace)
    message_name = args.type or names.message_of(args.key)
    session = _open(args)
    if session is None:
        return 1
    stop = _stop_event()
    printed = [0]

    def on_sample(sample):
        payload = sample.payload.to_bytes()
        try:
            message = _printable(decode(message_name, payload)) if message_name else payload.hex()
        except MessageError as error:
            message = {"error": str(error)}
        print(json.dumps({"key": str(sample.key_expr), "message": message}), flush=True)
        printed[0] += 1
        if args.count and printed[0] >= args.count:
            stop.set()

    subscriber = session.declare_subscriber(names(args.key), on_sample)
    while not stop.wait(0.2):
        pass
    subscriber.undeclare()
    session.close()
    return 0


def command_hz(args) -> int:
    names = Keys(args.namespace)
    session = _open(args)
    if session is None:
        return 1
    stop = _stop_event()
    arrivals: list[float] = []
    lock = threading.Lock()

    def on_sample(_sample):
        with lock:
            arrivals.append(time.monotonic())

    subscriber = session.declare_subscriber(names(args.key), on_sample)
    reports = 0
    while not stop.wait(args.window):
        now = time.monotonic()
        with lock:
            recent = [t for t in arrivals if t >= now - args.window]
            arrivals[:] = recent
        rate = (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 1 else 0.0
        print(f"{names(args.key)}: {rate:.2f} Hz ({len(recent)} messages in {args.window:.1f} s)",
              flush=True)
        reports += 1
        if args.count and reports >= args.count:
            break
    subscriber.undeclare()
    session.close()
    return 0


def command_config(args) -> int:
    try:
        changes = parse_overrides(args.changes)
    except ConfigError as error:
        print(f"balltrack config: {error}", file=sys.stderr)
        return 2
    session = _open(args)
    if session is None:
        return 1
    names = Keys(args.namespace)
    request = encode("ConfigRequest", {"set": changes} if changes else {})
    replies = list(session.get(names(key_table.config_key(args.service)), payload=request,
                               timeout=args.timeout))
    session.close()
    for reply in replies:
        if reply.ok is None:
            continue
        answer = decode("ConfigReply", reply.ok.payload.to_bytes())
        if not answer["ok"]:
            print(f"balltrack config: {answer.get('error')}", file=sys.stderr)
            return 2
        print(json.dumps(answer["config"], indent=2))
        return 0
    print(f"balltrack config: no {args.service} answered on {names(key_table.config_key(args.service))}",
          file=sys.stderr)
    return 1


def _argument_value(text: str):
    """``0.1`` -> 0.1, ``1.5,0.2`` or ``[1.5, 0.2]`` -> [1.5, 0.2], anything else -> the string."""
    try:
        return json.loads(text)
    except ValueError:
        pass
    if "," in text:
        try:
            return [float(part) for part in text.split(",")]
        except ValueError:
            pass
    return text


def command_sim(args) -> int:
    from balltrack.services.simulator.control import send_command

    try:
        request = {"op": args.op, **{key: _argument_value(value)
                                     for key, value in parse_overrides(args.arguments).items()}}
    except ConfigError as error:
        print(f"balltrack sim: {error}", file=sys.stderr)
        return 2
    session = _open(args)
    if session is None:
        return 1
    reply = send_command(session, request, args.namespace, args.timeout)
    session.close()
    if not reply["ok"]:
        print(f"balltrack sim: {reply.get('error')}", file=sys.stderr)
        return 1
    print(json.dumps(reply))
    return 0


def command_experiment(args) -> int:
    from balltrack.experiments.cli import main as experiment_main

    return experiment_main(args.rest)


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="balltrack", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, parser_class=ArgumentParser)

    router = commands.add_parser("router", help="run a Zenoh router")
    router.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help=f"endpoint to listen on, repeatable (default tcp/0.0.0.0:{DEFAULT_PORT})")
    router.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="another router to join (a cluster), repeatable")
    router.add_argument("--zenoh-config", metavar="FILE", help="a Zenoh json5 config file")
    router.set_defaults(handler=command_router)

    detect = commands.add_parser("detect", help="run the detector offline on image files")
    detect.add_argument("images", nargs="+", metavar="IMAGE")
    detect.add_argument("--config", metavar="FILE")
    detect.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE")
    detect.set_defaults(handler=command_detect)

    def networked(name, help_text, handler):
        sub = commands.add_parser(name, help=help_text)
        add_session_arguments(sub, config_file=False)
        sub.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for answers")
        sub.set_defaults(handler=handler)
        return sub

    networked("status", "which services are alive, with their stats", command_status)
    echo = networked("echo", "print decoded messages of a key", command_echo)
    echo.add_argument("key")
    echo.add_argument("--count", type=int, default=0, help="stop after N messages")
    echo.add_argument("--type", choices=sorted(SCHEMAS),
                      help="message type (default: from the key table)")
    hz = networked("hz", "measure the rate of a key", command_hz)
    hz.add_argument("key")
    hz.add_argument("--window", type=float, default=2.0)
    hz.add_argument("--count", type=int, default=0, help="stop after N reports")
    config = networked("config", "read or change a service's parameters live", command_config)
    config.add_argument("service", choices=key_table.SERVICES)
    config.add_argument("changes", nargs="*", metavar="KEY=VALUE")

    sim = networked("sim", "control the simulator: reset, set_light, place_ball, place_robot",
                    command_sim)
    sim.add_argument("op", choices=SIM_OPS)
    sim.add_argument("arguments", nargs="*", metavar="KEY=VALUE",
                     help="e.g. diffuse=0.1, id=tennis position=1.5,0.2, scenario=search")

    experiment = commands.add_parser("experiment", help="run an experiment (see --help)",
                                     add_help=False)
    experiment.add_argument("rest", nargs=argparse.REMAINDER)
    experiment.set_defaults(handler=command_experiment)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "namespace", None) is not None:
        try:
            Keys(args.namespace)
        except ValueError as error:
            print(f"balltrack {args.command}: {error}", file=sys.stderr)
            return 2
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
