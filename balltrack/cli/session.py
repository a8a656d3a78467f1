"""What every networked ``balltrack`` command shares: its options and opening its session."""

import os
import sys

from balltrack.common.arguments import seconds
from balltrack.common.keys import Keys
from balltrack.common.session import (SessionOpenError, ZenohConfigError, add_session_arguments, close_session,
                                      open_from_args, open_until_stopped, zenoh_reason)


def networked(commands, name: str, help_text: str, handler, timeout: float = 3.0, peer: bool = False):
    """A subcommand with the session options (``peer``: and --peer) and ``--timeout``."""
    sub = commands.add_parser(name, help=help_text, description=help_text)
    add_session_arguments(sub, config_file=False, peer=peer)
    sub.add_argument("--timeout", type=seconds(minimum=0), default=timeout,
                     help=f"seconds to wait for a router and for answers (default {timeout:g})")
    sub.set_defaults(handler=handler)
    return sub


def check_keys(keys: list[str], namespace: str) -> None:
    """ValueError naming the first of ``keys`` Zenoh refuses as a key expression (in
    ``namespace``): said before a command waits for a router and subscribes (echo, hz, record:
    a traceback, and record's empty file, after)."""
    import zenoh

    for key in keys:
        try:
            zenoh.KeyExpr(Keys(namespace)(key))
        except zenoh.ZError as error:
            raise ValueError(f"{key!r}: not a key expression ({zenoh_reason(error)})") from None


def roles_that_may(kind: str, key: str) -> list[str]:
    """The roles of a secure profile whose access control lets them ``kind`` ("puts" or
    "queries", as in ``deploy.secure.permissions``) on ``key`` (without namespace), as
    ``balltrack secure init`` writes it."""
    import zenoh

    from balltrack.deploy.secure import ROLES, permissions

    return [role for role in ROLES
            if any(zenoh.KeyExpr(allowed).includes(zenoh.KeyExpr(key)) for allowed in getattr(permissions(role), kind))]


def refused_for_role(args, kind: str, keys: list[str]) -> bool:
    """With --secure: True after one line on stderr when the profile's access control does not
    let this command's ``--role`` ``kind`` on one of ``keys``: said before anything is sent
    (the router would drop it without a word; it still does when this check is not made). A
    role the profile's code does not know (added by hand) is left to the router."""
    from balltrack.deploy.secure import ROLES

    if not getattr(args, "secure", None) or args.role not in ROLES:
        return False
    for key in keys:
        allowed = roles_that_may(kind, key)
        if args.role in allowed:
            continue
        # (a person's role first: the services' own are for the services)
        needed = [role for role in allowed if not ROLES[role].service] or allowed
        if needed:
            either = needed[0] if len(needed) == 1 else f"{', '.join(needed[:-1])} or {needed[-1]}"
            reason = f"{key} needs --role {either}"
        else:
            reason = f"no role of the profile may {'put on' if kind == 'puts' else 'ask'} {key}"
        print(f"balltrack {args.command}: {reason} (this client is {args.role})", file=sys.stderr)
        return True
    return False


def open_or_report(args, stop=None):
    """The session, or None after a one-line reason on stderr. ``stop``: the command's event
    of SIGINT and SIGTERM; set while the router is still out of reach, it ends the command at
    once, status 0, as it does once the command runs (without it, the wait goes on for up to
    ``--timeout`` seconds)."""
    try:
        if stop is None:
            return open_from_args(args, open_timeout=args.timeout)
        session = open_until_stopped(args, stop, open_timeout=args.timeout)
    except (SessionOpenError, ZenohConfigError) as error:
        print(f"balltrack {args.command}: {error}", file=sys.stderr)
        return None
    if session is None:
        sys.stdout.flush()
        os._exit(0)  # nothing to close; the opening thread is inside Zenoh and cannot be joined
    return session


def close_or_report(args, session) -> None:
    """Close the session; when the router cannot be told (the network is gone), one line on
    stderr instead of Zenoh's traceback, and the command's exit status stays its own."""
    reason = close_session(session)
    if reason:
        print(f"balltrack {args.command}: {reason}", file=sys.stderr)
