"""Scenarios: what is in the simulated world, read from TOML files in ``scenarios/``.

A scenario file (every table and key is optional unless marked)::

    name = "chase"                    # default: the file's stem
    description = "one ball 2 m ahead, 30 degrees to the left"

    [world]
    size = 10.0                       # side of the square world (m); walls stand on its edges
    wall_height = 0.5                 # 0 = no walls (the robot is still kept inside)

    [floor]
    texture = "checker"               # "checker", "grid" or "plain"
    rgb1 = [0.55, 0.55, 0.55]         # colours in [0, 1]
    rgb2 = [0.35, 0.35, 0.35]
    tile = 0.5                        # checker square / grid cell (m)

    [robot]                           # start pose, world frame (m, radians)
    x = 0.0
    y = 0.0
    yaw = 0.0

    [fleet]                           # where the robots start when the simulator runs
    spacing = 1.5                     # several (robots >= 1): rows centred on [robot], facing
    columns = 8                       # its yaw; m between neighbours, robots per row,
    row_spacing = 3.0                 # m between rows
    ball_distance = 0.0               # > 0: each robot gets its own tennis ball this far
    ball_offset = 0.0                 # ahead of its centre (m), and this far to its left

    [light]
    diffuse = 0.8                     # main light's diffuse grey level, or [r, g, b]
    ambient = 0.4                     # scene ambient grey level, or [r, g, b]; 0 = none
    direction = [0.5, 0.2, -0.9]      # where the (directional) main light shines

    [[balls]]                         # any number, zero included
    id = "tennis"                     # default "ball<index>"; unique
    radius = 0.033                    # m (a tennis ball)
    rgb = [0.7, 0.85, 0.15]           # default: tennis-ball yellow-green
    position = [1.73, 1.0]            # required: [x, y] on the floor (z = radius) or [x, y, z]
    [balls.motion]                    # optional scripted motion
    type = "line"                     # back and forth between position and end ...
    end = [1.73, -1.0]
    speed = 0.3                       # ... at this speed (m/s)
    # type = "circle": center = [x, y], radius (m), speed (m/s, > 0 counter-clockwise);
    # the ball starts on the circle at the angle of its `position` seen from the centre.

    [[distractors]]                   # static objects that are not the target
    shape = "box"                     # "box", "cylinder" or "sphere"
    rgb = [0.8, 0.1, 0.1]
    size = [0.2, 0.2, 0.2]            # box: full [x, y, z] extents; cylinder: [radius, height];
                                      # sphere: [radius]
    position = [2.0, -1.0]            # [x, y] resting on the floor, or [x, y, z] of the centre
    yaw = 0.0

A problem (missing file, bad TOML, unknown key, wrong type, out-of-range value) raises
:class:`common.config.ConfigError` whose message names the file and the key.
"""

import math
import os
import stat
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from balltrack.common.config import ConfigError
from balltrack.common.messages import shorten
from balltrack.services.simulator.checked_table import CheckedTable

SCENARIO_DIR = Path(str(resources.files("balltrack.services.simulator") / "scenarios"))
TENNIS_RGB = (0.7, 0.85, 0.15)
TENNIS_RADIUS = 0.033
DEFAULT_DIFFUSE = 0.8
# Gazebo's default scene ambient; with 0 the unlit side of every object is black.
DEFAULT_AMBIENT = 0.4
# Gazebo's default sun shines along (-0.5, 0.1, -0.9); this one shines the other way along x
# so that a robot facing +x (every shipped scenario's start) sees the lit side of the balls.
DEFAULT_LIGHT_DIRECTION = (0.5, 0.2, -0.9)
FLOOR_TEXTURES = ("checker", "grid", "plain")
MOTION_TYPES = ("line", "circle")
SHAPES = ("box", "cylinder", "sphere")
# How close (m) the robot's centre may come to the world's edge.
ROBOT_MARGIN = 0.2
# A scenario file is a few hundred bytes; anything far larger is not one (or is /dev/zero).
MAX_SCENARIO_BYTES = 1 << 20

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]


