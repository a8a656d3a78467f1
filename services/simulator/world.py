"""Builds the MuJoCo model (MJCF XML) of a scenario: floor, walls, robot, camera, balls, light.

Design choices, and why:

* The robot is a planar base: x and y slide joints and a yaw hinge, each driven by a velocity
  actuator. The simulation rotates the body-frame command (v, w) into world x/y velocities each
  physics step. This follows (v, w) exactly in steady state, which a wheeled model with contact
  friction does not without a lot of tuning. The wheels are only for looks.
* Contacts are disabled: the robot's height is fixed by its joints, balls and distractors are
  kinematic, so nothing needs them. The robot therefore drives through objects; the simulation
  keeps it inside the walls by clamping its position.
* Balls are mocap bodies: scripted motion and ``place_ball`` just set their position.
* The camera sits low (0.10 m) at the robot's front and looks horizontally forward, like the
  paper's small robot. Its ``fovy`` is derived from hfov and the aspect ratio so that
  fx = fy = (W/2) / tan(hfov/2) exactly.
* The headlight is off and the main light is directional (a sun), so its diffuse level
  controls the image brightness as in the paper's Gazebo experiment; the scene ambient is the
  main light's ambient term. Shadows and multisampling are off by default because the
  software rasteriser spends most of its time on them.
"""

import math
from xml.sax.saxutils import quoteattr

from balltrack.services.simulator.config import SimulatorConfig
from balltrack.services.simulator.fleet import robot_names
from balltrack.services.simulator.scenario import Scenario

CAMERA_NAME = "front"
# Views for people (demo pictures, videos): behind the robot following it, and the whole world
# from above. They are not the robot's sensor.
VIEW_NAMES = ("front", "follow", "top")
LIGHT_NAME = "sun"
ROBOT_BODY = "robot"
ROBOT_JOINTS = ("base_x", "base_y", "base_yaw")
# Camera mount in the robot frame (m): at the chassis' front edge, 0.10 m above the floor.
CAMERA_POSITION = (0.11, 0.0, 0.10)
ROBOT_MASS = 2.0
ROBOT_YAW_INERTIA = 0.02
# Velocity-actuator time constant (s): gain = mass (or inertia) / time constant.
ACTUATOR_TIME_CONSTANT = 0.01
# The light's specular part follows its diffuse level so that a dim light has dim highlights.
SPECULAR_PER_DIFFUSE = 0.25
SHADOW_SIZE = 1024


def ball_body_name(index: int) -> str:
    return f"ball_{index}"


def element_name(robot: str, element: str) -> str:
    """The model name of one robot's ``element`` (a joint, camera, actuator, geom): as it is
    for the single robot (``robot`` ""), prefixed with the robot's name in a fleet
    (``robot2_front``, see services/simulator/fleet.py)."""
    return f"{robot}_{element}" if robot else element


def robot_body_name(robot: str) -> str:
    return robot or ROBOT_BODY


def _vec(values) -> str:
    return " ".join(f"{value:.6g}" for value in values)


def camera_fovy_degrees(config: SimulatorConfig) -> float:
    """MuJoCo's camera fovy (vertical, degrees) for config.hfov at config's aspect ratio."""
    return math.degrees(config.vfov)


def physics_substeps(config: SimulatorConfig) -> int:
    """Whole physics steps per camera frame, so frames fall exactly on multiples of 1/rate_hz."""
    return max(1, round(config.period / config.timestep))


def light_levels(config: SimulatorConfig, scenario: Scenario) -> tuple[tuple, tuple]:
    """(diffuse rgb, ambient rgb) after the config's overrides (negative = scenario's)."""
    diffuse = scenario.light.diffuse
    ambient = scenario.light.ambient
    if config.light_diffuse >= 0:
        diffuse = (config.light_diffuse,) * 3
    if config.ambient >= 0:
        ambient = (config.ambient,) * 3
    return tuple(diffuse), tuple(ambient)


def _floor_texture(scenario: Scenario) -> tuple[str, float]:
    floor = scenario.floor
    # Returns the texture and its texrepeat. On a plane with texuniform, one texture spans
    # 2 / texrepeat metres (measured); a builtin checker texture holds 2x2 tiles.
    if floor.texture == "checker":
        texture = (f'<texture name="floor" type="2d" builtin="checker" width="256" height="256" '
                   f'rgb1="{_vec(floor.rgb1)}" rgb2="{_vec(floor.rgb2)}"/>')
        return texture, 1 / floor.tile
    if floor.texture == "grid":
        texture = (f'<texture name="floor" type="2d" builtin="flat" mark="edge" width="256" '
                   f'height="256" rgb1="{_vec(floor.rgb1)}" markrgb="{_vec(floor.rgb2)}"/>')
        return texture, 2 / floor.tile
    texture = (f'<texture name="floor" type="2d" builtin="flat" width="16" height="16" '
               f'rgb1="{_vec(floor.rgb1)}"/>')
    return texture, 1.0


