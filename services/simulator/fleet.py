"""Several robots in one simulated world: their names, where they start, their own balls.

The simulator's ``robots`` setting says how many robots its world holds:

* ``robots = 0`` (the default): one robot, on the service's own keys (``cmd_vel``,
  ``camera/image_raw``...), named in the model as before fleets (body ``robot``, camera
  ``front``). Nothing here changes it.
* ``robots = N`` (1 to 64): robots ``robot1`` to ``robotN``. Robot k is the namespace
  ``robotK`` under the service's namespace: ``balltrack run simulator --namespace site --set
  robots=2`` serves ``site/robot1/cmd_vel``, ``site/robot2/camera/image_raw``... Each robot's
  elements in the model carry its name (body ``robot2``, camera ``robot2_front``).
  ``first_robot`` numbers them from another robot than 1 (``first_robot = 5``: ``robot5`` to
  ``robot8`` for ``robots = 4``), so that simulators on several hosts hold distinct robots.

The robots stand in rows (the scenario's ``[fleet]`` table), centred on the scenario's
``[robot]`` start and facing its yaw: ``columns`` per row, ``spacing`` metres apart, robot 1 on
the left; further rows ``row_spacing`` metres behind. With ``ball_distance`` > 0 each robot
also gets its own tennis ball, ``tennisK``, ``ball_distance`` ahead of its centre and
``ball_offset`` to its left (the ``fleet`` scenario); the scenario's own balls are shared.

Pure geometry, no MuJoCo: :func:`fleet_layout` raises ConfigError when a robot or its ball
would stand outside the world.
"""

import math
from dataclasses import dataclass

from balltrack.common.config import ConfigError
from balltrack.common.referee import Referee
from balltrack.services.simulator.scenario import TENNIS_RADIUS, BallSpec, RobotStart, Scenario


def robot_name(robot: int) -> str:
    """The namespace (and model name) of robot ``robot`` (1-based): ``robot3``."""
    return f"robot{robot}"


def own_ball_id(robot: int) -> str:
    """The id of robot ``robot``'s own ball (1-based) in a scenario that gives each one."""
    return f"tennis{robot}"


def robot_names(robots: int, first: int = 1) -> list[str]:
    """The model name prefix of each robot for the ``robots`` setting: ``[""]`` for the single
    robot of ``robots = 0``, else ``robot<first>`` to ``robot<first + robots - 1>``."""
    return [""] if robots == 0 else [robot_name(first + index) for index in range(robots)]


@dataclass
class FleetLayout:
    """Each robot's start pose, and every ball of the world (the scenario's, then the robots' own)."""

    starts: list[RobotStart]
    balls: list[BallSpec]


def start_poses(scenario: Scenario, count: int) -> list[RobotStart]:
    """Where ``count`` robots start (see the module doc), before any check that they fit."""
    fleet, origin = scenario.fleet, scenario.robot
    columns = min(count, fleet.columns)
    rows = math.ceil(count / columns)
    cos_yaw, sin_yaw = math.cos(origin.yaw), math.sin(origin.yaw)
    starts = []
    for index in range(count):
        row, column = divmod(index, columns)
        in_row = min(columns, count - row * columns)
        forward = ((rows - 1) / 2 - row) * fleet.row_spacing
        left = ((in_row - 1) / 2 - column) * fleet.spacing
        starts.append(RobotStart(x=origin.x + forward * cos_yaw - left * sin_yaw,
                                 y=origin.y + forward * sin_yaw + left * cos_yaw, yaw=origin.yaw))
    return starts


def own_balls(scenario: Scenario, starts: list[RobotStart], first: int = 1) -> list[BallSpec]:
    """Each robot's own ball (none when the scenario's ``ball_distance`` is 0), robot ``first``'s
    first."""
    fleet = scenario.fleet
    if fleet.ball_distance <= 0:
        return []
    balls = []
    for index, start in enumerate(starts):
        cos_yaw, sin_yaw = math.cos(start.yaw), math.sin(start.yaw)
        x = start.x + fleet.ball_distance * cos_yaw - fleet.ball_offset * sin_yaw
        y = start.y + fleet.ball_distance * sin_yaw + fleet.ball_offset * cos_yaw
        balls.append(BallSpec(id=own_ball_id(first + index), position=(x, y, TENNIS_RADIUS)))
    return balls


def fleet_layout(scenario: Scenario, robots: int, first: int = 1) -> FleetLayout:
    """The robots and balls of ``scenario`` for the ``robots`` and ``first_robot`` settings;
    ConfigError naming the first robot or ball outside the world, or an own ball's id the
    scenario already uses."""
    if robots == 0:  # (one robot, as the scenario says; its own ball, if any, is tennis1)
        starts = [scenario.robot]
    else:
        starts = start_poses(scenario, robots)
    where = f"robots: {max(robots, 1)} in scenario {scenario.name!r}"
    limit = scenario.robot_limit
    for index, start in enumerate(starts):
        if abs(start.x) > limit or abs(start.y) > limit:
            raise ConfigError(f"{where}: robot {first + index} would start at ({start.x:.3g}, "
                              f"{start.y:.3g}), outside the world (|x|, |y| <= {limit:g}); fewer "
                              f"robots, more columns or a larger world")
    balls = own_balls(scenario, starts, first)
    ids = {ball.id for ball in scenario.balls}
    for ball in balls:
        x, y, _ = ball.position
        if abs(x) > scenario.half_size - ball.radius or abs(y) > scenario.half_size - ball.radius:
            raise ConfigError(f"{where}: ball {ball.id} would lie at ({x:.3g}, {y:.3g}), outside "
                              f"the world")
        if ball.id in ids:
            raise ConfigError(f"{where}: the scenario already has a ball {ball.id!r}, the id of "
                              f"a robot's own ball")
    return FleetLayout(starts=starts, balls=scenario.balls + balls)


def own_ball_referees(robots: int, first: int = 1, **criteria) -> dict[str, Referee]:
    """One :class:`common.referee.Referee` per robot, judging whether it reached its own ball,
    keyed by the robot's namespace (``""`` for the single robot of ``robots = 0``)."""
    return {name: Referee(target=own_ball_id(first + index), **criteria)
            for index, name in enumerate(robot_names(robots, first))}


def robot_key(robot: str, key: str) -> str:
    """``key`` of robot ``robot`` (a name from :func:`robot_names`), under the service's
    namespace: ``robot2/cmd_vel``, or ``cmd_vel`` itself for the single robot."""
    return f"{robot}/{key}" if robot else key
