"""Opening Zenoh sessions the same way in every process.

Services are clients of a router (``tcp/127.0.0.1:7447`` unless ``--connect`` or the
``BALLTRACK_CONNECT`` environment variable say otherwise). Multicast scouting is off so that
only the routers named are joined: two test runs on one machine never discover each other,
and peers never mesh around a router's access control. The reconnection period is short so
a restarted router is rejoined in a fraction of a second.

Services launched with their own router on one host (``--peer``, which the launcher gives
them; the demo gives it to its recorder too) join it as peers instead, as rmw_zenoh's nodes
do: the router tells each about the others (gossip), and they exchange messages over direct
links, listening on the loopback interface only, so only processes of this host link to them.
A message then crosses one link instead of two and skips the router's process: frame ->
``detected_ball_3d`` took 0.3-0.4 ms less in the demo (``balltrack experiment latency``,
alternated runs). Secure setups stay clients.
"""

import argparse
import json
import os
import re
import threading
from pathlib import Path
from typing import Any

from balltrack.common.keys import validate_namespace

DEFAULT_PORT = 7447
DEFAULT_ENDPOINT = f"tcp/127.0.0.1:{DEFAULT_PORT}"
# How long a client waits for its router at start before giving up (seconds); -1 = forever.
DEFAULT_OPEN_TIMEOUT = float(os.environ.get("BALLTRACK_OPEN_TIMEOUT", "30"))
# A secure profile (`balltrack secure init DIR`, deploy/secure.py): DIR/<role>/client.json5 per
# role, DIR/<host>/router.json5 per router; the settings naming files next to them.
SECURE_CLIENT_CONFIG = "client.json5"
ROUTER_CONFIG = "router.json5"
SECURE_FILE_SETTINGS = tuple(f"transport/link/tls/{name}" for name in (
    "root_ca_certificate", "listen_private_key", "listen_certificate", "connect_private_key",
    "connect_certificate")) + ("transport/auth/usrpwd/dictionary_file",)
# A fleet's profile (`balltrack secure init --robots`) adds DIR/robots/<robot>/<role>/ per robot,
# each reaching only its own robot's keys; a robot's name is a folder name and a user name's part.
ROBOTS_FOLDER = "robots"
ROBOT_NAME = r"[A-Za-z0-9]([A-Za-z0-9._-]*[A-Za-z0-9])?"
# Who the `balltrack` commands (status, echo, config, sim...) are in a secure profile: one that
# reads; pub, sim, config and play ask for --role operator (balltrack/cli/session.py).
DEFAULT_COMMAND_ROLE = "viewer"


def default_endpoints() -> list[str]:
    configured = os.environ.get("BALLTRACK_CONNECT", "")
    return [item for item in configured.split(",") if item.strip()] or [DEFAULT_ENDPOINT]


def add_session_arguments(parser: argparse.ArgumentParser, config_file: bool = True,
                          role: str | None = None, peer: bool = False) -> None:
    """The options every service and command shares: --connect, --namespace, --config, --set,
    --secure (a service's ``role`` is its name; a command takes ``--role``); with ``peer``,
    --peer (``peer_conflict`` says when it cannot be used)."""
    parser.add_argument("--connect", action="append", metavar="ENDPOINT", default=None,
                        help=f"router endpoint, repeatable (default: {DEFAULT_ENDPOINT} "
                             "or $BALLTRACK_CONNECT)")
    parser.add_argument("--namespace", default=os.environ.get("BALLTRACK_NAMESPACE", ""),
                        metavar="NS", help="key prefix, e.g. robot1 (default: none)")
    parser.add_argument("--zenoh-config", default=None, metavar="FILE",
                        help="a Zenoh json5 config file for the session (optional)")
    parser.add_argument("--secure", default=None, metavar="DIR",
                        help="a secure profile (balltrack secure init): use DIR/<role>/client.json5")
    if role is None:
        parser.add_argument("--role", default=DEFAULT_COMMAND_ROLE, metavar="ROLE",
                            help=f"the role with --secure (default {DEFAULT_COMMAND_ROLE}: it reads; pub, sim, "
                                 "config and play need operator)")
    else:
        parser.set_defaults(role=role)
    if peer:
        parser.add_argument("--peer", action="store_true",
                            help="join the router as a peer: messages to and from the other peers of "
                                 "this host go over direct links, not through the router (no --secure, "
                                 "no --zenoh-config; the launcher and the demo give it to what they "
                                 "start beside their own router)")
    if config_file:
        parser.add_argument("--config", default=None, metavar="FILE", help="TOML parameter file")
        parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                            dest="overrides", help="override a parameter, repeatable")


