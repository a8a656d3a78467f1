"""``balltrack deploy start|stop`` (or ``python -m balltrack.deploy``): run balltrack under the
supervisor, in one run folder.

    balltrack deploy start --router                          # router + four services (one host)
    balltrack deploy start --router --listen tcp/0.0.0.0:7447 --services detector,locator,follower
    balltrack deploy start --connect tcp/192.168.1.10:7447 --services detector --namespace robot1
    balltrack deploy start --router --set follower.max_size_thresh=0.3
    balltrack deploy start --router --secure secure/         # TLS, passwords, access control
    balltrack status --run-dir runs/default                  # pids, restarts, liveliness, stats
    balltrack deploy stop

``start`` writes ``launch.json`` into the run folder (default ``runs/default``), starts the
supervisor in the background and returns once every service has declared its liveliness token
(``--wait`` seconds at most; ``--foreground`` keeps the supervisor in this terminal instead, Ctrl-C
stops it). ``stop`` sends the supervisor SIGTERM and waits for it. The one status command is
``balltrack status``; with ``--run-dir`` it adds the supervisor's pids, restarts and last exits.
"""

import argparse
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from balltrack.common.arguments import ArgumentParser, seconds
from balltrack.common.config import ConfigError, settings_by_service
from balltrack.common.keys import (CORE_SERVICES, SERVICES, SERVICES_OF_MANY_ROBOTS, Keys, namespace_list,
                                   process_services, services_of)
from balltrack.common.network import port_taken
from balltrack.common.session import (DEFAULT_PORT, ROBOTS_FOLDER, SessionOpenError, client_config, close_session,
                                      config_endpoints, default_endpoints, load_config_file,
                                      router_config, secure_client_path, secure_router_path)
from balltrack.common.status import service_status
from balltrack.common.waiting import poll_until
from balltrack.deploy.supervisor import (ChildSpec, SupervisorSettings, child_environment, describe_exit,
                                         die_with_parent, open_for, pid_alive, save_launch, serving_namespaces,
                                         supervise, wait_alive)

DEFAULT_RUN_DIR = "runs/default"
DEFAULT_LISTEN = f"tcp/0.0.0.0:{DEFAULT_PORT}"


class LaunchError(RuntimeError):
    pass


# -- building the command lines --------------------------------------------------------------
def endpoint_port(endpoint: str) -> int | None:
    """The port of ``tcp/HOST:PORT`` (also udp, tls, quic), or None."""
    address = endpoint.split("/", 1)[-1].split("#", 1)[0]
    try:
        return int(address.rsplit(":", 1)[1])
    except (IndexError, ValueError):
        return None


def endpoint_parts(endpoint: str) -> tuple[str, str, str]:
    """(protocol, host, port) of ``tcp/HOST:PORT#config``, as text ("" for a missing part)."""
    protocol, _, address = endpoint.partition("/")
    host, _, port = address.split("#", 1)[0].rpartition(":")
    return protocol, host, port


def local_endpoint(listen: str) -> str:
    """Where a process on the same host reaches a router listening on ``listen``."""
    protocol, host, port = endpoint_parts(listen)
    if host in ("0.0.0.0", "", "[::]", "*"):
        host = "127.0.0.1"
    return f"{protocol}/{host}:{port}"


def parse_service_overrides(items: list[str], services: list[str]) -> dict[str, list[str]]:
    """``--set SERVICE.KEY=VALUE`` items per service of ``services`` (processes: a name may
    join several, ``detector+locator``), as ``KEY=VALUE``."""
    try:
        return settings_by_service(items, services_of(services), "--services")
    except ConfigError as error:
        raise LaunchError(str(error)) from None


