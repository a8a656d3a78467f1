"""``balltrack view --foxglove`` as a real process between a real router and detector, read by a
WebSocket client speaking the Foxglove protocol (subprotocol foxglove.sdk.v1): the channels are
advertised, and the annotated frame arrives as a CompressedImage whose JPEG shows the ball."""

import asyncio
import json
import re
import socket
import struct
import sys
import threading

import cv2
import numpy as np
import pytest

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")

from balltrack.common.images import bgr_to_message  # noqa: E402
from balltrack.common.messages import encode  # noqa: E402
from tests.harness import Process, draw_ball, floor_image, free_port  # noqa: E402

WIDTH, HEIGHT = 320, 240
BALL_U, BALL_V, BALL_RADIUS = 200.0, 140.0, 30.0
SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 1  # the server's binary opcode for a channel message


def protobuf_fields(buffer: bytes) -> dict[int, list]:
    """The top-level fields of a protobuf message: {field number: [values]} (varints as int,
    length-delimited as bytes; fixed-width skipped). Enough to read a CompressedImage."""
    fields: dict[int, list] = {}
    position = 0

    def varint():
        nonlocal position
        value, shift = 0, 0
        while True:
            byte = buffer[position]
            position += 1
            value |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                return value

    while position < len(buffer):
        tag = varint()
        number, wire_type = tag >> 3, tag & 7
        if wire_type == 0:
            value = varint()
        elif wire_type == 2:
            length = varint()
            value = buffer[position:position + length]
            position += length
        elif wire_type == 1:
            value, position = None, position + 8
        elif wire_type == 5:
            value, position = None, position + 4
        else:
            raise AssertionError(f"protobuf wire type {wire_type} in a CompressedImage")
        fields.setdefault(number, []).append(value)
    return fields


def frame_payload(seq: int) -> bytes:
    image = draw_ball(floor_image(WIDTH, HEIGHT, seq), BALL_U, BALL_V, BALL_RADIUS)
    return encode("Image", bgr_to_message(image, 1_000_000 + seq, seq, "camera", "bgr8"))


async def first_image(port: int, timeout: float) -> tuple[dict, dict, bytes]:
    """serverInfo, the /image channel's advertisement, and the first binary message on it."""
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL],
                                  max_size=None) as connection:
        assert connection.subprotocol == SUBPROTOCOL
        server_info, channels = None, {}
        async with asyncio.timeout(timeout):
            while server_info is None or "/image" not in channels:
                message = await connection.recv()
                if isinstance(message, bytes):
                    continue
                parsed = json.loads(message)
                if parsed["op"] == "serverInfo":
                    server_info = parsed
                elif parsed["op"] == "advertise":
                    channels.update({channel["topic"]: channel for channel in parsed["channels"]})
            image_channel = channels["/image"]
            await connection.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 7, "channelId": image_channel["id"]}]}))
            while True:
                message = await connection.recv()
                if isinstance(message, bytes) and message[0] == MESSAGE_DATA:
                    subscription, _log_time = struct.unpack_from("<IQ", message, 1)
                    assert subscription == 7
                    return server_info, channels, message[13:]


@pytest.fixture
def viewer(router, log_dir):
    process = Process([sys.executable, "-m", "balltrack", "view", "--foxglove", "--port", "0",
                       "--connect", router.endpoint], log_dir / "viewer.log")
    yield process
    assert process.stop() == 0, process.output()


