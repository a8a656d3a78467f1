"""The service runner: everything a balltrack service does besides its own work.

``run_service`` parses the shared options, loads the config (a bad one exits 2 with one
line), opens the session, declares the liveliness token ``alive/<service>``, publishes
``<service>/stats`` at 1 Hz, answers ``<service>/config`` (read, change parameters live, or
``{"describe": true}`` for their declarations), and stops on SIGINT/SIGTERM by setting one
event, closing the session explicitly, exit 0.

With ``--namespaces robot1,robot2`` (or ``auto``) one process serves several robots: each
service is built once per robot, under its namespace (see ``serve``).

A service module only says what it subscribes to and publishes, through the
``ServiceContext`` (``context.py``) its ``build`` is given::

    def build(service: ServiceContext):
        out = service.publisher(keys.DETECTED_BALL_3D, "Ball3D")
        service.subscribe(keys.DETECTED_BALL, "Ball2D", lambda ball: out.put(...))

    def main(argv=None):
        return run_service("locator", LocatorConfig, build, argv, __doc__)
"""

import argparse
import logging
import os
import queue
import sys
import threading
import time
from typing import Any, Callable

import zenoh

from balltrack.common import keys as key_table
from balltrack.common.arguments import ArgumentParser
from balltrack.common.config import (ConfigError, config_to_dict, describe_config, help_text, load_config,
                                     settings_by_service)
from balltrack.common.context import ServiceContext, SharedLatestWorker
from balltrack.common.keys import (FRAME_SOURCES, PROCESS_JOIN, SERVICES_OF_MANY_ROBOTS, namespace_list,
                                   validate_namespace)
from balltrack.common.messages import MessageError, decode, encode, shorten
from balltrack.common.session import (SessionOpenError, ZenohConfigError, add_session_arguments, close_session,
                                      open_until_stopped, peer_conflict)
from balltrack.common.shutdown import stop_on_signals

LOG_FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"


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
    if name in SERVICES_OF_MANY_ROBOTS:
        add_namespaces_argument(parser)
    parser.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    return parser


# ``--namespaces auto``: serve each robot whose frame source is alive, as it appears.
DISCOVER = "auto"


def add_namespaces_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--namespaces", default=None, metavar="NS,NS,...|auto",
                        help="serve several robots in this one process, each under its own namespace "
                             "(robot1,robot2): each keeps its own state, parameters, stats and liveliness "
                             "token, and one worker serves their newest frames in turn; auto: every "
                             f"namespace where a frame source ({', '.join(FRAME_SOURCES)}) is alive, as it "
                             f"appears (not with --namespace; services {', '.join(SERVICES_OF_MANY_ROBOTS)})")


def robot_namespaces(args, parser: argparse.ArgumentParser, names: list[str]) -> list[str]:
    """The namespaces this process serves: ``--namespaces``' list, else ``--namespace``'s one.
    ValueError, one line, for a list that cannot be served."""
    args.discover_robots = False
    if getattr(args, "namespaces", None) is None:
        return [validate_namespace(args.namespace)]
    if args.namespace != parser.get_default("namespace"):
        raise ValueError("--namespaces: not with --namespace (one robot's namespace goes in either)")
    single = [name for name in names if name not in SERVICES_OF_MANY_ROBOTS]
    if single:
        raise ValueError(f"--namespaces: {', '.join(single)} serves one robot per process (run one with "
                         f"--namespace for each); several robots in one process: "
                         f"{', '.join(SERVICES_OF_MANY_ROBOTS)}")
    if args.namespaces.strip() == DISCOVER:
        args.discover_robots = True
        return []
    return namespace_list(args.namespaces, "--namespaces")


# Seconds a stopped process waits for its teardown (tokens, entities, session) before it exits
# without it: past Zenoh's own ~10 s for a router out of reach, within a supervisor's 15 s.
CLOSE_LIMIT_S = 12.0


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
        preflight(config)
        args.namespaces = robot_namespaces(args, parser, [name])
    except (ConfigError, ValueError) as error:
        print(f"{name}: {error}", file=sys.stderr)
        return 2
    return serve(name, args, [(name, config, build)])