def build_specs(args) -> tuple[list[ChildSpec], dict]:
    """The children (router first) and the facts ``status`` needs, from ``start``'s options."""
    services = [name.strip() for name in args.services.split(",") if name.strip()]
    if not services:
        # (an empty shell variable, most likely: a router alone is `balltrack router`)
        raise LaunchError(f"--services: {args.services!r} names no service (known: {', '.join(SERVICES)}; "
                          "a router alone: balltrack router)")
    names = services_of(services)
    unknown = [name for name in names if name not in SERVICES]
    if unknown:
        raise LaunchError(f"--services: unknown {', '.join(unknown)} (known: {', '.join(SERVICES)})")
    if len(set(names)) != len(names):
        raise LaunchError(f"--services: {args.services}: a service may run once")
    if not args.router and (args.listen or args.router_connect or args.router_config or args.host):
        raise LaunchError("--listen, --router-connect, --router-config and --host need --router")
    if args.secure and (args.router_config or args.zenoh_config):
        raise LaunchError("--secure names the Zenoh configs itself: no --router-config or --zenoh-config with it")
    namespaces = robots_served(args, services)
    if args.listen:
        listen = args.listen
    elif args.secure and args.router:
        listen = secure_listen(args.secure, args.host)
    else:
        # (a --router-config's own endpoints stand: a file that keeps the router on 127.0.0.1
        # must not be overridden by the default's every interface)
        listen = (args.router_config and config_listen(args.router_config)) or [DEFAULT_LISTEN]
    # An endpoint or config file that Zenoh refuses is a bad argument (ZenohConfigError, a
    # ValueError), said before anything starts.
    if args.router:
        router_config(listen, args.router_connect, args.router_config)
    client_config(args.connect, args.zenoh_config)
    return make_specs(services, parse_service_overrides(args.overrides, services), router=args.router,
                      listen=listen, router_connect=args.router_connect,
                      router_config=args.router_config, connect=args.connect,
                      zenoh_config=args.zenoh_config, namespace=args.namespace, namespaces=namespaces,
                      config_dir=args.config_dir, log_level=args.log_level, secure=args.secure, host=args.host,
                      run_dir=args.run_dir)


def robots_served(args, services: list[str]) -> list[str]:
    """``--namespaces``' robots (none without it), each served by the processes of detector,
    locator and follower; LaunchError, one line, for what cannot be served so."""
    if args.namespaces is None:
        return []
    if args.namespaces.strip() == "auto":
        raise LaunchError("--namespaces auto: not under the supervisor, which waits for each robot's services; "
                          "name the robots (robot1,robot2), or run `balltrack run ... --namespaces auto`")
    if args.namespace:
        raise LaunchError("--namespaces: not with --namespace (one robot's namespace goes in either)")
    single = [name for process in services for name in process_services(process)
              if name not in SERVICES_OF_MANY_ROBOTS and name != "simulator"]
    mixed = [process for process in services if "simulator" in process_services(process)
             and len(process_services(process)) > 1]
    if single or mixed:
        raise LaunchError(f"--namespaces: {', '.join(single + mixed)} serves one robot per process; with "
                          f"--namespaces: {', '.join(SERVICES_OF_MANY_ROBOTS)}, and a simulator of its own "
                          "(--set simulator.robots=N)")
    try:
        robots = namespace_list(args.namespaces, "--namespaces")
    except ValueError as error:
        raise LaunchError(str(error)) from None
    # (the fleet-wide roles of a fleet's profile are allowed its robots' keys; a profile made
    # without them would let the services join and then drop every message)
    unknown = [robot for robot in robots if args.secure and not (Path(args.secure) / ROBOTS_FOLDER / robot).is_dir()]
    if unknown:
        raise LaunchError(f"--namespaces: {args.secure} is no profile of robot {unknown[0]} "
                          f"(balltrack secure init --robots {','.join(robots)})")
    return robots


def secure_listen(directory: str, host: str | None) -> list[str]:
    """The endpoints in a secure profile's router config (``tls/0.0.0.0:7447``)."""
    try:
        path = secure_router_path(directory, host)
    except ValueError as error:
        raise LaunchError(str(error)) from None
    return config_listen(str(path))


def config_listen(path: str) -> list[str]:
    """The endpoints a router started with a Zenoh json5 config file listens on."""
    try:
        config = load_config_file(path)
    except ValueError as error:
        raise LaunchError(str(error)) from None
    return config_endpoints(config, "listen", ("router",))


