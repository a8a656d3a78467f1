"""Which services are alive (liveliness tokens) and their latest stats, as one snapshot."""

import threading

from balltrack.common.keys import Keys
from balltrack.common.messages import MessageError, decode


def service_status(session, namespace: str = "", timeout: float = 3.0,
                   stats_wait: float = 1.5) -> tuple[set[str], dict[str, dict]]:
    """(names of the services alive, latest Stats per service). Stats come at 1 Hz, so after
    the liveliness query this waits up to ``timeout + stats_wait`` for one from each."""
    keys = Keys(namespace)
    alive: set[str] = set()
    for reply in session.liveliness().get(keys("alive/*"), timeout=timeout):
        if reply.ok is not None:
            alive.add(keys.strip(str(reply.ok.key_expr)).split("/", 1)[1])
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