@dataclass
class Motion:
    """Scripted ball motion: ``line`` (ping-pong from the start to ``end``) or ``circle``."""

    type: str
    speed: float
    end: Vec2 | None = None
    center: Vec2 | None = None
    radius: float = 0.0


@dataclass
class BallSpec:
    """One ball: a coloured sphere, static or moving along a scripted path."""

    id: str
    position: Vec3
    radius: float = TENNIS_RADIUS
    rgb: Vec3 = TENNIS_RGB
    motion: Motion | None = None

    def position_at(self, elapsed: float) -> Vec3:
        """World position ``elapsed`` seconds after the scenario started (pure function)."""
        x, y, z = self.position
        motion = self.motion
        if motion is None:
            return (x, y, z)
        if motion.type == "line":
            end_x, end_y = motion.end
            length = math.hypot(end_x - x, end_y - y)
            if length == 0 or motion.speed == 0:
                return (x, y, z)
            travelled = math.fmod(abs(motion.speed) * elapsed, 2 * length)
            along = travelled if travelled <= length else 2 * length - travelled
            fraction = along / length
            return (x + (end_x - x) * fraction, y + (end_y - y) * fraction, z)
        center_x, center_y = motion.center
        start_angle = 0.0
        if (x, y) != (center_x, center_y):
            start_angle = math.atan2(y - center_y, x - center_x)
        angle = start_angle + motion.speed / motion.radius * elapsed
        return (center_x + motion.radius * math.cos(angle),
                center_y + motion.radius * math.sin(angle), z)


@dataclass
class Distractor:
    """A static object that is not a target: a coloured box, cylinder or sphere."""

    shape: str
    rgb: Vec3
    size: tuple[float, ...]
    position: Vec3
    yaw: float = 0.0


@dataclass
class LightSpec:
    """The main (directional) light and the scene's ambient level, as RGB in [0, 1]."""

    diffuse: Vec3 = (DEFAULT_DIFFUSE,) * 3
    ambient: Vec3 = (DEFAULT_AMBIENT,) * 3
    direction: Vec3 = DEFAULT_LIGHT_DIRECTION


@dataclass
class FloorSpec:
    """The floor's look: a texture so that motion is visible in the camera image."""

    texture: str = "checker"
    rgb1: Vec3 = (0.55, 0.55, 0.55)
    rgb2: Vec3 = (0.35, 0.35, 0.35)
    tile: float = 0.5


@dataclass
class RobotStart:
    """The robot's start pose in the world frame."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0


@dataclass
class FleetSpec:
    """How the robots stand when the simulator holds several, and whether each has its own ball
    (services/simulator/fleet.py lays them out)."""

    spacing: float = 1.5
    columns: int = 8
    row_spacing: float = 3.0
    ball_distance: float = 0.0
    ball_offset: float = 0.0


@dataclass
class Scenario:
    """Everything that makes up one simulated world."""

    name: str
    description: str = ""
    size: float = 10.0
    wall_height: float = 0.5
    floor: FloorSpec = field(default_factory=FloorSpec)
    robot: RobotStart = field(default_factory=RobotStart)
    fleet: FleetSpec = field(default_factory=FleetSpec)
    light: LightSpec = field(default_factory=LightSpec)
    balls: list[BallSpec] = field(default_factory=list)
    distractors: list[Distractor] = field(default_factory=list)
    source: str = ""

    @property
    def half_size(self) -> float:
        return self.size / 2

    @property
    def robot_limit(self) -> float:
        """The robot's centre stays within [-robot_limit, robot_limit] on x and y."""
        return self.half_size - ROBOT_MARGIN

    def ball(self, ball_id: str) -> BallSpec | None:
        for ball in self.balls:
            if ball.id == ball_id:
                return ball
        return None


# ---------------------------------------------------------------------------------------------
# Parsing: every value is type- and range-checked, every unknown key is an error.