def make_specs(services: list[str], overrides: dict[str, list[str]], router: bool = False,
               listen: list[str] = (DEFAULT_LISTEN,), router_connect: list[str] = (),
               router_config: str | None = None, connect: list[str] | None = None,
               zenoh_config: str | None = None, namespace: str = "", namespaces: list[str] = (),
               config_dir: str | None = None, log_level: str = "INFO", secure: str | None = None,
               host: str | None = None, run_dir: str | None = None) -> tuple[list[ChildSpec], dict]:
    """The children (router first, then ``services`` in order) and the facts ``status`` needs.

    ``overrides`` maps a service to its ``key=value`` settings. With our own router each
    service must be alive before the next starts, so the last (the simulator) meets a ready
    pipeline; services of a remote router start at once (it may not be up yet). ``secure``:
    a profile folder (``balltrack secure init``); the router is ``host``'s, each service its
    own role, and this program watches them as ``viewer``. Services of a router started here
    join it as peers (``--peer``), unless secure, given a Zenoh config or told to ``connect``
    elsewhere. A simulator keeps its clock in ``run_dir``/simulator.clock, so that it goes on
    across the supervisor's restarts (a ``--set clock_file=...`` of the caller's wins). With
    ``namespaces`` (robots, see :func:`robots_served`) each process of detector, locator and
    follower serves every robot under its namespace (``--namespaces``)."""
    python = sys.executable
    Keys(namespace)  # raises ValueError for a namespace Zenoh cannot route
    absolute = lambda path: str(Path(path).resolve()) if path else None  # noqa: E731
    joined = [process for process in services if len(process_services(process)) > 1]
    if secure and joined:
        raise LaunchError(f"{joined[0]}: with --secure each service has its own certificate and role, "
                          "so each runs in a process of its own")
    if secure:
        try:
            if router:
                secure_router_path(secure, host)
            for role in [*services, "viewer"]:
                secure_client_path(secure, role, Keys(namespace).namespace)
        except ValueError as error:
            raise LaunchError(str(error)) from None
        # for wait_alive and status (a robot's own viewer in a fleet's profile)
        zenoh_config = str(secure_client_path(absolute(secure), "viewer", Keys(namespace).namespace))
    specs: list[ChildSpec] = []
    if router:
        argv = [python, "-m", "balltrack", "router"]
        for endpoint in listen:
            argv += ["--listen", endpoint]
        for endpoint in router_connect:
            argv += ["--connect", endpoint]
        if router_config:
            argv += ["--zenoh-config", absolute(router_config)]
        if secure:
            argv += ["--secure", absolute(secure)] + (["--host", host] if host else [])
        # A TLS listener accepts TCP connections too: the supervisor's readiness check works.
        port = endpoint_port(listen[0]) if listen[0].startswith(("tcp/", "tls/")) else None
        if port == 0:
            raise LaunchError("--listen: give a port (0 would be chosen by the router, unknown to the services)")
        # (else the services would find and join whatever holds the port, while our router
        # fails to listen and is restarted for ever)
        if port is not None and port_taken(port, endpoint_parts(listen[0])[1]):
            raise LaunchError(f"--listen {listen[0]}: port {port} is in use (another router? stop it, "
                              "or give --listen another port)")
        specs.append(ChildSpec("router", argv, port=port))

    # (services of a router started here, dialling it on this host, may link to each other)
    peers = router and not connect and not secure and not zenoh_config
    if connect:
        connect = list(connect)
    elif router and secure and list(listen) == secure_listen(secure, host):
        # (the profile's own client endpoints name this router as its certificate does; a
        # --no-localhost profile's certificate lacks the 127.0.0.1 that local_endpoint dials)
        connect = []
    elif router:
        connect = [local_endpoint(listen[0])]
    elif zenoh_config:
        connect = []  # the json5 file names the router
    else:
        connect = default_endpoints()
    config_path = Path(config_dir).resolve() if config_dir else None
    if config_path is not None and not config_path.is_dir():
        raise LaunchError(f"--config-dir: {config_dir} is not a directory")
    for process in services:
        names = process_services(process)
        joined = len(names) > 1
        # (services joined in one process: ``balltrack run``, their files and settings named)
        argv = [python, "-m", "balltrack", "run", process] if joined else [python, "-m", f"balltrack.services.{process}"]
        for endpoint in connect:
            argv += ["--connect", endpoint]
        if namespaces and set(names) <= set(SERVICES_OF_MANY_ROBOTS):
            argv += ["--namespaces", ",".join(namespaces)]
        elif namespace:
            argv += ["--namespace", namespace]
        if secure:
            argv += ["--secure", absolute(secure)]
        elif zenoh_config:
            argv += ["--zenoh-config", absolute(zenoh_config)]
        elif peers:
            argv += ["--peer"]  # (direct links between this host's services: common/session.py)
        state_files = []
        for name in names:
            if config_path is not None and (config_path / f"{name}.toml").is_file():
                path = str(config_path / f"{name}.toml")
                argv += ["--config", f"{name}={path}" if joined else path]
            settings = list(overrides.get(name, []))
            if name == "simulator" and run_dir:
                state_files.append(str(Path(run_dir).resolve() / "simulator.clock"))
                settings.insert(0, f"clock_file={state_files[-1]}")
            for override in settings:
                argv += ["--set", f"{name}.{override}" if joined else override]
        argv += ["--log-level", log_level]
        specs.append(ChildSpec(process, argv, wait_alive=router and process != services[-1],
                               state_files=state_files))
    # (the services themselves, each with its liveliness token, whichever process runs it)
    info = {"connect": connect, "namespace": namespace, "namespaces": list(namespaces),
            "services": services_of(services),
            "zenoh_config": absolute(zenoh_config), "router": bool(router), "secure": absolute(secure)}
    return specs, info


