"""A recording's Foxglove channels, read as Foxglove would: the protobuf schemas stored in the
file decode the messages with Google's protobuf runtime (not the foxglove-sdk that wrote them)
and give the recorded values; ``play`` publishes the msgpack channels only.
"""

import json

import cv2
import numpy as np
import pytest
import zenoh

from balltrack.common.messages import encode, header
from balltrack.deploy.recording import Recording
from tests.harness import wait_matched
from tests.integration.test_recording import Received, balltrack

pytest.importorskip("foxglove")
descriptor_pb2 = pytest.importorskip("google.protobuf.descriptor_pb2")
from google.protobuf import descriptor_pool, message_factory  # noqa: E402
from mcap.reader import make_reader  # noqa: E402


def protobuf_class(schema):
    """The message class a stored FileDescriptorSet describes."""
    files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def test_foxglove_channels_decode_independently_and_play_skips_them(router, session, tmp_path):
    path = tmp_path / "run.mcap"
    frame = np.zeros((48, 64, 3), np.uint8)
    frame[10:30, 20:40] = (40, 220, 200)  # BGR: a yellow-green square
    messages = [
        ("camera/image_raw", "Image", {"header": header(1_000_000_001, 7, "camera_optical"), "width": 64,
                                       "height": 48, "encoding": "bgr8", "data": frame.tobytes()}),
        ("detected_ball_3d", "Ball3D", {"header": header(1_000_000_002, 7, "camera_optical"),
                                        "x": 0.1, "y": -0.2, "z": 1.5, "distance": 1.52}),
        ("sim/ground_truth", "GroundTruth", {
            "header": header(1_000_000_003, 7, "world"), "robot": {"x": 1.0, "y": 2.0, "yaw": np.pi / 2},
            "balls": [{"id": "ball0", "radius": 0.033, "position": [3.0, 2.0, 0.033],
                       "in_camera": [0.0, 0.0, 2.0], "visible": True}]}),
        ("cmd_vel", "Twist", {"header": header(1_000_000_004, 7), "linear": [0.2, 0.0, 0.0],
                              "angular": [0.0, 0.0, -0.5]}),
    ]
    recording = Recording(session, path, [key for key, _, _ in messages], foxglove=True)
    publishers = {key: session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
                  for key, _, _ in messages}
    for publisher in publishers.values():
        wait_matched(publisher)
    for key, message_type, message in messages:
        publishers[key].put(encode(message_type, message))
    publishers["detected_ball_3d"].put(b"\xc1 not msgpack")  # kept raw, no scene made of it
    received = Received(session, "**")  # for the replay below; subscribed after the recording
    assert recording.wait_received(len(messages) + 1, timeout=20), recording.counts
    assert recording.close().written == len(messages) + 1

    decoded = {}
    with open(path, "rb") as file:
        for schema, channel, record in make_reader(file).iter_messages():
            if channel.message_encoding == "protobuf":
                decoded.setdefault(channel.topic, []).append(protobuf_class(schema).FromString(record.data))
            elif channel.message_encoding == "json":
                assert schema.encoding == "jsonschema" and json.loads(schema.data)["type"] == "object"
                decoded.setdefault(channel.topic, []).append(json.loads(record.data))
    assert sorted(decoded) == ["/camera/image", "/cmd_vel", "/scene", "/tf"]

    (image,) = decoded["/camera/image"]
    assert image.format == "jpeg" and image.frame_id == "camera_optical"
    assert (image.timestamp.seconds, image.timestamp.nanos) == (1, 1)
    pixels = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
    assert pixels.shape == frame.shape and np.abs(pixels.astype(int) - frame).mean() < 4

    # the two scene updates come from two keys, so in either order
    scenes = {update.entities[0].id: update for update in decoded["/scene"]}
    assert sorted(scenes) == ["detected_ball", "true_balls"]
    located, truth = scenes["detected_ball"], scenes["true_balls"]
    sphere = located.entities[0].spheres[0]
    assert located.entities[0].frame_id == "camera_optical"
    assert (sphere.pose.position.x, sphere.pose.position.y, sphere.pose.position.z) == (0.1, -0.2, 1.5)
    true_sphere = truth.entities[0].spheres[0]
    assert truth.entities[0].frame_id == "world" and true_sphere.pose.position.x == 3.0
    assert true_sphere.size.x == pytest.approx(0.066)

    (transform,) = decoded["/tf"]
    assert (transform.parent_frame_id, transform.child_frame_id) == ("world", "base_link")
    assert (transform.translation.x, transform.translation.y) == (1.0, 2.0)
    assert transform.rotation.z == pytest.approx(np.sin(np.pi / 4))

    assert decoded["/cmd_vel"] == [{"stamp": 1_000_000_004, "linear": [0.2, 0.0, 0.0],
                                    "angular": [0.0, 0.0, -0.5]}]

    # play: the balltrack keys byte for byte, no Foxglove topic put on Zenoh; a Foxglove
    # channel asked for by name is refused as one
    refused = balltrack("play", str(path), "--keys", "/tf", "--connect", router.endpoint)
    assert refused.returncode == 2
    assert refused.stderr.startswith("balltrack play: '/tf' is a Foxglove channel, for viewing: play publishes")
    result = balltrack("play", str(path), "--rate", "0", "--connect", router.endpoint)
    assert result.returncode == 0, result.stderr
    assert f"published {len(messages) + 1} messages" in result.stdout
    replayed = received.wait_count(len(messages) + 1)
    assert sorted(key for key, _ in replayed) == sorted([key for key, _, _ in messages] + ["detected_ball_3d"])
