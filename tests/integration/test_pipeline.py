"""Detector, locator and follower together: drawn frames in, 3D positions and commands out,
with the three in a process each and in one process (``balltrack run detector+locator+follower``)."""

import math

import pytest

from balltrack.common.images import bgr_to_message
from balltrack.common.messages import encode, header
from balltrack.common.pinhole import Intrinsics
from balltrack.services.locator.projection import project_sphere
from tests.harness import Collector, draw_ball, floor_image, put_until, query_config

WIDTH, HEIGHT = 640, 480
INTRINSICS = Intrinsics.from_fov(WIDTH, HEIGHT, 1.089)
CAMERA_INFO = {"header": header(0, 0), "width": WIDTH, "height": HEIGHT, "fx": INTRINSICS.fx,
               "fy": INTRINSICS.fy, "cx": INTRINSICS.cx, "cy": INTRINSICS.cy,
               "hfov": INTRINSICS.h_fov, "vfov": INTRINSICS.v_fov}
# Ball centres in the camera optical frame (x right, y down, z forward), a camera 0.1 m up.
POINTS = [(0.0, 0.067, 0.4), (0.25, 0.067, 1.0), (-0.6, 0.067, 2.0), (0.5, 0.067, 3.0)]


JOINED = "detector+locator+follower"


@pytest.fixture(params=["separate", "joined"])
def pipeline(request, launch):
    # The ball jumps between frames here, so the follower steers by the largest ball as the
    # paper's does (keep_target would rightly ignore a far jump for target_hold_secs).
    if request.param == "joined":
        return [launch(JOINED, "follower.keep_target=false")]
    return [launch("detector"), launch("locator"), launch("follower", "keep_target=false")]


def test_frames_to_positions_and_commands(session, pipeline):
    located = Collector(session, "detected_ball_3d", "Ball3D")
    commands = Collector(session, "cmd_vel", "Twist")
    session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
    for seq, point in enumerate(POINTS, start=1):
        u, v, radius = project_sphere(point, 0.033, INTRINSICS)
        image = draw_ball(floor_image(WIDTH, HEIGHT, seq), u, v, radius)
        stamp = 1_000_000_000 * seq
        # Repeat the frame until its 3D position arrives: the first may precede CameraInfo.
        position = put_until(
            lambda _: session.put("camera/image_raw", encode("Image", bgr_to_message(image, stamp, seq))),
            located, lambda m: [x for x in m if x["header"]["seq"] == seq], 100, 2, f"seq {seq}")[-1]
        truth = math.dist(point, (0, 0, 0))
        # Stated tolerance: distance within 5%, position within 5% of the distance.
        assert abs(position["distance"] - truth) < 0.05 * truth, (point, position)
        assert math.dist((position["x"], position["y"], position["z"]), point) < 0.05 * truth
        assert position["header"]["stamp"] == stamp
        command = commands.wait_for(lambda m: [c for c in m if c["header"]["seq"] == seq], 5,
                                    f"command for seq {seq}")[-1]
        # Turn toward the ball: negative angular velocity for a ball on the right.
        if abs(point[0]) > 0.1:
            assert math.copysign(1, command["angular"][2]) == -math.copysign(1, point[0])
        assert command["header"]["stamp"] == stamp


def test_services_in_one_process_answer_each_for_itself(session, launch):
    """Joined in one process, each service keeps its own parameters, config queries, stats and
    liveliness token, as when it runs alone."""
    launch(JOINED, "locator.ball_radius=0.04", "follower.keep_target=false")
    stats = {name: Collector(session, f"{name}/stats", "Stats") for name in ("detector", "locator", "follower")}
    assert query_config(session, "locator")["config"]["ball_radius"] == 0.04
    assert query_config(session, "follower")["config"]["keep_target"] is False
    assert "v_min" in query_config(session, "detector")["config"]
    changed = query_config(session, "detector", {"v_min": 31})
    assert changed["ok"] and changed["config"]["v_min"] == 31
    assert query_config(session, "locator")["config"]["ball_radius"] == 0.04  # (its own, unchanged)
    located = Collector(session, "detected_ball_3d", "Ball3D")
    session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
    u, v, radius = project_sphere(POINTS[1], 0.033, INTRINSICS)
    image = draw_ball(floor_image(WIDTH, HEIGHT, 1), u, v, radius)
    put_until(lambda _: session.put("camera/image_raw", encode("Image", bgr_to_message(image, 10, 1))),
              located, lambda messages: messages, 100, 2, "a 3D position")
    for name, collector in stats.items():
        # (each service counts what it received: the detector frames, the others detections)
        collector.wait_for(lambda messages: [m for m in messages if m["service"] == name and m["received"] > 0],
                           10, f"{name}'s stats with a message received")
