"""Several robots in one simulator process over a real router: each robot's namespace gets its
frames, camera info, clock and ground truth, obeys its own cmd_vel and sim/control, and in
lockstep each robot's pipeline is waited for.

Frames are small (160x120) to keep the CPU low; waits are on messages, never on sleeps.
"""

import numpy as np
import pytest

from balltrack.common.clock import TimerTicks
from balltrack.common.messages import decode, encode, header
from balltrack.services.simulator.control import send_command
from balltrack.services.simulator.fleet import own_ball_id
from tests.harness import Collector, Liveliness, put_until, start_service

SMALL = ("--set", "width=160", "--set", "height=120")
NAMESPACE = "site"
ROBOTS = ("robot1", "robot2", "robot3")


def twist(linear: float, angular: float) -> dict:
    return {"header": header(0, 0, "base_link"), "linear": [linear, 0.0, 0.0],
            "angular": [0.0, 0.0, angular]}


def robot_key(robot: str, key: str) -> str:
    return f"{NAMESPACE}/{robot}/{key}"


@pytest.fixture
def fleet_simulator(router, session, log_dir):
    """A simulator of three robots in the ``fleet`` scenario under the namespace ``site``,
    with a collector for each robot's keys; stopped at teardown (exit 0)."""
    collectors = {robot: {"images": Collector(session, robot_key(robot, "camera/image_raw"), "Image"),
                          "truths": Collector(session, robot_key(robot, "sim/ground_truth"), "GroundTruth"),
                          "clocks": Collector(session, robot_key(robot, "clock"), "Clock"),
                          "infos": Collector(session, robot_key(robot, "camera/camera_info"), "CameraInfo")}
                  for robot in ROBOTS}
    unprefixed = [Collector(session, f"{NAMESPACE}/{key}", None)
                  for key in ("camera/image_raw", "sim/ground_truth", "clock")]
    process = start_service("simulator", router.endpoint, log_dir, "--namespace", NAMESPACE, *SMALL,
                            "--set", "scenario=fleet", "--set", f"robots={len(ROBOTS)}",
                            "--set", "pacing=realtime")
    Liveliness(session, NAMESPACE).wait("simulator", timeout=40)
    for robot in ROBOTS:  # each robot's namespace shows its frame source alive
        Liveliness(session, f"{NAMESPACE}/{robot}").wait("simulator", timeout=10)
    yield collectors, unprefixed
    assert process.stop() == 0, process.output()


def test_each_robot_has_its_own_frames_clock_camera_info_and_ground_truth(session, fleet_simulator):
    collectors, unprefixed = fleet_simulator
    for robot, keys in collectors.items():
        for collector in keys.values():
            collector.wait_count(1, 30)
        keys["images"].wait_count(5, 30)
    # The same frames for every robot: frame k is seq k on every robot's keys. (A robot's first
    # frame may go out before the simulator heard of this subscriber: Zenoh drops a put nobody
    # is known to want at the writer. So from the first frame every robot's collector has.)
    first = max(keys["images"].messages[0]["header"]["seq"] for keys in collectors.values())
    for keys in collectors.values():
        keys["images"].wait_for(lambda messages: messages[-1]["header"]["seq"] >= first + 4, 30, "5 common frames")
    same_frames = [[image for image in keys["images"].messages if first <= image["header"]["seq"] < first + 5]
                   for keys in collectors.values()]
    seqs = [[image["header"]["seq"] for image in images] for images in same_frames]
    assert seqs[0] == seqs[1] == seqs[2] == list(range(first, first + 5))
    # Each camera sees its own view: the same frame differs between robots.
    pictures = [np.frombuffer(images[4]["data"], np.uint8) for images in same_frames]
    assert not np.array_equal(pictures[0], pictures[1]) and not np.array_equal(pictures[1], pictures[2])
    for index, (robot, keys) in enumerate(collectors.items()):
        truth = keys["truths"].messages[0]
        # Robots 1.5 m apart, robot1 on the left (+y), each seeing its own ball only.
        assert truth["robot"]["y"] == pytest.approx(1.5 - 1.5 * index)
        assert [ball["id"] for ball in truth["balls"] if ball["visible"]] == [own_ball_id(index + 1)]
        assert (keys["infos"].messages[0]["width"], keys["infos"].messages[0]["height"]) == (160, 120)
        # (from the later of their first messages: either may have missed the first frame)
        clock_stamps = [message["stamp"] for message in keys["clocks"].messages]
        truth_stamps = [message["header"]["stamp"] for message in keys["truths"].messages]
        common = max(clock_stamps[0], truth_stamps[0])
        assert common in clock_stamps and common in truth_stamps
        replies = [decode("CameraInfo", reply.ok.payload.to_bytes()) for reply in
                   session.get(robot_key(robot, "camera/camera_info"), timeout=5) if reply.ok is not None]
        assert [reply["width"] for reply in replies] == [160]
    # Nothing on the service's own keys: a fleet's robots are only on theirs.
    assert all(collector.messages == [] for collector in unprefixed)