def _inside(table: CheckedTable, key: str, x: float, y: float, limit: float) -> None:
    if abs(x) > limit or abs(y) > limit:
        table.fail(table.path(key), f"({x:g}, {y:g}) is outside the world "
                                    f"(|x|, |y| must be <= {limit:g})")


def _parse_motion(table: CheckedTable, ball_xy: Vec2, limit: float) -> Motion:
    kind = table.string("type", choices=MOTION_TYPES)
    if kind == "line":
        end = table.vector("end", (2,))
        _inside(table, "end", *end, limit)
        speed = table.number("speed", minimum=0.0, maximum=20.0)
        motion = Motion(type="line", speed=speed, end=end)
    else:
        center = table.vector("center", (2,))
        radius = table.number("radius", positive=True)
        speed = table.number("speed", minimum=-20.0, maximum=20.0)
        if abs(center[0]) + radius > limit or abs(center[1]) + radius > limit:
            table.fail(table.path("radius"), f"the circle around ({center[0]:g}, {center[1]:g}) "
                                             f"leaves the world")
        motion = Motion(type="circle", speed=speed, center=center, radius=radius)
    table.finish()
    return motion


def _parse_ball(table: CheckedTable, index: int, limit: float) -> BallSpec:
    ball_id = table.string("id", default=f"ball{index}")
    if not ball_id:
        table.fail(table.path("id"), "must not be empty")
    radius = table.number("radius", default=TENNIS_RADIUS, positive=True, maximum=1.0)
    rgb = table.colour("rgb", default=TENNIS_RGB)
    position = table.vector("position", (2, 3))
    _inside(table, "position", position[0], position[1], limit - radius)
    if len(position) == 2:
        position = (position[0], position[1], radius)
    elif not 0.0 <= position[2] <= 10.0:
        table.fail(table.path("position"), f"z must be between 0 and 10 m, got {position[2]:g}")
    motion = None
    if table.has("motion"):
        motion = _parse_motion(table.table("motion"), position[:2], limit - radius)
    table.finish()
    return BallSpec(id=ball_id, position=position, radius=radius, rgb=rgb, motion=motion)


def _parse_distractor(table: CheckedTable, limit: float) -> Distractor:
    shape = table.string("shape", choices=SHAPES)
    rgb = table.colour("rgb", default=(0.8, 0.1, 0.1))
    expected = {"box": 3, "cylinder": 2, "sphere": 1}[shape]
    size = table.vector("size", (expected,))
    for value in size:
        if value <= 0 or value > 10:
            table.fail(table.path("size"), f"sizes must be > 0 and <= 10 m, got {list(size)}")
    position = table.vector("position", (2, 3))
    _inside(table, "position", position[0], position[1], limit)
    if len(position) == 2:
        rest_height = {"box": size[-1] / 2, "cylinder": size[-1] / 2, "sphere": size[0]}[shape]
        position = (position[0], position[1], rest_height)
    yaw = table.number("yaw", default=0.0)
    table.finish()
    return Distractor(shape=shape, rgb=rgb, size=size, position=position, yaw=yaw)


