"""``balltrack view`` (Rerun) while a small system runs, seen by a real browser: headless
Chromium opens the viewer's web page and the screenshots, taken over the DevTools protocol until
the page shows the system's data, must not be blank and must show the ball's yellow-green."""

import re
import sys

import cv2
import numpy as np
import pytest

pytest.importorskip("rerun")
websockets = pytest.importorskip("websockets")

from balltrack.common.network import free_port  # noqa: E402
from balltrack.common.waiting import poll_until  # noqa: E402
from balltrack.deploy.launcher import start_system  # noqa: E402
from balltrack.experiments.browser import CHROMIUM, Chromium  # noqa: E402
from tests.harness import REPO, Process  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

DEMO_CONFIG = REPO / "deploy" / "config" / "demo"
SERVICES = ("simulator", "detector", "locator", "follower")
# 5 frames a second: the system, the viewer and a browser rendering in software share 2 cores.
# (At 10, on 2026-11-26's machine, half as fast as usual, the browser twice stopped answering
# screenshots for the whole 180 s in the full suite, while the viewer's sender waited on it.)
SETTINGS = {"simulator": ["width=320", "height=240", "pacing=realtime", "rate_hz=5"],
            "follower": ["use_sim_time=true"]}
# A screenshot counts as the system's picture once this many pixels are the ball's colour: the
# annotated frame's ball and the 3D view's true ball (the plots' colours and the viewer's own
# have none). At 320x240 the demo's ball, 2 m away, is about 50 px in the frame, more shown large.
BALL_PIXELS = 40
# Seconds between screenshots: the condition is the picture, this only spares the shared CPU.
SCREENSHOT_INTERVAL = 3.0


def ball_coloured_pixels(image: np.ndarray) -> int:
    """Pixels of a tennis ball's yellow-green: OpenCV hue 25-50 (of 180), saturated and bright."""
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    return int(np.count_nonzero((hsv[..., 0] >= 25) & (hsv[..., 0] <= 50)
                                & (hsv[..., 1] > 100) & (hsv[..., 2] > 100)))


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (deploy/setup.sh installs it)")
def test_the_rerun_page_shows_the_running_system(tmp_path):
    web_port, grpc_port = free_port(), free_port()
    with start_system(tmp_path / "run", SERVICES, SETTINGS, config_dir=DEMO_CONFIG, output=None) as system:
        viewer = Process([sys.executable, "-m", "balltrack", "view", "--port", str(web_port),
                          "--grpc-port", str(grpc_port), "--connect", system.endpoint], tmp_path / "viewer.log")
        try:
            viewer.wait_for_output("Rerun viewer on http://", 60)
            profile = tmp_path / "chromium"
            profile.mkdir()
            browser = Chromium(profile, tmp_path / "chromium.log")
            try:
                # (the address the command prints, as a user opens it)
                url = re.search(r"Rerun viewer on (\S+)", viewer.output()).group(1)
                assert url == f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"
                browser.open(url)
                shots = []

                def ball_shown() -> bool:
                    # (None: the page still loading, or too busy to answer: a failed try)
                    shot = browser.screenshot()
                    if shot is not None:
                        shots.append(shot)
                    return shot is not None and ball_coloured_pixels(shot) >= BALL_PIXELS

                poll_until(ball_shown, 300, interval=SCREENSHOT_INTERVAL)
                assert shots, "the page gave no screenshot in 300 s"
                image = shots[-1]
            finally:
                browser.stop()
        finally:
            assert viewer.stop() == 0, viewer.output()
        assert system.stop() == 0
    cv2.imwrite(str(tmp_path / "viewer.png"), image)
    assert image.shape[:2] == (800, 1280)
    assert float(image.std()) > 10, "the page is blank"
    assert ball_coloured_pixels(image) >= BALL_PIXELS, f"no ball in the viewer (see {tmp_path / 'viewer.png'})"
    assert " 0 malformed" in viewer.output(), viewer.output()