def peer_conflict(args) -> str | None:
    """Why ``--peer`` cannot be used with these options (one line), or None."""
    if getattr(args, "peer", False) and (getattr(args, "secure", None) or getattr(args, "zenoh_config", None)):
        return ("--peer: a peer joins a plain local router (its links bypass a secure router's "
                "access control); drop --secure and --zenoh-config, or --peer")
    return None


class ZenohConfigError(ValueError):
    """A Zenoh setting that Zenoh refuses (a config file, an endpoint); the message is one line
    naming the option it came from."""


def zenoh_reason(error: Exception, in_file: bool = False) -> str:
    """The reason in one of Zenoh's multi-line errors, on one line: its message without the
    source locations and the ``Json5Err(Message { msg: ...`` wrapping; ``in_file`` (an error
    about a config file): after the line and column it points at (``line 2, column 9: ...``)."""
    text = re.sub(r" at /\S+\.rs:\d+\.?", "", str(error)).strip()
    message = (re.search(r'msg: "(.*?)"(?:, location|\s*\})', text, re.S)
               or re.search(r"^\s*= (.+)$", text, re.M))
    reason = message.group(1).strip() if message else (text.splitlines() or [type(error).__name__])[0]
    position = (re.search(r"^\s*--> (\d+):(\d+)", text, re.M)
                or re.search(r"Location \{ line: (\d+), column: (\d+)", text))
    if in_file and position:
        reason = f"line {position.group(1)}, column {position.group(2)}: {reason}"
    return reason


def _insert(config, key: str, value, option: str | None = None) -> None:
    """Set ``key``; a value Zenoh refuses is a ZenohConfigError naming ``option`` (the command's
    option it came from), so that a typo is one line, not a traceback."""
    import zenoh

    shown = ", ".join(map(str, value)) if isinstance(value, list) else value
    try:
        config.insert_json5(key, json.dumps(value))
    except zenoh.ZError as error:
        raise ZenohConfigError(f"{option or key} {shown}: {zenoh_reason(error)}") from None
    if key.endswith("/endpoints"):
        # (Zenoh takes tcp/HOST:99999 here and fails only when it listens or dials)
        for endpoint in value:
            port = re.fullmatch(r"[a-z]+/.*:(\d+)", str(endpoint).split("#", 1)[0].split("?", 1)[0])
            if port and int(port.group(1)) > 65535:
                raise ZenohConfigError(f"{option or key} {shown}: port {port.group(1)} is past 65535")


def _common_settings(config) -> None:
    _insert(config, "scouting/multicast/enabled", False)
    _insert(config, "connect/retry", {"period_init_ms": 100, "period_max_ms": 500,
                                      "period_increase_factor": 1.5})


def load_config_file(path: str | Path):
    """A Zenoh json5 file whose relative file names (certificates, keys, users) are taken
    relative to the file's own folder, so a profile folder works from anywhere."""
    import zenoh

    try:
        config = zenoh.Config.from_file(str(path))
    except zenoh.ZError as error:
        raise ZenohConfigError(f"{path}: {zenoh_reason(error, in_file=True)}") from None
    for setting in SECURE_FILE_SETTINGS:
        value = json.loads(config.get_json(setting))
        if isinstance(value, str) and value and not os.path.isabs(value):
            _insert(config, setting, str(Path(path).resolve().parent / value))
    return config