def parse_scenario(data: dict[str, Any], source: str, default_name: str) -> Scenario:
    """Build a validated Scenario from a parsed TOML document; ``source`` names it in errors."""
    top = CheckedTable(data, "", source)
    name = top.string("name", default=default_name)
    description = top.string("description", default="")

    world = top.table("world")
    size = world.number("size", default=10.0, minimum=1.0, maximum=200.0)
    wall_height = world.number("wall_height", default=0.5, minimum=0.0, maximum=10.0)
    world.finish()
    half = size / 2

    floor_table = top.table("floor")
    floor = FloorSpec(
        texture=floor_table.string("texture", default="checker", choices=FLOOR_TEXTURES),
        rgb1=floor_table.colour("rgb1", default=FloorSpec.rgb1),
        rgb2=floor_table.colour("rgb2", default=FloorSpec.rgb2),
        tile=floor_table.number("tile", default=0.5, positive=True, maximum=size),
    )
    floor_table.finish()

    robot_table = top.table("robot")
    robot = RobotStart(x=robot_table.number("x", default=0.0),
                       y=robot_table.number("y", default=0.0),
                       yaw=robot_table.number("yaw", default=0.0))
    _inside(robot_table, "x", robot.x, robot.y, half - ROBOT_MARGIN)
    robot_table.finish()

    fleet_table = top.table("fleet")
    fleet = FleetSpec(
        spacing=fleet_table.number("spacing", default=1.5, positive=True, maximum=size),
        columns=int(fleet_table.number("columns", default=8, minimum=1, maximum=64)),
        row_spacing=fleet_table.number("row_spacing", default=3.0, positive=True, maximum=size),
        ball_distance=fleet_table.number("ball_distance", default=0.0, minimum=0.0, maximum=size),
        ball_offset=fleet_table.number("ball_offset", default=0.0, minimum=-size, maximum=size))
    if fleet_table.has("columns") and fleet.columns != fleet_table.data["columns"]:
        fleet_table.fail(fleet_table.path("columns"), f"must be a whole number, got {fleet_table.data['columns']}")
    fleet_table.finish()

    light_table = top.table("light")
    light = LightSpec(
        diffuse=light_table.colour("diffuse", default=LightSpec.diffuse, grey_allowed=True),
        ambient=light_table.colour("ambient", default=LightSpec.ambient, grey_allowed=True),
        direction=light_table.vector("direction", (3,), default=DEFAULT_LIGHT_DIRECTION),
    )
    if light.direction[2] >= 0:
        light_table.fail(light_table.path("direction"), "must point downwards (z < 0)")
    light_table.finish()

    balls = [_parse_ball(table, index, half) for index, table in enumerate(top.tables("balls"))]
    seen: set[str] = set()
    for index, ball in enumerate(balls):
        if ball.id in seen:
            top.fail(f"balls[{index}].id", f"duplicate id {ball.id!r}")
        seen.add(ball.id)
    distractors = [_parse_distractor(table, half) for table in top.tables("distractors")]
    top.finish()
    return Scenario(name=name, description=description, size=size, wall_height=wall_height,
                    floor=floor, robot=robot, fleet=fleet, light=light, balls=balls,
                    distractors=distractors, source=source)


def available_scenarios() -> list[str]:
    """Names of the scenarios shipped in ``scenarios/``."""
    return sorted(path.stem for path in SCENARIO_DIR.glob("*.toml"))


def scenario_path(name_or_path: str) -> Path:
    """The file a scenario name (``"chase"``) or path (``"my/world.toml"``) refers to."""
    text = str(name_or_path).strip()
    if text.endswith(".toml") or "/" in text or "\\" in text:
        return Path(text)
    return SCENARIO_DIR / f"{text}.toml"


def load_scenario(name_or_path: str) -> Scenario:
    """Read and validate a scenario; ConfigError names the file and the problem."""
    path = scenario_path(name_or_path)
    shown = shorten(str(path), 200)
    try:
        with open(path, "rb") as handle:
            if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
                raise ConfigError(f"{shown}: not a regular file")
            raw = handle.read(MAX_SCENARIO_BYTES + 1)
        if len(raw) > MAX_SCENARIO_BYTES:
            raise ConfigError(f"{shown}: larger than {MAX_SCENARIO_BYTES} bytes, not a scenario")
        data = tomllib.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        known = ", ".join(available_scenarios())
        raise ConfigError(f"{shown}: no such scenario file (shipped scenarios: {known})") from None
    except IsADirectoryError:
        raise ConfigError(f"{shown}: is a directory, not a scenario file") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{shown}: not UTF-8 text") from None
    except RecursionError:  # tomllib recurses into nested arrays and inline tables
        raise ConfigError(f"{shown}: nested too deeply") from None
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{shown}: not valid TOML ({shorten(str(error), 200)})") from None
    except OSError as error:  # e.g. a name too long, or no permission
        raise ConfigError(f"{shown}: cannot read ({error.strerror or type(error).__name__})") from None
    return parse_scenario(data, str(path), path.stem)
