"""One process serving two robots (``balltrack run detector+locator+follower --namespaces
robot1,robot2``): each robot's frames become its own 3D positions and commands, located with
its own camera model; each robot's services answer, count and change parameters under its own
namespace; and a robot flooding frames does not stop the other's."""

import math
import re
import subprocess
import sys
import threading

import pytest

from balltrack.common.images import bgr_to_message
from balltrack.common.keys import Keys
from balltrack.common.messages import encode, header
from balltrack.common.pinhole import Intrinsics
from balltrack.common.status import service_status
from balltrack.services.locator.projection import project_sphere
from tests.harness import (Collector, Liveliness, draw_ball, floor_image, process_environment, put_until,
                           query_config, start_service)

JOINED = "detector+locator+follower"
ROBOTS = ("robot1", "robot2")
WIDTH, HEIGHT = 320, 240
# Each robot its own lens: a robot's positions come out right only with its own camera model.
CAMERAS = {"robot1": Intrinsics.from_fov(WIDTH, HEIGHT, 1.089), "robot2": Intrinsics.from_fov(WIDTH, HEIGHT, 0.7)}
# Where each robot's ball is (camera optical frame, metres): on the right for robot1, on the
# left for robot2, so their commands turn opposite ways.
BALLS = {"robot1": (0.2, 0.067, 1.0), "robot2": (-0.2, 0.067, 1.5)}
RADIUS = 0.033


def camera_info(intrinsics: Intrinsics) -> dict:
    return {"header": header(0, 0), "width": WIDTH, "height": HEIGHT, "fx": intrinsics.fx,
            "fy": intrinsics.fy, "cx": intrinsics.cx, "cy": intrinsics.cy,
            "hfov": intrinsics.h_fov, "vfov": intrinsics.v_fov}


def ball_frame(robot: str, seed: int):
    u, v, radius = project_sphere(BALLS[robot], RADIUS, CAMERAS[robot])
    return draw_ball(floor_image(WIDTH, HEIGHT, seed), u, v, radius)


@pytest.fixture
def robots(router, session, log_dir):
    """The one process serving both robots, its services alive under each namespace."""
    process = start_service(JOINED, router.endpoint, log_dir, "--namespaces", ",".join(ROBOTS),
                            "--set", "follower.keep_target=false")
    try:
        for robot in ROBOTS:
            liveliness = Liveliness(session, robot)
            for service in JOINED.split("+"):
                liveliness.wait(service, timeout=60)
        for robot in ROBOTS:
            session.put(Keys(robot)("camera/camera_info"), encode("CameraInfo", camera_info(CAMERAS[robot])))
        yield process
    finally:
        assert process.stop() == 0, process.output()


def locate(session, robot: str, seq: int, located: Collector, timeout: float = 60) -> dict:
    """Put ``robot``'s frame ``seq`` until its 3D position comes back (the first frames may
    arrive before the robot's CameraInfo, or before the subscription reached the router)."""
    image = ball_frame(robot, seq)
    key = Keys(robot)("camera/image_raw")
    return put_until(lambda _: session.put(key, encode("Image", bgr_to_message(image, 1_000_000_000 * seq, seq))),
                     located, lambda messages: [m for m in messages if m["header"]["seq"] == seq],
                     timeout, 2, f"{robot}'s position of frame {seq}")[-1]


def test_each_robot_gets_its_own_positions_and_commands(router, session, robots):
    located = {robot: Collector(session, Keys(robot)("detected_ball_3d"), "Ball3D") for robot in ROBOTS}
    commands = {robot: Collector(session, Keys(robot)("cmd_vel"), "Twist") for robot in ROBOTS}
    for seq, robot in enumerate(ROBOTS, start=1):
        position = locate(session, robot, seq, located[robot])
        truth = math.dist(BALLS[robot], (0, 0, 0))
        # Stated tolerance: within 5% of the distance (a wrong lens would be ~50% off here).
        assert math.dist((position["x"], position["y"], position["z"]), BALLS[robot]) < 0.05 * truth, (robot, position)
        command = commands[robot].wait_for(lambda messages: [m for m in messages if m["header"]["seq"] == seq],
                                           10, f"{robot}'s command for frame {seq}")[-1]
        # Turn toward the ball: robot1's is on the right (negative angular), robot2's on the left.
        assert math.copysign(1, command["angular"][2]) == -math.copysign(1, BALLS[robot][0]), (robot, command)
    # Nothing of one robot went out under the other's namespace (robot1's frames were 1, robot2's 2).
    assert {m["header"]["seq"] for m in located["robot1"].messages} == {1}
    assert {m["header"]["seq"] for m in located["robot2"].messages} == {2}
    for robot in ROBOTS:
        alive, _ = service_status(session, robot)
        assert alive == set(JOINED.split("+")), (robot, alive)
    # `balltrack status` shows one robot's services and says where the others are.
    status = subprocess.run([sys.executable, "-m", "balltrack", "status", "--connect", router.endpoint,
                             "--namespace", "robot1"], capture_output=True, text=True, timeout=60,
                            env=process_environment())
    assert status.returncode == 0, status.stderr
    assert re.search(r"^locator +yes +[1-9]", status.stdout, re.M), status.stdout
    assert "other namespaces (balltrack status --namespace NS): robot2: detector, follower, locator" in status.stdout


