"""Watching the system live:

    balltrack view [--port 9090]              # Rerun's web viewer: open the address it prints
    balltrack view --foxglove [--port 8765]   # a Foxglove WebSocket server (ws://HOST:PORT)
    balltrack view --namespaces robot1,robot2 # Rerun: several robots, a tab each

Rerun shows the annotated frame, the true balls and the robot's path in the world frame, and
time plots of cmd_vel and of the located-ball rate (its data over gRPC on --grpc-port).
Foxglove (app or https://app.foxglove.dev) opens ws://localhost:8765 and shows /image (the
detector's annotated frame), /scene (located and true balls), /tf (world -> base_link) and
/cmd_vel. Stops within a fraction of a second on SIGINT or SIGTERM.
"""

import re
import sys
import urllib.parse

from balltrack.cli.session import close_or_report, networked, open_or_report
from balltrack.common.config import ConfigError, load_config
from balltrack.common.keys import namespace_list
from balltrack.common.network import port_taken
from balltrack.common.shutdown import stop_on_signals
from balltrack.deploy.view_config import RerunViewConfig


def _fail(args, reason: str, status: int) -> int:
    print(f"balltrack {args.command}: {reason}", file=sys.stderr)
    return status


# The amounts Rerun's server_memory_limit takes (it refuses "100", "1gb", "1KB").
MEMORY_LIMIT = re.compile(r"0|\d+(\.\d+)? ?(%|B|kB|MB|GB|TB|KiB|MiB|GiB|TiB)")


def _serve_rerun(args, session, stop, config) -> int:
    import rerun as rr

    from balltrack.deploy.view import RerunBridge, rerun_blueprint

    recording = rr.RecordingStream("balltrack")
    # (Rerun only logs that its data port is taken, and goes on: the page it serves would then
    # show whatever holds that port)
    for port in (args.grpc_port, args.port):
        if port_taken(port):
            return _fail(args, f"cannot serve on ports {args.port}/{args.grpc_port}: port {port} is in use", 1)
    try:
        server = recording.serve_grpc(grpc_port=args.grpc_port, server_memory_limit=args.memory_limit,
                                      default_blueprint=rerun_blueprint(config, args.robots))
        rr.serve_web_viewer(web_port=args.port, open_browser=False, connect_to=server)
    except Exception as error:  # the port taken, an address not ours
        return _fail(args, f"cannot serve on ports {args.port}/{args.grpc_port}: "
                           f"{str(error).strip().splitlines()[0]}", 1)
    bridges = ([RerunBridge(session, recording, robot, config, entity_prefix=f"{robot}/") for robot in args.robots]
               or [RerunBridge(session, recording, args.namespace, config)])
    # (Rerun's Python API binds every interface, and serves without a password)
    print(f"balltrack view: Rerun viewer on {viewer_url(args.port, server)} (served on every interface, "
          "to anyone who reaches these ports; from another host, its address in place of both "
          "127.0.0.1; Ctrl-C to stop)", file=sys.stderr, flush=True)
    stop.wait()
    for bridge in bridges:
        bridge.close()
    recording.disconnect()
    return _report(bridges)


def viewer_url(web_port: int, data_url: str) -> str:
    """The address of Rerun's web page that opens with its data: the page's own address
    shows only Rerun's welcome screen (its ``connect_to`` is not passed on to a browser opened
    by hand), so the data's address (``rerun+http://127.0.0.1:9876/proxy``) goes in its ``url``
    query."""
    return f"http://127.0.0.1:{web_port}/?url={urllib.parse.quote(data_url, safe=':/')}"


def _serve_foxglove(args, session, stop) -> int:
    import foxglove

    from balltrack.deploy.view import FoxgloveBridge

    try:
        server = foxglove.start_server(host=args.host, port=args.port, name="balltrack")
    except Exception as error:  # the port taken, an address not ours
        return _fail(args, f"cannot serve on {args.host}:{args.port}: {str(error).strip()}", 1)
    bridge = FoxgloveBridge(session, args.namespace)
    print(f"balltrack view: Foxglove server on ws://{args.host}:{server.port} (Ctrl-C to stop)",
          file=sys.stderr, flush=True)
    stop.wait()
    bridge.close()
    server.stop()
    return _report([bridge])


