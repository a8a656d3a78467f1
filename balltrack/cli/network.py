"""Commands that talk to running services: router, status, sim."""

import json
import sys
from pathlib import Path

from balltrack.cli.session import close_or_report, networked, open_or_report, refused_for_role
from balltrack.common import keys as key_table
from balltrack.common.config import ConfigError, parse_overrides
from balltrack.common.messages import SIM_OPS
from balltrack.common.session import (DEFAULT_PORT, ZenohConfigError, config_endpoints, router_config,
                                      secure_router_path, zenoh_reason)
from balltrack.common.shutdown import stop_on_signals
from balltrack.common.keys import validate_namespace
from balltrack.common.status import other_figures, service_status, services_by_namespace


def command_router(args) -> int:
    import zenoh

    zenoh_config = args.zenoh_config
    if args.secure:
        try:
            zenoh_config = str(secure_router_path(args.secure, args.host))
        except ValueError as error:
            print(f"balltrack router: {error}", file=sys.stderr)
            return 2
    # A config file's own endpoints stand unless --listen replaces them.
    listen = args.listen or ([] if zenoh_config else [f"tcp/0.0.0.0:{DEFAULT_PORT}"])
    try:
        config = router_config(listen, args.connect, zenoh_config)
    except ZenohConfigError as error:
        print(f"balltrack router: {error}", file=sys.stderr)
        return 2
    try:
        listen = listen or config_endpoints(config, "listen", ("router",))
        session = zenoh.open(config)
    except Exception as error:
        print(f"balltrack router: cannot listen on {', '.join(map(str, listen)) or 'its endpoints'}: "
              f"{zenoh_reason(error)}", file=sys.stderr)
        return 1
    # The endpoints as given, then where they are reached when that differs: the port the
    # system chose for port 0, each interface's address for 0.0.0.0.
    listening = ", ".join(listen)
    locators = own_locators(session)
    names = tls_names(config)
    if names is not None:
        # (a TLS client checks the router's name: only those its certificate holds are reached)
        ports = sorted({endpoint.rsplit(":", 1)[-1] for endpoint in locators or listen if endpoint.startswith("tls/")})
        listening += f" (reached at {', '.join(f'tls/{name}:{port}' for port in ports for name in names)}: " \
                     "the names its certificate holds)"
    elif locators and sorted(locators) != sorted(listen):
        listening += f" (reached at {', '.join(locators)})"
    print(f"router {session.zid()} listening on {listening}", flush=True)
    stop = stop_on_signals()
    while not stop.wait(0.5):
        pass
    close_or_report(args, session)
    return 0


def tls_names(config) -> list[str] | None:
    """The names a TLS router's certificate holds (None: no TLS certificate in ``config``)."""
    from balltrack.deploy.secure import certificate_names

    try:
        path = json.loads(config.get_json("transport/link/tls/listen_certificate"))
    except Exception:  # (no TLS section)
        return None
    if not path:
        return None
    try:
        return certificate_names(path)
    except (OSError, ValueError):  # (Zenoh says what is wrong with it when it listens)
        return None


def own_locators(session, timeout: float = 2.0) -> list[str]:
    """The endpoints a router session listens on, as its admin space reports them: a port 0
    replaced by the port the system chose, an unspecified address (0.0.0.0) by each interface's.
    Empty when its admin space is not readable (a configuration file without it)."""
    import zenoh

    try:
        for reply in session.get(f"@/{session.zid()}/router", timeout=timeout):
            if reply.ok is not None:
                return [str(locator) for locator in json.loads(reply.ok.payload.to_bytes())["locators"]]
    except (zenoh.ZError, ValueError, KeyError, TypeError):
        pass
    return []


def _run_folder_status(args) -> int:
    """The supervisor's view of a run folder: pids, restarts, last exits, with liveliness and stats."""
    from balltrack.deploy.cli import collect_status

    run_dir = Path(args.run_dir).resolve()
    result = collect_status(run_dir, args.timeout, network=not args.no_network)
    if args.json:
        print(json.dumps(result, indent=2))
        return _run_folder_status_code(result)
    supervisor = result["supervisor"]
    if "error" in result:
        print(f"{run_dir}: {result['error']}", file=sys.stderr)
        return 1
    state = "running" if supervisor["running"] else f"not running ({supervisor.get('state')})"
    print(f"supervisor pid {supervisor.get('pid')} {state}; run folder {run_dir}")
    if result.get("network_error"):
        print(f"network: {result['network_error']}")
    # (a process of joined services is named after all of them: detector+locator+follower)
    width = max([12, *(len(name) for name in result["children"])])
    print(f"{'name':<{width}} {'pid':>7} {'state':<8} {'restarts':>8} {'last exit':<18} {'alive':<5} "
          f"{'received':>8} {'published':>9} {'rejected':>8} {'dropped':>7} {'p50_ms':>7} {'p99_ms':>7} other")

    def shown(entry: dict) -> tuple[str, str]:
        alive = {True: "yes", False: "no", None: "?"}[entry.get("alive")] if "alive" in entry else "-"
        stats = entry.get("stats")
        figures = (f"{stats['received']:>8} {stats['published']:>9} {stats['rejected']:>8} "
                   f"{stats['dropped']:>7} {stats['p50_ms']:>7.2f} {stats['p99_ms']:>7.2f} "
                   f"{other_figures(stats)}") if stats else ""
        return alive, figures

    for name, child in result["children"].items():
        alive, figures = shown(child)
        pid = child["pid"] if child.get("running") else "-"
        print(f"{name:<{width}} {pid!s:>7} {child['state']:<8} {child['restarts']:>8} "
              f"{child.get('last_exit_text') or '-':<18} {alive:<5} {figures}".rstrip())
        for service, entry in child.get("services", {}).items():  # (each of a joined process's)
            alive, figures = shown(entry)
            print(f"{'  ' + service:<{width}} {'':>7} {'':<8} {'':>8} {'':<18} {alive:<5} {figures}".rstrip())
    return _run_folder_status_code(result)


