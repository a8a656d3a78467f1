"""``balltrack topic list`` and ``balltrack topic info KEY``: what is live on the network.

Who publishes and subscribes comes from the router's admin space (read-only; balltrack's
routers enable it), where every declared publisher, subscriber and liveliness token is listed
with the Zenoh ids of the sessions that declared it; a session that declared ``alive/<service>``
is shown by that service's name. Rates are measured by listening for ``--window`` seconds.
"""

import json
import sys
import threading
import time
from collections import defaultdict

from balltrack.cli.output import Output
from balltrack.common.terminal import silence_closed_stdout
from balltrack.cli.session import close_or_report, networked, open_or_report
from balltrack.common.arguments import seconds
from balltrack.common import keys as key_table
from balltrack.common.keys import Keys
from balltrack.common.shutdown import stop_on_signals

ADMIN_KINDS = ("publisher", "subscriber", "token")


class Graph:
    """Declared publishers and subscribers per key, by name where a token tells it."""

    def __init__(self):
        self.declared = {kind: defaultdict(set) for kind in ADMIN_KINDS}  # kind -> key -> zids
        self.readable = False

    @classmethod
    def query(cls, session, timeout: float) -> "Graph":
        graph = cls()
        for reply in session.get("@/*/router/**", timeout=timeout):
            if reply.ok is None:
                continue
            parts = str(reply.ok.key_expr).split("/")
            graph.readable = True
            if len(parts) < 5 or parts[2] != "router" or parts[3] not in ADMIN_KINDS:
                continue
            try:
                holders = json.loads(reply.ok.payload.to_bytes())
            except ValueError:
                continue
            # (not "routers": a router lists itself there for every declaration it routes, and
            # its own id would then stand for every service behind it; each router of a cluster
            # answers this query, naming its own peers and clients)
            zids = {zid for group in ("peers", "clients") for zid in holders.get(group, [])}
            graph.declared[parts[3]]["/".join(parts[4:])] |= zids
        return graph

    def _tokens(self) -> list[tuple[str, str, set[str]]]:
        """(namespace, service, zids) of every ``[<namespace>/]alive/<service>`` token."""
        return [(*token, zids) for key, zids in self.declared["token"].items()
                if (token := key_table.alive_token(key)) is not None]

    def names(self) -> dict[str, list[str]]:
        """Zenoh id -> the services of that session (sorted), from the ``alive/<service>``
        tokens of any namespace: several for services joined in one process
        (``balltrack run a+b``)."""
        result: dict[str, set[str]] = defaultdict(set)
        for _, service, zids in self._tokens():
            for zid in zids:
                result[zid].add(service)
        return {zid: sorted(services) for zid, services in result.items()}

    def keys_of(self, full_key: str, keys: Keys) -> Keys:
        """The namespace ``full_key`` is in: ``keys``' own, or (listed from the root) the
        longest of the live services' namespaces it starts with, so that ``robot1/cmd_vel``
        is typed and attributed as ``cmd_vel`` is."""
        namespaces = {namespace for namespace, _, _ in self._tokens()} | {keys.namespace}
        within = [namespace for namespace in namespaces
                  if namespace and full_key.startswith(namespace + "/")]
        return Keys(max(within, key=len)) if within else keys

    def who(self, kind: str, full_key: str, keys: Keys) -> list[str]:
        names = self.names()
        key = self.keys_of(full_key, keys).strip(full_key)
        return sorted(_holder(kind, key, names[zid]) if zid in names else zid[:8]
                      for zid in self.declared[kind].get(full_key, ()))

    def keys(self, kind: str) -> set[str]:
        return set(self.declared[kind])


def _holder(kind: str, key: str, services: list[str]) -> str:
    """Which of the services of one session declared ``key``: the one the key is of
    (``locator/stats``) or, for a publisher, the one the key table names (``detected_ball_3d``:
    the locator); else all of them, joined as the process is (``detector+locator``)."""
    if len(services) == 1:
        return services[0]
    first, _, rest = key.partition("/")
    owner = rest if first == "alive" else first
    if owner in services:
        return owner
    if kind == "publisher":
        named = [spec.publisher.split(" or ") for spec in key_table.TABLE if spec.key == key]
        among = [service for service in (named[0] if named else []) if service in services]
        if len(among) == 1:
            return among[0]
    return key_table.PROCESS_JOIN.join(services)


