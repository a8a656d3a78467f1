"""The demo with a secure profile: TLS, passwords and access control, and the robot still
reaches the ball (the demo's own referee decides; exit 0)."""

import subprocess
import sys

import pytest

from balltrack.deploy.secure import init_profile
from tests.harness import REPO, process_environment


@pytest.mark.slow
def test_the_secure_demo_reaches_the_ball(tmp_path):
    profile = tmp_path / "profile"
    init_profile(profile, ["testhost"])
    result = subprocess.run([sys.executable, "-m", "balltrack.deploy.demo", "--secure", str(profile),
                             "--time-limit", "60", "--port", "0", "--no-video", "--run-dir", str(tmp_path / "run")],
                            cwd=REPO, env=process_environment(), capture_output=True, text=True, timeout=280)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "REACHED the ball" in result.stdout
    assert "router on tls/127.0.0.1:" in result.stdout
