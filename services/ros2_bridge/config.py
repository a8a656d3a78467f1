"""ROS 2 bridge parameters: the key prefix of the ROS side, its topic names, and which routes run.

A ROS topic ``/name`` travels on the Zenoh key ``<prefix>name`` (zenoh-bridge-ros2dds drops
the leading slash; its ``namespace`` setting adds one in front, which is what ``prefix``
matches). Example::

    balltrack run ros2_bridge --set prefix=robot/ --set in_compressed_image=true --set in_image=false
"""

from dataclasses import dataclass

from balltrack.common import keys as key_table
from balltrack.common.config import ConfigError, check_fields, param
from balltrack.common.keys import validate_namespace


@dataclass
class Ros2BridgeConfig:
    """Which balltrack keys are converted to ROS 2 messages in CDR and back, and on which keys."""

    prefix: str = param("ros/", "key prefix of every ROS-side key, so CDR and balltrack's msgpack "
                                "never share a key (zenoh-bridge-ros2dds `namespace: \"/ros\"`)")
    to_ros: bool = param(True, "convert balltrack's outputs to ROS messages (the three `out_` routes)")
    from_ros: bool = param(True, "convert a ROS camera's messages to balltrack's (the three `in_` routes)")
    out_detected_ball: bool = param(True, "`detected_ball` -> geometry_msgs/msg/Point (x, y "
                                           "normalised, z the apparent size)")
    out_detected_ball_3d: bool = param(True, "`detected_ball_3d` -> geometry_msgs/msg/PointStamped")
    out_cmd_vel: bool = param(True, "`cmd_vel` -> geometry_msgs/msg/Twist")
    # image_transport publishes a camera both raw and compressed: converting both would feed
    # every frame to the detector twice, so only the raw one is on by default.
    in_image: bool = param(True, "sensor_msgs/msg/Image (rgb8, bgr8, mono8) -> `camera/image_raw`")
    in_compressed_image: bool = param(False, "sensor_msgs/msg/CompressedImage (jpeg) -> "
                                             "`camera/image_raw` (turn `in_image` off)")
    in_camera_info: bool = param(True, "sensor_msgs/msg/CameraInfo -> `camera/camera_info`")
    detected_ball_topic: str = param("/detected_ball", "ROS topic of the Point")
    detected_ball_3d_topic: str = param("/detected_ball_3d", "ROS topic of the PointStamped")
    cmd_vel_topic: str = param("/cmd_vel", "ROS topic of the Twist")
    image_topic: str = param("/camera/image_raw", "ROS topic of the camera's Image")
    compressed_image_topic: str = param("/camera/image_raw/compressed",
                                        "ROS topic of the camera's CompressedImage")
    camera_info_topic: str = param("/camera/camera_info", "ROS topic of the camera's CameraInfo")

    def __post_init__(self):
        check_fields(self)
        for name in ("prefix", *TOPIC_FIELDS):
            if len(getattr(self, name)) > MAX_NAME:
                raise ConfigError(f"{name}: longer than {MAX_NAME} characters")
        try:
            cleaned = validate_namespace(self.prefix)
        except ValueError:
            raise ConfigError(f"prefix: {self.prefix!r} may not contain '*', '$', '?', '#', "
                              "spaces or '//'") from None
        self.prefix = f"{cleaned}/" if cleaned else ""
        for name in TOPIC_FIELDS:
            topic = getattr(self, name)
            stripped = topic.strip("/")
            if not stripped or any(character in stripped for character in "*$?# ") or "//" in stripped:
                raise ConfigError(f"{name}: {topic!r} is not a ROS topic name")
            key = self.prefix + stripped
            # Balltrack's own keys carry msgpack: CDR on one of them would be rejected by every
            # service there, and the bridge would read back what it wrote.
            if key in BALLTRACK_KEYS:
                raise ConfigError(f"{name}: {topic!r} with prefix {self.prefix!r} is balltrack's own "
                                  f"key {key!r}; set a prefix")
        # Two routes on one key: the bridge would read back what it writes there, or take one
        # ROS type for another (a CompressedImage where an Image belongs), and reject half.
        routed: dict[str, str] = {}
        for name in ROUTE_SWITCHES:
            if self.routes(name):
                key = self.ros_key(name)
                if key in routed:
                    raise ConfigError(f"{name}: {getattr(self, name)!r} is also {routed[key]} (key {key!r}); "
                                      "two routes cannot share a topic")
                routed[key] = name

    def routes(self, topic_field: str) -> bool:
        """Whether the route of one ROS topic field is on: its direction's switch and its own."""
        return all(getattr(self, switch) for switch in ROUTE_SWITCHES[topic_field])

    def ros_key(self, topic_field: str) -> str:
        """The Zenoh key (without the service's namespace) of one ROS topic field."""
        return self.prefix + getattr(self, topic_field).strip("/")


# ROS names are a few words; a key is copied into every sample the bridge routes.
MAX_NAME = 256
TOPIC_FIELDS = ("detected_ball_topic", "detected_ball_3d_topic", "cmd_vel_topic", "image_topic",
                "compressed_image_topic", "camera_info_topic")
# Each topic field with the switches that turn its route on, its direction's then its own (the
# routes: ``service.ROUTES``).
ROUTE_SWITCHES = {"detected_ball_topic": ("to_ros", "out_detected_ball"),
                  "detected_ball_3d_topic": ("to_ros", "out_detected_ball_3d"),
                  "cmd_vel_topic": ("to_ros", "out_cmd_vel"),
                  "image_topic": ("from_ros", "in_image"),
                  "compressed_image_topic": ("from_ros", "in_compressed_image"),
                  "camera_info_topic": ("from_ros", "in_camera_info")}
BALLTRACK_KEYS = frozenset(spec.key for spec in key_table.TABLE if "<" not in spec.key)
