"""Headless Chromium driven over the DevTools protocol, to see a web page as a user would: the
Rerun viewer's page in ``tests/e2e/test_view_rerun.py`` and the ``live_view`` experiment.

Example::

    browser = Chromium(profile_folder, log_path)
    try:
        browser.open("http://127.0.0.1:9090/?url=...")
        picture = browser.screenshot()  # BGR pixels, or None when the page did not answer
    finally:
        browser.stop()

Needs ``chromium`` (deploy/setup.sh installs it) and ``websockets`` (the test extra).
"""

import base64
import contextlib
import json
import shutil
import subprocess
import urllib.request
from pathlib import Path

import cv2
import numpy as np

from balltrack.common.waiting import poll_until

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# Seconds a DevTools call may take before it counts as a failed try: a page busy rendering in
# software can take long to paint, and a late answer must not hang the caller.
CALL_WAIT = 60.0


class Chromium:
    """Headless Chromium of ``width`` x ``height`` CSS pixels, WebGL in software (swiftshader:
    the machines it runs on may have no GPU); its DevTools port read from the profile's
    DevToolsActivePort file, so no port is fixed."""

    def __init__(self, profile: Path, log_path: Path, width: int = 1280, height: int = 800):
        from websockets.sync.client import connect

        if CHROMIUM is None:
            raise RuntimeError("chromium is not installed (deploy/setup.sh installs it)")
        self.width, self.height = width, height
        self._closing = contextlib.ExitStack()  # the DevTools connection, once open
        self._log = open(log_path, "wb")
        self.popen = subprocess.Popen(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
             "--disable-quic", "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
             f"--window-size={width},{height}", "--remote-debugging-port=0", "about:blank"],
            stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        port_file = Path(profile) / "DevToolsActivePort"

        def port_written() -> bool:
            if self.popen.poll() is not None:
                raise RuntimeError(f"chromium exited {self.popen.returncode}: {log_path.read_text()[-2000:]}")
            return port_file.exists() and bool(port_file.read_text().strip())

        try:
            if not poll_until(port_written, 60):
                raise RuntimeError("chromium wrote no DevTools port in 60 s")
            port = int(port_file.read_text().split()[0])
            pages = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10))
            page = next(page["webSocketDebuggerUrl"] for page in pages if page["type"] == "page")
            self._connection = self._closing.enter_context(connect(page, max_size=None))
        except Exception:
            self.stop()
            raise
        self._request = 0

    def call(self, method: str, **params) -> dict:
        """One DevTools call's reply: ``{"result": ...}``, or ``{"error": ...}`` (also when no
        answer came in CALL_WAIT seconds)."""
        self._request += 1
        self._connection.send(json.dumps({"id": self._request, "method": method, "params": params}))
        try:
            while True:
                reply = json.loads(self._connection.recv(timeout=CALL_WAIT))
                if reply.get("id") == self._request:
                    return reply
        except TimeoutError:
            return {"error": f"{method}: no answer in {CALL_WAIT:g} s"}

    def open(self, url: str) -> None:
        self.call("Emulation.setDeviceMetricsOverride", width=self.width, height=self.height,
                  deviceScaleFactor=1, mobile=False)
        self.call("Page.navigate", url=url)

    def screenshot(self, clip: tuple[int, int, int, int] | None = None, scale: float = 1.0,
                   image_format: str = "png") -> np.ndarray | None:
        """The page as BGR pixels (``clip``: only x, y, width, height of it, ``scale`` times
        as large); None when the page gave none (still loading, or too busy to answer)."""
        params: dict = {"format": image_format}
        if clip is not None:
            x, y, width, height = clip
            params["clip"] = {"x": x, "y": y, "width": width, "height": height, "scale": scale}
        reply = self.call("Page.captureScreenshot", **params)
        if "result" not in reply:
            return None
        return cv2.imdecode(np.frombuffer(base64.b64decode(reply["result"]["data"]), np.uint8), cv2.IMREAD_COLOR)

    def stop(self) -> None:
        self._closing.close()
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(15)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        self._log.close()
