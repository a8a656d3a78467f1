"""experiments.fleet without Zenoh: what a robot count's window measures from the messages as
they arrive (each robot's frames matched to its own positions by seq, drops from its detector's
stats, the real-time factor from robot 1's clock, the referees), and ``max_robots``."""

import numpy as np
import pytest

from balltrack.common.messages import encode, header
from balltrack.experiments import cli
from balltrack.experiments.base import ExperimentResult
from balltrack.experiments.fleet import FleetObserver, failed_row, in_real_time, max_robots, report, window_figures


def frame(seq: int) -> bytes:
    return encode("Image", {"header": header(seq * 66_666_667, seq), "height": 2, "width": 2,
                            "encoding": "bgr8", "step": 6, "data": np.zeros(12, np.uint8).tobytes()})


def position(seq: int) -> bytes:
    return encode("Ball3D", {"header": header(seq * 66_666_667, seq), "x": 0.0, "y": 0.0, "z": 1.0,
                             "distance": 1.0})


def stats(received: int, dropped: int) -> bytes:
    return encode("Stats", {"service": "detector", "stamp": 1, "received": received, "published": received,
                            "rejected": 0, "dropped": dropped, "p50_ms": 1.0, "p99_ms": 2.0})


def truth(seconds: float, robot_x: float, ball: str) -> bytes:
    return encode("GroundTruth", {"header": header(int(seconds * 1e9), 0),
                                  "robot": {"x": robot_x, "y": 0.0, "yaw": 0.0},
                                  "balls": [{"id": ball, "radius": 0.033, "position": [1.2, 0.0, 0.033],
                                             "in_camera": [0.0, 0.0, 1.0], "visible": True}]})


def test_each_robot_s_frames_are_matched_to_its_own_positions_and_drops_come_from_its_detector():
    observer = FleetObserver(2)
    observer.take_sample("robot1/detector/stats", stats(100, 0), 0.0)
    observer.take_sample("robot2/detector/stats", stats(100, 10), 0.0)
    assert not observer.located()
    before = observer.window_start()
    observer.take_sample("robot1/clock", encode("Clock", {"stamp": 0}), 10.0)
    for seq in range(10):
        arrival = 10.0 + seq / 15
        observer.take_sample("robot1/camera/image_raw", frame(seq), arrival)
        observer.take_sample("robot2/camera/image_raw", frame(seq), arrival + 0.001)
        observer.take_sample("robot1/detected_ball_3d", position(seq), arrival + 0.004)
        if seq % 2 == 0:  # robot 2 locates every other frame, 20 ms after its own frame
            observer.take_sample("robot2/detected_ball_3d", position(seq), arrival + 0.021)
    observer.take_sample("robot3/detected_ball_3d", position(1), 11.0)  # no such robot: counted, not matched
    observer.take_sample("robot1/clock", encode("Clock", {"stamp": 1_900_000_000}), 12.0)
    observer.take_sample("robot1/detector/stats", stats(110, 0), 12.0)
    observer.take_sample("robot2/detector/stats", stats(120, 12), 12.0)
    assert observer.located()
    row = observer.window_end(before, 2.0)
    assert row["robots"]["robot1"]["p50_ms"] == pytest.approx(4.0)
    assert row["robots"]["robot2"]["p99_ms"] == pytest.approx(20.0)
    assert row["robots"]["robot2"]["positions"] == 5
    assert row["robots"]["robot1"]["frames_per_s"] == pytest.approx(5.0)
    assert row["worst_p99_ms"] == pytest.approx(20.0)
    assert row["robots"]["robot1"]["dropped_share"] == 0.0
    assert row["robots"]["robot2"]["dropped_share"] == pytest.approx(0.1)
    assert row["dropped_share"] == pytest.approx(2 / 30)
    assert row["real_time_factor"] == pytest.approx(0.95)
    assert row["messages_per_s"] == pytest.approx(40 / 2)
    # The next window starts empty.
    assert observer.window_end(observer.window_start(), 1.0)["robots"]["robot1"]["positions"] == 0


def test_a_malformed_message_is_skipped_and_each_robot_is_judged_on_its_own_ball():
    observer = FleetObserver(2)
    observer.take_sample("robot1/detected_ball_3d", b"\x00not msgpack", 0.0)
    for step in range(20):  # robot 1 stands within reach of its own ball for 2 simulated seconds
        observer.take_sample("robot1/sim/ground_truth", truth(step / 10, 1.0, "tennis1"), step / 10)
        observer.take_sample("robot2/sim/ground_truth", truth(step / 10, 1.0, "tennis1"), step / 10)
    with observer.lock:
        assert observer.robots["robot1"].referee.reached
        assert not observer.robots["robot2"].referee.reached  # tennis1 is not robot 2's ball
    assert not observer.reached()


def row(real_time_factor=1.0, dropped_share=0.0, worst_p99_ms=20.0) -> dict:
    return {"real_time_factor": real_time_factor, "dropped_share": dropped_share, "worst_p99_ms": worst_p99_ms}


def test_max_robots_is_the_largest_count_that_met_every_criterion():
    assert in_real_time(row(0.95, 0.0099, 50.0))
    for failing in (row(real_time_factor=0.94), row(dropped_share=0.01), row(worst_p99_ms=50.1),
                    row(real_time_factor=None), row(dropped_share=None), row(worst_p99_ms=None)):
        assert not in_real_time(failing)
    assert max_robots({1: row(), 2: row(), 4: row(), 8: row(worst_p99_ms=80.0), 16: row(0.6)}) == 4
    # (the largest that met them, even past one that did not: a noisy count is not the limit)
    assert max_robots({1: row(), 2: row(dropped_share=0.02), 4: row()}) == 4
    assert max_robots({1: row(0.5), 2: row(0.4)}) == 0
    assert max_robots({}) == 0


def test_the_fleet_experiment_is_registered():
    options = cli.parse(["fleet", "--quick", "--out", "/tmp/unused-fleet-out"])
    assert options.name == "fleet" and options.quick
    assert "fleet" in cli.EXPERIMENTS


def test_a_robot_count_that_failed_is_reported_as_not_in_real_time(tmp_path):
    measured = window_figures({"robot1": {"lags": [0.004] * 20, "frames": 30, "stats_before": None,
                                          "stats_after": {"dropped": 0, "received": 30}}},
                              messages=260, clock=[(0.0, 0), (2.0, 2_000_000_000)], seconds=2.0)
    # (a served row: the window's figures over a failed row's, for the process figures not made here)
    served = {**failed_row(1, ""), **measured, "cpu_per_robot_second": 0.1, "reached": 1}
    del served["error"]
    result = ExperimentResult("fleet", "test")
    report(result, {1: served, 2: failed_row(2, "not every robot located in 120 s")}, 8.0, tmp_path)
    assert result.figures["fleet/max_robots"] == 1
    assert result.figures["fleet/robots_2/real_time_factor"] is None
    assert result.figures["fleet/robots_1/robot1/p99_ms"] == pytest.approx(4.0)
    assert "no: not every robot located in 120 s" in result.tables[0]
    assert {goal.name: goal.passed for goal in result.goals} == {"fleet/max_robots": False, "fleet/reached": True}
    assert (tmp_path / "fleet.png").stat().st_size > 1000