def secure_client_path(directory: str | Path, role: str, namespace: str = "") -> Path:
    """A role's client config in a secure profile; ValueError with one line if absent. A process
    serving one robot (``namespace``) uses the robot's own credentials where the profile has
    them (a fleet's: ``secure init --robots``), the role's fleet-wide ones otherwise."""
    path = Path(directory) / role / SECURE_CLIENT_CONFIG
    robot = (Path(directory) / ROBOTS_FOLDER / namespace / role / SECURE_CLIENT_CONFIG
             if re.fullmatch(ROBOT_NAME, namespace) else None)
    if robot is not None and robot.is_file():
        return robot
    if not path.is_file():
        raise ValueError(f"--secure: no {f'{robot} nor ' if robot else ''}{path} (not a profile from "
                         f"`balltrack secure init`, or role {role}'s folder was not copied here)")
    return path


def served_namespace(args) -> str:
    """The one robot a process serves (``--namespace``, or ``--namespaces`` naming one), whose
    credentials it uses in a fleet's profile; "" when it serves several."""
    namespaces = getattr(args, "namespaces", None)
    if getattr(args, "discover_robots", False) or (isinstance(namespaces, list) and len(namespaces) > 1):
        return ""
    if isinstance(namespaces, list) and namespaces:
        return namespaces[0]
    return validate_namespace(getattr(args, "namespace", None) or "")


def secure_router_path(directory: str | Path, host: str | None = None) -> Path:
    """A host's router config in a secure profile: ``host``'s, else the only one in the folder."""
    directory = Path(directory)
    if host is None:
        hosts = sorted(path.parent.name for path in directory.glob(f"*/{ROUTER_CONFIG}"))
        if len(hosts) != 1:
            raise ValueError(f"--secure: {directory} holds routers for {', '.join(hosts) or 'no host'}; "
                             "name one with --host")
        host = hosts[0]
    path = directory / host / ROUTER_CONFIG
    if not path.is_file():
        raise ValueError(f"--secure: no {path} (host {host} is not in this profile)")
    return path


# A peer's own listening endpoint: any free port, on the loopback interface only.
PEER_LISTEN = "tcp/127.0.0.1:0"


def client_config(endpoints: list[str] | None = None, zenoh_config_file: str | None = None,
                  open_timeout: float | None = None, peer: bool = False):
    """A client of the routers at ``endpoints``; with ``peer``, a peer that joins them and
    links directly to their other peers (see above; not with ``zenoh_config_file``)."""
    import zenoh

    if peer and zenoh_config_file:
        raise ValueError("a peer session takes no Zenoh config file")
    config = load_config_file(zenoh_config_file) if zenoh_config_file else zenoh.Config()
    if not zenoh_config_file:
        _insert(config, "mode", "peer" if peer else "client")
        _common_settings(config)
    if peer:
        _insert(config, "listen/endpoints", [PEER_LISTEN])
        # (a peer opens without its router by default; like a client, give up instead)
        _insert(config, "connect/exit_on_failure", True)
    if endpoints or not zenoh_config_file:
        _insert(config, "connect/endpoints", list(endpoints or default_endpoints()), "--connect")
    timeout = DEFAULT_OPEN_TIMEOUT if open_timeout is None else open_timeout
    _insert(config, "connect/timeout_ms", -1 if timeout < 0 else int(timeout * 1000))
    return config


def router_config(listen: list[str], connect: list[str] | None = None,
                  zenoh_config_file: str | None = None):
    """A router listening on ``listen``; ``connect`` joins other routers (a cluster)."""
    import zenoh

    config = load_config_file(zenoh_config_file) if zenoh_config_file else zenoh.Config()
    _insert(config, "mode", "router")
    if not zenoh_config_file:
        _common_settings(config)
        # Read-only admin space: `balltrack topic list` shows who publishes and subscribes.
        _insert(config, "adminspace", {"enabled": True, "permissions": {"read": True, "write": False}})
        # Routers keep retrying their peers forever, so a cluster heals after a restart.
        _insert(config, "connect/timeout_ms", -1)
    if listen:
        _insert(config, "listen/endpoints", list(listen), "--listen")
    if connect:
        _insert(config, "connect/endpoints", list(connect), "--connect")
    return config


