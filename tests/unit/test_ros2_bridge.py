"""The ROS 2 bridge's conversions, checked against pycdr2 (a second CDR implementation) as well
as rosbags, and its config."""

import math
import subprocess
import sys

import cv2
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from balltrack.common.config import ConfigError
from balltrack.common.keys import CORE_SERVICES, SERVICES
from balltrack.common.messages import MessageError, header, validate
from balltrack.services.ros2_bridge import convert
from balltrack.services.ros2_bridge.config import ROUTE_SWITCHES, Ros2BridgeConfig
from balltrack.services.ros2_bridge.service import ROUTES, active_routes
from tests import ros2_idl as idl
from tests.harness import REPO

BALL2D = {"header": header(5, 1), "x": -0.25, "y": 0.5, "z": 0.125, "u": 240.0, "v": 360.0,
          "radius_px": 40.0, "image_width": 640, "image_height": 480, "score": 0.9}
BALL3D = {"header": header(1_700_000_000_123_456_789, 42, "camera_optical"),
          "x": 0.1, "y": -0.2, "z": 1.5, "distance": 1.52}
TWIST = {"header": header(7, 3), "linear": [0.3, 0.0, 0.0], "angular": [0.0, 0.0, -1.25]}


def test_ball2d_is_the_papers_point():
    data = convert.ball2d_to_ros(BALL2D)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR, little-endian: the encapsulation header
    assert idl.Point.deserialize(data) == idl.Point(-0.25, 0.5, 0.125)
    assert data == idl.Point(-0.25, 0.5, 0.125).serialize()
    assert convert.deserialize(data, convert.POINT).z == 0.125


def test_ball3d_is_a_point_stamped_with_its_stamp_and_frame():
    data = convert.ball3d_to_ros(BALL3D)
    decoded = idl.PointStamped.deserialize(data)
    assert decoded.header == idl.Header(idl.Time(1_700_000_000, 123_456_789), "camera_optical")
    assert decoded.point == idl.Point(0.1, -0.2, 1.5)
    assert data == decoded.serialize()
    rosbags = convert.deserialize(data, convert.POINT_STAMPED)
    assert (rosbags.header.stamp.sec, rosbags.header.stamp.nanosec) == (1_700_000_000, 123_456_789)


def test_twist():
    decoded = idl.Twist.deserialize(convert.twist_to_ros(TWIST))
    assert decoded == idl.Twist(idl.Vector3(0.3, 0.0, 0.0), idl.Vector3(0.0, 0.0, -1.25))


def test_a_stamp_past_ross_int32_seconds_is_refused():
    late = {**BALL3D, "header": header(2 ** 31 * 1_000_000_000, 1)}
    with pytest.raises(MessageError, match="int32"):
        convert.ball3d_to_ros(late)


def pixels(width, height, channels, seed=0):
    shape = (height, width, channels) if channels > 1 else (height, width)
    return np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)


@pytest.mark.parametrize("encoding, channels", [("rgb8", 3), ("bgr8", 3), ("mono8", 1)])
@pytest.mark.parametrize("padding", [0, 13])
def test_image_from_ros_keeps_the_pixels_and_drops_row_padding(encoding, channels, padding):
    width, height = 37, 11  # an odd width: rows of rgb8 are not a multiple of 4 bytes
    image = pixels(width, height, channels)
    step = width * channels + padding
    rows = np.zeros((height, step), np.uint8)
    rows[:, :width * channels] = image.reshape(height, -1)
    rows[:, width * channels:] = 0xAB  # padding that must not reach balltrack
    data = idl.Image(idl.header(1_234_567_890_123), height, width, encoding, 0, step,
                     rows.tobytes()).serialize()
    message = convert.image_from_ros(data, 9)
    assert message["header"] == {"stamp": 1_234_567_890_123, "frame_id": "camera", "seq": 9}
    assert (message["width"], message["height"], message["encoding"]) == (width, height, encoding)
    assert message["data"] == image.tobytes()
    validate("Image", message)