def _report(bridges: list) -> int:
    # One summary line (the viewer_cost experiment reads it): what was shown and how late.
    lags = sorted(lag for bridge in bridges for lag in bridge.lags)
    lag = (f"; arrival -> shown p50 {1000 * lags[len(lags) // 2]:.1f} ms, "
           f"p99 {1000 * lags[min(len(lags) - 1, int(0.99 * len(lags)))]:.1f} ms" if lags else "")
    total = {name: sum(getattr(bridge, name) for bridge in bridges)
             for name in ("handled", "skipped_frames", "dropped", "rejected")}
    print(f"balltrack view: shown {total['handled']} messages, {total['skipped_frames']} older frames skipped, "
          f"{total['dropped']} dropped, {total['rejected']} malformed{lag}", file=sys.stderr)
    return 0


def command_view(args) -> int:
    if args.port is None:
        args.port = 8765 if args.foxglove else 9090
    if args.host is not None and not args.foxglove:
        # (one address or all: a --host that was quietly not kept would leave the viewer open
        # to every network the host is on)
        return _fail(args, "--host: Rerun's viewer serves on every interface (its Python API takes "
                           "no address); --foxglove serves on one", 2)
    args.host = args.host or "127.0.0.1"
    try:
        args.robots = namespace_list(args.namespaces, "--namespaces") if args.namespaces is not None else []
    except ValueError as error:
        return _fail(args, str(error), 2)
    if args.robots and (args.foxglove or args.namespace):
        return _fail(args, "--namespaces: Rerun only, and not with --namespace", 2)
    if args.overrides and args.foxglove:
        return _fail(args, "--set: the settings are Rerun's (deploy/view_config.py); Foxglove has none", 2)
    try:
        config = load_config(RerunViewConfig, None, args.overrides)
    except ConfigError as error:
        return _fail(args, f"--set: {error}", 2)
    if not args.foxglove and not MEMORY_LIMIT.fullmatch(args.memory_limit):
        return _fail(args, f"--memory-limit: expected an amount such as 256MiB, 2GB or 25% (of the RAM), "
                           f"got {args.memory_limit!r}", 2)
    for option, port in (("--port", args.port), ("--grpc-port", args.grpc_port)):
        if not 0 <= port <= 65535 or (port == 0 and not args.foxglove):
            return _fail(args, f"{option}: {port} is not a TCP port (1-65535; 0, any free one, "
                               "only with --foxglove)", 2)
    try:
        import foxglove  # noqa: F401  (both viewers' bridges live in deploy/view.py)
        import rerun  # noqa: F401
    except ImportError as error:
        return _fail(args, f"{error.name} is not installed (pip install 'balltrack[view]')", 1)
    stop = stop_on_signals()
    session = open_or_report(args, stop)
    if session is None:
        return 1
    try:
        return _serve_foxglove(args, session, stop) if args.foxglove else _serve_rerun(args, session, stop, config)
    finally:
        close_or_report(args, session)


def register(commands) -> None:
    sub = networked(commands, "view", "watch the system live in Rerun or Foxglove", command_view)
    sub.add_argument("--foxglove", action="store_true",
                     help="serve the Foxglove WebSocket protocol (open it in the Foxglove app)")
    sub.add_argument("--host", default=None,
                     help="Foxglove: the address to serve on (default 127.0.0.1; 0.0.0.0 for other "
                          "hosts); Rerun serves on every interface")
    sub.add_argument("--port", type=int, default=None,
                     help="port to serve on (Rerun's web page: default 9090; Foxglove: 8765, 0 = any)")
    sub.add_argument("--grpc-port", type=int, default=9876,
                     help="Rerun: the port its viewer reads the data from (default 9876)")
    # (a page that connects gets all of it first, before the present: the less kept, the sooner
    # a page opened late is live; at the default rates this is a minute or two of the past)
    sub.add_argument("--memory-limit", default="32MiB",
                     help="Rerun: data kept for viewers that connect later (default 32MiB; e.g. 2GB, 25%% of the RAM)")
    sub.add_argument("--namespaces", default=None, metavar="NS,NS,...",
                     help="Rerun: several robots in one page, a tab each (e.g. robot1,robot2)")
    sub.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE",
                     help="Rerun: what is sent to its page, e.g. update_rate_hz=10 or frame_width=640 (repeatable; "
                          "the keys: docs/parameters.md, view)")
