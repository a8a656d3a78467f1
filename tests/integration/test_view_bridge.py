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


def ball(seq: int) -> bytes:
    return encode("Ball3D", {"header": header(seq * 33_000_000, seq), "x": 0.1, "y": 0.0, "z": 2.0,
                             "distance": 2.0 + seq / 100})


def truth(seq: int, x: float) -> bytes:
    return encode("GroundTruth", {"header": header(seq * 33_000_000, seq), "robot": {"x": x, "y": 0.0, "yaw": 0.0},
                                  "balls": []})


def chunks_of(path) -> dict[str, list]:
    """The non-static chunks of a saved recording, by entity."""
    from rerun.chunk import RrdReader

    found: dict[str, list] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        if not chunk.is_static:
            found.setdefault(chunk.entity_path, []).append(chunk)
    return found


def test_rerun_gets_what_came_in_one_update_frames_shrunk_and_the_path_thinned(session, tmp_path):
    import numpy as np
    import rerun as rr

    from balltrack.common.images import bgr_to_message
    from balltrack.common.keys import DETECTED_BALL_3D, GROUND_TRUTH, IMAGE_OUT
    from balltrack.deploy.view_config import RerunViewConfig

    recording = rr.RecordingStream("balltrack-test")
    recording.save(tmp_path / "view.rrd")
    # (an update period longer than the test: what came is sent once, by close())
    config = RerunViewConfig(update_rate_hz=0.01, frame_width=320, path_step_m=0.05)
    bridge = view.RerunBridge(session, recording, config=config)
    try:
        publishers = {key: session.declare_publisher(key) for key in (IMAGE_OUT, DETECTED_BALL_3D, GROUND_TRUTH)}
        for publisher in publishers.values():
            wait_until(lambda: publisher.matching_status.matching, 10, "the bridge's subscriber")
        for seq in range(20):
            publishers[IMAGE_OUT].put(encode("Image", bgr_to_message(np.full((480, 640, 3), seq, np.uint8), seq, seq)))
            publishers[DETECTED_BALL_3D].put(ball(seq))
            # the robot 1 cm further each time: every 5th position kept
            publishers[GROUND_TRUTH].put(truth(seq, seq / 100))
        wait_until(lambda: (bridge._frame or {}).get("header", {}).get("seq") == 19
                   and (bridge._truth or {}).get("header", {}).get("seq") == 19
                   and len(bridge._points["plots/ball_distance_m"]) == 20, 10, "every message taken, none sent")
    finally:
        bridge.close()
        recording.disconnect()
    chunks = chunks_of(tmp_path / "view.rrd")
    # one frame, the newest, shrunk to frame_width
    (image,) = [chunk.to_record_batch() for chunk in chunks["/camera/image"]]
    assert [(entry["width"], entry["height"]) for entry in image.column("Image:format").to_pylist()[0]] == [(320, 240)]
    assert np.asarray(image.column("Image:buffer").to_pylist()[0][0]).max() == 19
    for series in ("/plots/ball_distance_m", "/plots/located_balls_hz"):
        assert [chunk.num_rows for chunk in chunks[series]] == [20], series
    (path,) = [chunk.to_record_batch() for chunk in chunks["/world/path"]]
    assert [len(strip) for strip in path.column("LineStrips3D:strips").to_pylist()[0]] == [4]
    assert bridge.rejected == 0


def test_rerun_shows_several_robots_each_under_its_name(session, tmp_path):
    import numpy as np
    import rerun as rr

    from balltrack.common.images import bgr_to_message
    from balltrack.common.keys import GROUND_TRUTH, IMAGE_OUT, Keys
    from balltrack.deploy.view_config import RerunViewConfig

    robots = ("robot1", "robot2")
    recording = rr.RecordingStream("balltrack-test")
    recording.save(tmp_path / "view.rrd")
    config = RerunViewConfig(update_rate_hz=0.01)  # (sent once, by close())
    bridges = {robot: view.RerunBridge(session, recording, robot, config, entity_prefix=f"{robot}/")
               for robot in robots}
    try:
        for value, robot in enumerate(robots, start=1):
            names = Keys(robot)
            frames, truths = session.declare_publisher(names(IMAGE_OUT)), session.declare_publisher(names(GROUND_TRUTH))
            for publisher in (frames, truths):
                wait_until(lambda: publisher.matching_status.matching, 10, f"{robot}'s bridge")
            frames.put(encode("Image", bgr_to_message(np.full((240, 320, 3), 10 * value, np.uint8), 1, 1)))
            truths.put(truth(1, float(value)))
        for robot, bridge in bridges.items():
            wait_until(lambda: bridge._frame is not None and bridge._truth is not None, 10, f"{robot}'s messages")
    finally:
        for bridge in bridges.values():
            bridge.close()
        recording.disconnect()
    chunks = chunks_of(tmp_path / "view.rrd")
    assert "/camera/image" not in chunks
    for value, robot in enumerate(robots, start=1):
        (image,) = [chunk.to_record_batch() for chunk in chunks[f"/{robot}/camera/image"]]
        # each robot's own frame under its own name
        assert np.asarray(image.column("Image:buffer").to_pylist()[0][0]).max() == 10 * value
        assert f"/{robot}/world/robot" in chunks
    blueprint = view.rerun_blueprint(config, list(robots))
    assert blueprint is not None