class SessionOpenError(RuntimeError):
    pass


def open_session(endpoints: list[str] | None = None, zenoh_config_file: str | None = None,
                 open_timeout: float | None = None, peer: bool = False):
    """Open a client (or ``peer``) session; SessionOpenError with a one-line reason if no
    router answers, ZenohConfigError if Zenoh refuses a setting."""
    import zenoh

    config = client_config(endpoints, zenoh_config_file, open_timeout, peer)
    try:
        return zenoh.open(config)
    except Exception as error:  # zenoh raises ZError with a multi-line message
        where = ", ".join(dialled_endpoints(config) or endpoints or default_endpoints())
        raise SessionOpenError(f"cannot reach a Zenoh router at {where}: {zenoh_reason(error)}") from None


def config_endpoints(config, section: str, modes: tuple[str, ...]) -> list[str]:
    """The ``section`` ("listen" or "connect") endpoints of a Zenoh ``config``: a list, or,
    per mode as Zenoh keeps its own defaults, the first of ``modes`` that has some; [] when
    there are none or Zenoh cannot show them."""
    try:
        endpoints = json.loads(config.get_json(f"{section}/endpoints"))
    except Exception:  # (a config Zenoh cannot show: the caller names what it was given)
        return []
    if isinstance(endpoints, dict):
        endpoints = next((endpoints[mode] for mode in modes if endpoints.get(mode)), [])
    return [str(endpoint) for endpoint in endpoints or []]


def dialled_endpoints(config) -> list[str]:
    """The endpoints a session of ``config`` dials: those given, or those of its config file
    (a secure profile's ``tls/...``); [] when it names none."""
    return config_endpoints(config, "connect", ("client", "peer"))


def close_session(session) -> str | None:
    """Close ``session``; None when closed, else the one-line reason it could not be.

    Zenoh's close tells the router and waits for that to be sent. With the network gone (a
    pulled cable, a host cut off) it gives up after about 10 s and raises; the session is
    closed on this side all the same, and the router forgets it when its lease ends. A
    process stopping then has done what it was asked: callers log the reason and exit as usual.
    """
    import zenoh

    try:
        session.close()
    except zenoh.ZError as error:
        return f"the router was not told that this session closed ({zenoh_reason(error)}); " \
               "it forgets the session when its lease ends"
    return None


def open_until_stopped(args, stop, open_timeout: float | None = None):
    """``open_from_args`` in a thread of its own, so that ``stop`` (SIGINT, SIGTERM) set while
    the router is still out of reach ends the wait at once: the session, or None when stopped
    first; SessionOpenError and ZenohConfigError as ``open_from_args`` raises them. When None,
    the opening thread is still inside Zenoh and cannot be joined: the caller ends the process
    with ``os._exit`` (nothing is open to close)."""
    opened: dict[str, Any] = {}

    def opening() -> None:
        try:
            opened["session"] = open_from_args(args, open_timeout)
        except (SessionOpenError, ZenohConfigError) as error:
            opened["error"] = error
        finally:
            opened["done"] = True

    threading.Thread(target=opening, name="session-open", daemon=True).start()
    while "done" not in opened and not stop.wait(0.1):
        pass
    if "error" in opened:
        raise opened["error"]
    return opened.get("session")


def open_from_args(args, open_timeout: float | None = None):
    zenoh_config = getattr(args, "zenoh_config", None)
    if getattr(args, "secure", None):
        try:
            zenoh_config = str(secure_client_path(args.secure, args.role, served_namespace(args)))
        except ValueError as error:  # (a bad --secure, as a bad --zenoh-config: not worth waiting for)
            raise ZenohConfigError(str(error)) from None
    return open_session(args.connect, zenoh_config, open_timeout, getattr(args, "peer", False))