def _listen(session, expression: str, window: float, stop) -> dict[str, list[tuple[float, int]]]:
    """(arrival time, size) of every sample per key, for ``window`` seconds."""
    arrivals: dict[str, list[tuple[float, int]]] = defaultdict(list)
    lock = threading.Lock()

    def on_sample(sample):
        with lock:
            arrivals[str(sample.key_expr)].append((time.monotonic(), len(sample.payload)))

    subscriber = session.declare_subscriber(expression, on_sample)
    stop.wait(window)
    subscriber.undeclare()
    with lock:
        return dict(arrivals)


def rate(samples: list[tuple[float, int]], window: float) -> float:
    """Messages per second: over the span of those seen, or (one seen, a 1 Hz key in a 1 s
    window) as many as seen in ``window``."""
    if len(samples) < 2 or samples[-1][0] <= samples[0][0]:
        return len(samples) / window
    return (len(samples) - 1) / (samples[-1][0] - samples[0][0])


def _message_type(keys: Keys, full_key: str) -> str:
    return keys.message_of(full_key) or "-"


def _snapshot(args):
    stop = stop_on_signals()
    session = open_or_report(args, stop)
    if session is None:
        return None
    keys = Keys(args.namespace)
    try:
        graph = Graph.query(session, args.timeout)
        traffic = _listen(session, keys("**"), args.window, stop)
    finally:
        close_or_report(args, session)
    return keys, graph, traffic


def command_topic_list(args) -> int:
    snapshot = _snapshot(args)
    if snapshot is None:
        return 1
    keys, graph, traffic = snapshot
    # (as ros2 topic list: a key that only has subscribers is listed too; a subscriber's
    # wildcard, a recorder's "**", is not a key)
    subscribed = {key for key in graph.keys("subscriber") if "*" not in key}
    live = {key for key in graph.keys("publisher") | subscribed | set(traffic)
            if not key.startswith("@") and (not keys.namespace or key.startswith(keys.namespace + "/"))}
    out = Output(stop_on_signals())
    if not graph.readable:
        out.line("# the router's admin space is not readable: publishers and subscribers unknown")
    out.line(f"{'key':<28} {'type':<12} {'rate_hz':>8} {'publishers':<24} subscribers")
    for key in sorted(live):
        publishers = ",".join(graph.who("publisher", key, keys)) or "-"
        subscribers = ",".join(graph.who("subscriber", key, keys)) or "-"
        if not out.line(f"{keys.strip(key):<28} {_message_type(graph.keys_of(key, keys), key):<12} "
                        f"{rate(traffic.get(key, []), args.window):>8.2f} {publishers:<24} {subscribers}"):
            break
    if out.closed:
        silence_closed_stdout()
    return 0


def command_topic_info(args) -> int:
    snapshot = _snapshot(args)
    if snapshot is None:
        return 1
    keys, graph, traffic = snapshot
    full_key = keys(args.key)
    samples = traffic.get(full_key, [])
    table_key = graph.keys_of(full_key, keys).strip(full_key)  # (robot1/cmd_vel is cmd_vel)
    spec = next((spec for spec in key_table.TABLE if spec.key == table_key), None)
    publishers = graph.who("publisher", full_key, keys) if graph.readable else None
    subscribers = graph.who("subscriber", full_key, keys) if graph.readable else None
    if spec is None and not samples and not publishers and not subscribers:
        # (as `ros2 topic info` of an unknown topic: a key of the user's own apps shows once seen)
        print(f"balltrack topic info: {args.key}: not a key of balltrack's table (balltrack topic list), "
              f"and no publisher, subscriber or message of it seen in {args.window:g} s", file=sys.stderr)
        return 1
    sizes = [size for _, size in samples]
    info = {
        "key": full_key,
        "type": _message_type(graph.keys_of(full_key, keys), full_key),
        "declared_publisher": spec.publisher if spec else None,
        "when": spec.when if spec else None,
        "publishers": publishers,
        "subscribers": subscribers,
        "rate_hz": round(rate(samples, args.window), 3),
        "messages_seen": len(samples),
        "mean_bytes": round(sum(sizes) / len(sizes), 1) if sizes else None,
        "window_s": args.window,
    }
    print(json.dumps(info, indent=2))
    return 0


def register(commands) -> None:
    topic = commands.add_parser("topic", help="live keys: list, info KEY (as ros2 topic)")
    actions = topic.add_subparsers(dest="action", required=True, parser_class=type(topic))

    def window(sub):
        sub.add_argument("--window", type=seconds(minimum=0.01), default=1.0,
                         help="seconds to listen for rates (default 1)")
        return sub

    window(networked(actions, "list", "live keys with message type, publishers, subscribers, rate",
                     command_topic_list))
    info = window(networked(actions, "info", "one key: type, publishers, subscribers, rate, size",
                            command_topic_info))
    info.add_argument("key")
