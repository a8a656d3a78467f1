"""``balltrack secure init DIR --hosts NAME[,NAME...]``: a secure deployment profile.

A certificate authority, a router certificate per host, a certificate and a password per role,
the routers' users file and the Zenoh json5 configs (TLS with mutual authentication, user and
password, access control): see ``deploy/secure.py``. Then ``balltrack router --secure DIR``,
``balltrack run SERVICE --secure DIR``, ``balltrack deploy start --secure DIR``.
"""

import argparse
import sys

from balltrack.common.arguments import integer
from balltrack.deploy.secure import DEFAULT_PORT, ROLES, ProfileError, init_profile, parse_hosts


def command_init(args) -> int:
    try:
        summary = init_profile(args.directory, parse_hosts(args.hosts), args.port, args.namespace,
                               local=not args.no_localhost, force=args.force, days=args.days)
    except (ProfileError, ValueError) as error:
        print(f"balltrack secure init: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"balltrack secure init: cannot write {args.directory}: {error.strerror or error}", file=sys.stderr)
        return 1
    directory = summary["directory"]
    print(f"secure profile in {directory} (CA: {directory}/ca; keep ca/ca.key on this machine only)")
    for host, names in summary["router_names"].items():
        print(f"  router {host:<12} {directory}/{host}/   certificate names: {', '.join(names)}")
    print(f"  roles: {', '.join(summary['roles'])}   ({directory}/<role>/, "
          f"clients dial {summary['client_endpoint']} unless --connect)")
    return 0


def register(commands) -> None:
    secure = commands.add_parser("secure", help="a secure deployment profile (secure init --help)",
                                 description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    actions = secure.add_subparsers(dest="action", required=True, parser_class=type(secure))
    init = actions.add_parser("init", help="create keys, certificates, passwords and Zenoh configs",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    init.add_argument("directory", metavar="DIR", help="the profile folder to create")
    init.add_argument("--hosts", required=True, metavar="NAME[,NAME...]",
                      help="the hosts running a router: the names or addresses clients dial")
    init.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"the routers' TLS port (default {DEFAULT_PORT})")
    init.add_argument("--namespace", default="", metavar="NS",
                      help="the key prefix the services use (the access rules name full keys)")
    init.add_argument("--no-localhost", action="store_true",
                      help="router certificates name only the hosts, not localhost/127.0.0.1 "
                           "(then every client dials a host name)")
    # (a lifetime past the year 9999 cannot be written in a certificate: 100 years is plenty)
    init.add_argument("--days", type=integer(minimum=1, maximum=36500), default=825,
                      help="certificate lifetime (default 825, at most 36500)")
    init.add_argument("--force", action="store_true", help="replace an existing profile (new keys, passwords)")
    init.set_defaults(handler=command_init, roles=list(ROLES))
