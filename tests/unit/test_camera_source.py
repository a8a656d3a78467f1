"""The camera's source core: what ``source`` names, pacing, and a live source that goes away.

A device cannot be unplugged here, so the reconnect test drives FrameFeed with a capture whose
frames come from a script (it stands for cv2.VideoCapture of a device that vanishes and comes
back); everything else runs on real files.
"""

import logging
import threading

import cv2
import numpy as np
import pytest

from balltrack.common.clock import TIMER_SLICE_S
from balltrack.services.camera.config import CameraConfig
from balltrack.services.camera.source import Capture, FrameFeed, ImageFiles, Pacer, SourceError, SourceSpec, parse_source


def test_source_kinds(tmp_path):
    assert parse_source("0") == SourceSpec("device", 0)
    assert parse_source(" 2 ") == SourceSpec("device", 2)
    assert parse_source("rtsp://127.0.0.1:8554/cam").kind == "stream"
    assert parse_source("http://127.0.0.1/video.mjpg").live
    # A video file a server hands out plays at its own rate and ends, as a local one does.
    for url in ("http://127.0.0.1:8000/clips/run.MP4?token=1", "https://h/a.webm", "file:///tmp/a.avi"):
        assert parse_source(url) == SourceSpec("video", url)
    assert parse_source("http://127.0.0.1/live/index.m3u8").live
    for name in ("b.png", "a.jpg", "c.txt"):
        (tmp_path / name).write_bytes(b"x")
    assert parse_source(str(tmp_path)).paths == (str(tmp_path / "a.jpg"), str(tmp_path / "b.png"))
    assert parse_source(str(tmp_path / "*.png")).paths == (str(tmp_path / "b.png"),)
    assert parse_source(str(tmp_path / "a.jpg")).kind == "images"
    (tmp_path / "clip.mp4").write_bytes(b"x")
    assert parse_source(str(tmp_path / "clip.mp4")) == SourceSpec("video", str(tmp_path / "clip.mp4"))
    for bad, reason in ((str(tmp_path / "none.mp4"), "no such file"), (str(tmp_path / "*.gif"), "no file matches"),
                        ("/dev/video77", "no such device")):
        with pytest.raises(SourceError, match=reason):
            parse_source(bad)
    (tmp_path / "empty").mkdir()
    with pytest.raises(SourceError, match="no images"):
        parse_source(str(tmp_path / "empty"))


def test_pacer_books_due_times_without_bursts():
    pacer = Pacer()
    assert pacer.delay(10.0, 100.0) == 0.0
    assert pacer.delay(10.0, 100.02) == pytest.approx(0.08)
    assert pacer.delay(10.0, 100.5) == 0.0        # fell behind: no burst to catch up
    assert pacer.delay(10.0, 100.5) == pytest.approx(0.1)
    assert pacer.delay(None, 101.0) == 0.0
    live = Pacer()
    sent = [live.due(10.0, 0.0 + index / 30) for index in range(30)]  # a 30 Hz device at 10 Hz
    assert sum(sent) == 10


class ScriptedDevice:
    """A capture that yields ``frames`` frames then fails, as a device that is unplugged."""

    def __init__(self, opens: list):
        self.opens = opens  # per open(): None = cannot open, else how many frames it gives

    def __call__(self, target):
        script = self.opens.pop(0) if self.opens else None
        return _Capture(script)


class _Capture:
    def __init__(self, frames):
        self.frames = frames

    def isOpened(self):
        return self.frames is not None

    def read(self):
        if not self.frames:
            return False, None
        self.frames -= 1
        return True, np.zeros((4, 4, 3), np.uint8)

    def set(self, *args):
        return True

    def get(self, prop):
        return 30.0

    def release(self):
        pass


def test_a_device_that_disappears_is_reopened_with_backoff_and_counted():
    # Opened with 3 frames; lost; the first retry fails; the second brings 2 more frames; lost
    # again, and the test stops it while it retries.
    device = ScriptedDevice([3, None, 2])
    stop = threading.Event()
    capture = Capture(SourceSpec("device", 5), opener=device)
    feed = FrameFeed(SourceSpec("device", 5), capture, lambda: CameraConfig(), stop)
    frames = []
    for image in feed:
        frames.append(image)
        if len(frames) == 5:
            threading.Timer(0.2, stop.set).start()
    assert len(frames) == 5
    assert feed.disconnects == 2 and feed.reconnects == 1
    assert not feed.ended  # stopped, not the end of a file
    assert feed.stats()["reconnects"] == 1


def test_a_device_that_cannot_be_opened_is_an_error():
    with pytest.raises(SourceError, match="cannot open device 5"):
        Capture(SourceSpec("device", 5), opener=ScriptedDevice([None]))
    with pytest.raises(SourceError, match="cannot open device 5"):
        Capture(SourceSpec("device", 5), opener=ScriptedDevice([0]))  # opens, but no frame


