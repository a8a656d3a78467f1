"""balltrack messages as Foxglove message types, for the live server (``balltrack view
--foxglove``) and for recordings (``balltrack record`` and the demo's ``run.mcap`` carry these
channels beside the raw msgpack ones, so Foxglove opens a recording directly):

    /image             CompressedImage (JPEG)   the detector's annotated frame (``image_out``)
    /camera/image      CompressedImage (JPEG)   the camera's frames (``camera/image_raw``)
    /scene             SceneUpdate              one sphere per located ball (``detected_ball_3d``,
                                                camera_optical frame) and the true balls (world)
    /tf                FrameTransform           world -> base_link from ``sim/ground_truth``
    /cmd_vel           JSON                     the follower's Twist, for plots

Conversions take decoded (validated) messages and return Foxglove objects; nothing here touches
Zenoh. JPEG frames pass through as they are; raw frames are JPEG-encoded.
"""

import json
import math

import cv2
from foxglove.messages import (Color, CompressedImage, FrameTransform, Pose, Quaternion, SceneEntity,
                               SceneUpdate, SpherePrimitive, Timestamp, Vector3)

from balltrack.common.images import image_to_bgr
from balltrack.common.keys import IMAGE_RAW, CMD_VEL, DETECTED_BALL_3D, GROUND_TRUTH, IMAGE_OUT

IMAGE_TOPIC = "/image"
CAMERA_TOPIC = "/camera/image"
SCENE_TOPIC = "/scene"
TF_TOPIC = "/tf"
CMD_VEL_TOPIC = "/cmd_vel"

DETECTED_COLOUR = Color(r=0.8, g=1.0, b=0.2, a=0.9)  # the tennis ball's yellow-green
TRUE_COLOUR = Color(r=0.3, g=0.6, b=1.0, a=0.4)      # ground truth: translucent blue
DETECTED_DIAMETER = 0.067  # a tennis ball; Ball3D carries no radius

# cmd_vel goes as JSON (Foxglove plots JSON fields); the schema says what the fields are.
TWIST_SCHEMA = {
    "type": "object",
    "properties": {
        "stamp": {"type": "integer"},
        "linear": {"type": "array", "items": {"type": "number"}},
        "angular": {"type": "array", "items": {"type": "number"}},
    },
}


def timestamp(nanoseconds: int) -> Timestamp:
    return Timestamp(nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000)


def yaw_quaternion(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _point(x: float, y: float, z: float) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(w=1.0))


def jpeg_of(image: dict, quality: int) -> bytes | None:
    """An Image message's frame as JPEG bytes (a JPEG frame as it is); None if encoding fails.
    Raises MessageError for pixels that do not match the message's size."""
    if image["encoding"] == "jpeg":
        return bytes(image["data"])
    ok, buffer = cv2.imencode(".jpg", image_to_bgr(image), [cv2.IMWRITE_JPEG_QUALITY, quality])
    return buffer.tobytes() if ok else None


def compressed_image(header: dict, jpeg: bytes) -> CompressedImage:
    return CompressedImage(timestamp=timestamp(header["stamp"]), frame_id=header["frame_id"],
                           data=jpeg, format="jpeg")


def located_scene(ball: dict) -> SceneUpdate:
    """A located ball (Ball3D) as a sphere in the camera's optical frame."""
    header = ball["header"]
    sphere = SpherePrimitive(pose=_point(ball["x"], ball["y"], ball["z"]),
                             size=Vector3(x=DETECTED_DIAMETER, y=DETECTED_DIAMETER, z=DETECTED_DIAMETER),
                             color=DETECTED_COLOUR)
    return SceneUpdate(entities=[SceneEntity(timestamp=timestamp(header["stamp"]), frame_id=header["frame_id"],
                                             id="detected_ball", spheres=[sphere])])


def truth_scene(truth: dict) -> SceneUpdate:
    """The true balls (GroundTruth) as spheres of their own size in the world frame."""
    spheres = [SpherePrimitive(pose=_point(*ball["position"]),
                               size=Vector3(x=2 * ball["radius"], y=2 * ball["radius"], z=2 * ball["radius"]),
                               color=TRUE_COLOUR) for ball in truth["balls"]]
    return SceneUpdate(entities=[SceneEntity(timestamp=timestamp(truth["header"]["stamp"]), frame_id="world",
                                             id="true_balls", spheres=spheres)])


def robot_transform(truth: dict) -> FrameTransform:
    """world -> base_link from the robot's true pose."""
    robot = truth["robot"]
    return FrameTransform(timestamp=timestamp(truth["header"]["stamp"]), parent_frame_id="world",
                          child_frame_id="base_link", translation=Vector3(x=robot["x"], y=robot["y"], z=0.0),
                          rotation=yaw_quaternion(robot["yaw"]))


def twist_json(twist: dict) -> dict:
    return {"stamp": twist["header"]["stamp"], "linear": list(twist["linear"]),
            "angular": list(twist["angular"])}


# The message types the recorder converts, by key (without namespace).
RECORDED_TYPES = {IMAGE_OUT: "Image", IMAGE_RAW: "Image", DETECTED_BALL_3D: "Ball3D",
                  GROUND_TRUTH: "GroundTruth", CMD_VEL: "Twist"}


def recorded_messages(key: str, message: dict, jpeg_quality: int = 80) -> list[tuple[str, object]]:
    """(Foxglove topic, message) pairs a recording stores for a decoded message of ``key``: a
    Foxglove message object, or a dict for the JSON channel. Keys without a Foxglove view give
    none."""
    if key in (IMAGE_OUT, IMAGE_RAW):
        jpeg = jpeg_of(message, jpeg_quality)
        if jpeg is None:
            return []
        return [(IMAGE_TOPIC if key == IMAGE_OUT else CAMERA_TOPIC, compressed_image(message["header"], jpeg))]
    if key == DETECTED_BALL_3D:
        return [(SCENE_TOPIC, located_scene(message))]
    if key == GROUND_TRUTH:
        return [(TF_TOPIC, robot_transform(message)), (SCENE_TOPIC, truth_scene(message))]
    if key == CMD_VEL:
        return [(CMD_VEL_TOPIC, twist_json(message))]
    return []


def mcap_encoding(message) -> tuple[str, str, bytes, str, bytes]:
    """(schema name, schema encoding, schema data, message encoding, payload) of a converted
    message as MCAP stores it: protobuf for Foxglove's types, JSON for the Twist."""
    if isinstance(message, dict):
        return "Twist", "jsonschema", json.dumps(TWIST_SCHEMA).encode(), "json", json.dumps(message).encode()
    schema = type(message).get_schema()
    return schema.name, schema.encoding, bytes(schema.data), "protobuf", bytes(message.encode())