def _run_folder_status_code(result: dict) -> int:
    """0: the supervisor runs and no child has failed; 1: it does not run; 3: it runs, but a
    child is ``failed`` (given up or misconfigured: not restarted), for scripts that check health."""
    if not result["supervisor"].get("running"):
        return 1
    return 3 if any(child.get("state") == "failed" for child in result.get("children", {}).values()) else 0



def command_status(args) -> int:
    if args.run_dir:
        return _run_folder_status(args)
    for option, given in (("--json", args.json), ("--no-network", args.no_network)):
        if given:  # (ignored, a script would read the table as JSON, or wait on a router)
            print(f"balltrack status: {option}: only with --run-dir", file=sys.stderr)
            return 2
    session = open_or_report(args, stop_on_signals())  # (see cli/config.ask)
    if session is None:
        return 1
    alive, stats = service_status(session, args.namespace, args.timeout)
    others = {namespace: services for namespace, services in services_by_namespace(session, args.timeout).items()
              if namespace != validate_namespace(args.namespace)}
    close_or_report(args, session)
    print(f"{'service':<12} {'alive':<6} {'received':>9} {'published':>9} {'rejected':>8} "
          f"{'dropped':>8} {'p50_ms':>7} {'p99_ms':>7} other")
    for service in key_table.SERVICES:
        row = stats.get(service)
        figures = (f"{row['received']:>9} {row['published']:>9} {row['rejected']:>8} "
                   f"{row['dropped']:>8} {row['p50_ms']:>7.2f} {row['p99_ms']:>7.2f} "
                   f"{other_figures(row)}") if row else ""
        print(f"{service:<12} {'yes' if service in alive else 'no':<6} {figures}".rstrip())
    if others:
        # (the robots of a fleet each have a namespace: say where they are, not just "no")
        print("alive in other namespaces (balltrack status --namespace NS): "
              + "; ".join(f"{namespace or '(none)'}: {', '.join(sorted(services))}"
                          for namespace, services in sorted(others.items())))
    return 0


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
    from balltrack.services.simulator.requests import checked_form

    try:
        request = {"op": args.op, **{key: _argument_value(value)
                                     for key, value in parse_overrides(args.arguments).items()}}
        # (what the simulator would refuse whatever its world is: refused here, as a bad argument)
        checked_form(request)
    except (ConfigError, ValueError) as error:
        print(f"balltrack sim: {error}", file=sys.stderr)
        return 2
    if refused_for_role(args, "queries", [key_table.SIM_CONTROL]):
        return 2
    session = open_or_report(args, stop_on_signals())  # (see cli/config.ask)
    if session is None:
        return 1
    reply = send_command(session, request, args.namespace, args.timeout)
    close_or_report(args, session)
    if not reply["ok"]:
        print(f"balltrack sim: {reply.get('error')}", file=sys.stderr)
        return 1
    print(json.dumps(reply))
    return 0



def register(commands) -> None:
    router = commands.add_parser("router", help="run a Zenoh router")
    router.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help=f"endpoint to listen on, repeatable (default tcp/0.0.0.0:{DEFAULT_PORT})")
    router.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="another router to join (a cluster), repeatable")
    router.add_argument("--zenoh-config", metavar="FILE", help="a Zenoh json5 config file")
    router.add_argument("--secure", metavar="DIR", help="a secure profile: DIR/HOST/router.json5 "
                        "(balltrack secure init)")
    router.add_argument("--host", metavar="NAME", help="with --secure: this host's name in the profile "
                        "(default: the only host in DIR)")
    router.set_defaults(handler=command_router)

    status = networked(commands, "status", "which services are alive, with their stats; with "
                       "--run-dir also the supervisor's pids, restarts and last exits", command_status)
    status.add_argument("--run-dir", metavar="DIR", help="a run folder of `balltrack deploy start` "
                        "(e.g. runs/default)")
    status.add_argument("--json", action="store_true", help="with --run-dir: machine-readable output")
    status.add_argument("--no-network", action="store_true", help="with --run-dir: the folder only, no Zenoh")
    sim = networked(commands, "sim", "control the simulator: reset, set_light, place_ball, "
                    "place_robot", command_sim)
    sim.add_argument("op", choices=SIM_OPS)
    sim.add_argument("arguments", nargs="*", default=[], metavar="KEY=VALUE",
                     help="e.g. diffuse=0.1, id=tennis position=1.5,0.2, scenario=search")
