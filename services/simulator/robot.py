"""One robot's base in the simulated world (part of the simulator's pure core, see ``sim.py``):
the command it obeys, the velocity it applies under its acceleration limits, its safety stop,
and its joints in the shared MuJoCo model.

The base is planar (x and y slide joints and a yaw hinge, each driven by a velocity actuator,
services/simulator/world.py); each physics step turns the body-frame command (v, w) into world
x/y velocities. ``Simulation`` holds one per robot and takes its lock around every call.
"""

import math

import mujoco

from balltrack.common.geometry import wrap_angle
from balltrack.services.simulator.config import SimulatorConfig
from balltrack.services.simulator.requests import finite_number
from balltrack.services.simulator.scenario import RobotStart
from balltrack.services.simulator.world import ROBOT_JOINTS, element_name

# Commands beyond these are not "fast", they are broken (wrong units, garbage): rejected.
ABSURD_LINEAR = 100.0
ABSURD_ANGULAR = 100.0
ACTUATORS = ("drive_x", "drive_y", "drive_yaw")


class RobotBase:
    """The base of robot ``name`` ("" for the single robot) in ``model``."""

    def __init__(self, model: mujoco.MjModel, name: str, config: SimulatorConfig):
        self.name = name
        self._config = config
        joints = [model.joint(element_name(name, joint)) for joint in ROBOT_JOINTS]
        self._qpos_index = [int(joint.qposadr[0]) for joint in joints]
        self._qvel_index = [int(joint.dofadr[0]) for joint in joints]
        self._ctrl_index = [model.actuator(element_name(name, actuator)).id for actuator in ACTUATORS]
        self.command_count = 0
        self.restart_command()

    def restart_command(self) -> None:
        """No command, standing still (a scenario's start)."""
        self._command_linear = 0.0
        self._command_angular = 0.0
        self._command_time = -math.inf
        self.linear = 0.0
        self.angular = 0.0

    def place(self, data: mujoco.MjData, pose: RobotStart) -> None:
        """Put the base at ``pose``, standing still (the command is kept)."""
        qx, qy, qyaw = self._qpos_index
        data.qpos[qx], data.qpos[qy], data.qpos[qyaw] = pose.x, pose.y, pose.yaw
        data.qvel[self._qvel_index] = 0.0
        self.linear = 0.0
        self.angular = 0.0

    def pose(self, data: mujoco.MjData) -> tuple[float, float, float]:
        qx, qy, qyaw = self._qpos_index
        return float(data.qpos[qx]), float(data.qpos[qy]), wrap_angle(float(data.qpos[qyaw]))

    # -- commands -----------------------------------------------------------------------------

    def set_command(self, linear: float, angular: float, stamp: float) -> None:
        """See ``Simulation.set_command``: ValueError for a bad command, else clamped and held."""
        linear = finite_number("linear", linear)
        angular = finite_number("angular", angular)
        stamp = finite_number("sim_time", stamp)
        if abs(linear) > ABSURD_LINEAR:
            raise ValueError(f"linear: {linear:g} m/s is not a plausible command")
        if abs(angular) > ABSURD_ANGULAR:
            raise ValueError(f"angular: {angular:g} rad/s is not a plausible command")
        limit_linear = self._config.max_linear
        limit_angular = self._config.max_angular
        self._command_linear = min(max(linear, -limit_linear), limit_linear)
        self._command_angular = min(max(angular, -limit_angular), limit_angular)
        self._command_time = stamp
        self.command_count += 1

    def safety_stopped(self, now: float) -> bool:
        """True while no command arrived within cmd_timeout (the robot is told to stop)."""
        return now - self._command_time > self._config.cmd_timeout

    def commanded_velocity(self, now: float) -> tuple[float, float]:
        """The (linear, angular) target at ``now``: the clamped command, or zeros after a timeout."""
        if self.safety_stopped(now):
            return 0.0, 0.0
        return self._command_linear, self._command_angular

    @property
    def command_time(self) -> float | None:
        """Simulated time at which the last command was taken (None before the first)."""
        return None if self._command_time == -math.inf else self._command_time

    # -- stepping -----------------------------------------------------------------------------

    def drive(self, data: mujoco.MjData, dt: float) -> None:
        """Before one physics step of ``dt`` s: move the applied velocity towards the command
        within the acceleration limits, and set the actuators to it in the world frame."""
        config = self._config
        linear_step = config.max_linear_accel * dt
        angular_step = config.max_angular_accel * dt
        target_linear, target_angular = self.commanded_velocity(data.time)
        self.linear += min(max(target_linear - self.linear, -linear_step), linear_step)
        self.angular += min(max(target_angular - self.angular, -angular_step), angular_step)
        yaw = data.qpos[self._qpos_index[2]]
        drive_x, drive_y, drive_yaw = self._ctrl_index
        data.ctrl[drive_x] = self.linear * math.cos(yaw)
        data.ctrl[drive_y] = self.linear * math.sin(yaw)
        data.ctrl[drive_yaw] = self.angular

    def keep_inside(self, data: mujoco.MjData, limit: float) -> None:
        """After a physics step: the robot never leaves the world, it stops at the edge."""
        for position_index, velocity_index in zip(self._qpos_index[:2], self._qvel_index[:2]):
            if abs(data.qpos[position_index]) > limit:
                data.qpos[position_index] = math.copysign(limit, data.qpos[position_index])
                data.qvel[velocity_index] = 0.0
