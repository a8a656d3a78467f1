"""``balltrack view`` (Rerun) while a small system runs, seen by a real browser: headless
Chromium opens the viewer's web page and the screenshots, taken over the DevTools protocol until
the page shows the system's data, must not be blank and must show the ball's yellow-green."""

import asyncio
import base64
import json
import re
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("rerun")
websockets = pytest.importorskip("websockets")

from balltrack.common.network import free_port  # noqa: E402
from balltrack.deploy.launcher import start_system  # noqa: E402
from tests.harness import REPO, Process, wait_until  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
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
# Seconds a DevTools call may take before it counts as a failed try (see Chromium.screenshots).
SCREENSHOT_WAIT = 60


def ball_coloured_pixels(image: np.ndarray) -> int:
    """Pixels of a tennis ball's yellow-green: OpenCV hue 25-50 (of 180), saturated and bright."""
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    return int(np.count_nonzero((hsv[..., 0] >= 25) & (hsv[..., 0] <= 50)
                                & (hsv[..., 1] > 100) & (hsv[..., 2] > 100)))


class Chromium:
    """Headless Chromium driven over the DevTools protocol (its port read from the profile's
    DevToolsActivePort file, so no port is fixed)."""

    def __init__(self, profile: Path, log_path: Path):
        self._log = open(log_path, "wb")
        # swiftshader: WebGL in software, as the machine has no GPU (the viewer says so in its bar)
        self.popen = subprocess.Popen(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
             "--disable-quic", "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
             "--window-size=1280,800", "--remote-debugging-port=0", "about:blank"],
            stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        port_file = profile / "DevToolsActivePort"

        def port_written() -> bool:
            if self.popen.poll() is not None:
                raise AssertionError(f"chromium exited {self.popen.returncode}: {log_path.read_text()[-2000:]}")
            return port_file.exists() and bool(port_file.read_text().strip())

        wait_until(port_written, 60, "chromium's DevTools port (its file)")
        port = int(port_file.read_text().split()[0])
        pages = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10))
        self.page = next(page["webSocketDebuggerUrl"] for page in pages if page["type"] == "page")

    async def screenshots(self, url: str, until, timeout: float) -> np.ndarray:
        """Open ``url``, then screenshot until ``until(image)`` or ``timeout``: the last one."""
        async with websockets.connect(self.page, max_size=None) as connection:
            request = 0

            async def call(method: str, **params):
                nonlocal request
                request += 1
                await connection.send(json.dumps({"id": request, "method": method, "params": params}))
                try:
                    # a page busy rendering in software can take long to paint: a late answer is
                    # a failed try (an error reply), not a hang
                    async with asyncio.timeout(SCREENSHOT_WAIT):
                        while True:
                            reply = json.loads(await connection.recv())
                            if reply.get("id") == request:
                                return reply
                except TimeoutError:
                    return {"error": f"{method}: no answer in {SCREENSHOT_WAIT} s"}

            await call("Emulation.setDeviceMetricsOverride", width=1280, height=800, deviceScaleFactor=1,
                       mobile=False)
            await call("Page.navigate", url=url)
            deadline = time.monotonic() + timeout
            while True:
                reply = await call("Page.captureScreenshot", format="png")
                if "result" in reply:  # an error while the page is still loading: try again
                    image = cv2.imdecode(np.frombuffer(base64.b64decode(reply["result"]["data"]), np.uint8),
                                         cv2.IMREAD_COLOR)
                    if until(image):
                        return image
                if time.monotonic() > deadline:
                    if "result" not in reply:
                        raise AssertionError(f"no screenshot: {reply}")
                    return image
                await asyncio.sleep(3.0)  # the next screenshot; the condition is the picture

    def stop(self) -> None:
        self.popen.terminate()
        try:
            self.popen.wait(15)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait()
        self._log.close()


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
                image = asyncio.run(browser.screenshots(
                    url, lambda shot: ball_coloured_pixels(shot) >= BALL_PIXELS, timeout=300))
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