# -- the network side: liveliness and stats --------------------------------------------------
def network_status(info: dict, timeout: float) -> tuple[dict[str, tuple[set[str], dict[str, dict]]] | None,
                                                       str | None]:
    """Per namespace (the run's, and each of its robots'): (services alive, stats per service);
    None and the error when the router is out of reach."""
    try:
        session = open_for(info, timeout)
    except SessionOpenError as error:
        return None, str(error)
    namespaces = dict.fromkeys([info.get("namespace", ""), *(info.get("namespaces") or [])])
    found = {namespace: service_status(session, namespace, timeout) for namespace in namespaces}
    return found, close_session(session)


# -- run folders -----------------------------------------------------------------------------
def read_pid(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


def read_status(run_dir: Path) -> dict | None:
    try:
        return json.loads((run_dir / "status.json").read_text())
    except (OSError, ValueError):
        return None


def running_supervisor(run_dir: Path) -> int | None:
    pid = read_pid(run_dir / "supervisor.pid")
    return pid if pid is not None and pid_alive(pid) else None


def tail(path: Path, lines: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return ""


class Launched:
    """A supervisor started in the background by this process (see :func:`launch`)."""

    def __init__(self, run_dir: Path, popen: subprocess.Popen):
        self.run_dir = run_dir
        self.popen = popen

    def stop(self, timeout: float = 40.0) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        return self.popen.returncode


def launch(run_dir: Path, specs: list[ChildSpec], info: dict, wait: float = 60.0,
           output=sys.stdout, tie_to_parent: bool = False) -> Launched:
    """Start a supervisor in the background; return once the services are alive.

    ``tie_to_parent``: the supervisor (and so everything) gets SIGTERM if this process dies
    (the demo); without it the supervisor outlives ``balltrack deploy start``. ``output``
    (None: quiet) gets a line once the supervisor runs and once the services are alive.
    Raises LaunchError (with the supervisor stopped) if it cannot start or a service fails."""
    run_dir = Path(run_dir).resolve()
    if running_supervisor(run_dir):
        raise LaunchError(f"a supervisor already runs in {run_dir} (balltrack deploy stop --run-dir {run_dir})")
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "status.json").unlink(missing_ok=True)
    save_launch(run_dir, specs, {**info, "run_dir": str(run_dir)})
    with open(run_dir / "supervisor.log", "ab") as log:
        popen = subprocess.Popen([sys.executable, "-m", "balltrack.deploy", "supervise", "--run-dir", str(run_dir)],
                                 stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                 env=child_environment(), start_new_session=True,
                                 preexec_fn=die_with_parent if tie_to_parent else None)
    launched = Launched(run_dir, popen)

    def failed_children() -> list[str]:
        status = read_status(run_dir) or {}
        return [name for name, child in status.get("children", {}).items() if child["state"] == "failed"]

    def give_up(reason: str):
        launched.stop()
        logs = "".join(f"\n--- {name}.log (end) ---\n{tail(run_dir / f'{name}.log')}"
                       for name in [spec.name for spec in specs] if (run_dir / f"{name}.log").exists())
        raise LaunchError(f"{reason}\n--- supervisor.log (end) ---\n{tail(run_dir / 'supervisor.log')}{logs}")

    def supervisor_running() -> bool:
        # (the supervisor rewrites status.json as it starts each child)
        if (read_status(run_dir) or {}).get("supervisor", {}).get("state") == "running":
            return True
        if popen.poll() is not None:
            give_up(f"the supervisor exited ({describe_exit(popen.returncode)})")
        return False

    if not poll_until(supervisor_running, max(wait, 30.0), interval=0.1):
        give_up("the supervisor did not start its children in time")
    if output is not None:
        print(f"supervisor pid {popen.pid}, run folder {run_dir}", file=output, flush=True)
    services = info.get("services", [])
    if wait > 0 and services:
        missing = wait_alive(info, services, wait, failed=lambda: bool(failed_children())
                             or popen.poll() is not None)
        if failed_children():
            give_up(f"failed: {', '.join(failed_children())}")
        if missing:
            give_up(f"not alive after {wait:.0f} s: {', '.join(sorted(missing))}")
        if output is not None:
            print(f"alive: {', '.join(services)}", file=output, flush=True)
    return launched


def stop_run(run_dir: Path, timeout: float = 40.0, output=sys.stdout) -> int:
    pid = running_supervisor(run_dir)
    if pid is None:
        stale = sorted(path.name for path in run_dir.glob("*.pid"))
        for path in run_dir.glob("*.pid"):  # left by a supervisor that was killed
            path.unlink(missing_ok=True)
        print(f"no supervisor running in {run_dir}"
              + (f" (removed stale {', '.join(stale)})" if stale else ""), file=output)
        return 0
    os.kill(pid, signal.SIGTERM)
    if not poll_until(lambda: not pid_alive(pid), timeout, interval=0.1):  # (not our child: no wait())
        print(f"supervisor {pid} still running after {timeout:.0f} s", file=sys.stderr)
        return 1
    status = read_status(run_dir) or {}
    exit_code = status.get("supervisor", {}).get("exit_code")
    for name, child in status.get("children", {}).items():
        print(f"{name:<10} {child['state']:<8} {child.get('last_exit_text') or ''}", file=output)
    print(f"supervisor {pid} stopped (exit {exit_code})", file=output)
    return 0 if exit_code == 0 else 1


# -- commands --------------------------------------------------------------------------------
def command_start(args) -> int:
    run_dir = Path(args.run_dir).resolve()
    try:
        specs, info = build_specs(args)
    except (LaunchError, ValueError) as error:
        print(f"deploy start: {error}", file=sys.stderr)
        return 2
    if args.foreground:
        if running_supervisor(run_dir):
            print(f"deploy start: a supervisor already runs in {run_dir}", file=sys.stderr)
            return 1
        save_launch(run_dir, specs, {**info, "run_dir": str(run_dir)})
        return supervise(run_dir, log_file=True)
    try:
        launch(run_dir, specs, info, args.wait)
    except LaunchError as error:
        print(f"deploy start: {error}", file=sys.stderr)
        return 1
    print(f"logs in {run_dir}; balltrack status --run-dir {args.run_dir}; "
          f"balltrack deploy stop --run-dir {args.run_dir}")
    return 0


def command_stop(args) -> int:
    return stop_run(Path(args.run_dir).resolve(), args.timeout)


def collect_status(run_dir: Path, timeout: float, network: bool = True) -> dict:
    status = read_status(run_dir)
    if status is None:
        return {"run_dir": str(run_dir), "supervisor": {"running": False}, "children": {},
                "error": "no status.json (never started here?)"}
    supervisor = status["supervisor"]
    supervisor["running"] = bool(supervisor.get("pid")) and running_supervisor(run_dir) == supervisor["pid"]
    for child in status["children"].values():
        child["running"] = bool(child["pid"]) and supervisor["running"] and pid_alive(child["pid"])
    result = {"run_dir": str(run_dir), **status}
    if network and supervisor["running"]:
        found, error = network_status(supervisor, timeout)
        result["network_error"] = error
        robots = supervisor.get("namespaces") or []
        for name, child in status["children"].items():
            # Each service of the process, under each robot it serves (robot1/detector...).
            entries = {}
            for service in (service for service in process_services(name) if service in SERVICES):
                for namespace in serving_namespaces(supervisor, service):
                    alive, stats = (found or {}).get(namespace, (set(), {}))
                    entries[f"{namespace}/{service}" if namespace in robots else service] = {
                        "alive": None if found is None else service in alive, "stats": stats.get(service)}
            if len(entries) == 1:
                (entry,) = entries.values()
                child["alive"], child["stats"] = entry["alive"], entry["stats"]
            elif entries:  # (services joined in one process, or robots: alive when all are)
                child["services"] = entries
                child["alive"] = None if found is None else all(entry["alive"] for entry in entries.values())
    return result


def build_parser(prog: str = "python -m balltrack.deploy") -> ArgumentParser:
    parser = ArgumentParser(prog=prog, description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, parser_class=ArgumentParser)

    def with_run_dir(sub):
        sub.add_argument("--run-dir", default=DEFAULT_RUN_DIR, metavar="DIR",
                         help=f"the run folder: logs, pid files, status (default {DEFAULT_RUN_DIR})")
        return sub

    start = with_run_dir(commands.add_parser("start", help="start a router and services under the supervisor"))
    start.add_argument("--router", action="store_true", help="also run a Zenoh router (first)")
    start.add_argument("--listen", action="append", metavar="ENDPOINT",
                       help=f"the router's endpoint, repeatable (default {DEFAULT_LISTEN})")
    start.add_argument("--router-connect", action="append", default=[], metavar="ENDPOINT",
                       help="another host's router for ours to join (a cluster), repeatable")
    start.add_argument("--router-config", metavar="FILE",
                       help="a Zenoh json5 config for the router (e.g. deploy/zenoh/router.json5)")
    start.add_argument("--services", default=",".join(CORE_SERVICES),
                       help=f"comma-separated services to run (default {','.join(CORE_SERVICES)}; "
                            f"known: {','.join(SERVICES)})")
    start.add_argument("--connect", action="append", metavar="ENDPOINT",
                       help="the router the services use, repeatable (default: ours with --router, "
                            "else $BALLTRACK_CONNECT or tcp/127.0.0.1:7447)")
    start.add_argument("--namespace", default=os.environ.get("BALLTRACK_NAMESPACE", ""), metavar="NS",
                       help="key prefix for every service, e.g. robot1")
    start.add_argument("--namespaces", metavar="NS,NS,...",
                       help="robots that each process of detector, locator and follower serves, each "
                            "under its namespace (robot1,robot2; a simulator holding them: --set "
                            "simulator.robots=2); with --secure, a fleet's profile (secure init --robots); "
                            "not with --namespace")
    start.add_argument("--zenoh-config", metavar="FILE",
                       help="a Zenoh json5 config for the services (e.g. deploy/zenoh/client.json5)")
    start.add_argument("--secure", metavar="DIR",
                       help="a secure profile (balltrack secure init): TLS, passwords, access control")
    start.add_argument("--host", metavar="NAME",
                       help="with --secure --router: this host's router in the profile (default: the only one)")
    start.add_argument("--config-dir", metavar="DIR",
                       help="parameter files DIR/<service>.toml (e.g. deploy/config/demo)")
    start.add_argument("--set", action="append", default=[], dest="overrides",
                       metavar="SERVICE.KEY=VALUE", help="a service parameter, repeatable")
    start.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    start.add_argument("--wait", type=seconds(minimum=0), default=60.0, metavar="SECONDS",
                       help="wait this long for the services' liveliness (0: do not wait)")
    start.add_argument("--foreground", action="store_true",
                       help="run the supervisor in this process (Ctrl-C stops everything)")
    start.set_defaults(handler=command_start)

    stop = with_run_dir(commands.add_parser("stop", help="stop the supervisor and its children"))
    stop.add_argument("--timeout", type=seconds(minimum=0), default=40.0)
    stop.set_defaults(handler=command_stop)

    supervise_command = with_run_dir(commands.add_parser(
        "supervise", help="(internal) run the supervisor of a run folder's launch.json"))
    supervise_command.set_defaults(handler=lambda args: supervise(Path(args.run_dir).resolve(),
                                                                  SupervisorSettings()))
    return parser


def main(argv: list[str] | None = None, prog: str = "python -m balltrack.deploy") -> int:
    args = build_parser(prog).parse_args(argv)
    return args.handler(args)
