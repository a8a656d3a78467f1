"""The simulator as a real process: frames, camera info, ground truth, commands, control, lockstep.

Frames are small (160x120) to keep the CPU low; waits are on messages (sim frames), never on
wall-clock sleeps.
"""

import json
import math

import msgpack
import numpy as np
import pytest

from balltrack.common.messages import decode, encode, header
from balltrack.services.simulator.control import send_command
from balltrack.common.clock import TimerTicks
from tests.harness import Collector, Liveliness, garbage_payloads, query_config, start_service

SMALL = ("width=160", "height=120")
PERIOD = 1 / 30
CHASE_BALL = [1.8421, 1.0, 0.033]  # services/simulator/scenarios/chase.toml


def twist(linear: float, angular: float, seq: int = 0) -> dict:
    return {"header": header(0, seq, "base_link"), "linear": [linear, 0.0, 0.0],
            "angular": [0.0, 0.0, angular]}


def newest(collector: Collector) -> dict:
    collector.wait_for(lambda messages: messages, 20, "a first message")
    return collector.messages[-1]


def wait_seq(collector: Collector, seq: int, timeout: float = 20) -> dict:
    """The first message whose header.seq is at least ``seq``."""
    return collector.wait_for(lambda messages: next(
        (message for message in messages if message["header"]["seq"] >= seq), None), timeout,
        f"a message with seq >= {seq}")


def brightness(image: dict) -> float:
    return float(np.frombuffer(image["data"], np.uint8).mean())


def moved(before: dict, after: dict) -> float:
    """How far the robot moved between two ground truths (metres + radians)."""
    return (abs(after["robot"]["x"] - before["robot"]["x"]) + abs(after["robot"]["y"] - before["robot"]["y"])
            + abs(after["robot"]["yaw"] - before["robot"]["yaw"]))


@pytest.fixture
def start_simulator(launch):
    return lambda *overrides, wait=True: launch("simulator", *overrides, wait=wait)


def test_frames_camera_info_and_ground_truth_agree(session, start_simulator):
    images = Collector(session, "camera/image_raw", "Image")
    truths = Collector(session, "sim/ground_truth", "GroundTruth")
    clocks = Collector(session, "clock", "Clock")
    infos = Collector(session, "camera/camera_info", "CameraInfo")
    start_simulator(*SMALL, "pacing=realtime", "real_time_factor=3")

    # Periodic camera info: on the first frame, then once per simulated second.
    infos.wait_count(2, 20)
    assert [info["header"]["seq"] for info in infos.messages[:2]] == [1, 30]
    replies = [decode("CameraInfo", reply.ok.payload.to_bytes())
               for reply in session.get("camera/camera_info", timeout=5) if reply.ok is not None]
    assert len(replies) == 1
    for info in (infos.messages[0], replies[0]):
        assert (info["width"], info["height"]) == (160, 120)
        assert info["fx"] == pytest.approx(80 / math.tan(1.089 / 2))
        assert (info["cx"], info["cy"]) == (79.5, 59.5)

    last = images.wait_count(30, 20)[29]
    frames = {image["header"]["seq"]: image for image in images.messages}
    for image in images.messages[:30]:
        assert (image["width"], image["height"], image["encoding"]) == (160, 120, "bgr8")
        assert image["header"]["frame_id"] == "camera"
        assert abs(image["header"]["stamp"] - image["header"]["seq"] * PERIOD * 1e9) < 1000
    assert sorted(frames)[:30] == list(range(1, 31)), "frames lost or out of order"
    truth = wait_seq(truths, last["header"]["seq"])
    assert truth["header"] == last["header"]
    clocks.wait_for(lambda m: [c for c in m if c["stamp"] == last["header"]["stamp"]], 10, "clock")

    # The ball's ground truth projects onto ball-coloured pixels of the same frame.
    assert send_command(session, {"op": "place_ball", "id": "tennis", "position": [1.0, 0.0]})["ok"]
    truth = truths.wait_for(lambda m: [t for t in m if t["balls"][0]["position"] == [1.0, 0.0, 0.033]],
                            10, "the placed ball")[0]
    image = wait_seq(images, truth["header"]["seq"])
    assert image["header"] == truth["header"]
    x, y, z = truth["balls"][0]["in_camera"]
    info = replies[0]
    u, v = info["cx"] + info["fx"] * x / z, info["cy"] + info["fy"] * y / z
    blue, green, red = np.frombuffer(image["data"], np.uint8).reshape(120, 160, 3)[round(v), round(u)]
    assert truth["balls"][0]["visible"] and green > 150 and blue < 90, (u, v, red, green, blue)