def _walls(scenario: Scenario) -> list[str]:
    if scenario.wall_height <= 0:
        return []
    half = scenario.half_size
    thickness = 0.05
    height = scenario.wall_height
    z = height / 2
    walls = []
    for name, position, size in (
        ("wall_north", (0, half + thickness, z), (half + 2 * thickness, thickness, z)),
        ("wall_south", (0, -half - thickness, z), (half + 2 * thickness, thickness, z)),
        ("wall_east", (half + thickness, 0, z), (thickness, half, z)),
        ("wall_west", (-half - thickness, 0, z), (thickness, half, z)),
    ):
        walls.append(f'<geom name="{name}" type="box" pos="{_vec(position)}" '
                     f'size="{_vec(size)}" material="wall"/>')
    return walls


def _distractors(scenario: Scenario) -> list[str]:
    geoms = []
    for index, item in enumerate(scenario.distractors):
        if item.shape == "box":
            size = (item.size[0] / 2, item.size[1] / 2, item.size[2] / 2)
        elif item.shape == "cylinder":
            size = (item.size[0], item.size[1] / 2)
        else:
            size = (item.size[0],)
        geoms.append(
            f'<geom name="distractor_{index}" type="{item.shape}" pos="{_vec(item.position)}" '
            f'euler="0 0 {item.yaw:.6g}" size="{_vec(size)}" rgba="{_vec(item.rgb)} 1" '
            f'material="matte"/>')
    return geoms


def _balls(scenario: Scenario) -> list[str]:
    bodies = []
    for index, ball in enumerate(scenario.balls):
        bodies.append(
            f'<body name="{ball_body_name(index)}" mocap="true" pos="{_vec(ball.position)}">'
            f'<geom name="{ball_body_name(index)}" type="sphere" size="{ball.radius:.6g}" '
            f'rgba="{_vec(ball.rgb)} 1" material="felt"/></body>')
    return bodies


def _robot(config: SimulatorConfig, robot: str) -> str:
    fovy = camera_fovy_degrees(config)

    def named(element: str) -> str:
        return element_name(robot, element)

    return f"""
    <body name="{robot_body_name(robot)}" pos="0 0 0">
      <joint name="{named('base_x')}" type="slide" axis="1 0 0"/>
      <joint name="{named('base_y')}" type="slide" axis="0 1 0"/>
      <joint name="{named('base_yaw')}" type="hinge" axis="0 0 1"/>
      <inertial pos="0 0 0.06" mass="{ROBOT_MASS}" diaginertia="0.01 0.01 {ROBOT_YAW_INERTIA}"/>
      <geom name="{named('chassis')}" type="box" pos="0 0 0.06" size="0.1 0.075 0.03" material="chassis"/>
      <geom name="{named('deck')}" type="box" pos="-0.01 0 0.0925" size="0.07 0.06 0.0025" material="deck"/>
      <geom name="{named('wheel_left')}" type="cylinder" fromto="0 0.078 0.035 0 0.102 0.035" size="0.035"
            material="tyre"/>
      <geom name="{named('wheel_right')}" type="cylinder" fromto="0 -0.078 0.035 0 -0.102 0.035" size="0.035"
            material="tyre"/>
      <geom name="{named('caster')}" type="sphere" pos="-0.075 0 0.015" size="0.015" material="tyre"/>
      <geom name="{named('camera_housing')}" type="box" pos="0.092 0 0.10" size="0.012 0.025 0.012"
            material="tyre"/>
      <camera name="{named(CAMERA_NAME)}" pos="{_vec(CAMERA_POSITION)}" xyaxes="0 -1 0 0 0 1"
              fovy="{fovy:.10g}"/>
      <camera name="{named('follow')}" mode="track" pos="-1.2 0 0.7" xyaxes="0 -1 0 0.5 0 1" fovy="50"/>
    </body>"""


def _actuators(robot: str, translation_gain: float, yaw_gain: float) -> list[str]:
    return [f'<velocity name="{element_name(robot, drive)}" joint="{element_name(robot, joint)}" '
            f'kv="{gain:.6g}" ctrllimited="false" forcelimited="false"/>'
            for drive, joint, gain in (("drive_x", "base_x", translation_gain),
                                       ("drive_y", "base_y", translation_gain),
                                       ("drive_yaw", "base_yaw", yaw_gain))]


