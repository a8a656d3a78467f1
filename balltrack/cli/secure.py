"""``balltrack secure init DIR --hosts NAME[,NAME...] [--robots NAME[,NAME...]]``: a secure deployment profile;
``balltrack secure renew DIR NAME[,NAME...]``: new credentials for some of its roles or hosts.

A certificate authority, a router certificate per host, a certificate and a password per role,
the routers' users file and the Zenoh json5 configs (TLS with mutual authentication, user and
password, access control), with ``--robots`` each robot's own credentials, confined to its
namespace: see ``deploy/secure.py``. Then ``balltrack router --secure DIR``,
``balltrack run SERVICE --secure DIR``, ``balltrack deploy start --secure DIR``.
"""

import argparse
import sys

from balltrack.common.arguments import integer
from balltrack.deploy.secure import (DEFAULT_PORT, LEAF_DAYS, ROLES, ProfileError, init_profile, parse_hosts,
                                     parse_robots, renew)


def _attempt(args, work) -> dict | int:
    """``work()``'s summary, or the exit status after one line on stderr."""
    try:
        return work()
    except (ProfileError, ValueError) as error:
        print(f"balltrack secure {args.action}: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"balltrack secure {args.action}: cannot write {args.directory}: {error.strerror or error}",
              file=sys.stderr)
        return 1


def command_init(args) -> int:
    summary = _attempt(args, lambda: init_profile(args.directory, parse_hosts(args.hosts), args.port, args.namespace,
                                                  local=not args.no_localhost, force=args.force, days=args.days,
                                                  robots=parse_robots(args.robots) if args.robots is not None else []))
    if isinstance(summary, int):
        return summary
    directory = summary["directory"]
    print(f"secure profile in {directory} (CA: {directory}/ca; keep ca/ca.key on this machine only)")
    for host, names in summary["router_names"].items():
        print(f"  router {host:<12} {directory}/{host}/   certificate names: {', '.join(names)}")
    print(f"  roles: {', '.join(summary['roles'])}   ({directory}/<role>/, "
          f"clients dial {summary['client_endpoint']} unless --connect)")
    if summary["robots"]:
        print(f"  robots: {', '.join(summary['robots'])}   ({directory}/robots/<robot>/<role>/ for "
              f"{', '.join(summary['robot_roles'])}: each reaches only <robot>/...; run with --namespace <robot>)")
    return 0


def command_renew(args) -> int:
    names = [name.strip() for name in args.names.split(",") if name.strip()]

    def renewing() -> dict:
        if not names:
            raise ProfileError("name a role or a host, e.g. operator or robot")
        return renew(args.directory, names, args.days)

    summary = _attempt(args, renewing)
    if isinstance(summary, int):
        return summary
    print(f"renewed {', '.join(names)}: new keys, certificates and passwords in {', '.join(summary['changed'])}")
    for path in summary["users"]:
        print(f"  {path}: the new password")
    print("copy these to their hosts and restart the routers (they read users.txt when they start) and the "
          "renewed roles' processes; the old password is refused from then on")
    return 0


def register(commands) -> None:
    secure = commands.add_parser("secure", help="a secure deployment profile (secure init --help, secure renew --help)",
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
    init.add_argument("--robots", default=None, metavar="NAME[,NAME...]",
                      help="a fleet: each robot's namespace is its name, and it gets credentials of its own for "
                           "each service, allowed only its own keys (not with --namespace)")
    init.add_argument("--no-localhost", action="store_true",
                      help="router certificates name only the hosts, not localhost/127.0.0.1 "
                           "(then every client dials a host name)")
    # (a lifetime past the year 9999 cannot be written in a certificate: 100 years is plenty)
    init.add_argument("--days", type=integer(minimum=1, maximum=36500), default=LEAF_DAYS,
                      help=f"certificate lifetime (default {LEAF_DAYS}, at most 36500)")
    init.add_argument("--force", action="store_true", help="replace an existing profile (new keys, passwords)")
    init.set_defaults(handler=command_init, roles=list(ROLES))
    again = actions.add_parser("renew", help="new key, certificate and password for roles or hosts, the rest kept",
                               description="A new key, certificate and password for each role or host named, "
                                           "signed by the profile's CA (DIR/ca/ca.key): the role's folder, or the "
                                           "host's router files, and their lines in the hosts' users.txt. The other "
                                           "keys and the access control stay.")
    again.add_argument("directory", metavar="DIR", help="the profile folder, with its CA")
    again.add_argument("names", metavar="NAME[,NAME...]",
                       help=f"roles ({', '.join(ROLES)}), a robot's roles (follower@robot1) or hosts of the profile")
    again.add_argument("--days", type=integer(minimum=1, maximum=36500), default=LEAF_DAYS,
                       help=f"certificate lifetime (default {LEAF_DAYS}, at most 36500)")
    again.set_defaults(handler=command_renew)
