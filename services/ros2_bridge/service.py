"""ROS 2 bridge service: balltrack's msgpack keys <-> ROS 2 messages in CDR, on the keys
zenoh-bridge-ros2dds uses (the ROS topic without its leading slash) under ``prefix``.

Subscribes: ``detected_ball``, ``detected_ball_3d``, ``cmd_vel`` (msgpack), and on the ROS side
``<prefix>camera/image_raw`` (sensor_msgs/msg/Image), ``<prefix>camera/image_raw/compressed``
(CompressedImage, off by default), ``<prefix>camera/camera_info`` (CameraInfo). Publishes:
``<prefix>detected_ball`` (geometry_msgs/msg/Point), ``<prefix>detected_ball_3d``
(PointStamped), ``<prefix>cmd_vel`` (Twist), and ``camera/image_raw``, ``camera/camera_info``
(msgpack) for the detector and the locator. Needs ``pip install balltrack[ros]`` (rosbags).

Example:
    balltrack run ros2_bridge --set prefix=ros/ --set out_cmd_vel=false
"""

import sys
import threading
import time
import traceback
from dataclasses import dataclass
from typing import Callable

import zenoh

from balltrack.common import keys
from balltrack.common.messages import MessageError, shorten
from balltrack.common.context import ServiceContext, in_order
from balltrack.common.runner import run_service
from balltrack.services.ros2_bridge.config import ROUTE_SWITCHES, Ros2BridgeConfig

NAME = "ros2_bridge"


@dataclass(frozen=True)
class Route:
    """One conversion: ``topic`` names the config field holding the ROS topic (and, in
    ``ROUTE_SWITCHES``, the fields that turn the route on); ``key``/``message`` are balltrack's
    side."""

    topic: str
    key: str
    message: str
    convert: str
    ros_type: str  # the ROS side's message type (named in its samples' Zenoh encoding)

    @property
    def direction(self) -> str:
        """``to_ros`` or ``from_ros``: the config field of the routes that way."""
        return ROUTE_SWITCHES[self.topic][0]


ROUTES = (
    Route("detected_ball_topic", keys.DETECTED_BALL, "Ball2D", "ball2d_to_ros", "geometry_msgs/msg/Point"),
    Route("detected_ball_3d_topic", keys.DETECTED_BALL_3D, "Ball3D", "ball3d_to_ros",
          "geometry_msgs/msg/PointStamped"),
    Route("cmd_vel_topic", keys.CMD_VEL, "Twist", "twist_to_ros", "geometry_msgs/msg/Twist"),
    Route("image_topic", keys.IMAGE_RAW, "Image", "image_from_ros", "sensor_msgs/msg/Image"),
    Route("compressed_image_topic", keys.IMAGE_RAW, "Image", "compressed_image_from_ros",
          "sensor_msgs/msg/CompressedImage"),
    Route("camera_info_topic", keys.CAMERA_INFO, "CameraInfo", "camera_info_from_ros",
          "sensor_msgs/msg/CameraInfo"),
)


def active_routes(config: Ros2BridgeConfig) -> dict[Route, str]:
    """The routes ``config`` turns on, each with its ROS-side key (without the namespace)."""
    return {route: config.ros_key(route.topic) for route in ROUTES if config.routes(route.topic)}


