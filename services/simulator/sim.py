"""The simulator's pure core: a MuJoCo world stepped one camera frame at a time (no Zenoh here).

The service wiring drives it in a loop and does the pacing::

    simulation = Simulation(config)                 # scenario from config.scenario
    while running:
        simulation.set_command(v, w, simulation.time)   # whenever a cmd_vel arrives
        simulation.step_frame()                      # advance 1 / rate_hz simulated seconds
        image = simulation.render()                  # H x W x 3 uint8, RGB
        truth = simulation.ground_truth()            # robot pose, balls in world and camera
        ... publish with stamp = simulation.stamp_ns, seq = simulation.frame_index ...
    simulation.close()

``handle_command`` serves the SimCommand query (reset, set_light, place_ball, place_robot).

With ``robots`` >= 1 the world holds that many robots (services/simulator/fleet.py): the
methods about one robot (commands, pose, camera, ground truth, place_robot) take its index,
``robot=0`` to ``robot_count - 1``, 0 by default; one step moves them all.

Conventions:

* Camera optical frame: x right, y down, z forward (metres). Pixel coordinates follow OpenCV:
  the centre of pixel (column i, row j) is (u, v) = (i, j). In that convention MuJoCo's
  image centre is (cx, cy) = ((W - 1) / 2, (H - 1) / 2), measured by comparing the centroid of
  a ball's segmentation mask with the analytic image of the sphere (agree within 0.05 px);
  ``camera_info()`` reports those values, and fx = fy = (W / 2) / tan(hfov / 2).
* Time is simulated seconds; it only moves forward, also across ``reset`` (a reset restarts
  the scenario, scripted motion included, at the current time), so stamps stay monotonic.
* Threads: every public method takes an internal lock, and the OpenGL (EGL) context is
  released after each use, so the frame loop may run in one thread while another (a query
  callback) calls ``handle_command``, and the simulation may be built in a third.
* Determinism: the same config (seed included), scenario and sequence of calls give
  bit-identical ground truth and images.
"""

import dataclasses
import functools
import os
import threading
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402  (MUJOCO_GL must be set before the import)
import numpy as np  # noqa: E402

from balltrack.common.memory import release_freed_memory  # noqa: E402
from balltrack.services.simulator.config import SimulatorConfig  # noqa: E402
from balltrack.services.simulator.requests import (  # noqa: E402
    ball_index,
    ball_position,
    checked_form,
    finite_number,
    requested_light,
    robot_position,
    scenario_name,
)
from balltrack.services.simulator.fleet import fleet_layout, robot_names  # noqa: E402
from balltrack.services.simulator.robot import ABSURD_ANGULAR, ABSURD_LINEAR, RobotBase  # noqa: E402, F401
from balltrack.services.simulator.scenario import RobotStart, Scenario, load_scenario  # noqa: E402
from balltrack.services.simulator.sim_camera import SimCamera, camera_info, project  # noqa: E402
from balltrack.services.simulator.world import (  # noqa: E402
    LIGHT_NAME,
    SPECULAR_PER_DIFFUSE,
    ball_body_name,
    build_mjcf,
    light_levels,
    physics_substeps,
)


