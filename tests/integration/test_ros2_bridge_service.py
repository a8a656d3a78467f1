"""The ROS 2 bridge as a real process over a real router; the ROS side read and written with
pycdr2, a CDR implementation independent of the bridge's rosbags."""

import cv2
import numpy as np
import pytest

from balltrack.common.messages import encode, header
from tests import ros2_idl as idl
from tests.harness import Collector, query_config

BALL3D = {"header": header(1_700_000_001_000_000_002, 12, "camera_optical"),
          "x": 0.25, "y": -0.5, "z": 2.0, "distance": 2.077}


@pytest.fixture
def bridge(launch):
    return launch("ros2_bridge")


def first(collector: Collector) -> bytes:
    return collector.wait_count(1, 10)[0]["payload"]


def test_balltrack_to_ros(session, bridge):
    points_3d = Collector(session, "ros/detected_ball_3d", None)
    points = Collector(session, "ros/detected_ball", None)
    twists = Collector(session, "ros/cmd_vel", None)
    session.put("detected_ball_3d", encode("Ball3D", BALL3D))
    session.put("detected_ball", encode("Ball2D", {
        "header": header(5, 1), "x": 0.5, "y": -0.25, "z": 0.0625, "u": 480.0, "v": 180.0,
        "radius_px": 20.0, "image_width": 640, "image_height": 480, "score": 1.0}))
    session.put("cmd_vel", encode("Twist", {"header": header(6, 2), "linear": [0.2, 0.0, 0.0],
                                            "angular": [0.0, 0.0, 0.75]}))

    stamped = idl.PointStamped.deserialize(first(points_3d))
    assert stamped == idl.PointStamped(idl.Header(idl.Time(1_700_000_001, 2), "camera_optical"),
                                       idl.Point(0.25, -0.5, 2.0))
    assert idl.Point.deserialize(first(points)) == idl.Point(0.5, -0.25, 0.0625)
    assert idl.Twist.deserialize(first(twists)) == idl.Twist(idl.Vector3(0.2, 0.0, 0.0),
                                                                     idl.Vector3(0.0, 0.0, 0.75))


def test_ros_camera_to_balltrack(session, bridge):
    images = Collector(session, "camera/image_raw", "Image")
    infos = Collector(session, "camera/camera_info", "CameraInfo")
    width, height = 161, 120
    pixels = np.random.default_rng(1).integers(0, 256, (height, width, 3), dtype=np.uint8)
    step = width * 3 + 5  # padded rows, as some drivers send
    rows = np.zeros((height, step), np.uint8)
    rows[:, :width * 3] = pixels.reshape(height, -1)
    session.put("ros/camera/image_raw",
                idl.Image(idl.header(2_000_000_123, "usb_cam"), height, width, "bgr8", 0, step,
                          rows.tobytes()).serialize())
    image = images.wait_count(1, 10)[0]
    assert (image["width"], image["height"], image["encoding"]) == (width, height, "bgr8")
    assert image["data"] == pixels.tobytes()
    assert image["header"] == {"stamp": 2_000_000_123, "frame_id": "usb_cam", "seq": 0}

    session.put("ros/camera/camera_info",
                idl.camera_info(width, height, 150.0, 151.0, 80.5, 59.5, d=[0.1, -0.01, 0.0, 0.0, 0.0],
                                stamp_ns=2_000_000_123).serialize())
    info = infos.wait_count(1, 10)[0]
    assert (info["fx"], info["fy"], info["cx"], info["cy"]) == (150.0, 151.0, 80.5, 59.5)
    assert info["distortion_model"] == "plumb_bob" and info["d"] == [0.1, -0.01, 0.0, 0.0, 0.0]

    # Garbage on the ROS side is dropped and counted; the next good frame still gets through.
    stats = Collector(session, "ros2_bridge/stats", "Stats")
    for bad in (b"", b"\x00\x01\x00\x00garbage", idl.Point(1.0, 2.0, 3.0).serialize(),
                idl.Image(idl.header(0), 2, 2, "bgra8", 0, 8, bytes(16)).serialize()):
        session.put("ros/camera/image_raw", bad)
    session.put("ros/camera/image_raw",
                idl.Image(idl.header(3), 1, 2, "mono8", 0, 2, b"\x07\x09").serialize())
    later = images.wait_count(2, 10)[1]
    assert (later["data"], later["header"]["seq"]) == (b"\x07\x09", 1)
    stats.wait_for(lambda messages: messages and messages[-1]["rejected"] >= 4, 10, "4 rejected")


def test_live_config_moves_and_switches_routes(session, bridge):
    reply = query_config(session, "ros2_bridge", {"prefix": "robot7/", "in_image": False,
                                                  "in_compressed_image": True})
    assert reply["ok"], reply
    assert reply["config"]["prefix"] == "robot7/"
    points_3d = Collector(session, "robot7/detected_ball_3d", None)
    session.put("detected_ball_3d", encode("Ball3D", BALL3D))
    assert idl.PointStamped.deserialize(first(points_3d)).point.z == 2.0

    images = Collector(session, "camera/image_raw", "Image")
    ok, jpeg = cv2.imencode(".jpg", np.full((48, 64, 3), 128, np.uint8))
    assert ok
    session.put("robot7/camera/image_raw/compressed",
                idl.CompressedImage(idl.header(9), "bgr8; jpeg compressed bgr8", jpeg.tobytes()).serialize())
    image = images.wait_count(1, 10)[0]
    assert (image["encoding"], image["width"], image["height"]) == ("jpeg", 64, 48)
    assert image["data"] == jpeg.tobytes()

    refused = query_config(session, "ros2_bridge", {"prefix": ""})
    assert not refused["ok"] and "balltrack's own key" in refused["error"]
    assert query_config(session, "ros2_bridge")["config"]["prefix"] == "robot7/"
