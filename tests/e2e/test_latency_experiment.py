"""The latency experiment runs the real demo (router, simulator, services) once per follower
mode and reports what the demo measured; this checks the figures are a chase's, not the times."""

import json

import pytest

from balltrack.experiments import cli

pytestmark = pytest.mark.slow


def test_latency_experiment_reports_both_follower_modes(tmp_path):
    assert cli.main(["latency", "--quick", "--out", str(tmp_path), "--no-progress"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    figures = results["figures"]
    for mode in ("event", "timer"):
        assert figures[f"latency/{mode}/runs"] == 1  # (--quick: the goals' mode once too)
        assert figures[f"latency/{mode}/reached"] is True
        assert figures[f"latency/{mode}/detected_ball_3d/count"] > 100
        assert 0 < figures[f"latency/{mode}/detected_ball_3d/p50_ms"] <= figures[f"latency/{mode}/detected_ball_3d/p99_ms"]
        assert (tmp_path / "latency" / mode / "run.mcap").is_file()
        # (the services' own processing time, from their stats: a part of the latency)
        assert 0 < figures[f"latency/{mode}/locator_handler_p50_ms"] < figures[f"latency/{mode}/detected_ball_3d/p50_ms"]
    # Event mode commands on each of the 30 detections a second (and on the 10 Hz timer, the
    # search watchdog); the paper's mode on the timer alone.
    assert figures["latency/event/cmd_vel_per_s"] > 25
    assert figures["latency/timer/cmd_vel_per_s"] < 15
    goals = {goal["name"] for goal in results["goals"]}
    assert goals == {"latency/ball_3d", "latency/cmd_vel"}