class Bridge:
    """Declares the Zenoh side of the active routes, and declares them again when a config
    change alters which routes run or on which keys (parameters are live, as in every service)."""

    def __init__(self, service: ServiceContext, convert):
        self.service = service
        self.convert = convert
        self.routes: dict[Route, str] = {}
        self._declared: list = []
        self._sequence: dict[Route, int] = {}
        self._lock = threading.Lock()
        # One balltrack publisher per key, for the life of the service (two routes share
        # camera/image_raw).
        self._balltrack = {route.key: service.publisher(route.key, route.message)
                           for route in ROUTES if route.direction == "from_ros"}

    def apply(self, config: Ros2BridgeConfig) -> None:
        wanted = active_routes(config)
        with self._lock:
            if wanted == self.routes:
                return
            self._undeclare()
            for route, ros_key in wanted.items():
                if route.direction == "to_ros":
                    self._declare_out(route, ros_key)
                else:
                    self._declare_in(route, ros_key)
            self.routes = wanted
        self.service.log.info("routes: %s", ", ".join(f"{route.key} {'->' if route.direction == 'to_ros' else '<-'} "
                                                    f"{self.service.keys(key)}" for route, key in wanted.items())
                              or "none")

    def close(self) -> None:
        with self._lock:
            self._undeclare()
            self.routes = {}

    def _undeclare(self) -> None:
        for entity in reversed(self._declared):
            try:
                entity.undeclare()
            except Exception:  # already gone with the session: nothing left to release
                pass
        self._declared = []

    def _declare_out(self, route: Route, ros_key: str) -> None:
        service = self.service
        convert: Callable[[dict], bytes] = getattr(self.convert, route.convert)
        # (the encoding names the ROS type: `balltrack record` then stores the samples as a
        # ROS 2 bag's channel, which Foxglove and ROS 2 tools read)
        publisher = service.session.declare_publisher(
            service.keys(ros_key), encoding=zenoh.Encoding.APPLICATION_CDR.with_schema(route.ros_type))
        full_key = service.keys(route.key)

        def handle(message: dict) -> None:
            # A message that validates as balltrack's may still not fit a ROS field (a stamp
            # past 2038): the converter raises MessageError and the runner counts it.
            publisher.put(convert(message))
            service.stats.count("published")

        def on_sample(sample) -> None:
            service.stats.count("received")
            service.process(full_key, route.message, sample.payload.to_bytes(), handle, True)

        self._declared.append(publisher)
        self._declared.append(service.session.declare_subscriber(full_key, in_order(on_sample)))

    def _declare_in(self, route: Route, ros_key: str) -> None:
        service = self.service
        convert: Callable[[bytes, int], dict] = getattr(self.convert, route.convert)
        output = self._balltrack[route.key]
        full_key = service.keys(ros_key)

        def on_sample(sample) -> None:
            service.stats.count("received")
            started = time.perf_counter()
            try:
                sequence = self._sequence.get(route, 0)
                output.put(convert(sample.payload.to_bytes(), sequence))
                self._sequence[route] = sequence + 1
            except MessageError as error:  # not the ROS type, or not a valid balltrack message
                service.reject(full_key, str(error))
                return
            except Exception as error:  # a bug must not kill the bridge; logged loudly
                service.reject(full_key, f"internal error: {shorten(error)}")
                service.log.debug("%s", traceback.format_exc())
                return
            service.stats.record_duration(time.perf_counter() - started)

        self._declared.append(service.session.declare_subscriber(full_key, in_order(on_sample)))


def build(service: ServiceContext):
    from balltrack.services.ros2_bridge import convert

    bridge = Bridge(service, convert)
    bridge.apply(service.config)
    service.on_config_change(bridge.apply)

    def loop(context: ServiceContext) -> None:
        # The routes' entities are the bridge's own (they change with the config): release them
        # before the runner closes the session.
        while not context.stop.wait(0.5):
            pass
        bridge.close()

    return loop


def rosbags_missing() -> bool:
    try:
        import rosbags.typesys  # noqa: F401
    except ImportError:
        return True
    return False


def unavailable() -> str | None:
    """Why this service cannot run here (one line), or None; checked before any session opens,
    alone (``main``) or joined with others (``balltrack run A+B``)."""
    if rosbags_missing():
        return "needs the rosbags package for ROS 2 messages: pip install balltrack[ros]"
    return None


# The service's parameters (``balltrack run ros2_bridge --help`` lists them); ``build`` wires it.
CONFIG = Ros2BridgeConfig


def main(argv=None) -> int:
    reason = unavailable()
    if reason:
        print(f"{NAME}: {reason}", file=sys.stderr)
        return 2
    return run_service(NAME, CONFIG, build, argv, __doc__)
