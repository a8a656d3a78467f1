"""deploy/view.Bridge between a real router and a viewer that is slower than the data: what has
waited longer than MAX_AGE is dropped and counted, not shown late; a viewer that keeps up gets
every message."""

import threading
import time

import pytest

pytest.importorskip("rerun")
pytest.importorskip("foxglove")

from balltrack.common.keys import CMD_VEL  # noqa: E402
from balltrack.common.messages import encode, header  # noqa: E402
from balltrack.deploy import view  # noqa: E402
from tests.harness import wait_until  # noqa: E402

COUNT = 40


class Twists(view.Bridge):
    """Shows only cmd_vel; each show waits until ``released`` is set."""

    def __init__(self, session):
        self.released = threading.Event()
        self.shown: list[int] = []
        super().__init__(session)

    def show_twist(self, twist: dict) -> None:
        self.released.wait(30)
        self.shown.append(twist["header"]["seq"])


def twist(seq: int) -> bytes:
    return encode("Twist", {"header": header(1_000 + seq, seq), "linear": [0.1, 0.0, 0.0],
                            "angular": [0.0, 0.0, 0.0]})


def publish_all(session, bridge: Twists) -> None:
    publisher = session.declare_publisher(CMD_VEL)
    wait_until(lambda: publisher.matching_status.matching, 10, "the bridge's subscriber")
    for seq in range(COUNT):
        publisher.put(twist(seq))
    publisher.undeclare()


def test_messages_that_waited_too_long_are_dropped_not_shown_late(session):
    bridge = Twists(session)
    try:
        publish_all(session, bridge)
        wait_until(lambda: bridge.shown == [] and len(bridge._queued) == COUNT - 1, 10,
                   "one show in progress, the rest queued behind it")
        # (the first was taken at once: the worker waits for nothing else)
        # (the newest, not the oldest: on a loaded machine the 39 can arrive over more than MAX_AGE)
        wait_until(lambda: time.monotonic() - bridge._queued[-1][2] > view.MAX_AGE, 10,
                   "every queued message older than MAX_AGE")
        bridge.released.set()
        wait_until(lambda: bridge.handled + bridge.dropped == COUNT, 10, "every message shown or dropped")
    finally:
        bridge.released.set()
        bridge.close()
    assert bridge.shown == [0] and bridge.dropped == COUNT - 1 and bridge.rejected == 0


def test_a_viewer_that_keeps_up_shows_every_message_in_order(session):
    bridge = Twists(session)
    bridge.released.set()
    try:
        publish_all(session, bridge)
        wait_until(lambda: bridge.handled == COUNT, 10, "every message shown")
    finally:
        bridge.close()
    assert bridge.shown == list(range(COUNT)) and bridge.dropped == 0