def test_image_whose_last_row_carries_no_padding():
    image = pixels(5, 3, 3)
    step = 20
    data = b"".join(image[row].tobytes() + (b"\x00" * 5 if row < 2 else b"") for row in range(3))
    message = convert.image_from_ros(idl.Image(idl.header(0), 3, 5, "rgb8", 0, step, data).serialize(), 0)
    assert message["data"] == image.tobytes()


@pytest.mark.parametrize("encoding, width, step, size, reason", [
    ("bgra8", 4, 16, 64, "encoding"),
    ("16UC1", 4, 8, 32, "encoding"),
    ("rgb8", 4, 11, 44, "step"),          # a row needs 12 bytes
    ("rgb8", 4, 12, 40, "data"),          # 4 rows of 12 need 48
    ("mono8", 0, 0, 0, "size"),
])
def test_image_from_ros_refuses(encoding, width, step, size, reason):
    data = idl.Image(idl.header(0), 4, width, encoding, 0, step, bytes(size)).serialize()
    with pytest.raises(MessageError, match=reason):
        convert.image_from_ros(data, 0)


@pytest.mark.parametrize("format_name", ["jpeg", "bgr8; jpeg compressed bgr8", "JPG"])
def test_compressed_image_from_ros(format_name):
    ok, jpeg = cv2.imencode(".jpg", pixels(64, 48, 3))
    assert ok
    data = idl.CompressedImage(idl.header(77, "cam"), format_name, jpeg.tobytes()).serialize()
    message = convert.compressed_image_from_ros(data, 4)
    assert (message["width"], message["height"], message["encoding"]) == (64, 48, "jpeg")
    assert message["data"] == jpeg.tobytes()
    assert message["header"] == {"stamp": 77, "frame_id": "cam", "seq": 4}
    validate("Image", message)


def test_compressed_image_that_is_not_jpeg_is_refused():
    ok, png = cv2.imencode(".png", pixels(8, 8, 3))
    with pytest.raises(MessageError, match="format"):
        convert.compressed_image_from_ros(idl.CompressedImage(idl.header(0), "png", png.tobytes()).serialize(), 0)
    with pytest.raises(MessageError, match="SOI"):
        convert.compressed_image_from_ros(idl.CompressedImage(idl.header(0), "jpeg", png.tobytes()).serialize(), 0)


def test_camera_info_gives_balltracks_intrinsics_and_fields_of_view():
    # The simulator's camera: fx = fy = (W / 2) / tan(hfov / 2), so hfov must come back.
    width, height, hfov = 640, 480, 1.089
    focal = (width / 2) / math.tan(hfov / 2)
    d = [-0.2, 0.05, 0.001, -0.002, 0.0]
    data = idl.camera_info(width, height, focal, focal, 319.5, 239.5, d=d, stamp_ns=3_000_000_001).serialize()
    info = validate("CameraInfo", convert.camera_info_from_ros(data, 2))
    assert (info["fx"], info["fy"], info["cx"], info["cy"]) == (focal, focal, 319.5, 239.5)
    assert abs(info["hfov"] - hfov) < 1e-12
    assert abs(info["vfov"] - 2 * math.atan(math.tan(hfov / 2) * height / width)) < 1e-12
    assert info["distortion_model"] == "plumb_bob" and info["d"] == d
    assert info["header"] == {"stamp": 3_000_000_001, "frame_id": "camera", "seq": 2}


def test_camera_info_distortion_models():
    rational = idl.camera_info(640, 480, 500.0, 500.0, 320.0, 240.0, "rational_polynomial",
                               [0.1, 0.01, 0.0, 0.0, 0.001, 0.2, 0.02, 0.002]).serialize()
    info = validate("CameraInfo", convert.camera_info_from_ros(rational, 0))
    assert info["distortion_model"] == "plumb_bob" and len(info["d"]) == 8
    none = idl.camera_info(640, 480, 500.0, 500.0, 320.0, 240.0, "", []).serialize()
    assert validate("CameraInfo", convert.camera_info_from_ros(none, 0))["distortion_model"] == "none"
    fisheye = idl.camera_info(640, 480, 500.0, 500.0, 320.0, 240.0, "equidistant", [0.1] * 4).serialize()
    with pytest.raises(MessageError, match="distortion_model"):
        convert.camera_info_from_ros(fisheye, 0)
    uncalibrated = idl.camera_info(640, 480, 0.0, 0.0, 0.0, 0.0).serialize()
    with pytest.raises(MessageError, match="uncalibrated"):
        convert.camera_info_from_ros(uncalibrated, 0)