def test_cmd_vel_drives_the_robot_and_the_safety_stop_halts_it(session, start_simulator):
    truths = Collector(session, "sim/ground_truth", "GroundTruth")
    start_simulator(*SMALL, "pacing=realtime", "cmd_timeout=0.5", "max_linear_accel=50",
                    "max_angular_accel=50")
    first = newest(truths)
    # Command every third frame (10 Hz of simulated time) for 1.5 simulated seconds.
    seq = first["header"]["seq"]
    while seq < first["header"]["seq"] + 45:
        last_sent = truths.messages[-1]["header"]["stamp"] / 1e9  # the command arrives after this
        session.put("cmd_vel", encode("Twist", twist(0.3, 0.5)))
        seq = wait_seq(truths, seq + 3)["header"]["seq"]

    by_time = {truth["header"]["stamp"] / 1e9: truth for truth in truths.wait_for(
        lambda m: m[-1]["header"]["stamp"] / 1e9 > last_sent + 1.2 and m, 20, "1.2 s more")}
    times = sorted(by_time)
    # While commanded: 0.3 m/s forward and 0.5 rad/s, measured over 0.5 s of ground truth.
    start_time = next(t for t in times if t > first["header"]["stamp"] / 1e9 + 0.2)
    end_time = next(t for t in times if t > start_time + 0.5)
    start, end = by_time[start_time], by_time[end_time]
    span = end_time - start_time
    distance = math.hypot(end["robot"]["x"] - start["robot"]["x"], end["robot"]["y"] - start["robot"]["y"])
    assert distance / span == pytest.approx(0.3, rel=0.05)
    assert (end["robot"]["yaw"] - start["robot"]["yaw"]) / span == pytest.approx(0.5, rel=0.05)
    # The last command holds for cmd_timeout of simulated time, then the robot stops within a
    # frame. It was sent after the frame stamped last_sent and applied before the next step
    # (or, on a busy machine, the one after): stopped from last_sent + cmd_timeout + 3 frames.
    pairs = list(zip(times, times[1:]))
    holding = [moved(by_time[a], by_time[b]) for a, b in pairs
               if start_time <= a and b < last_sent + 0.5 - PERIOD]
    stopped = [moved(by_time[a], by_time[b]) for a, b in pairs if a >= last_sent + 0.5 + 3 * PERIOD]
    assert holding and min(holding) > 0.005, "stopped before cmd_timeout"
    # (The base's velocity servo lets the last millimetres per second decay within a frame.)
    assert stopped and max(stopped) < 1e-4, "still moving after cmd_timeout + a frame"


def test_bad_cmd_vel_is_rejected_and_good_commands_still_obeyed(session, start_simulator):
    truths = Collector(session, "sim/ground_truth", "GroundTruth")
    stats = Collector(session, "simulator/stats", "Stats")
    start_simulator(*SMALL, "pacing=realtime")
    good = twist(0.2, 0.0)
    pack = lambda message: msgpack.packb(message, use_bin_type=True)  # noqa: E731
    cases = garbage_payloads(good) + [
        ("NaN", pack({**good, "linear": [float("nan"), 0.0, 0.0]})),
        ("inf", pack({**good, "angular": [0.0, 0.0, float("-inf")]})),
        ("absurd linear", pack({**good, "linear": [1e6, 0.0, 0.0]})),
        ("absurd angular", pack({**good, "angular": [0.0, 0.0, -500.0]})),
        ("wrong shape", pack({**good, "linear": [0.2, 0.0]})),
        ("text in a vector", pack({**good, "linear": ["fast", 0.0, 0.0]})),
        ("boolean", pack({**good, "linear": [True, 0.0, 0.0]})),
        ("not a vector", pack({**good, "angular": 0.5})),
    ]
    before = newest(truths)
    for _, payload in cases:
        session.put("cmd_vel", payload)
    snapshot = stats.wait_for(lambda m: m and m[-1]["rejected"] >= len(cases) and m[-1], 10,
                              "every bad cmd_vel rejected")
    assert snapshot["rejected"] == len(cases) and snapshot["received"] == len(cases)
    assert moved(before, truths.messages[-1]) == 0.0, "a bad command moved the robot"

    seq = truths.messages[-1]["header"]["seq"]
    while truths.messages[-1]["robot"]["x"] < 0.1:
        session.put("cmd_vel", encode("Twist", good))
        seq = wait_seq(truths, seq + 3)["header"]["seq"]
        assert seq < before["header"]["seq"] + 120, "the robot does not obey good commands"
    assert abs(truths.messages[-1]["robot"]["yaw"]) < 1e-9


