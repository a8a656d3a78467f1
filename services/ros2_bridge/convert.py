"""Balltrack messages (dicts of :mod:`common.messages`) to and from ROS 2 messages in CDR.

CDR is what DDS, zenoh-bridge-ros2dds and rosbag2 carry: a 4-byte encapsulation header
(``00 01 00 00``, little-endian CDR) then the fields in order, aligned to their size. The
serialisation is ``rosbags``' pure-Python one with the ROS 2 Humble type definitions (these
six types are the same in every ROS 2 release). Every ``*_from_ros`` raises
:class:`MessageError` with a one-line reason for bytes that are not the type they should be,
so the service drops and counts them.

Out to ROS:

- ``Ball2D`` -> ``geometry_msgs/msg/Point``: x, y normalised to [-1, 1], z the ball's apparent
  diameter over the image width, as the paper's ``detect_ball`` node publishes it.
- ``Ball3D`` -> ``geometry_msgs/msg/PointStamped``: the header's ns stamp becomes
  ``sec``/``nanosec``, its frame id is kept.
- ``Twist`` -> ``geometry_msgs/msg/Twist`` (ROS's has no header).

In from ROS:

- ``sensor_msgs/msg/Image`` (rgb8, bgr8, mono8; rows padded to ``step`` are unpadded) and
  ``sensor_msgs/msg/CompressedImage`` (jpeg) -> ``Image``.
- ``sensor_msgs/msg/CameraInfo`` -> ``CameraInfo``: fx, fy, cx, cy from K, fields of view
  from them (``hfov = 2 atan(W / 2 fx)``), distortion kept as ``distortion_model`` and ``d``.

ROS 2 headers have no sequence number: the caller passes one (a count of the messages it
converted) for balltrack's ``seq``.
"""

import math

import numpy as np
from rosbags.typesys import Stores, get_typestore

from balltrack.common.images import jpeg_size
from balltrack.common.messages import ENCODINGS, MAX_IMAGE_SIDE, MessageError, shorten

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)

POINT = "geometry_msgs/msg/Point"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
TWIST = "geometry_msgs/msg/Twist"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"

RAW_ENCODINGS = ("rgb8", "bgr8", "mono8")
# OpenCV's 5 and 8 coefficient models are ROS's plumb_bob and rational_polynomial (k1, k2, p1,
# p2, k3[, k4, k5, k6]); balltrack calls both plumb_bob. A fisheye (equidistant) lens is not
# that model at all, so its CameraInfo is refused rather than read wrongly.
DISTORTION_MODELS = {"plumb_bob": "plumb_bob", "rational_polynomial": "plumb_bob",
                     "": "none", "none": "none"}
MAX_DISTORTION = 8

_types = TYPESTORE.types
_Time = _types["builtin_interfaces/msg/Time"]
_Header = _types["std_msgs/msg/Header"]
_Point = _types[POINT]
_PointStamped = _types[POINT_STAMPED]
_Vector3 = _types["geometry_msgs/msg/Vector3"]
_Twist = _types[TWIST]


def serialize(message, typename: str) -> bytes:
    return bytes(TYPESTORE.serialize_cdr(message, typename))


def deserialize(data: bytes | bytearray | memoryview, typename: str):
    """The ROS message in ``data``, or MessageError saying why it is not one."""
    if len(data) < 4:
        raise MessageError(f"not a CDR {typename}: {len(data)} bytes, shorter than the "
                           "encapsulation header")
    if data[0] != 0 or data[1] not in (0, 1):
        raise MessageError(f"not a CDR {typename}: encapsulation {bytes(data[:2]).hex()} "
                           "is not plain CDR (0000 or 0001)")
    try:
        return TYPESTORE.deserialize_cdr(bytes(data), typename)
    except Exception as error:  # rosbags raises SerdeError, struct.error, UnicodeDecodeError...
        raise MessageError(f"not a CDR {typename}: {shorten(str(error), 150)}") from None


def ros_time(stamp_ns: int):
    seconds, nanoseconds = divmod(int(stamp_ns), 1_000_000_000)
    if seconds >= 2 ** 31:
        raise MessageError(f"header.stamp: {stamp_ns} ns does not fit ROS's int32 seconds")
    return _Time(sec=seconds, nanosec=nanoseconds)


def stamp_from_ros(header) -> int:
    stamp = header.stamp
    if stamp.sec < 0 or stamp.nanosec >= 1_000_000_000:
        raise MessageError(f"header.stamp: {stamp.sec} s {stamp.nanosec} ns is not a time after 1970")
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _header(header, seq: int) -> dict:
    return {"stamp": stamp_from_ros(header), "frame_id": header.frame_id, "seq": int(seq)}


def ball2d_to_ros(ball: dict) -> bytes:
    """A ``Ball2D`` as the paper's ``/detected_ball`` ``geometry_msgs/msg/Point``."""
    return serialize(_Point(x=float(ball["x"]), y=float(ball["y"]), z=float(ball["z"])), POINT)


