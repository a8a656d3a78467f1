"""The ROS 2 bridge as a real process over a real router; the ROS side read and written with
pycdr2, a CDR implementation independent of the bridge's rosbags."""

import json

import cv2
import numpy as np
import pytest

from balltrack.common.messages import encode, header
from balltrack.common.recording import Recorder, RecordingFile
from balltrack.services.ros2_bridge import convert
from tests import ros2_idl as idl
from tests.harness import Collector, Process, query_config, wait_matched, wait_until
from tests.integration.test_recording import BALLTRACK, balltrack

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


def test_the_bridge_s_ros_keys_are_recorded_as_ros_2_channels_and_played_as_they_came(router, session, bridge,
                                                                                      tmp_path):
    # (they were written as msgpack channels without a schema: a CDR payload that no msgpack
    # reader decodes, and that Foxglove skipped)
    path = tmp_path / "ros.mcap"
    recorder = Process([*BALLTRACK, "record", "-o", str(path), "ros/**", "--connect", router.endpoint,
                        "--progress", "0.1"], tmp_path / "record.log")
    recorder.wait_for_output("recording", 30)
    probe = session.declare_publisher("ros/detected_ball_3d")
    wait_matched(probe)  # (the router knows the recorder's subscription: the bridge's points reach it)
    probe.undeclare()
    balls = [{**BALL3D, "header": header(1_700_000_001_000_000_002 + seq, seq, "camera_optical")} for seq in range(5)]
    for ball in balls:
        session.put("detected_ball_3d", encode("Ball3D", ball))
    sent = [convert.ball3d_to_ros(ball) for ball in balls]  # (what the bridge puts)
    recorder.wait_for_output(f"{len(sent)} messages written", 30)
    assert recorder.stop() == 0, recorder.output()

    info = json.loads(balltrack("info", str(path), "--json").stdout)
    assert [(item["key"], item["type"], item["encoding"]) for item in info["keys"]] == \
        [("ros/detected_ball_3d", "geometry_msgs/msg/PointStamped", "cdr")]
    with RecordingFile(path) as recording:
        recorded = [message.payload for message in recording.messages()]
        (channel,) = recording._summary.channels.values()
        schema = recording._summary.schemas[channel.schema_id]
    assert recorded == sent and schema.encoding == "ros2msg"
    assert b"geometry_msgs/Point point" in schema.data  # (the definition, as a ROS 2 bag's)

    replayed = []
    subscriber = session.declare_subscriber("again/ros/detected_ball_3d", lambda sample: replayed.append(
        (sample.payload.to_bytes(), str(sample.encoding))))
    try:
        played = balltrack("play", str(path), "--rate", "0", "--namespace", "again", "--connect", router.endpoint)
        assert played.returncode == 0, played.stderr
        wait_until(lambda: len(replayed) >= len(sent), 10, "the replayed points")
    finally:
        subscriber.undeclare()
    assert replayed == [(payload, "application/cdr;geometry_msgs/msg/PointStamped") for payload in sent]


def test_play_refuses_a_ros_2_bag_of_another_recorder_in_one_line(router, tmp_path):
    path = tmp_path / "bag.mcap"
    recorder = Recorder(path)
    channel = recorder.add_channel("/chatter", "std_msgs/msg/String", "ros2msg", b"string data",
                                   message_encoding="cdr")
    recorder.write(channel, b"\x00\x01\x00\x00\x06\x00\x00\x00hello\x00", 1_000, 1_000)
    recorder.close()
    every = balltrack("play", str(path), "--connect", router.endpoint)
    assert (every.returncode, every.stderr) == (2, "balltrack play: no channel of the recording is one balltrack "
                                                   "recorded from a Zenoh key (/chatter: a ROS 2 (CDR) channel of "
                                                   "another recorder): nothing to play\n")
    named = balltrack("play", str(path), "--keys", "/chatter", "--connect", router.endpoint)
    assert named.returncode == 2
    assert named.stderr.startswith("balltrack play: '/chatter' is a ROS 2 (CDR) channel of another recorder")
