"""The latency experiment runs the real demo (router, simulator, services) once per follower
mode and reports what the demo measured; this checks the figures are a chase's, not the times."""

import json

from balltrack.experiments import cli


def test_latency_experiment_reports_both_follower_modes(tmp_path):
    assert cli.main(["latency", "--quick", "--out", str(tmp_path), "--no-progress"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    figures = results["figures"]
    for mode in ("event", "timer"):
        assert figures[f"latency/{mode}/reached"] is True
        assert figures[f"latency/{mode}/detected_ball_3d/count"] > 100
        assert 0 < figures[f"latency/{mode}/detected_ball_3d/p50_ms"] <= figures[f"latency/{mode}/detected_ball_3d/p99_ms"]
        assert (tmp_path / "latency" / mode / "run.mcap").is_file()
    # On the timer a command waits for the next 100 ms tick; on each detection it does not.
    assert figures["latency/timer/cmd_vel/p50_ms"] > figures["latency/event/cmd_vel/p50_ms"]
    goals = {goal["name"] for goal in results["goals"]}
    assert goals == {"latency/ball_3d", "latency/cmd_vel"}