def test_a_robots_parameters_change_without_the_others(session, robots):
    changed = query_config(session, "locator", {"ball_radius": 0.05}, namespace="robot2")
    assert changed["ok"] and changed["config"]["ball_radius"] == 0.05
    assert query_config(session, "locator", namespace="robot1")["config"]["ball_radius"] == RADIUS
    assert query_config(session, "detector", {"v_min": 31}, namespace="robot1")["config"]["v_min"] == 31
    assert query_config(session, "detector", namespace="robot2")["config"]["v_min"] != 31
    # And in effect: robot2 now takes the same picture for a bigger ball, farther away.
    located = {robot: Collector(session, Keys(robot)("detected_ball_3d"), "Ball3D") for robot in ROBOTS}
    near = locate(session, "robot1", 1, located["robot1"])
    far = locate(session, "robot2", 2, located["robot2"])
    assert abs(near["distance"] - math.dist(BALLS["robot1"], (0, 0, 0))) < 0.05 * near["distance"]
    assert far["distance"] > 1.4 * math.dist(BALLS["robot2"], (0, 0, 0)), far


def test_a_robot_flooding_frames_does_not_stop_the_other(session, robots):
    flood_stats = Collector(session, Keys("robot1")("detector/stats"), "Stats")
    located = Collector(session, Keys("robot2")("detected_ball_3d"), "Ball3D")
    # Large JPEG frames, slow to decode: they come faster than the detector can take them, so
    # robot1's slot is full whenever the worker looks (a worker that served the first full slot
    # rather than the next in turn would then serve robot1 alone).
    flood_frame = encode("Image", bgr_to_message(draw_ball(floor_image(1600, 1200), 800, 600, 80), 1, 1,
                                                 encoding="jpeg"))
    flood_key = Keys("robot1")("camera/image_raw")
    flooding = threading.Event()
    stop = threading.Event()

    def flood():
        publisher = session.declare_publisher(flood_key)
        flooding.set()
        while not stop.is_set():
            publisher.put(flood_frame)
        publisher.undeclare()

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    try:
        assert flooding.wait(10)
        # The flood is on when robot1's detector drops frames it had no time for.
        flood_stats.wait_for(lambda messages: [m for m in messages if m["dropped"] > 0], 30,
                             "robot1's detector dropping frames")
        for seq in range(10, 15):
            # (served in turn, a frame is located within a few of robot1's frames; were robot1
            # served first, robot2's would wait for a gap in the flood: seconds, often more)
            locate(session, "robot2", seq, located, timeout=10)
        assert flooder.is_alive()  # (robot2 was served during the flood, not after it)
    finally:
        stop.set()
        flooder.join(10)


def test_auto_serves_each_robot_whose_frame_source_appears(router, session, log_dir):
    process = start_service(JOINED, router.endpoint, log_dir, "--namespaces", "auto",
                            "--set", "follower.keep_target=false")
    # Frame sources as the simulator and the camera service announce themselves: robot1's
    # before the process starts looking (two of them: one robot all the same), robot2's after
    # it serves robot1; robot3 has only a locator, no frames to serve.
    sources = [session.liveliness().declare_token(Keys("robot1")(f"alive/{source}"))
               for source in ("simulator", "camera")]
    try:
        for robot, source in (("robot1", None), ("robot2", "camera")):
            if source is not None:
                sources.append(session.liveliness().declare_token(Keys("robot3")("alive/locator")))
                sources.append(session.liveliness().declare_token(Keys(robot)(f"alive/{source}")))
            liveliness = Liveliness(session, robot)
            for service in JOINED.split("+"):
                liveliness.wait(service, timeout=60)
            session.put(Keys(robot)("camera/camera_info"), encode("CameraInfo", camera_info(CAMERAS[robot])))
            located = Collector(session, Keys(robot)("detected_ball_3d"), "Ball3D")
            position = locate(session, robot, 1, located)
            truth = math.dist(BALLS[robot], (0, 0, 0))
            assert math.dist((position["x"], position["y"], position["z"]), BALLS[robot]) < 0.05 * truth, robot
    finally:
        for token in sources:
            token.undeclare()
        assert process.stop() == 0, process.output()
    # Each robot once; robot3's token, seen before robot2's, served nothing.
    assert process.output().count("serving it") == 2, process.output()
    assert "'robot3'" not in process.output()
