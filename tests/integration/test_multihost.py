"""The system spread over three hosts, each a Linux network namespace on one bridged /24.

    host A (10.213.0.1)  router (listening on A's address only), simulator, detector, follower
    host B (10.213.0.2)  locator                 -> connects to A's router over the "LAN"
    host C (10.213.0.3)  examples/subscribe_ball3d.py, and two `balltrack echo` checkers

Frames rendered and detected on A become 3D positions on B, which reach C. The test process
stays in its own namespace (nothing is added to it) and reads everything from the output of the
processes on C: the checkers print every ``detected_ball_3d`` and ``sim/ground_truth`` message
as JSON lines, and the example app prints each position with its frame's ``seq``, so every
position is compared, frame by frame, with where the simulator put the ball.
"""

import json
import math
import re
import sys

import pytest

from tests.harness import REPO, Process, fully_in_view, wait_until
from tests.netns import NetworkNamespaces, netns_available, remove_stale

pytestmark = pytest.mark.netns

EXAMPLE = REPO / "examples" / "subscribe_ball3d.py"
# The chase scenario: one tennis ball 2 m from the camera; the follower drives up to it and
# stops where it looks max_size_thresh = 0.1 of the image wide, ~0.55 m away.
DISTANCE_RANGE = (0.3, 2.3)
MATCHED = 10   # located balls compared with the ground truth
PRINTED = 5    # positions the example app must print (and that have ground truth)
STARTUP = 60.0  # seconds for every process to connect (MuJoCo and OpenCV imports on 2 busy cores)
FLOW = 60.0     # seconds for the positions to come through once everything runs


@pytest.fixture
def network():
    available, reason = netns_available()
    if not available:
        pytest.skip(reason)
    remove_stale()
    with NetworkNamespaces(("a", "b", "c")) as hosts:
        yield hosts


@pytest.fixture
def launch(network, tmp_path):
    """Start ``python ARGS`` on a host; at teardown SIGTERM all (last started first), expect 0."""
    started: list[tuple[str, Process]] = []

    def start(host: str, name: str, arguments: list[str]) -> Process:
        process = Process(network.command(host, [sys.executable, *arguments]),
                          tmp_path / f"{host}-{name}.log")
        started.append((f"{name} on {host}", process))
        return process

    yield start
    failures = []
    for name, process in reversed(started):
        try:
            status = process.stop()
        except AssertionError as error:  # it ignored SIGTERM and was killed
            failures.append(str(error))
            continue
        if status != 0:
            failures.append(f"{name} exited {status}:\n{process.output()[-4000:]}")
    assert not failures, "\n\n".join(failures)


def json_lines(process: Process) -> list[dict]:
    """The JSON lines a `balltrack echo` printed (its log lines are not JSON)."""
    messages = []
    for line in process.output().splitlines():
        if line.startswith("{"):
            try:
                messages.append(json.loads(line)["message"])
            except (ValueError, KeyError):
                pass  # a line still being written
    return messages


def at_least(count: int, collect):
    """A condition for wait_until: the list ``collect()`` returns, once it has ``count`` items."""
    def condition():
        found = collect()
        return found if len(found) >= count else None
    return condition


def true_positions(truths: Process) -> dict[int, dict]:
    """Per frame seq: where the one wholly visible ball was ({in_camera, distance})."""
    found = {}
    for truth in json_lines(truths):
        visible = [ball for ball in truth["balls"]
                   if ball["visible"] and fully_in_view(ball["in_camera"], ball["radius"])]
        if len(visible) == 1:
            in_camera = visible[0]["in_camera"]
            found[truth["header"]["seq"]] = {"in_camera": in_camera,
                                             "distance": math.dist(in_camera, (0, 0, 0))}
    return found


def with_truth(positions: list[dict], truths: Process) -> list[tuple[dict, dict]]:
    """(position, truth) pairs for the positions whose frame the ground truth checker saw."""
    known = true_positions(truths)
    return [(position, known[position["seq"]]) for position in positions
            if position["seq"] in known]


def located_positions(located: Process) -> list[dict]:
    return [{**message, "seq": message["header"]["seq"]} for message in json_lines(located)]


NUMBER = r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?"


def printed_positions(example: Process) -> list[dict]:
    """What the example app printed: ``seq 12  x +0.123  y +0.065  z 1.890  distance 1.895 m``."""
    positions = []
    for line in example.output().splitlines():
        figures = dict(re.findall(rf"\b(seq|x|y|z|distance)\s*[=:]?\s*({NUMBER})", line))
        if {"seq", "x", "y", "z", "distance"} <= set(figures):
            positions.append({name: int(value) if name == "seq" else float(value)
                              for name, value in figures.items()})
    return positions


def test_detections_on_a_located_on_b_printed_on_c(network, launch):
    port = network.free_port("a")
    endpoint = f"tcp/{network.address('a')}:{port}"
    connect = ["--connect", endpoint]

    router = launch("a", "router", ["-m", "balltrack", "router", "--listen", endpoint])
    router.wait_for_output("listening on", STARTUP)
    echo = ["-m", "balltrack", "echo", *connect, "--timeout", str(STARTUP)]
    truths = launch("c", "ground-truth", [*echo, "sim/ground_truth"])
    located = launch("c", "located", [*echo, "detected_ball_3d"])
    example = launch("c", "example", [str(EXAMPLE), *connect])
    services = {"locator": launch("b", "locator", ["-m", "balltrack.services.locator", *connect])}
    for name in ("detector", "follower"):
        services[name] = launch("a", name, ["-m", f"balltrack.services.{name}", *connect])
    # 10 frames a second keep the rendering cheap on a shared machine; the chase is the same.
    services["simulator"] = launch("a", "simulator", [
        "-m", "balltrack.services.simulator", *connect, "--set", "scenario=chase",
        "--set", "pacing=realtime", "--set", "rate_hz=10"])
    everything = [router, truths, located, example, *services.values()]
    wait_until(lambda: "listening on" in example.output(), STARTUP, "the example app", *everything)
    for name, process in services.items():
        wait_until(lambda: "INFO running (" in process.output(), STARTUP, f"{name} running",
                   *everything)

    # Positions located on B from detections made on A, seen on C, against the ground truth.
    pairs = wait_until(at_least(MATCHED, lambda: with_truth(located_positions(located), truths)),
                       FLOW, f"{MATCHED} located balls with ground truth", *everything)
    for position, truth in pairs:
        assert position["header"]["frame_id"] == "camera_optical"
        # The stated tolerance: distance within 5%, position within 5% of the distance.
        assert abs(position["distance"] - truth["distance"]) <= 0.05 * truth["distance"], \
            (position, truth)
        assert math.dist((position["x"], position["y"], position["z"]), truth["in_camera"]) <= \
            0.05 * truth["distance"], (position, truth)

    # The example app on C prints those positions, frame by frame, as plausible as they are.
    printed = wait_until(at_least(PRINTED, lambda: with_truth(printed_positions(example), truths)),
                         FLOW, f"{PRINTED} positions printed by the example app", *everything)
    published = {position["seq"]: position for position in located_positions(located)}
    low, high = DISTANCE_RANGE
    for position, truth in printed:
        assert low <= position["distance"] <= high, position
        assert abs(position["distance"] - truth["distance"]) <= 0.05 * truth["distance"], \
            (position, truth)
        if position["seq"] in published:  # the same figures, rounded to millimetres
            for name in ("x", "y", "z", "distance"):
                assert position[name] == pytest.approx(published[position["seq"]][name],
                                                       abs=0.0006), (name, position)
