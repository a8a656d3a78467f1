"""In-process test rig: the simulator core, the detector core and the locator geometry together.

The perception experiments render a frame with :class:`services.simulator.sim.Simulation`,
run :class:`services.detector.detector.BallDetector` on it and locate the result with
:mod:`services.locator.geometry`, exactly the computations the services do, without Zenoh in
between (which would only add transport time). :class:`ClosedLoop` adds the follower's
controller at 10 Hz on simulated time for the tracking experiments.

Ground truth: a ball's expected circle is the exact pinhole image of the sphere
(``project_sphere``, the best-fit-circle model the locator assumes); a detection *matches* a
ball when its centre lies within half the expected radius (+ 2 px) of the expected centre, the
same rule as the real-photo scoring.
"""

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import Detection, build_detector
from balltrack.services.follower.config import FollowerConfig
from balltrack.services.follower.controller import Command, FollowerController
from balltrack.common.pinhole import Intrinsics
from balltrack.services.locator.geometry import Position3D, locate_exact, locate_faithful
from balltrack.services.locator.projection import project_sphere, silhouette_ellipse
from balltrack.services.simulator.config import SimulatorConfig
from balltrack.services.simulator.scenario import Scenario, parse_scenario
from balltrack.services.simulator.sim import Simulation
from balltrack.services.simulator.world import CAMERA_POSITION

CAMERA_AHEAD = CAMERA_POSITION[0]   # camera in front of the robot's centre (m)
CAMERA_HEIGHT = CAMERA_POSITION[2]  # camera above the floor (m)
TENNIS_RADIUS = 0.033
TENNIS_RGB = [0.7, 0.85, 0.15]
WORLD_SIZE = 10.0


# ---------------------------------------------------------------------------------------------
# Scenarios built in code (dicts in the TOML layout of services/simulator/scenario.py)


def scenario_data(balls: list[dict] | None = None, distractors: list[dict] | None = None,
                  robot: dict | None = None, light: dict | None = None, name: str = "experiment",
                  description: str = "") -> dict[str, Any]:
    data: dict[str, Any] = {"name": name, "description": description,
                            "world": {"size": WORLD_SIZE, "wall_height": 0.5}}
    if robot:
        data["robot"] = robot
    if light:
        data["light"] = light
    data["balls"] = balls or []
    data["distractors"] = distractors or []
    return data


def build_scenario(data: dict[str, Any]) -> Scenario:
    """A validated Scenario from a dict (the same checks as a TOML file gets)."""
    return parse_scenario(data, f"<experiment {data.get('name', '')}>", data.get("name", "experiment"))


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    raise TypeError(f"cannot write {value!r} as TOML")


def scenario_toml(data: dict[str, Any]) -> str:
    """The scenario dict as a TOML document (for the simulator service's ``reset``)."""
    lines = []
    for key, value in data.items():
        if not isinstance(value, (dict, list)) or (isinstance(value, list) and value
                                                   and not isinstance(value[0], dict)):
            lines.append(f"{key} = {_toml_value(value)}")
    for key, value in data.items():
        if isinstance(value, dict):
            lines.append(f"\n[{key}]")
            lines += [f"{inner} = {_toml_value(item)}" for inner, item in value.items()]
    for key, value in data.items():
        if isinstance(value, list) and value and isinstance(value[0], dict):
            for item in value:
                lines.append(f"\n[[{key}]]")
                nested = {}
                for inner, entry in item.items():
                    if isinstance(entry, dict):
                        nested[inner] = entry
                    else:
                        lines.append(f"{inner} = {_toml_value(entry)}")
                for inner, entry in nested.items():
                    lines.append(f"[{key}.{inner}]")
                    lines += [f"{k} = {_toml_value(v)}" for k, v in entry.items()]
    return "\n".join(lines) + "\n"


def write_scenario(data: dict[str, Any], path: Path) -> Path:
    build_scenario(data)  # validate before anyone loads it
    path.write_text(scenario_toml(data))
    return path


def camera_pose(robot_x: float, robot_y: float, yaw: float) -> tuple[float, float]:
    """World (x, y) of the camera of a robot at (robot_x, robot_y, yaw)."""
    return robot_x + CAMERA_AHEAD * math.cos(yaw), robot_y + CAMERA_AHEAD * math.sin(yaw)


def point_from_camera(robot_x: float, robot_y: float, yaw: float, distance: float,
                      bearing: float) -> tuple[float, float]:
    """World (x, y) at horizontal ``distance`` from the camera, ``bearing`` left of its axis."""
    camera_x, camera_y = camera_pose(robot_x, robot_y, yaw)
    return (camera_x + distance * math.cos(yaw + bearing),
            camera_y + distance * math.sin(yaw + bearing))


