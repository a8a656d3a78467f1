"""Every Zenoh key of balltrack, in one table (like openpilot's services list).

Keys are written without a namespace here; :class:`Keys` adds the optional ``NS/`` prefix so
several robots can share one Zenoh network (``robot1/camera/image_raw``). The paper's ROS
topics map to keys by dropping the leading slash, as zenoh-bridge-ros2dds does.
"""

from dataclasses import dataclass

# What `balltrack deploy start` runs by default; the ROS 2 bridge is started on request.
CORE_SERVICES = ("detector", "locator", "follower", "simulator")
# The camera publishes what the simulator does, from a real camera: one or the other runs.
SERVICES = (*CORE_SERVICES, "ros2_bridge", "camera")
# The services that publish a robot's frames (``camera/image_raw``): where one is alive, there
# is a robot to serve (``--namespaces auto``).
FRAME_SOURCES = ("simulator", "camera", "ros2_bridge")
# Services one process can run for several robots (``--namespaces robot1,robot2``): those that
# handle a robot's messages. A source of frames, or the ROS 2 bridge, runs a process per robot.
SERVICES_OF_MANY_ROBOTS = ("detector", "locator", "follower")
# Services joined by this run in one process, on one session (``balltrack run detector+locator``).
PROCESS_JOIN = "+"


def process_services(process: str) -> list[str]:
    """The services of a process name: ``detector+locator`` -> ``["detector", "locator"]``."""
    return process.split(PROCESS_JOIN)


def services_of(processes) -> list[str]:
    """Every service of ``processes`` (names as ``process_services`` reads them), in order."""
    return [name for process in processes for name in process_services(process)]

IMAGE_RAW = "camera/image_raw"
CAMERA_INFO = "camera/camera_info"
DETECTED_BALL = "detected_ball"
DETECTED_BALLS = "detected_balls"
DETECTED_BALL_3D = "detected_ball_3d"
CMD_VEL = "cmd_vel"
IMAGE_OUT = "image_out"
IMAGE_TUNING = "image_tuning"
CLOCK = "clock"
GROUND_TRUTH = "sim/ground_truth"
SIM_CONTROL = "sim/control"


@dataclass(frozen=True)
class KeySpec:
    key: str
    message: str
    publisher: str
    when: str


TABLE: tuple[KeySpec, ...] = (
    KeySpec(IMAGE_RAW, "Image", "simulator, camera service, ROS 2 bridge, or any camera",
            "every frame (30 Hz default)"),
    KeySpec(CAMERA_INFO, "CameraInfo", "simulator, camera service or ROS 2 bridge",
            "1 Hz, and before the first frame of each new frame size; answered as a query"),
    KeySpec(DETECTED_BALL, "Ball2D", "detector", "each frame with a ball: the largest one"),
    KeySpec(DETECTED_BALLS, "Ball2DArray", "detector", "every frame, empty list when none"),
    KeySpec(DETECTED_BALL_3D, "Ball3D", "locator", "each detected_ball"),
    KeySpec(CMD_VEL, "Twist", "follower", "10 Hz timer"),
    KeySpec(IMAGE_OUT, "Image", "detector", "annotated frame, only while someone subscribes"),
    KeySpec(IMAGE_TUNING, "Image", "detector", "the colour mask, only while someone subscribes"),
    KeySpec(CLOCK, "Clock", "simulator", "every rendered frame"),
    KeySpec(GROUND_TRUTH, "GroundTruth", "simulator", "every rendered frame"),
    KeySpec(SIM_CONTROL, "SimCommand -> SimReply", "simulator", "query, on request"),
    KeySpec("<service>/config", "ConfigRequest -> ConfigReply", "every service", "query"),
    KeySpec("<service>/stats", "Stats", "every service", "1 Hz"),
    KeySpec("alive/<service>", "liveliness token", "every service", "while it runs"),
)

# Which message schema travels on each fixed data key (used by `balltrack echo`).
MESSAGE_OF_KEY = {spec.key: spec.message for spec in TABLE if "<" not in spec.key
                  and "->" not in spec.message}


def stats_key(service: str) -> str:
    return f"{service}/stats"


def config_key(service: str) -> str:
    return f"{service}/config"


def alive_key(service: str) -> str:
    return f"alive/{service}"


def alive_token(full_key: str) -> tuple[str, str] | None:
    """(namespace, service) of a ``[<namespace>/]alive/<service>`` token's key, or None."""
    namespace, separator, service = ("/" + full_key).rpartition("/alive/")
    if not separator or not service or "/" in service:
        return None
    return namespace.lstrip("/"), service


def validate_namespace(namespace: str) -> str:
    """Return the namespace without surrounding slashes; reject what Zenoh cannot route."""
    cleaned = (namespace or "").strip().strip("/")
    if any(character in cleaned for character in "*$?#") or "//" in cleaned or " " in cleaned:
        raise ValueError(f"namespace: {namespace!r} may not contain '*', '$', '?', '#', spaces or '//'")
    return cleaned


def namespace_list(text: str, option: str) -> list[str]:
    """``robot1,robot2``: each namespace (``validate_namespace``), in order; ValueError naming
    ``option``, one line, for a bad, empty or repeated one."""
    namespaces: list[str] = []
    for item in text.split(","):
        try:
            namespace = validate_namespace(item)
        except ValueError as error:
            raise ValueError(f"{option}: {error}") from None
        if not namespace:
            raise ValueError(f"{option}: {text!r} has an empty name (expected NS,NS,..., e.g. robot1,robot2)")
        if namespace in namespaces:
            raise ValueError(f"{option}: {namespace!r} is listed twice")
        namespaces.append(namespace)
    return namespaces


class Keys:
    """Namespaced key strings: ``Keys("robot1")(CMD_VEL) == "robot1/cmd_vel"``."""

    def __init__(self, namespace: str = ""):
        self.namespace = validate_namespace(namespace)

    def __call__(self, key: str) -> str:
        return f"{self.namespace}/{key}" if self.namespace else key

    def strip(self, full_key: str) -> str:
        """The key without this namespace (as found in the table)."""
        prefix = f"{self.namespace}/" if self.namespace else ""
        return full_key[len(prefix):] if prefix and full_key.startswith(prefix) else full_key

    def message_of(self, full_key: str) -> str | None:
        """The schema name carried on ``full_key``, or None if it is not a data key."""
        key = self.strip(str(full_key))
        if key in MESSAGE_OF_KEY:
            return MESSAGE_OF_KEY[key]
        if key.endswith("/stats") and key.split("/")[0] in SERVICES:
            return "Stats"
        return None