GOOD = {
    "image_from_ros": idl.Image(idl.header(1), 2, 3, "rgb8", 0, 9, bytes(18)).serialize(),
    "compressed_image_from_ros": idl.CompressedImage(
        idl.header(1), "jpeg", cv2.imencode(".jpg", np.zeros((4, 4, 3), np.uint8))[1].tobytes()).serialize(),
    "camera_info_from_ros": idl.camera_info(640, 480, 500.0, 500.0, 320.0, 240.0).serialize(),
}


@pytest.mark.parametrize("name", sorted(GOOD))
def test_bad_bytes_are_message_errors(name):
    function = getattr(convert, name)
    good = GOOD[name]
    function(good, 0)
    cases = [b"", b"\x00\x01\x00", b"\x00\x07\x00\x00" + good[4:],  # XCDR2, not plain CDR
             good + bytes(8),  # more than the alignment padding DDS may add
             idl.Point(1.0, 2.0, 3.0).serialize(),
             idl.header(5).serialize()]
    cases += [good[:cut] for cut in range(0, len(good), max(1, len(good) // 40))]
    for case in cases:
        with pytest.raises(MessageError):
            function(case, 0)


def test_negative_ros_stamp_is_refused():
    data = idl.Image(idl.Header(idl.Time(-1, 0), "camera"), 1, 1, "mono8", 0, 1, b"\x00").serialize()
    with pytest.raises(MessageError, match="stamp"):
        convert.image_from_ros(data, 0)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300), st.sampled_from(sorted(GOOD)))
def test_arbitrary_bytes_never_raise_anything_but_message_error(data, name):
    try:
        validate("Image" if "image" in name else "CameraInfo", getattr(convert, name)(data, 0))
    except MessageError:
        pass


@settings(max_examples=200, deadline=None)
@given(st.data(), st.sampled_from(sorted(GOOD)))
def test_corrupted_good_messages_never_raise_anything_but_message_error(data, name):
    good = bytearray(GOOD[name])
    for _ in range(data.draw(st.integers(1, 4))):
        good[data.draw(st.integers(0, len(good) - 1))] = data.draw(st.integers(0, 255))
    try:
        validate("Image" if "image" in name else "CameraInfo", getattr(convert, name)(bytes(good), 0))
    except MessageError:
        pass


def test_config_prefix_and_routes():
    config = Ros2BridgeConfig(prefix="/robot1/ros")
    assert config.prefix == "robot1/ros/"
    assert config.ros_key("image_topic") == "robot1/ros/camera/image_raw"
    routes = active_routes(Ros2BridgeConfig())
    assert sorted(routes.values()) == ["ros/camera/camera_info", "ros/camera/image_raw", "ros/cmd_vel",
                                       "ros/detected_ball", "ros/detected_ball_3d"]
    assert sorted(active_routes(Ros2BridgeConfig(to_ros=False)).values()) == [
        "ros/camera/camera_info", "ros/camera/image_raw"]
    assert sorted(active_routes(Ros2BridgeConfig(from_ros=False, out_cmd_vel=False)).values()) == [
        "ros/detected_ball", "ros/detected_ball_3d"]
    assert list(active_routes(Ros2BridgeConfig(in_image=False, in_compressed_image=True,
                                               to_ros=False)).values()) == [
        "ros/camera/image_raw/compressed", "ros/camera/camera_info"]
    assert "ros2_bridge" in SERVICES and "ros2_bridge" not in CORE_SERVICES


@pytest.mark.parametrize("changes, field", [
    ({"prefix": ""}, "detected_ball_topic"),           # CDR on balltrack's own msgpack key
    ({"prefix": "ros/*"}, "prefix"),
    ({"image_topic": "/"}, "image_topic"),
    ({"cmd_vel_topic": "/cmd vel"}, "cmd_vel_topic"),
    ({"to_ros": "sometimes"}, "to_ros"),
    ({"prefix": "x" * 100_000}, "prefix"),
    ({"image_topic": "/x" * 200}, "image_topic"),
])
def test_config_refuses(changes, field):
    with pytest.raises(ConfigError, match=f"^{field}"):
        Ros2BridgeConfig(**changes)


def test_without_rosbags_the_service_exits_2_naming_the_extra():
    # A None entry in sys.modules makes `import rosbags` fail as if it were not installed.
    code = ("import sys; sys.modules['rosbags'] = None; from balltrack.cli import main; "
            "sys.exit(main(['run', 'ros2_bridge', '--connect', 'tcp/127.0.0.1:1']))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO,
                            timeout=60)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install balltrack[ros]" in lines[0], result.stderr


def test_a_joined_process_says_when_the_bridge_cannot_run_here(monkeypatch, capsys):
    """Without rosbags the bridge exits 2 with one line alone (its main) and joined with other
    services (``balltrack run A+B``), before any session opens."""
    import argparse

    from balltrack.cli.run import command_run
    from balltrack.services.ros2_bridge import service

    monkeypatch.setattr(service, "rosbags_missing", lambda: True)
    status = command_run(argparse.Namespace(service="locator+ros2_bridge", arguments=[]))
    error = capsys.readouterr().err
    assert status == 2 and error.splitlines() == [
        "balltrack run: ros2_bridge: needs the rosbags package for ROS 2 messages: pip install balltrack[ros]"]
    assert service.main([]) == 2 and "pip install balltrack[ros]" in capsys.readouterr().err


def test_each_route_names_the_ros_type_its_converter_reads_or_writes():
    # (the type goes out in the samples' Zenoh encoding, and a recording's schema is made from it)
    messages = {"Ball2D": BALL2D, "Ball3D": BALL3D,
                "Twist": {"header": header(6, 2), "linear": [0.2, 0.0, 0.0], "angular": [0.0, 0.0, 0.75]}}
    for route in ROUTES:
        if route.direction == "to_ros":
            data = getattr(convert, route.convert)(messages[route.message])
            assert convert.TYPESTORE.deserialize_cdr(data, route.ros_type) is not None, route
        else:
            reads = {"image_from_ros": convert.IMAGE, "compressed_image_from_ros": convert.COMPRESSED_IMAGE,
                     "camera_info_from_ros": convert.CAMERA_INFO}
            assert route.ros_type == reads[route.convert], route


def test_the_config_knows_each_route_s_switches():
    assert set(ROUTE_SWITCHES) == {route.topic for route in ROUTES}
    assert all(switches[0] in ("to_ros", "from_ros") for switches in ROUTE_SWITCHES.values())


@pytest.mark.parametrize("settings, reason", [
    ({"image_topic": "/detected_ball"}, "image_topic: '/detected_ball' is also detected_ball_topic "
                                        "(key 'ros/detected_ball'); two routes cannot share a topic"),
    ({"in_compressed_image": True, "compressed_image_topic": "/camera/image_raw"},
     "compressed_image_topic: '/camera/image_raw' is also image_topic"),
    ({"cmd_vel_topic": "detected_ball_3d"}, "cmd_vel_topic: 'detected_ball_3d' is also detected_ball_3d_topic"),
])
def test_two_routes_on_one_topic_are_refused(settings, reason):
    # (the bridge read its own Points back as Images, and rejected every second message)
    with pytest.raises(ConfigError) as raised:
        Ros2BridgeConfig(**settings)
    assert str(raised.value).startswith(reason)


def test_a_topic_shared_with_a_route_that_is_off_is_allowed():
    config = Ros2BridgeConfig(compressed_image_topic="/camera/image_raw")  # (in_compressed_image is off)
    assert config.ros_key("compressed_image_topic") == config.ros_key("image_topic")
    assert Ros2BridgeConfig(image_topic="/detected_ball", from_ros=False).to_ros