def segment_across(middle: tuple[float, float], heading: float,
                   half_length: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """The ends of a straight path of ``2 * half_length`` through ``middle`` along ``heading``
    (world radians): the line a scripted ball moves on."""
    dx, dy = half_length * math.cos(heading), half_length * math.sin(heading)
    return (middle[0] - dx, middle[1] - dy), (middle[0] + dx, middle[1] + dy)


# ---------------------------------------------------------------------------------------------
# Perception


@dataclass
class Located:
    """One detection located by both locator models, with its errors against ground truth."""

    detection: Detection
    exact: Position3D
    faithful: Position3D


def normalised(detection: Detection, width: int, height: int) -> tuple[float, float, float]:
    """The contract's Ball2D (x, y, z) of a detection."""
    return ((detection.u - width / 2) / (width / 2), (detection.v - height / 2) / (height / 2),
            2 * detection.radius_px / width)


class Perception:
    """A simulated world with the detector and locator cores attached."""

    def __init__(self, scenario: dict[str, Any] | Scenario, simulator: dict[str, Any] | None = None,
                 detector: DetectorConfig | None = None):
        self.config = SimulatorConfig(**(simulator or {}))
        scene = scenario if isinstance(scenario, Scenario) else build_scenario(scenario)
        self.sim = Simulation(self.config, scene)
        self.detector = build_detector(detector or DetectorConfig())
        self.info = self.sim.camera_info()
        self.intrinsics = Intrinsics.from_camera_info(self.info)
        self.width, self.height = self.info["width"], self.info["height"]
        self.last_image: np.ndarray | None = None

    def close(self) -> None:
        self.sim.close()

    def __enter__(self) -> "Perception":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- placing things relative to the camera ------------------------------------------------

    def place_robot(self, x: float, y: float, yaw: float) -> None:
        self.sim.place_robot(x, y, yaw)

    def place_ball_from_camera(self, ball_id: str, distance: float, bearing: float,
                               height: float | None = None) -> tuple[float, float, float]:
        """Put a ball at horizontal ``distance`` from the camera, ``bearing`` rad to its left,
        its centre ``height`` above the floor (default: resting on the floor)."""
        robot_x, robot_y, yaw = self.sim.robot_pose()
        x, y = point_from_camera(robot_x, robot_y, yaw, distance, bearing)
        radius = self.sim.scenario.ball(ball_id).radius
        z = radius if height is None else height
        self.sim.place_ball(ball_id, [x, y, z])
        return x, y, z

    # -- frames ---------------------------------------------------------------------------------

    def detect(self) -> list[Detection]:
        """Render the camera image and detect balls in it (largest first)."""
        image = cv2.cvtColor(self.sim.render(), cv2.COLOR_RGB2BGR)
        self.last_image = image
        return self.detector.detect(image).detections

    def truth(self) -> list[dict[str, Any]]:
        """Ground truth of every ball, plus its expected circle and analytic visible fraction."""
        balls = self.sim.ground_truth()["balls"]
        for ball in balls:
            ball["expected"] = self.expected_circle(ball["in_camera"], ball["radius"])
            ball["fraction_in_frame"] = self.fraction_in_frame(ball["in_camera"], ball["radius"])
            ball["distance"] = float(np.linalg.norm(ball["in_camera"]))
        return balls

    def expected_circle(self, in_camera, radius: float) -> tuple[float, float, float] | None:
        if in_camera[2] <= radius * 1.001:
            return None
        return project_sphere(in_camera, radius, self.intrinsics)

    def fraction_in_frame(self, in_camera, radius: float, samples: int = 48) -> float:
        """Share of the ball's silhouette area inside the image (occlusion not considered)."""
        if in_camera[2] <= radius * 1.001:
            return 0.0
        ellipse = silhouette_ellipse(in_camera, radius, self.intrinsics)
        grid = (np.arange(samples) + 0.5) / samples * 2 - 1
        gx, gy = np.meshgrid(grid, grid)
        inside = gx * gx + gy * gy <= 1
        gx, gy = gx[inside] * ellipse.semi_major, gy[inside] * ellipse.semi_minor
        cos_a, sin_a = math.cos(ellipse.angle), math.sin(ellipse.angle)
        us = ellipse.u + gx * cos_a - gy * sin_a
        vs = ellipse.v + gx * sin_a + gy * cos_a
        within = ((us >= -0.5) & (us <= self.width - 0.5) & (vs >= -0.5) & (vs <= self.height - 0.5))
        return float(within.mean())

    @staticmethod
    def match(detections: list[Detection], balls: list[dict[str, Any]]) -> dict[str, int]:
        """Ball id -> index of the detection that matches it (greedy, nearest first)."""
        pairs = []
        for ball in balls:
            expected = ball.get("expected")
            if expected is None:
                continue
            u, v, radius = expected
            for index, detection in enumerate(detections):
                offset = math.hypot(detection.u - u, detection.v - v)
                if offset <= 0.5 * radius + 2.0:
                    pairs.append((offset, ball["id"], index))
        pairs.sort()
        matched: dict[str, int] = {}
        used: set[int] = set()
        for _offset, ball_id, index in pairs:
            if ball_id not in matched and index not in used:
                matched[ball_id] = index
                used.add(index)
        return matched

    def locate(self, detection: Detection, ball_radius: float = TENNIS_RADIUS) -> Located:
        """Both locator models, as the locator service computes them with CameraInfo."""
        exact = locate_exact(detection.u, detection.v, detection.radius_px, self.intrinsics,
                             ball_radius)
        x, y, z = normalised(detection, self.width, self.height)
        faithful = locate_faithful(x, y, z, self.info["hfov"], self.intrinsics.v_fov, ball_radius)
        return Located(detection, exact, faithful)


def position_errors(located: Located, in_camera) -> dict[str, float]:
    """3D error (m), and relative distance and 3D errors, of both models."""
    truth = np.asarray(in_camera, dtype=float)
    distance = float(np.linalg.norm(truth))
    errors = {}
    for label, position in (("exact", located.exact), ("faithful", located.faithful)):
        estimate = np.array([position.x, position.y, position.z])
        error = float(np.linalg.norm(estimate - truth))
        errors[f"{label}_error_m"] = error
        errors[f"{label}_error_rel"] = error / distance
        errors[f"{label}_distance_rel"] = (position.distance - distance) / distance
    return errors


# ---------------------------------------------------------------------------------------------
# Closed loop: simulator + detector + follower controller


@dataclass
class LoopFrame:
    """What happened in one camera frame of a closed-loop run."""

    time: float
    detections: list[Detection]
    command: Command | None        # issued at this frame (10 Hz), else None
    robot: tuple[float, float, float]
    velocity: tuple[float, float]  # applied (after acceleration limits)
    balls: list[dict[str, Any]]
    target_index: int | None       # the detection the controller was given (None: none)


class ClosedLoop:
    """The follower driving the simulated robot from the detector's balls.

    Every camera frame is detected (the detector service runs on every image); the ball the
    follower service would choose goes to the controller at the frame's simulated time (no transport latency), and
    the controller's timer runs at ``rate_hz`` on simulated time, as the follower service does
    with ``use_sim_time``.
    """

    def __init__(self, perception: Perception, follower: FollowerConfig):
        self.perception = perception
        self.controller = FollowerController(follower)
        self.period = 1.0 / follower.rate_hz
        self.next_tick = perception.sim.time

    def step(self, with_truth: bool = True) -> LoopFrame:
        sim = self.perception.sim
        now = sim.time
        detections = self.perception.detect()
        balls = self.perception.truth() if with_truth else []
        target_index = None
        if detections:
            # As the follower service does: with keep_target it picks among all the balls
            # (detected_balls), otherwise it steers by the largest (detected_ball, the paper's).
            fields = [dict(zip(("x", "y", "z"), normalised(detection, self.perception.width,
                                                           self.perception.height)))
                      for detection in detections]
            if self.controller.config.keep_target:
                chosen = self.controller.choose(fields, now)
                target_index = None if chosen is None else fields.index(chosen)
            else:
                target_index = 0
            if target_index is not None:
                target = fields[target_index]
                self.controller.on_detection(target["x"], target["z"], now)
        command = None
        if now >= self.next_tick - 1e-9:
            command = self.controller.tick(now)
            sim.set_command(command.linear, command.angular, now)
            self.next_tick += self.period
        frame = LoopFrame(now, detections, command, sim.robot_pose(), sim.robot_velocity(), balls,
                          target_index)
        sim.step_frame()
        return frame


def draw_detections(image_bgr: np.ndarray, detections: list[Detection], path: Path) -> None:
    """Save a frame with the detections drawn on it (for diagnosing false detections)."""
    picture = image_bgr.copy()
    for detection in detections:
        cv2.circle(picture, (int(round(detection.u)), int(round(detection.v))),
                   max(1, int(round(detection.radius_px))), (255, 0, 255), 2)
    cv2.imwrite(str(path), picture)
