"""The ROS 2 messages the bridge speaks, declared a second time with pycdr2 (an independent CDR
implementation, not rosbags) from their .msg definitions, so tests check the bridge's bytes
against another reading of the standard rather than against the library that wrote them."""

from dataclasses import dataclass

from pycdr2 import IdlStruct
from pycdr2.types import array, float64, int32, sequence, uint8, uint32


@dataclass
class Time(IdlStruct, typename="builtin_interfaces/msg/Time"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs/msg/Header"):
    stamp: Time
    frame_id: str


@dataclass
class Point(IdlStruct, typename="geometry_msgs/msg/Point"):
    x: float64
    y: float64
    z: float64


@dataclass
class PointStamped(IdlStruct, typename="geometry_msgs/msg/PointStamped"):
    header: Header
    point: Point


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs/msg/Vector3"):
    x: float64
    y: float64
    z: float64


@dataclass
class Twist(IdlStruct, typename="geometry_msgs/msg/Twist"):
    linear: Vector3
    angular: Vector3


@dataclass
class Image(IdlStruct, typename="sensor_msgs/msg/Image"):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


@dataclass
class CompressedImage(IdlStruct, typename="sensor_msgs/msg/CompressedImage"):
    header: Header
    format: str
    data: sequence[uint8]


@dataclass
class RegionOfInterest(IdlStruct, typename="sensor_msgs/msg/RegionOfInterest"):
    x_offset: uint32
    y_offset: uint32
    height: uint32
    width: uint32
    do_rectify: bool


@dataclass
class CameraInfo(IdlStruct, typename="sensor_msgs/msg/CameraInfo"):
    header: Header
    height: uint32
    width: uint32
    distortion_model: str
    d: sequence[float64]
    k: array[float64, 9]
    r: array[float64, 9]
    p: array[float64, 12]
    binning_x: uint32
    binning_y: uint32
    roi: RegionOfInterest


def header(stamp_ns: int, frame_id: str = "camera") -> Header:
    return Header(Time(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000), frame_id)


def camera_info(width: int, height: int, fx: float, fy: float, cx: float, cy: float,
                distortion_model: str = "plumb_bob", d: list[float] | None = None,
                stamp_ns: int = 0) -> CameraInfo:
    k = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    return CameraInfo(header(stamp_ns), height, width, distortion_model,
                      [0.0] * 5 if d is None else d, k, [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
                      [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0], 0, 0,
                      RegionOfInterest(0, 0, 0, 0, False))