def build_mjcf(scenario: Scenario, config: SimulatorConfig) -> str:
    """The MJCF document of ``scenario`` rendered with ``config``'s camera and light settings,
    with config's robots (services/simulator/fleet.py: one robot named as before fleets, or
    ``robot1`` to ``robotN``) all standing at the origin: their joints place them."""
    diffuse, ambient = light_levels(config, scenario)
    specular = tuple(SPECULAR_PER_DIFFUSE * level for level in diffuse)
    floor_texture, texture_repeat = _floor_texture(scenario)
    half = scenario.half_size
    substeps = physics_substeps(config)
    timestep = config.period / substeps
    shadow_size = SHADOW_SIZE if config.shadows else 0
    castshadow = "true" if config.shadows else "false"
    extent = max(scenario.size, 2.0)
    # Near/far clip planes are fractions of the extent: 5 mm near so a ball touching the
    # camera still renders; far beyond the world's diagonal.
    znear = 0.005 / extent
    zfar = 3.0
    wall_rgb = (0.75, 0.75, 0.72)
    robot_translation_gain = ROBOT_MASS / ACTUATOR_TIME_CONSTANT
    robot_yaw_gain = ROBOT_YAW_INERTIA / ACTUATOR_TIME_CONSTANT
    name = quoteattr(f"balltrack_{scenario.name}")
    lines = [
        f'<mujoco model={name}>',
        '  <compiler angle="radian"/>',
        f'  <option timestep="{timestep:.10g}" integrator="implicitfast">',
        '    <flag contact="disable"/>',
        '  </option>',
        f'  <statistic extent="{extent:.6g}" center="0 0 0.5"/>',
        '  <visual>',
        f'    <global offwidth="{config.width}" offheight="{config.height}"/>',
        f'    <quality shadowsize="{shadow_size}" offsamples="0"/>',
        '    <headlight active="0" ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/>',
        f'    <map znear="{znear:.6g}" zfar="{zfar:.6g}" shadowclip="1.5"/>',
        '    <rgba haze="0 0 0 0"/>',
        '  </visual>',
        '  <asset>',
        '    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.72 0.74 0.78" '
        'rgb2="0.5 0.52 0.56" width="64" height="64"/>',
        f'    {floor_texture}',
        f'    <material name="floor" texture="floor" texrepeat="{texture_repeat:.6g} '
        f'{texture_repeat:.6g}" texuniform="true" specular="0.05" shininess="0.1" '
        'reflectance="0"/>',
        f'    <material name="wall" rgba="{_vec(wall_rgb)} 1" specular="0.05" shininess="0.1"/>',
        '    <material name="matte" specular="0.1" shininess="0.2"/>',
        '    <material name="felt" specular="0.1" shininess="0.1"/>',
        '    <material name="chassis" rgba="0.15 0.25 0.45 1" specular="0.3" shininess="0.4"/>',
        '    <material name="deck" rgba="0.1 0.1 0.1 1" specular="0.2"/>',
        '    <material name="tyre" rgba="0.05 0.05 0.05 1" specular="0.1"/>',
        '  </asset>',
        '  <worldbody>',
        f'    <light name="{LIGHT_NAME}" directional="true" pos="0 0 {max(5.0, half):.6g}" '
        f'dir="{_vec(scenario.light.direction)}" diffuse="{_vec(diffuse)}" '
        f'ambient="{_vec(ambient)}" specular="{_vec(specular)}" castshadow="{castshadow}"/>',
        f'    <geom name="floor" type="plane" size="{half:.6g} {half:.6g} 0.1" material="floor"/>',
    ]
    lines += [f"    {geom}" for geom in _walls(scenario)]
    lines += [f"    {geom}" for geom in _distractors(scenario)]
    top_height = half / math.tan(math.radians(22.5)) * 1.05
    lines.append(f'    <camera name="top" pos="0 0 {top_height:.6g}" xyaxes="1 0 0 0 1 0" '
                 'fovy="45"/>')
    robots = robot_names(config.robots, config.first_robot)
    lines += [_robot(config, robot) for robot in robots]
    lines += [f"    {body}" for body in _balls(scenario)]
    lines += ['  </worldbody>', '  <actuator>']
    lines += [f"    {actuator}" for robot in robots
              for actuator in _actuators(robot, robot_translation_gain, robot_yaw_gain)]
    lines += ['  </actuator>', '</mujoco>']
    return "\n".join(lines) + "\n"