def ball3d_to_ros(ball: dict) -> bytes:
    """A ``Ball3D`` as ``geometry_msgs/msg/PointStamped`` (metres, in the header's frame)."""
    header = _Header(stamp=ros_time(ball["header"]["stamp"]), frame_id=ball["header"]["frame_id"])
    point = _Point(x=float(ball["x"]), y=float(ball["y"]), z=float(ball["z"]))
    return serialize(_PointStamped(header=header, point=point), POINT_STAMPED)


def twist_to_ros(twist: dict) -> bytes:
    """A balltrack ``Twist`` (linear and angular as 3-lists) as ``geometry_msgs/msg/Twist``."""
    linear, angular = ([float(value) for value in twist[name]] for name in ("linear", "angular"))
    return serialize(_Twist(linear=_Vector3(*linear), angular=_Vector3(*angular)), TWIST)


def _check_size(width: int, height: int) -> None:
    if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE):
        raise MessageError(f"size: {width}x{height} is outside 1..{MAX_IMAGE_SIDE} pixels a side")


def image_from_ros(data: bytes, seq: int) -> dict:
    """A ``sensor_msgs/msg/Image`` as a balltrack ``Image`` (same encoding, rows unpadded)."""
    image = deserialize(data, IMAGE)
    if image.encoding not in RAW_ENCODINGS:
        raise MessageError(f"encoding: {shorten(image.encoding, 40)!r} is not supported "
                           f"({', '.join(RAW_ENCODINGS)})")
    width, height, step = image.width, image.height, image.step
    _check_size(width, height)
    row = width * ENCODINGS[image.encoding]
    if step < row:
        raise MessageError(f"step: {step} bytes is less than a {width} px {image.encoding} row ({row})")
    pixels = image.data
    # The last row need not carry its padding; anything shorter is a truncated frame.
    needed = step * (height - 1) + row
    if len(pixels) < needed:
        raise MessageError(f"data: {len(pixels)} bytes, but {height} rows of step {step} need {needed}")
    if step == row:
        packed = pixels[:row * height].tobytes()
    else:
        packed = np.ndarray((height, row), np.uint8, pixels, strides=(step, 1)).tobytes()
    return {"header": _header(image.header, seq), "width": width, "height": height,
            "encoding": image.encoding, "data": packed}


def compressed_image_from_ros(data: bytes, seq: int) -> dict:
    """A JPEG ``sensor_msgs/msg/CompressedImage`` as a balltrack ``Image`` (encoding jpeg).

    ``format`` is ``jpeg`` or image_transport's ``"bgr8; jpeg compressed bgr8"``; either way the
    data is a plain JPEG file, whose own header gives the size balltrack's Image states."""
    image = deserialize(data, COMPRESSED_IMAGE)
    kind = image.format.lower()
    if "jpeg" not in kind and "jpg" not in kind:
        raise MessageError(f"format: {shorten(image.format, 60)!r} is not JPEG")
    jpeg = image.data.tobytes()
    if len(jpeg) < 4 or jpeg[:2] != b"\xff\xd8":
        raise MessageError("data: not a JPEG file (no SOI marker)")
    width, height = jpeg_size(jpeg)
    _check_size(width, height)
    return {"header": _header(image.header, seq), "width": width, "height": height,
            "encoding": "jpeg", "data": jpeg}


def camera_info_from_ros(data: bytes, seq: int) -> dict:
    """A ``sensor_msgs/msg/CameraInfo`` as balltrack's ``CameraInfo``.

    The intrinsics are K's (the raw image's), as the detector sees the raw image; the fields of
    view are a pinhole's of that focal length, ``2 atan(W / 2 fx)``."""
    info = deserialize(data, CAMERA_INFO)
    width, height = info.width, info.height
    _check_size(width, height)
    k = [float(value) for value in info.k]
    fx, fy, cx, cy = k[0], k[4], k[2], k[5]
    if not all(math.isfinite(value) for value in k):
        raise MessageError("k: not finite")
    if fx <= 0 or fy <= 0:
        raise MessageError(f"k: focal lengths {fx}, {fy} are not positive (an uncalibrated camera)")
    model = DISTORTION_MODELS.get(info.distortion_model)
    if model is None:
        raise MessageError(f"distortion_model: {shorten(info.distortion_model, 40)!r} is not "
                           f"supported ({', '.join(name for name in DISTORTION_MODELS if name)})")
    distortion = [float(value) for value in info.d]
    if len(distortion) > MAX_DISTORTION:
        raise MessageError(f"d: {len(distortion)} coefficients, more than {MAX_DISTORTION}")
    if not all(math.isfinite(value) for value in distortion):
        raise MessageError("d: not finite")
    return {"header": _header(info.header, seq), "width": width, "height": height,
            "fx": fx, "fy": fy, "cx": cx, "cy": cy,
            "hfov": 2.0 * math.atan(width / (2.0 * fx)), "vfov": 2.0 * math.atan(height / (2.0 * fy)),
            "distortion_model": model, "d": distortion}
