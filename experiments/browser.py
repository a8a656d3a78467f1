"""Headless Chromium driven over the DevTools protocol, to see a web page as a user would: the
Rerun viewer's page in ``tests/e2e/test_view_rerun.py`` and the ``live_view`` experiment.

Example::

    browser = Chromium(profile_folder, log_path)
    try:
        browser.open("http://127.0.0.1:9090/?url=...")
        picture = browser.screenshot()  # BGR pixels, or None when the page did not answer
        browser.screencast(lambda picture, received_at: ...)  # each frame the page draws
    finally:
        browser.stop()

Needs ``chromium`` (deploy/setup.sh installs it) and ``websockets`` (the test extra).
"""

import base64
import contextlib
import itertools
import json
import shutil
import subprocess
import threading
import time
import urllib.request
from pathlib import Path

import cv2
import numpy as np

from balltrack.common.waiting import poll_until

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# Seconds a DevTools call may take before it counts as a failed try: a page busy rendering in
# software can take long to paint, and a late answer must not hang the caller.
CALL_WAIT = 60.0
# How the page draws on a machine without a GPU, both in software on the CPU: with Chromium's own
# SwiftShader, what it picks by itself there; or its WebGL with Mesa's llvmpipe (the OpenGL that
# MuJoCo renders with here) through ANGLE, which Chromium uses only when told to ignore its list
# of blocked drivers, the page composited in software as with SwiftShader (composited with
# llvmpipe too, a frame reaches a screencast only after a delay of its own).
RENDERERS = {
    "swiftshader": ["--disable-gpu", "--enable-unsafe-swiftshader"],
    "mesa": ["--use-gl=angle", "--use-angle=gl-egl", "--ignore-gpu-blocklist", "--disable-gpu-compositing"],
}
# What the page's WebGL runs on, as the page itself reads it.
WEBGL_RENDERER_SCRIPT = """(() => {
    const context = document.createElement("canvas").getContext("webgl2");
    if (!context) return "no WebGL2";
    const names = context.getExtension("WEBGL_debug_renderer_info");
    return context.getParameter(names ? names.UNMASKED_RENDERER_WEBGL : context.RENDERER);
})()"""


class Chromium:
    """Headless Chromium of ``width`` x ``height`` CSS pixels drawing in software with
    ``renderer`` (one of RENDERERS: the machines it runs on may have no GPU); its DevTools port
    read from the profile's DevToolsActivePort file, so no port is fixed."""

    def __init__(self, profile: Path, log_path: Path, width: int = 1280, height: int = 800,
                 renderer: str = "swiftshader"):
        from websockets.sync.client import connect

        if CHROMIUM is None:
            raise RuntimeError("chromium is not installed (deploy/setup.sh installs it)")
        if renderer not in RENDERERS:
            raise ValueError(f"renderer {renderer!r}: one of {', '.join(RENDERERS)}")
        self.width, self.height, self.renderer = width, height, renderer
        self._closing = contextlib.ExitStack()  # the DevTools connection, once open
        self._log = open(log_path, "wb")
        self.popen = subprocess.Popen(
            [CHROMIUM, "--headless", "--no-sandbox", *RENDERERS[renderer],
             "--disable-quic", "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
             f"--window-size={width},{height}", "--remote-debugging-port=0", "about:blank"],
            stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        port_file = Path(profile) / "DevToolsActivePort"
        # Replies by request id; requests whose caller gave up (their late replies are dropped).
        self._requests = itertools.count(1)
        self._replies: dict[int, dict] = {}
        self._abandoned: set[int] = set()
        self._answered = threading.Condition()
        self._on_frame = None  # the screencast's receiver, while one runs

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
        # One reader: replies wake their caller, screencast frames go to their receiver.
        self._reader = threading.Thread(target=self._read, name="devtools-reader", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            for text in self._connection:
                message = json.loads(text)
                if "id" in message:
                    with self._answered:
                        if message["id"] in self._abandoned:
                            self._abandoned.discard(message["id"])
                        else:
                            self._replies[message["id"]] = message
                            self._answered.notify_all()
                elif message.get("method") == "Page.screencastFrame":
                    self._frame_came(message["params"])
        except ConnectionClosed:
            pass

    def _send(self, method: str, params: dict, answer_wanted: bool = True) -> int:
        request = next(self._requests)
        if not answer_wanted:
            with self._answered:
                self._abandoned.add(request)
        self._connection.send(json.dumps({"id": request, "method": method, "params": params}))
        return request

    def call(self, method: str, **params) -> dict:
        """One DevTools call's reply: ``{"result": ...}``, or ``{"error": ...}`` (also when no
        answer came in CALL_WAIT seconds)."""
        request = self._send(method, params)
        with self._answered:
            if self._answered.wait_for(lambda: request in self._replies, CALL_WAIT):
                return self._replies.pop(request)
            self._abandoned.add(request)
        return {"error": f"{method}: no answer in {CALL_WAIT:g} s"}

    def evaluate(self, expression: str):
        """The value of a JavaScript ``expression`` in the page (None when it gave none)."""
        reply = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        return reply.get("result", {}).get("result", {}).get("value")

    def webgl_renderer(self) -> str | None:
        """What the page's WebGL draws with (e.g. SwiftShader's or llvmpipe's name)."""
        return self.evaluate(WEBGL_RENDERER_SCRIPT)

    def screencast(self, on_frame, max_width: int = 320, quality: int = 60) -> None:
        """Call ``on_frame(picture, received_at)`` with each frame the page draws from now on
        (BGR, shrunk to ``max_width``; ``received_at`` on ``time.monotonic()``), until
        :meth:`stop_screencast`. Each frame is acknowledged once received, which lets the
        browser send the next. A frame comes a little after it was drawn (its copy, shrinking and
        JPEG). The time the browser gives a frame is not used: it is when drawing it began,
        earlier by as long as the page takes to draw one, long for a page drawn in software."""
        self._on_frame = on_frame
        replies = []

        def started() -> bool:  # (refused while a page just navigated to is not yet the active one)
            replies.append(self.call("Page.startScreencast", format="jpeg", quality=quality, maxWidth=max_width,
                                     maxHeight=max_width * self.height // self.width, everyNthFrame=1))
            return "result" in replies[-1]

        if not poll_until(started, CALL_WAIT, interval=0.2):
            raise RuntimeError(f"Page.startScreencast: {replies[-1].get('error')}")

    def _frame_came(self, params: dict) -> None:
        received = time.monotonic()
        self._send("Page.screencastFrameAck", {"sessionId": params["sessionId"]}, answer_wanted=False)
        on_frame = self._on_frame
        if on_frame is None:
            return
        picture = cv2.imdecode(np.frombuffer(base64.b64decode(params["data"]), np.uint8), cv2.IMREAD_COLOR)
        if picture is not None:
            on_frame(picture, received)

    def stop_screencast(self) -> None:
        self._on_frame = None
        self.call("Page.stopScreencast")

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
        self._on_frame = None
        self._closing.close()
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(15)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        self._log.close()