def preflight(config) -> None:
    """Check what a service's settings name outside it (a camera's video file or calibration)
    before its session opens: a missing file is then one line and status 2 at once, not after a
    router answers. A config class opts in with a ``preflight()`` method raising ConfigError;
    this is not part of its validation, which describing settings and live changes run too."""
    check = getattr(config, "preflight", None)
    if check is not None:
        check()


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
    if any(name in SERVICES_OF_MANY_ROBOTS for name in names):  # (the others are named when refused)
        add_namespaces_argument(parser)
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
        configs = []
        for name, config_class, _ in services:
            try:  # (which of the joined services a bad setting or file is for)
                configs.append(load_config(config_class, files.get(name), overrides[name], section=name))
                preflight(configs[-1])
            except ConfigError as error:
                raise ConfigError(f"{name}: {error}") from None
        args.namespaces = robot_namespaces(args, parser, names)
    except (ConfigError, ValueError) as error:
        print(f"{label}: {error}", file=sys.stderr)
        return 2
    return serve(label, args, [(name, config, build) for (name, _, build), config in zip(services, configs)])


def serve(label: str, args, services: list[tuple[str, Any, Callable[[ServiceContext], Callable | None]]]) -> int:
    """Open the session of ``args`` and run ``services`` ((name, config, build) each) on it
    until SIGINT/SIGTERM: one process, one session, each service with its own context (stats,
    config queryable, liveliness token) as if it ran alone. ``label`` names the process in
    its messages. Every ``loop`` a build returns runs (the last in the main thread).

    With several namespaces in ``args.namespaces`` (one process serving several robots) each
    service is built once per robot, under that robot's namespace, and is there as if it ran
    alone: its own state, parameters, stats, config queryable and liveliness token. One worker
    per service serves every robot's newest frame in turn (``SharedLatestWorker``)."""
    # The session opens in a thread so that SIGINT/SIGTERM while the router is still
    # unreachable ends the service at once with status 0, as when it is running.
    stop = stop_on_signals()
    try:
        session = open_until_stopped(args, stop)
    except SessionOpenError as error:
        print(f"{label}: {error}", file=sys.stderr)
        return 1
    except ZenohConfigError as error:  # (a bad --connect or --zenoh-config: not worth waiting for)
        print(f"{label}: {error}", file=sys.stderr)
        return 2
    if session is None:
        logging.getLogger(label).info("stopped before a router answered")
        os._exit(0)  # nothing to close; the opening thread is inside Zenoh and cannot be joined

    namespaces = getattr(args, "namespaces", None) or []
    discover = getattr(args, "discover_robots", False)
    if not namespaces and not discover:
        namespaces = [args.namespace]
    shared_workers = ({name: SharedLatestWorker(name) for name, _, _ in services}
                      if len(namespaces) > 1 or discover else {})
    contexts: list[ServiceContext] = []
    loops: list[tuple[ServiceContext, Callable]] = []
    status = 0
    # What a loop in a thread of its own refused (a source none of whose photos is an image):
    # it stops the process and is reported as the main thread's loop's would be.
    refused: list[Exception] = []

    def run_loop(context: ServiceContext, loop: Callable) -> None:
        try:
            loop(context)
        except (ConfigError, ValueError) as error:
            refused.append(error)
            stop.set()

    # Liveliness tokens, and what else is undeclared before the services' own entities.
    tokens = []

    def build_robot(namespace: str) -> None:
        """Build and announce every service under ``namespace``: a robot's services one after
        another, as a process of its own builds them."""
        for name, config, build in services:
            context = ServiceContext(name, session, namespace, config, stop, shared_workers.get(name))
            contexts.append(context)
            loop = build(context)
            if loop is not None:
                loops.append((context, loop))
            tokens.append(_announce(context))

    try:
        for namespace in namespaces:
            build_robot(namespace)
        for context, loop in loops[:-1]:
            context.start_thread(lambda context=context, loop=loop: run_loop(context, loop), f"{context.name}-loop")
        if loops:
            loops[-1][1](loops[-1][0])
        if discover:
            _serve_discovered(session, stop, build_robot, tokens, logging.getLogger(label))
        # A timed wait keeps the main thread responsive to signals on every platform.
        while not stop.wait(0.5):
            pass
        if refused:
            raise refused[0]
    except (ConfigError, ValueError) as error:
        print(f"{label}: {error}", file=sys.stderr)
        status = 2
    finally:
        stop.set()
        closing = threading.Thread(target=_close, args=(label, tokens, contexts, session), daemon=True)
        closing.start()
        closing.join(CLOSE_LIMIT_S)
        if closing.is_alive():
            # Zenoh gives up on its own after ~10 s, but undeclaring behind a backlog of frames
            # to a frozen router took 20 s (TLS): past a supervisor's SIGKILL. The process has
            # stopped serving; the router forgets its session when the lease ends.
            logging.getLogger(label).warning("not closed %g s after the stop (its router out of reach?): "
                                             "exiting without waiting longer", CLOSE_LIMIT_S)
            for context in contexts:
                context.log.info("stopped")
            logging.shutdown()
            os._exit(status)
    for context in contexts:
        context.log.info("stopped")
    return status