def test_sim_control_rejects_bad_requests_and_serves_good_ones(session, start_simulator):
    truths = Collector(session, "sim/ground_truth", "GroundTruth")
    images = Collector(session, "camera/image_raw", "Image")
    start_simulator(*SMALL, "pacing=realtime")
    baseline_truth = newest(truths)
    baseline_light = brightness(wait_seq(images, baseline_truth["header"]["seq"]))

    def after_reply() -> tuple[dict, dict]:
        """Ground truth and image of a frame stepped after the last reply."""
        seq = truths.messages[-1]["header"]["seq"] + 2
        return wait_seq(truths, seq), wait_seq(images, seq)

    bad = [{"op": "explode"}, {"no_op": 1}, {"op": "place_ball", "id": "nope", "position": [1, 0]},
           {"op": "place_ball", "id": "tennis", "position": [99.0, 0.0]},
           {"op": "place_ball", "id": "tennis", "position": [1.0, "left"]},
           {"op": "place_ball", "id": "tennis", "position": [1.0, 0.0], "colour": "red"},
           {"op": "set_light", "diffuse": 5.0}, {"op": "set_light"},
           {"op": "set_light", "diffuse": 0.1, "ambient": [0.1, 0.2]},
           {"op": "place_robot", "x": float("nan"), "y": 0.0}, {"op": "place_robot", "x": 1.0},
           {"op": "reset", "scenario": "no_such_scenario"},
           b"\xc1garbage", b"", msgpack.packb([1, 2, 3])]
    for request in bad:
        reply = send_command(session, request)
        assert reply["ok"] is False and reply["error"], (request, reply)
    truth, image = after_reply()
    assert {k: truth[k] for k in ("robot", "balls")} == {k: baseline_truth[k] for k in ("robot", "balls")}
    assert brightness(image) == baseline_light

    assert send_command(session, {"op": "set_light", "diffuse": 0.1, "ambient": 0.05}) == {"ok": True}
    assert brightness(after_reply()[1]) < 0.6 * baseline_light
    assert send_command(session, {"op": "place_ball", "id": "tennis", "position": [1.0, 0.3]})["ok"]
    assert send_command(session, {"op": "place_robot", "x": 0.5, "y": -0.2, "yaw": 1.0})["ok"]
    truth, _ = after_reply()
    assert truth["balls"][0]["position"] == [1.0, 0.3, 0.033]
    assert truth["robot"] == pytest.approx({"x": 0.5, "y": -0.2, "yaw": 1.0}, abs=1e-6)

    assert send_command(session, {"op": "reset"}) == {"ok": True}
    truth, image = after_reply()
    assert truth["balls"][0]["position"] == CHASE_BALL
    assert truth["robot"] == {"x": 0.0, "y": 0.0, "yaw": 0.0}
    assert brightness(image) == baseline_light


def lockstep_run(router, session, log_dir, frames: int, pacing: str = "lockstep",
                 follower: tuple[str, ...] = ("use_sim_time=true",), lockstep_timeout: float = 10):
    """Detector, follower (simulated time, or the ``follower`` settings) and a simulator paced by
    ``pacing``: the first ``frames`` ground truths, the commands and the simulator's log; all
    stopped (exit 0). (With pacing=realtime or fast, two runs already differ within the first
    frames.)"""
    liveliness = Liveliness(session)
    pipeline = [start_service("detector", router.endpoint, log_dir),
                start_service("follower", router.endpoint, log_dir,
                              *[item for setting in follower for item in ("--set", setting)])]
    for name in ("detector", "follower"):
        liveliness.wait(name, timeout=30)
    truths = Collector(session, "sim/ground_truth", "GroundTruth")
    commands = Collector(session, "cmd_vel", "Twist")
    simulator = start_service("simulator", router.endpoint, log_dir, "--set", f"pacing={pacing}",
                              "--set", "width=320", "--set", "height=240", "--set", "seed=7",
                              "--set", "image_noise=2", "--set", f"lockstep_timeout={lockstep_timeout}")
    try:
        truths.wait_count(frames, 180)  # generous: a loaded 2-core machine renders slowly
    finally:
        codes = [process.stop() for process in (simulator, *pipeline)]
        for name in ("simulator", "detector", "follower"):
            liveliness.wait(name, alive=False, timeout=10)
        truths.close()
        commands.close()
    assert codes == [0, 0, 0], simulator.output()
    return truths.messages[:frames], list(commands.messages), simulator.output()


