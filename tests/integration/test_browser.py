"""experiments/browser.py with a real headless Chromium: each renderer draws WebGL in software
on the renderer it names, and the screencast hands over the page's frames as they are drawn,
each with the moment it came on this process's monotonic clock (what live_view times)."""

import threading
import time
import urllib.parse

import numpy as np
import pytest

pytest.importorskip("websockets")

from balltrack.experiments.browser import CHROMIUM, RENDERERS, Chromium  # noqa: E402

pytestmark = [pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (deploy/setup.sh installs it)"),
              pytest.mark.timeout(300)]

# What each renderer's WebGL reports itself as.
WEBGL_NAMES = {"swiftshader": "SwiftShader", "mesa": "llvmpipe"}
# A page that is black, and turns white once its own timer has run CHANGE_AFTER_MS (saying so in
# its title).
CHANGE_AFTER_MS = 1500
PAGE = ("<html><body style='margin:0;background:#000'><script>"
        f"setTimeout(() => {{ document.body.style.background = '#fff'; document.title = 'white'; }}, {CHANGE_AFTER_MS});"
        "</script></body></html>")


@pytest.mark.parametrize("renderer", sorted(RENDERERS))
def test_the_page_draws_webgl_with_the_renderer_named(tmp_path, renderer):
    browser = Chromium(tmp_path / "profile", tmp_path / "chromium.log", 320, 240, renderer=renderer)
    try:
        assert WEBGL_NAMES[renderer] in (browser.webgl_renderer() or "")
    finally:
        browser.stop()


def test_the_screencast_gives_each_frame_as_it_is_drawn(tmp_path):
    browser = Chromium(tmp_path / "profile", tmp_path / "chromium.log", 320, 240)
    frames: list[tuple[float, float]] = []  # (came at, mean grey)
    white = threading.Event()

    def frame_came(picture: np.ndarray, came_at: float) -> None:
        frames.append((came_at, float(picture.mean())))
        if picture.mean() > 200:
            white.set()

    try:
        opened = time.monotonic()
        browser.open("data:text/html," + urllib.parse.quote(PAGE))
        browser.screencast(frame_came, max_width=160)
        assert white.wait(60), f"no white frame in 60 s; frames: {frames[-5:]}"
        received = time.monotonic()
        browser.stop_screencast()
        assert browser.evaluate("document.title") == "white"
    finally:
        browser.stop()
    first_white = next(came_at for came_at, grey in frames if grey > 200)
    # After the page was opened and its timer ran; no sooner than the event it caused here.
    assert opened + CHANGE_AFTER_MS / 1000 <= first_white <= received
    assert all(grey < 50 for came_at, grey in frames if came_at < first_white)


def test_a_renderer_not_known_is_refused(tmp_path):
    with pytest.raises(ValueError, match="renderer 'opengl': one of swiftshader, mesa"):
        Chromium(tmp_path / "profile", tmp_path / "chromium.log", renderer="opengl")
