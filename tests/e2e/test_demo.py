"""The demo as the README's first command runs it: router, simulator, the detector, locator and
follower in one process, the recorder; the robot reaches the ball."""

import json
import subprocess
import sys

import pytest

from balltrack.common.network import free_port
from tests.harness import REPO, process_environment

pytestmark = pytest.mark.slow


def test_demo_reaches_the_ball_and_writes_its_outputs(tmp_path):
    run_dir = tmp_path / "demo"
    # A generous limit: the chase takes ~18 s of simulated time, slower on a busy machine.
    result = subprocess.run([sys.executable, "-m", "balltrack.deploy.demo", "--run-dir", str(run_dir),
                             "--port", str(free_port()), "--time-limit", "150"],
                            cwd=REPO, env=process_environment(), capture_output=True, text=True,
                            timeout=280)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "REACHED the ball" in result.stdout
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["reached"] and summary["final_distance_m"] <= 0.35
    assert abs(summary["final_heading_error_deg"]) <= 10
    assert summary["supervisor_exit"] == 0, (run_dir / "supervisor.log").read_text()
    for key in ("camera/image_raw", "detected_ball", "detected_ball_3d", "cmd_vel", "image_out",
                "sim/ground_truth"):
        assert summary["messages"][key] > 0, key
    for name in ("detected_ball", "detected_ball_3d", "cmd_vel"):
        latency = summary["latency_ms"][name]
        assert latency["count"] > 0 and 0 < latency["p50_ms"] <= latency["p99_ms"], (name, latency)
    # (the 3D position is derived from the detection: it cannot arrive first)
    assert summary["latency_ms"]["detected_ball"]["p50_ms"] < summary["latency_ms"]["detected_ball_3d"]["p50_ms"]
    for name in ("video.mp4", "trajectory.png", "velocity.png", "frame.png", "overview.png"):
        assert (run_dir / name).stat().st_size > 1000, name
    assert not list(run_dir.glob("*.pid"))
    # The three pipeline services ran in one process, each still counted as itself.
    assert (run_dir / "detector+locator+follower.log").is_file()
    for name in ("detector", "locator", "follower", "simulator"):
        assert summary["service_stats"][name]["received"] > 0, name
    # run.mcap, written by the demo's recorder process: complete, with the chase in it.
    info = subprocess.run([sys.executable, "-m", "balltrack", "info", str(run_dir / "run.mcap"), "--json"],
                          cwd=REPO, env=process_environment(), capture_output=True, text=True, timeout=60)
    assert info.returncode == 0, info.stderr
    recorded = json.loads(info.stdout)
    counts = {entry["key"]: entry["count"] for entry in recorded["keys"]}
    assert recorded["complete"] and summary["files"]["recording"] == str(run_dir / "run.mcap")
    for key in ("camera/image_raw", "detected_ball_3d", "cmd_vel"):  # it started before the chase
        assert counts.get(key, 0) >= 0.9 * summary["messages"][key], (key, counts, summary["messages"])
    assert counts["/camera/image"] == counts["camera/image_raw"]  # each frame also for Foxglove