def test_lockstep_runs_with_the_same_seed_are_identical(router, session, log_dir):
    frames = 60
    first, commands, log = lockstep_run(router, session, log_dir, frames)
    second, _, second_log = lockstep_run(router, session, log_dir, frames)
    assert [truth["header"]["seq"] for truth in first] == list(range(1, frames + 1))
    for log_text in (log, second_log):
        assert " 0 lockstep timeouts" in log_text, log_text
    # The follower ticked on exactly the frames the simulator waited for (its first clock,
    # then each crossing of a multiple of 0.1 s), each command stamped with that frame's clock.
    # (The last frame's clock may not be out yet when the simulator is stopped.)
    ticks = TimerTicks()
    expected = [truth["header"]["stamp"] for truth in first[:-1]
                if ticks.fires(truth["header"]["stamp"], 0.1)]
    assert [command["time"] for command in commands][:len(expected)] == expected
    assert any(command["mode"] == "chase" for command in commands), "the detector saw no ball"
    assert abs(first[-1]["robot"]["yaw"]) > 0.05, "the commands did not turn the robot"
    assert first == second


def test_lockstep_with_a_follower_on_the_wall_clock_gets_every_tick(router, session, log_dir):
    # `deploy start`'s follower runs on the wall clock. Its commands carry the frames' clock in
    # ``time``, so the tick a lockstep frame waits for (``time`` equal to the frame's stamp)
    # comes with the follower's next wall tick after it saw that frame's detections.
    frames = 30
    truths, commands, log = lockstep_run(router, session, log_dir, frames, follower=(),
                                         lockstep_timeout=2)
    assert " 0 lockstep timeouts" in log, log
    stamps = {0} | {truth["header"]["stamp"] for truth in truths}
    # (commands of frames past the first ``frames`` are on the same clock but not in ``truths``)
    last = truths[-1]["header"]["stamp"]
    for command in commands:
        if command["header"]["stamp"] <= last:
            assert command["header"]["stamp"] in stamps and command["time"] in stamps, command
    assert all(command["time"] < 10**15 for command in commands), "a command on the wall clock"
    assert any(command["mode"] == "chase" for command in commands), "the detector saw no ball"


def test_bad_config_exits_2_recording_and_sigterm_exits_0(router, session, log_dir, start_simulator):
    bad = start_service("simulator", router.endpoint, log_dir, "--set", "pacing=warp")
    assert bad.popen.wait(30) == 2
    assert "pacing" in bad.output()
    frames = Collector(session, "camera/image_raw", "Image")
    video, truth_log = log_dir / "run.avi", log_dir / "truth.jsonl"
    simulator = start_simulator(*SMALL, "pacing=fast", f"video_path={video}",
                                f"ground_truth_path={truth_log}")
    frames.wait_count(5, 20)
    assert simulator.stop() == 0, simulator.output()
    records = [json.loads(line) for line in truth_log.read_text().splitlines()]
    assert len(records) >= 5 and [record["seq"] for record in records[:5]] == [1, 2, 3, 4, 5]
    assert video.stat().st_size > 1000


def test_a_real_time_factor_changed_live_applies_to_the_frame_wait_under_way(session, start_simulator):
    # (at 1 frame per simulated second and real_time_factor 0.01 the second frame is due 100 s
    # after the first; the wait used to run that out whatever the factor became)
    truths = Collector(session, "sim/ground_truth", "GroundTruth")
    start_simulator(*SMALL, "rate_hz=1", "timestep=0.01", "publish_images=false", "pacing=realtime",
                    "real_time_factor=0.01")
    first = newest(truths)
    reply = query_config(session, "simulator", {"real_time_factor": 1.0})
    assert reply["ok"], reply
    # (the wait reads the factor again within TIMER_SLICE_S, then the frames come 1 s apart)
    wait_seq(truths, first["header"]["seq"] + 2, timeout=15)