def _serve_discovered(session, stop: threading.Event, build_robot: Callable[[str], None], tokens: list,
                      log: logging.Logger) -> None:
    """Until ``stop``: ``build_robot`` each namespace where a frame source (FRAME_SOURCES)
    declares its liveliness token ``<NS>/alive/<source>``, once, in this thread
    (``--namespaces auto``). A robot whose source goes away keeps its services: its state is
    there for when the source comes back."""
    found: queue.SimpleQueue = queue.SimpleQueue()

    def on_token(sample) -> None:
        token = key_table.alive_token(str(sample.key_expr))
        if sample.kind == zenoh.SampleKind.PUT and token is not None and token[1] in FRAME_SOURCES:
            found.put(token[0])

    tokens.append(session.liveliness().declare_subscriber("**/" + key_table.alive_key("*"), on_token, history=True))
    served: set[str] = set()
    while not stop.is_set():
        try:
            # (a timed wait: the main thread stays responsive to signals)
            namespace = found.get(timeout=0.5)
        except queue.Empty:
            continue
        if namespace not in served and not stop.is_set():
            served.add(namespace)
            log.info("a frame source is alive in namespace %r: serving it", namespace)
            build_robot(namespace)


def _close(label: str, tokens: list, contexts: list[ServiceContext], session) -> None:
    """A stopped process's teardown: liveliness tokens, then each service's entities and
    threads, then the session."""
    try:
        for token in tokens:
            token.undeclare()
    except Exception:  # (the session closes next anyway)
        pass
    for context in reversed(contexts):
        context.close()
    reason = close_session(session)
    if reason:
        logging.getLogger(label).warning("%s", reason)


def _announce(context: ServiceContext):
    """Publish a built service's stats at 1 Hz, answer its config queries and declare it
    alive; returns its liveliness token."""
    name = context.name
    stats_publisher = context.declare(context.session.declare_publisher(context.keys(key_table.stats_key(name))))
    context.queryable(key_table.config_key(name), lambda query: _serve_config(context, query))
    token = context.session.liveliness().declare_token(context.keys(key_table.alive_key(name)))

    def publish_stats():
        while not context.stop.wait(1.0):
            stats_publisher.put(encode("Stats", context.stats.snapshot(time.time_ns())))

    context.start_thread(publish_stats, f"{name}-stats")
    context.log.info("running (namespace %r)", context.keys.namespace)
    return token