def _locked(method):
    """Run ``method`` holding the simulation's lock (it may be called from several threads)."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)
    return wrapper


class Simulation:
    """One simulated world: physics, the robots and their cameras, scripted balls, and the
    SimCommands."""

    def __init__(self, config: SimulatorConfig, scenario: Scenario | None = None,
                 start_time: float = 0.0, start_frame: int = 0):
        """``start_time`` (simulated s) and ``start_frame``: the clock and frame number before the
        first frame, other than 0 when a restarted simulator goes on from its predecessor's
        (services/simulator/clock_file.py)."""
        self.config = config
        self._lock = threading.RLock()
        self._model: mujoco.MjModel | None = None
        self._camera: SimCamera | None = None
        self._frame_index = start_frame
        self.wall_time: float | None = None
        self._load(scenario if scenario is not None else load_scenario(config.scenario), start_time)
        self._restart()

    # -- construction -------------------------------------------------------------------------

    def _load(self, scenario: Scenario, start_time: float) -> None:
        """Build model, data and renderer for ``scenario`` (the only place they are created)."""
        config = self.config
        layout = fleet_layout(scenario, config.robots, config.first_robot)  # ConfigError if the robots do not fit
        # The world's scenario: the file's, with the robots' own balls if it gives them.
        scenario = dataclasses.replace(scenario, balls=layout.balls)
        model = mujoco.MjModel.from_xml_string(build_mjcf(scenario, config))
        data = mujoco.MjData(model)
        names = robot_names(config.robots, config.first_robot)
        camera = SimCamera(model, data, config, names)
        if self._camera is not None:
            self._camera.close()
        self.scenario = scenario
        self._model = model
        self._data = data
        self._camera = camera
        self._data.time = start_time
        self._substeps = physics_substeps(config)
        self._light_id = model.light(LIGHT_NAME).id
        self._robots = [RobotBase(model, name, config) for name in names]
        self._starts = layout.starts
        self._ball_mocap = [int(model.body(ball_body_name(index)).mocapid[0])
                            for index in range(len(scenario.balls))]
        self._ball_geoms = [model.geom(ball_body_name(index)).id
                            for index in range(len(scenario.balls))]
        self._default_light = light_levels(config, scenario)

    def _restart(self) -> None:
        """Put the current scenario back to its start state, keeping the clock running."""
        now = self._data.time
        mujoco.mj_resetData(self._model, self._data)
        self._data.time = now
        self._motion_start = now
        for robot, start in zip(self._robots, self._starts):
            robot.restart_command()
            robot.place(self._data, start)
        self._scripted = [ball.motion is not None for ball in self.scenario.balls]
        self._ball_positions = [tuple(ball.position) for ball in self.scenario.balls]
        self._apply_light(*self._default_light)
        self._rng = np.random.default_rng(self.config.seed)
        self._update_balls()
        mujoco.mj_forward(self._model, self._data)

    @_locked
    def close(self) -> None:
        """Free the renderer (and its OpenGL context). Safe to call twice."""
        self._camera.close()

    def __enter__(self) -> "Simulation":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- time ---------------------------------------------------------------------------------

    @property
    def time(self) -> float:
        """Simulated seconds, from ``start_time`` at construction."""
        return float(self._data.time)

    @property
    def stamp_ns(self) -> int:
        """``time`` as integer nanoseconds, the stamp of the frame rendered now."""
        return int(round(self._data.time * 1e9))

    @property
    def frame_index(self) -> int:
        """The seq of the current frame: ``start_frame`` plus the frames stepped so far."""
        return self._frame_index

    @property
    def period(self) -> float:
        return self.config.period

    @property
    def robot_count(self) -> int:
        """How many robots the world holds (1 for ``robots = 0``)."""
        return len(self._robots)

    @property
    def command_count(self) -> int:
        """Commands taken so far, every robot's."""
        return sum(robot.command_count for robot in self._robots)

    # -- commands -----------------------------------------------------------------------------

    @_locked
    def set_command(self, linear: float, angular: float, sim_time: float | None = None,
                    robot: int = 0) -> None:
        """Command body-frame velocities (m/s, rad/s), received at simulated time ``sim_time``.

        Non-numbers, non-finite and absurd values raise ValueError and leave the command as it
        was; other values are clamped to max_linear / max_angular. The command holds until the
        next one, or until cmd_timeout simulated seconds pass without one (safety stop).
        """
        self._robots[robot].set_command(linear, angular, self.time if sim_time is None else sim_time)

    @_locked
    def commanded_velocity(self, robot: int = 0) -> tuple[float, float]:
        """The (linear, angular) target now: the clamped command, or zeros after a timeout."""
        return self._robots[robot].commanded_velocity(self._data.time)

    @_locked
    def robot_velocity(self, robot: int = 0) -> tuple[float, float]:
        """The (linear, angular) velocity being applied, after the acceleration limits."""
        return self._robots[robot].linear, self._robots[robot].angular

    @property
    def command_time(self) -> float | None:
        """Simulated time at which the first robot's last command was taken (None before the first)."""
        return self._robots[0].command_time

    @property
    def safety_stopped(self) -> bool:
        """True while no command arrived within cmd_timeout (the first robot is told to stop)."""
        return self._robots[0].safety_stopped(self._data.time)

    # -- stepping -----------------------------------------------------------------------------

    @_locked
    def step_frame(self, now_wall: float | None = None) -> float:
        """Advance one camera period (1 / rate_hz simulated seconds); returns the new time.

        ``now_wall`` is the wall-clock time of the call, kept in ``wall_time`` for recordings.
        """
        model, data = self._model, self._data
        dt = model.opt.timestep
        limit = self.scenario.robot_limit
        for _ in range(self._substeps):
            for robot in self._robots:
                robot.drive(data, dt)
            mujoco.mj_step(model, data)
            for robot in self._robots:
                robot.keep_inside(data, limit)
        self._frame_index += 1
        self.wall_time = now_wall
        self._update_balls()
        # mj_step leaves derived quantities (camera pose) one step behind qpos: recompute.
        mujoco.mj_forward(model, data)
        return self.time

    def _update_balls(self) -> None:
        elapsed = self._data.time - self._motion_start
        for index, ball in enumerate(self.scenario.balls):
            if self._scripted[index]:
                self._ball_positions[index] = ball.position_at(elapsed)
            self._data.mocap_pos[self._ball_mocap[index]] = self._ball_positions[index]

    # -- camera -------------------------------------------------------------------------------

    def camera_info(self) -> dict[str, Any]:
        """Pinhole intrinsics of the rendered images (OpenCV pixel convention, see module doc)."""
        return camera_info(self.config)

    @_locked
    def render(self, robot: int = 0) -> np.ndarray:
        """The robot's camera image now: H x W x 3 uint8, RGB (plus seeded noise if
        image_noise > 0)."""
        return self._camera.render(self._rng, robot)

    @_locked
    def render_view(self, view: str = "follow", robot: int = 0) -> np.ndarray:
        """An RGB picture for people: "follow" (behind the robot), "top" (the whole world from
        above) or "front" (the robot's camera, without noise); same size as the camera image."""
        return self._camera.render_view(view, robot)

    @_locked
    def ball_masks(self, robot: int = 0) -> dict[str, np.ndarray]:
        """Per ball id, the H x W boolean mask of its pixels the robot's camera sees
        (segmentation rendering)."""
        return self._camera.ball_masks([ball.id for ball in self.scenario.balls], self._ball_geoms,
                                       robot)

    @_locked
    def world_to_camera(self, point, robot: int = 0) -> np.ndarray:
        """A world point in the robot's camera optical frame (x right, y down, z forward)."""
        return self._camera.world_to_camera(point, robot)

    def project(self, point_in_camera) -> tuple[float, float] | None:
        """Pixel (u, v) of an optical-frame point, or None when it is not in front."""
        return project(self.config, point_in_camera)

    # -- ground truth -------------------------------------------------------------------------

    @_locked
    def robot_pose(self, robot: int = 0) -> tuple[float, float, float]:
        return self._robots[robot].pose(self._data)

    @_locked
    def ground_truth(self, robot: int = 0) -> dict[str, Any]:
        """The GroundTruth message body of one robot: its pose and every ball in world and its
        camera's frames.

        A ball is ``visible`` when its centre is in front of the camera and projects inside
        the image (occlusion is not considered; ``ball_masks`` gives the pixels really seen).
        """
        x, y, yaw = self.robot_pose(robot)
        width, height = self.config.width, self.config.height
        balls = []
        for ball, position in zip(self.scenario.balls, self._ball_positions):
            in_camera = self.world_to_camera(position, robot)
            pixel = self.project(in_camera)
            visible = (pixel is not None and -0.5 <= pixel[0] <= width - 0.5
                       and -0.5 <= pixel[1] <= height - 0.5)
            balls.append({
                "id": ball.id,
                "radius": float(ball.radius),
                "position": [float(value) for value in position],
                "in_camera": [float(value) for value in in_camera],
                "visible": bool(visible),
            })
        return {"robot": {"x": x, "y": y, "yaw": yaw}, "balls": balls}

    # -- SimCommands --------------------------------------------------------------------------

    @_locked
    def handle_command(self, request: Any, robot: int = 0) -> dict[str, Any]:
        """Serve one SimCommand; returns {"ok": True} or {"ok": False, "error": ...}.

        A bad request (unknown op or argument, wrong type, out of range, unknown ball or
        scenario) changes nothing: every argument is validated before anything is applied.
        ``place_robot`` moves robot ``robot``; the other ops change the world every robot is in.
        """
        try:
            op, arguments = checked_form(request)
            getattr(self, op)(**arguments, **({"robot": robot} if op == "place_robot" else {}))
        except (ValueError, TypeError, KeyError) as error:
            return {"ok": False, "error": str(error)}
        return {"ok": True}

    @_locked
    def reset(self, scenario: str | None = None) -> None:
        """Restart the current scenario, or load the named one; the clock keeps running.

        Light changes, placed balls and robot moves are undone; the command is cleared.
        """
        if scenario_name(scenario) is not None:
            loaded = load_scenario(scenario)  # ConfigError (a ValueError) if bad: nothing changed
            self._load(loaded, self._data.time)
            # (the old world's model, data and renderer, freed amid the heap, would stay resident)
            release_freed_memory()
        self._restart()

    @_locked
    def set_light(self, diffuse: Any = None, ambient: Any = None) -> None:
        """Set the main light's diffuse and/or the ambient level: a grey level or [r, g, b]."""
        new_diffuse, new_ambient = requested_light(diffuse, ambient)
        model = self._model
        if new_diffuse is None:
            new_diffuse = tuple(float(value) for value in model.light_diffuse[self._light_id])
        if new_ambient is None:
            new_ambient = tuple(float(value) for value in model.light_ambient[self._light_id])
        self._apply_light(new_diffuse, new_ambient)

    def _apply_light(self, diffuse, ambient) -> None:
        model = self._model
        model.light_diffuse[self._light_id] = diffuse
        model.light_specular[self._light_id] = [SPECULAR_PER_DIFFUSE * level for level in diffuse]
        model.light_ambient[self._light_id] = ambient

    @_locked
    def light(self) -> dict[str, list[float]]:
        """The main light's current diffuse and ambient RGB."""
        return {"diffuse": [float(value) for value in self._model.light_diffuse[self._light_id]],
                "ambient": [float(value) for value in self._model.light_ambient[self._light_id]]}

    @_locked
    def place_ball(self, id: Any = None, position: Any = None) -> None:
        """Move ball ``id`` to [x, y] (resting on the floor) or [x, y, z]; stops its script."""
        index = ball_index(id, [ball.id for ball in self.scenario.balls])
        values = ball_position(position, self.scenario.balls[index].radius, self.scenario.half_size)
        self._scripted[index] = False
        self._ball_positions[index] = values
        self._update_balls()
        mujoco.mj_forward(self._model, self._data)

    @_locked
    def place_robot(self, x: Any = None, y: Any = None, yaw: Any = None, robot: int = 0) -> None:
        """Teleport the robot to (x, y) and heading yaw (default: keep), standing still."""
        new_x, new_y = robot_position(x, y, self.scenario.robot_limit)
        new_yaw = self.robot_pose(robot)[2] if yaw is None else finite_number("yaw", yaw)
        self._robots[robot].place(self._data, RobotStart(x=new_x, y=new_y, yaw=new_yaw))
        mujoco.mj_forward(self._model, self._data)
