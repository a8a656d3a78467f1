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

import functools
import math
import os
import threading
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402  (MUJOCO_GL must be set before the import)
import numpy as np  # noqa: E402

from balltrack.common.geometry import wrap_angle  # noqa: E402
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
from balltrack.services.simulator.scenario import Scenario, load_scenario  # noqa: E402
from balltrack.services.simulator.sim_camera import SimCamera, camera_info, project  # noqa: E402
from balltrack.services.simulator.world import (  # noqa: E402
    LIGHT_NAME,
    ROBOT_JOINTS,
    SPECULAR_PER_DIFFUSE,
    ball_body_name,
    build_mjcf,
    light_levels,
    physics_substeps,
)

# Commands beyond these are not "fast", they are broken (wrong units, garbage): rejected.
ABSURD_LINEAR = 100.0
ABSURD_ANGULAR = 100.0


def _locked(method):
    """Run ``method`` holding the simulation's lock (it may be called from several threads)."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)
    return wrapper


class Simulation:
    """One simulated world: physics, the robot's camera, scripted balls, and the SimCommands."""

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
        self.command_count = 0
        self._load(scenario if scenario is not None else load_scenario(config.scenario), start_time)
        self._restart()

    # -- construction -------------------------------------------------------------------------

    def _load(self, scenario: Scenario, start_time: float) -> None:
        """Build model, data and renderer for ``scenario`` (the only place they are created)."""
        config = self.config
        model = mujoco.MjModel.from_xml_string(build_mjcf(scenario, config))
        data = mujoco.MjData(model)
        camera = SimCamera(model, data, config)
        if self._camera is not None:
            self._camera.close()
        self.scenario = scenario
        self._model = model
        self._data = data
        self._camera = camera
        self._data.time = start_time
        self._substeps = physics_substeps(config)
        self._light_id = model.light(LIGHT_NAME).id
        self._qpos_index = [int(model.joint(name).qposadr[0]) for name in ROBOT_JOINTS]
        self._qvel_index = [int(model.joint(name).dofadr[0]) for name in ROBOT_JOINTS]
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
        start = self.scenario.robot
        qpos = self._data.qpos
        qpos[self._qpos_index[0]], qpos[self._qpos_index[1]], qpos[self._qpos_index[2]] = (
            start.x, start.y, start.yaw)
        self._scripted = [ball.motion is not None for ball in self.scenario.balls]
        self._ball_positions = [tuple(ball.position) for ball in self.scenario.balls]
        self._command_linear = 0.0
        self._command_angular = 0.0
        self._command_time = -math.inf
        self._linear = 0.0
        self._angular = 0.0
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

    # -- commands -----------------------------------------------------------------------------

    @_locked
    def set_command(self, linear: float, angular: float, sim_time: float | None = None) -> None:
        """Command body-frame velocities (m/s, rad/s), received at simulated time ``sim_time``.

        Non-numbers, non-finite and absurd values raise ValueError and leave the command as it
        was; other values are clamped to max_linear / max_angular. The command holds until the
        next one, or until cmd_timeout simulated seconds pass without one (safety stop).
        """
        linear = finite_number("linear", linear)
        angular = finite_number("angular", angular)
        stamp = self.time if sim_time is None else finite_number("sim_time", sim_time)
        if abs(linear) > ABSURD_LINEAR:
            raise ValueError(f"linear: {linear:g} m/s is not a plausible command")
        if abs(angular) > ABSURD_ANGULAR:
            raise ValueError(f"angular: {angular:g} rad/s is not a plausible command")
        limit_linear = self.config.max_linear
        limit_angular = self.config.max_angular
        self._command_linear = min(max(linear, -limit_linear), limit_linear)
        self._command_angular = min(max(angular, -limit_angular), limit_angular)
        self._command_time = stamp
        self.command_count += 1

    @_locked
    def commanded_velocity(self) -> tuple[float, float]:
        """The (linear, angular) target now: the clamped command, or zeros after a timeout."""
        if self._data.time - self._command_time > self.config.cmd_timeout:
            return 0.0, 0.0
        return self._command_linear, self._command_angular

    @_locked
    def robot_velocity(self) -> tuple[float, float]:
        """The (linear, angular) velocity being applied, after the acceleration limits."""
        return self._linear, self._angular

    @property
    def command_time(self) -> float | None:
        """Simulated time at which the last command was taken (None before the first)."""
        return None if self._command_time == -math.inf else self._command_time

    @property
    def safety_stopped(self) -> bool:
        """True while no command arrived within cmd_timeout (the robot is told to stop)."""
        return self._data.time - self._command_time > self.config.cmd_timeout

    # -- stepping -----------------------------------------------------------------------------

    @_locked
    def step_frame(self, now_wall: float | None = None) -> float:
        """Advance one camera period (1 / rate_hz simulated seconds); returns the new time.

        ``now_wall`` is the wall-clock time of the call, kept in ``wall_time`` for recordings.
        """
        model, data = self._model, self._data
        config = self.config
        dt = model.opt.timestep
        linear_step = config.max_linear_accel * dt
        angular_step = config.max_angular_accel * dt
        limit = self.scenario.robot_limit
        qx, qy, qyaw = self._qpos_index
        vx, vy, _ = self._qvel_index
        for _ in range(self._substeps):
            target_linear, target_angular = self.commanded_velocity()
            self._linear += min(max(target_linear - self._linear, -linear_step), linear_step)
            self._angular += min(max(target_angular - self._angular, -angular_step), angular_step)
            yaw = data.qpos[qyaw]
            # Body-frame command -> world-frame velocities for the planar base's actuators.
            data.ctrl[0] = self._linear * math.cos(yaw)
            data.ctrl[1] = self._linear * math.sin(yaw)
            data.ctrl[2] = self._angular
            mujoco.mj_step(model, data)
            # The robot never leaves the world: stop it at the edge.
            for position_index, velocity_index in ((qx, vx), (qy, vy)):
                if abs(data.qpos[position_index]) > limit:
                    data.qpos[position_index] = math.copysign(limit, data.qpos[position_index])
                    data.qvel[velocity_index] = 0.0
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
    def render(self) -> np.ndarray:
        """The camera image now: H x W x 3 uint8, RGB (plus seeded noise if image_noise > 0)."""
        return self._camera.render(self._rng)

    @_locked
    def render_view(self, view: str = "follow") -> np.ndarray:
        """An RGB picture for people: "follow" (behind the robot), "top" (the whole world from
        above) or "front" (the robot's camera, without noise); same size as the camera image."""
        return self._camera.render_view(view)

    @_locked
    def ball_masks(self) -> dict[str, np.ndarray]:
        """Per ball id, the H x W boolean mask of its visible pixels (segmentation rendering)."""
        return self._camera.ball_masks([ball.id for ball in self.scenario.balls], self._ball_geoms)

    @_locked
    def world_to_camera(self, point) -> np.ndarray:
        """A world point in the camera optical frame (x right, y down, z forward)."""
        return self._camera.world_to_camera(point)

    def project(self, point_in_camera) -> tuple[float, float] | None:
        """Pixel (u, v) of an optical-frame point, or None when it is not in front."""
        return project(self.config, point_in_camera)

    # -- ground truth -------------------------------------------------------------------------

    @_locked
    def robot_pose(self) -> tuple[float, float, float]:
        qx, qy, qyaw = self._qpos_index
        qpos = self._data.qpos
        return float(qpos[qx]), float(qpos[qy]), wrap_angle(float(qpos[qyaw]))

    @_locked
    def ground_truth(self) -> dict[str, Any]:
        """The GroundTruth message body: robot pose and every ball in world and camera frames.

        A ball is ``visible`` when its centre is in front of the camera and projects inside
        the image (occlusion is not considered; ``ball_masks`` gives the pixels really seen).
        """
        x, y, yaw = self.robot_pose()
        width, height = self.config.width, self.config.height
        balls = []
        for ball, position in zip(self.scenario.balls, self._ball_positions):
            in_camera = self.world_to_camera(position)
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
    def handle_command(self, request: Any) -> dict[str, Any]:
        """Serve one SimCommand; returns {"ok": True} or {"ok": False, "error": ...}.

        A bad request (unknown op or argument, wrong type, out of range, unknown ball or
        scenario) changes nothing: every argument is validated before anything is applied.
        """
        try:
            op, arguments = checked_form(request)
            getattr(self, op)(**arguments)
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
    def place_robot(self, x: Any = None, y: Any = None, yaw: Any = None) -> None:
        """Teleport the robot to (x, y) and heading yaw (default: keep), standing still."""
        new_x, new_y = robot_position(x, y, self.scenario.robot_limit)
        new_yaw = self.robot_pose()[2] if yaw is None else finite_number("yaw", yaw)
        qx, qy, qyaw = self._qpos_index
        self._data.qpos[qx], self._data.qpos[qy], self._data.qpos[qyaw] = new_x, new_y, new_yaw
        self._data.qvel[self._qvel_index] = 0.0
        self._linear = 0.0
        self._angular = 0.0
        mujoco.mj_forward(self._model, self._data)