def test_each_robot_obeys_its_own_cmd_vel_and_sim_control(session, fleet_simulator):
    collectors, _ = fleet_simulator
    truths = {robot: keys["truths"] for robot, keys in collectors.items()}
    starts = {robot: collector.wait_count(1, 30)[0]["robot"] for robot, collector in truths.items()}

    # robot2 is driven; robot1 and robot3 are not.
    driven = put_until(lambda attempt: session.put(robot_key("robot2", "cmd_vel"), encode("Twist", twist(0.4, 0.0))),
                       truths["robot2"],
                       lambda messages: messages[-1]["robot"]["x"] > starts["robot2"]["x"] + 0.15 and messages[-1],
                       60, 0.2, "robot2 driven 0.15 m forward")
    stamp = driven["header"]["stamp"]
    for robot in ("robot1", "robot3"):
        same_frame = truths[robot].wait_for(lambda messages: next(
            (truth for truth in messages if truth["header"]["stamp"] >= stamp), None), 20, "the same frame")
        assert same_frame["robot"] == starts[robot], f"{robot} moved"

    # place_robot on robot3's sim/control moves robot3 only; world ops change the shared world.
    reply = send_command(session, {"op": "place_robot", "x": -4.0, "y": -3.0, "yaw": 1.0},
                         namespace=f"{NAMESPACE}/robot3")
    assert reply == {"ok": True}
    placed = truths["robot3"].wait_for(lambda messages: next(
        (truth for truth in messages if truth["robot"]["x"] == pytest.approx(-4.0)), None), 20, "robot3 placed")
    assert (placed["robot"]["y"], placed["robot"]["yaw"]) == pytest.approx((-3.0, 1.0))
    same_frame = truths["robot1"].wait_for(lambda messages: next(
        (truth for truth in messages if truth["header"]["stamp"] >= placed["header"]["stamp"]), None),
        20, "the same frame")
    assert same_frame["robot"] == starts["robot1"]
    reply = send_command(session, {"op": "place_ball", "id": own_ball_id(1), "position": [5.0, 5.0]},
                         namespace=f"{NAMESPACE}/robot2")
    assert reply == {"ok": True}
    moved_ball = truths["robot1"].wait_for(lambda messages: next(
        (truth for truth in messages if truth["balls"][0]["position"][:2] == [5.0, 5.0]), None), 20,
        "tennis1 moved on robot1's ground truth")
    assert not moved_ball["balls"][0]["visible"]
    bad = send_command(session, {"op": "place_robot", "x": 99.0, "y": 0.0}, namespace=f"{NAMESPACE}/robot1")
    assert bad["ok"] is False and "outside the world" in bad["error"]


def test_lockstep_waits_for_each_robots_pipeline(router, session, log_dir):
    """Two robots, each with its own detector and follower (one process per robot, on
    simulated time): every frame waits for both detectors and every tick for both followers,
    and each robot turns towards its own ball (to its left)."""
    frames = 45
    liveliness = {robot: Liveliness(session, robot) for robot in ROBOTS[:2]}
    pipelines = [start_service("detector+follower", router.endpoint, log_dir, "--namespace", robot,
                               "--set", "follower.use_sim_time=true") for robot in ROBOTS[:2]]
    for robot in ROBOTS[:2]:
        for name in ("detector", "follower"):
            liveliness[robot].wait(name, timeout=60)
    truths = {robot: Collector(session, f"{robot}/sim/ground_truth", "GroundTruth") for robot in ROBOTS[:2]}
    commands = {robot: Collector(session, f"{robot}/cmd_vel", "Twist") for robot in ROBOTS[:2]}
    simulator = start_service("simulator", router.endpoint, log_dir, *SMALL, "--set", "scenario=fleet",
                              "--set", "robots=2", "--set", "pacing=lockstep",
                              "--set", "lockstep_timeout=10")
    try:
        for collector in truths.values():
            collector.wait_count(frames, 180)  # generous: a loaded 2-core machine
    finally:
        codes = [process.stop() for process in (simulator, *pipelines)]
    assert codes == [0, 0, 0], simulator.output()
    assert " 0 lockstep timeouts" in simulator.output(), simulator.output()
    for robot in ROBOTS[:2]:
        stamps = [truth["header"]["stamp"] for truth in truths[robot].messages[:frames]]
        assert [truth["header"]["seq"] for truth in truths[robot].messages[:frames]] == list(range(1, frames + 1))
        # The robot's follower ticked on exactly the frames the simulator waited for (its first
        # clock, then each crossing of a multiple of 0.1 s). (The last frame's clock may not be
        # out yet when the simulator is stopped.)
        ticks = TimerTicks()
        expected = [stamp for stamp in stamps[:-1] if ticks.fires(stamp, 0.1)]
        assert [command["time"] for command in commands[robot].messages][:len(expected)] == expected, robot
        assert any(command["mode"] == "chase" for command in commands[robot].messages), f"{robot} saw no ball"
        assert truths[robot].messages[frames - 1]["robot"]["yaw"] > 0.05, f"{robot} did not turn to its ball"