def test_annotated_frame_reaches_a_foxglove_client(session, launch, viewer):
    launch("detector")
    viewer.wait_for_output("Foxglove server on ws://", 30)
    port = int(re.search(r"ws://[\d.]+:(\d+)", viewer.output()).group(1))
    # Frames keep coming until the client has one: the detector draws image_out only once it
    # sees the viewer's subscriber, and the client subscribes only after the advertisement.
    done = threading.Event()

    def publish_frames():
        seq = 0
        while not done.wait(0.1):
            session.put("camera/image_raw", frame_payload(seq))
            seq += 1

    publisher = threading.Thread(target=publish_frames, daemon=True)
    publisher.start()
    try:
        server_info, channels, payload = asyncio.run(first_image(port, timeout=60))
    finally:
        done.set()
        publisher.join()

    assert server_info["name"] == "balltrack"
    assert {"/image", "/scene", "/tf", "/cmd_vel"} <= set(channels)
    assert channels["/image"]["schemaName"] == "foxglove.CompressedImage"
    assert channels["/image"]["encoding"] == "protobuf"
    assert channels["/cmd_vel"]["encoding"] == "json"

    # foxglove.CompressedImage: timestamp = 1, data = 2, format = 3, frame_id = 4
    fields = protobuf_fields(payload)
    assert fields[3] == [b"jpeg"]
    assert fields[4] == [b"camera"]
    image = cv2.imdecode(np.frombuffer(fields[2][0], np.uint8), cv2.IMREAD_COLOR)
    assert image is not None and image.shape == (HEIGHT, WIDTH, 3)
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH]
    distance = np.hypot(xs - BALL_U, ys - BALL_V)
    # Inside the ball, between the drawn centre mark and outline: yellow-green and saturated.
    inside = hsv[(distance > 0.3 * BALL_RADIUS) & (distance < 0.7 * BALL_RADIUS)]
    hue, saturation = np.median(inside[:, 0]), np.median(inside[:, 1])
    assert 25 <= hue <= 50 and saturation > 100, (hue, saturation)
    # Far from it, the grey floor and wall: no colour.
    outside = hsv[distance > 3 * BALL_RADIUS]
    assert np.median(outside[:, 1]) < 60


@pytest.mark.parametrize("arguments, reason", [
    (["--port", "70000"], "--port: 70000 is not a TCP port"),
    (["--port", "0"], "--port: 0 is not a TCP port"),
    (["--host", "127.0.0.1"], "--host: Rerun's viewer serves on every interface"),
    # (Rerun's own refusal came once its session had opened: "cannot serve on ports", status 1)
    (["--memory-limit", "abc"],
     "--memory-limit: expected an amount such as 256MiB, 2GB or 25% (of the RAM), got 'abc'"),
    (["--memory-limit", "100"], "--memory-limit: expected an amount"),
    (["--set", "update_rate_hz=0"], "--set: update_rate_hz: must be in (0, 30]"),
    (["--set", "frame_hz=5"], "--set: frame_hz: unknown parameter"),
    (["--foxglove", "--set", "update_rate_hz=5"], "--set: the settings are Rerun's"),
    (["--namespaces", "robot1,robot1"], "--namespaces: 'robot1' is listed twice"),
    (["--namespaces", "robot1", "--foxglove"], "--namespaces: Rerun only, and not with --namespace"),
])
def test_bad_options_are_one_line_errors(router, log_dir, arguments, reason):
    process = Process([sys.executable, "-m", "balltrack", "view", *arguments, "--connect", router.endpoint],
                      log_dir / "viewer-bad.log")
    assert process.popen.wait(30) == 2
    output = process.output()
    process.stop()
    assert reason in output and "Traceback" not in output, output


def test_rerun_s_data_port_in_use_is_refused_not_served_beside(router, log_dir):
    # (Rerun logged that it could not listen, and the viewer's link led to the other process)
    with socket.socket() as holder:
        holder.bind(("0.0.0.0", 0))
        holder.listen()
        taken, web = holder.getsockname()[1], free_port()
        process = Process([sys.executable, "-m", "balltrack", "view", "--port", str(web), "--grpc-port", str(taken),
                           "--connect", router.endpoint], log_dir / "viewer-taken.log")
        assert process.popen.wait(30) == 1, process.output()
    errors = [line for line in process.output().splitlines() if line.startswith("balltrack view:")]
    assert errors == [f"balltrack view: cannot serve on ports {web}/{taken}: port {taken} is in use"], process.output()
