"""Which services are alive (liveliness tokens) and their latest stats, as one snapshot."""

import threading

from balltrack.common.keys import Keys, alive_key, alive_token
from balltrack.common.messages import MessageError, decode


# A liveliness query sometimes comes back empty at once although tokens are alive (Zenoh 1.10,
# most often the first query of a fresh session): an empty answer is asked again. When nothing
# is alive the router answers at once too, so the retries cost little.
EMPTY_RETRIES = 3


# The figures every service's Stats has; ``other_figures`` shows what a service adds to them.
COMMON_FIELDS = ("service", "stamp", "stamp_clock", "received", "published", "rejected", "dropped",
                 "p50_ms", "p99_ms")


def other_figures(stats: dict) -> str:
    """A service's own figures, those past COMMON_FIELDS (the camera's frames and unreadable
    files, the simulator's real-time factor), as ``name=value`` in the order it sent them."""
    return " ".join(f"{name}={value:.4g}" if isinstance(value, float) else f"{name}={value}"
                    for name, value in stats.items() if name not in COMMON_FIELDS)


def liveliness_keys(session, key_expression: str, timeout: float) -> set[str]:
    """The keys of the liveliness tokens alive under ``key_expression``."""
    for _ in range(EMPTY_RETRIES):
        found = {str(reply.ok.key_expr) for reply in session.liveliness().get(key_expression, timeout=timeout)
                 if reply.ok is not None}
        if found:
            return found
    return set()


def service_status(session, namespace: str = "", timeout: float = 3.0,
                   stats_wait: float = 1.5) -> tuple[set[str], dict[str, dict]]:
    """(names of the services alive, latest Stats per service). Stats come at 1 Hz, so after
    the liveliness query this waits up to ``timeout + stats_wait`` for one from each."""
    keys = Keys(namespace)
    alive = {keys.strip(key).split("/", 1)[1] for key in liveliness_keys(session, keys("alive/*"), timeout)}
    stats: dict[str, dict] = {}
    complete = threading.Event()

    def on_stats(sample):
        try:
            message = decode("Stats", sample.payload.to_bytes())
        except MessageError:
            return
        stats[message["service"]] = message
        if alive <= set(stats):
            complete.set()

    subscriber = session.declare_subscriber(keys("*/stats"), on_stats)
    if alive:
        complete.wait(timeout + stats_wait)
    subscriber.undeclare()
    return alive, stats


def services_by_namespace(session, timeout: float = 3.0) -> dict[str, set[str]]:
    """The services alive in every namespace (``""``: none), from their liveliness tokens: the
    robots one process serves (``--namespaces``) each have theirs."""
    found: dict[str, set[str]] = {}
    for key in liveliness_keys(session, "**/" + alive_key("*"), timeout):
        token = alive_token(key)
        if token is not None:
            found.setdefault(token[0], set()).add(token[1])
    return found
