"""``balltrack config``: a running service's parameters, read, changed, saved and restored.

    balltrack config detector                    # read (JSON)
    balltrack config detector v_min=30 param2=18 # change live (all or nothing)
    balltrack config dump detector > detector.yaml
    balltrack config load detector detector.yaml # set them again (--config at start reads TOML)
    balltrack config detector --describe         # every parameter: type, default, bounds, meaning
"""

import json
import sys
from pathlib import Path

import yaml

from balltrack.cli.session import close_or_report, networked, open_or_report, refused_for_role
from balltrack.common import keys as key_table
from balltrack.common.config import ConfigError, parse_overrides
from balltrack.common.keys import Keys
from balltrack.common.messages import MessageError, decode, encode, shorten
from balltrack.common.shutdown import stop_on_signals

ACTIONS = ("dump", "load")


def ask(args, service: str, request: dict, field: str = "config") -> tuple[int, dict | None]:
    """(exit status, the ConfigReply's ``field``) after one ConfigRequest to ``service``."""
    # (a stop while the router is out of reach ends the command at once, status 0, as echo's
    # does; after that the stop waits for the answer, at most --timeout)
    session = open_or_report(args, stop_on_signals())
    if session is None:
        return 1, None
    key = Keys(args.namespace)(key_table.config_key(service))
    try:
        replies = list(session.get(key, payload=encode("ConfigRequest", request), timeout=args.timeout))
    finally:
        close_or_report(args, session)
    for reply in replies:
        if reply.ok is None:
            continue
        try:
            answer = decode("ConfigReply", reply.ok.payload.to_bytes())
        except MessageError as error:
            print(f"balltrack config: {service} answered badly: {error}", file=sys.stderr)
            return 1, None
        if not answer["ok"]:
            print(f"balltrack config: {answer.get('error')}", file=sys.stderr)
            return 2, None
        return 0, answer.get(field)
    # (a secure router's access control drops what a role may not ask, without a word)
    unanswered = (f"; or the access control does not let role {args.role} ask it" if getattr(args, "secure", None)
                  else "")
    print(f"balltrack config: no {service} answered on {key}{unanswered}", file=sys.stderr)
    return 1, None


def _read_file(path: str, service: str) -> dict:
    """A YAML (or JSON) map of parameters; a ``service:`` section is accepted as in TOML files."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except OSError as error:
        raise ConfigError(f"{path}: {error.strerror}") from None
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not YAML ({shorten(str(error).splitlines()[0], 100)})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not YAML (not UTF-8 text)") from None
    if isinstance(data, dict) and isinstance(data.get(service), dict):
        data = data[service]
    if not isinstance(data, dict) or not data:
        raise ConfigError(f"{path}: expected a map of parameter names to values")
    return data


def command_config(args) -> int:
    words = [args.target, *args.rest]
    action = words[0] if words[0] in ACTIONS else None
    operands = words[1:] if action else words
    service = operands[0] if operands else None
    expected = {"dump": 1, "load": 2}.get(action)
    if service not in key_table.SERVICES or (expected and len(operands) != expected):
        usage = {"dump": "dump SERVICE", "load": "load SERVICE FILE"}.get(action, "SERVICE [KEY=VALUE...]")
        print(f"balltrack config: expected {usage}, with SERVICE one of {', '.join(key_table.SERVICES)}",
              file=sys.stderr)
        return 2
    try:
        if action == "load":
            changes = _read_file(operands[1], service)
        else:
            changes = parse_overrides(operands[1:]) if action is None else {}
    except ConfigError as error:
        print(f"balltrack config: {error}", file=sys.stderr)
        return 2
    # (a read too: the access control cannot tell a query that reads from one that sets)
    if refused_for_role(args, "queries", [key_table.config_key(service)]):
        return 2
    if args.describe:
        status, parameters = ask(args, service, {"describe": True, **({"set": changes} if changes else {})},
                                 "parameters")
        if status == 0 and parameters is None:
            print(f"balltrack config: {service} did not describe its parameters", file=sys.stderr)
            return 1
        if parameters is not None:
            print(json.dumps(parameters, indent=2))
        return status
    status, config = ask(args, service, {"set": changes} if changes else {})
    if config is None:
        return status
    if action == "dump":
        # (YAML, as `ros2 param dump`; --config reads TOML)
        sys.stdout.write(f"# balltrack config dump {service}: load with `balltrack config load {service} "
                         "FILE`; --config at start takes these keys as TOML (key = value), not this YAML\n")
        sys.stdout.write(yaml.safe_dump(config, sort_keys=False))
    elif action == "load":
        print(f"{service}: {len(changes)} parameters loaded", file=sys.stderr)
    else:
        print(json.dumps(config, indent=2))
    return 0


def register(commands) -> None:
    config = networked(commands, "config", "read, change, dump or load a service's parameters live",
                       command_config)
    config.add_argument("target", metavar="SERVICE|dump|load")
    config.add_argument("rest", nargs="*", default=[], metavar="KEY=VALUE | SERVICE [FILE]")
    config.add_argument("--describe", action="store_true",
                        help="print every parameter's type, default, bounds or choices and meaning")