def test_video_file_rate_loop_and_end(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48))
    for index in range(4):
        writer.write(np.full((48, 64, 3), 50 * index, np.uint8))
    writer.release()
    spec = parse_source(str(path))
    settings = {"config": CameraConfig(source=str(path), rate_hz=1000.0)}
    feed = FrameFeed(spec, Capture(spec), lambda: settings["config"], threading.Event())
    assert feed.rate() == 1000.0
    settings["config"] = CameraConfig(source=str(path), rate_hz=0.0)
    assert feed.rate() == pytest.approx(25.0)  # the file's own
    settings["config"] = CameraConfig(source=str(path), rate_hz=1000.0, loop=True)
    levels = []
    for image in feed:
        levels.append(int(round(image.mean() / 50)))
        if len(levels) == 6:
            settings["config"] = CameraConfig(source=str(path), rate_hz=1000.0, loop=False)
    assert levels == [0, 1, 2, 3, 0, 1, 2, 3]
    assert feed.ended and feed.rewinds == 1


def test_photos_without_one_readable_file_end_even_with_loop(tmp_path):
    (tmp_path / "a.png").write_bytes(b"broken")
    spec = parse_source(str(tmp_path))
    feed = FrameFeed(spec, ImageFiles(spec.paths), lambda: CameraConfig(source="x", loop=True), threading.Event())
    assert list(feed) == [] and feed.ended
    assert feed.stats()["unreadable_files"] == 1


class SimulatedTime:
    """A clock and a stop event in one: waiting moves the clock on by the time waited."""

    def __init__(self):
        self.now = 0.0

    def clock(self) -> float:
        return self.now

    def is_set(self) -> bool:
        return False

    def wait(self, seconds: float) -> bool:
        self.now += seconds
        return False


def test_looped_photos_keep_to_rate_hz_across_each_new_pass(tmp_path):
    for index in range(2):
        cv2.imwrite(str(tmp_path / f"{index}.png"), np.full((24, 32, 3), 100 * index, np.uint8))
    spec = parse_source(str(tmp_path))
    time_source = SimulatedTime()
    feed = FrameFeed(spec, ImageFiles(spec.paths), lambda: CameraConfig(source="x", loop=True, rate_hz=10.0),
                     time_source, clock=time_source.clock)
    shown = []
    for image in feed:
        shown.append((round(time_source.now, 6), int(image.mean())))
        if len(shown) == 6:
            break
    # (one frame per 0.1 s, the passes back to back: a rewind used to cost a slot of its own)
    assert shown == [(0.0, 0), (0.1, 100), (0.2, 0), (0.3, 100), (0.4, 0), (0.5, 100)]
    assert feed.rewinds == 2


def test_a_rate_changed_live_ends_the_wait_for_the_old_rate_s_next_frame(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.full((24, 32, 3), 100, np.uint8))
    spec = parse_source(str(tmp_path))
    settings = {"config": CameraConfig(source="x", loop=True, rate_hz=0.01)}

    class ChangeAtOneSecond(SimulatedTime):
        def wait(self, seconds: float) -> bool:
            self.now += seconds
            if self.now >= 1.0:  # (1 s into the wait for a frame due 100 s on)
                settings["config"] = CameraConfig(source="x", loop=True, rate_hz=10.0)
            return False

    time_source = ChangeAtOneSecond()
    feed = FrameFeed(spec, ImageFiles(spec.paths), lambda: settings["config"], time_source,
                     clock=time_source.clock)
    shown = []
    for _image in feed:
        shown.append(time_source.now)
        if len(shown) == 3:
            break
    # (the wait reads the rate every TIMER_SLICE_S: the frame after the change comes by then)
    assert shown[0] == 0.0 and 1.0 <= shown[1] <= 1.0 + TIMER_SLICE_S
    assert shown[2] == pytest.approx(shown[1] + 0.1)


def test_an_unreadable_photo_is_counted_once_across_passes_and_no_more_once_written(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.full((8, 8, 3), 50, np.uint8))
    (tmp_path / "b.png").write_bytes(b"still being written")
    spec = parse_source(str(tmp_path))
    reader = ImageFiles(spec.paths)
    for _ in range(3):  # three passes, as loop makes
        assert reader.read() is not None and reader.read() is None
        reader.rewind()
    assert reader.unreadable == 1 and reader.last_unreadable.startswith(str(tmp_path / "b.png"))
    cv2.imwrite(str(tmp_path / "b.png"), np.full((8, 8, 3), 90, np.uint8))
    assert reader.read() is not None and reader.read() is not None
    assert reader.unreadable == 0


def test_a_video_damaged_midway_is_warned_of_at_its_end_and_a_whole_one_is_not(tmp_path, caplog):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48))
    for index in range(20):
        noise = np.random.default_rng(index).integers(0, 255, (48, 64, 3), dtype=np.uint8)
        writer.write(noise)  # (noise: frames of similar, incompressible size)
    writer.release()
    whole = path.read_bytes()
    damaged = tmp_path / "damaged.avi"
    middle = len(whole) // 3
    damaged.write_bytes(whole[:middle] + bytes(len(whole) - middle))
    logger = logging.getLogger("camera-test")
    for video, warned in ((path, False), (damaged, True)):
        caplog.clear()
        spec = parse_source(str(video))
        feed = FrameFeed(spec, Capture(spec), lambda: CameraConfig(source=str(video), rate_hz=1000.0),
                         threading.Event(), logger)
        frames = len(list(feed))
        assert feed.ended and (frames < 20) == warned, frames
        messages = [record.getMessage() for record in caplog.records if record.levelno == logging.WARNING]
        assert bool(messages) == warned, messages
        if warned:
            assert messages == [f"video {damaged}: {frames} of the 20 frames its container states could "
                                "be read; the rest is damaged or missing"]
