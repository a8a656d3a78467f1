"""Where frames come from, and when: the camera service's core (no Zenoh).

:func:`open_source` turns the ``source`` setting into one of two readers, both through OpenCV:
:class:`ImageFiles` (a folder or glob of photos, decoded in name order by
``common.images.read_image``) or :class:`Capture` (cv2.VideoCapture: a device, a video file or
a stream URL). :class:`FrameFeed` reads one at the configured rate and applies the
end-of-source rules: a file ends (or starts again with ``loop``); a live source (device,
stream) that stops delivering is reopened with backoff, and the failures and reconnections are
counted for the service's stats.
"""

import glob
import math
import os
import threading
import time
import urllib.parse
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import cv2
import numpy as np

from balltrack.common.clock import wait_out
from balltrack.common.images import UnreadableImage, read_image

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm", ".pnm"}
# A URL whose path ends so names a video file that a server hands out whole (played at its frame
# rate, to its end), not a live stream; MJPEG (.mjpg) and HLS (.m3u8, .ts) URLs stay live.
VIDEO_SUFFIXES = {".mp4", ".m4v", ".mov", ".avi", ".mkv", ".webm", ".mpg", ".mpeg", ".wmv", ".flv",
                  ".ogv", ".3gp"}
FILE_SCHEMES = {"http", "https", "ftp", "file"}
# A video whose container does not say its frame rate is played at this rate.
FALLBACK_VIDEO_RATE_HZ = 30.0
# Reopening a lost live source waits this long first, doubling up to the maximum.
RETRY_FIRST_S = 0.5
RETRY_MAX_S = 8.0

# FFmpeg's own log line (``[tcp @ 0x...] Connection ... refused``) would come before our one-line
# error; quiet unless the user asked for FFmpeg's log, and the error says how to.
FFMPEG_QUIET = os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8") == "-8"

try:  # OpenCV's own warnings (a device that is not there) would add lines to our one-line error
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
except AttributeError:
    pass


class SourceError(Exception):
    """A source that cannot be opened; the message is one line naming it."""


@dataclass(frozen=True)
class SourceSpec:
    """What the ``source`` setting names: ``kind`` is device, stream, video or images."""

    kind: str
    target: int | str
    paths: tuple[str, ...] = ()

    @property
    def live(self) -> bool:
        return self.kind in ("device", "stream")


def parse_source(text: str) -> SourceSpec:
    """Classify ``source``; SourceError if it names nothing that exists."""
    text = text.strip()
    if text.isdigit():
        return SourceSpec("device", int(text))
    if "://" in text:
        url = urllib.parse.urlparse(text)
        if url.scheme.lower() in FILE_SCHEMES and Path(url.path).suffix.lower() in VIDEO_SUFFIXES:
            return SourceSpec("video", text)
        return SourceSpec("stream", text)
    if text.startswith("/dev/"):
        if not os.path.exists(text):
            raise SourceError(f"source: no such device {text}")
        return SourceSpec("device", text)
    path = Path(text).expanduser()
    if path.is_dir():
        paths = sorted(str(item) for item in path.iterdir()
                       if item.is_file() and item.suffix.lower() in IMAGE_SUFFIXES)
        if not paths:
            raise SourceError(f"source: no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in folder {text}")
        return SourceSpec("images", str(path), tuple(paths))
    if any(character in text for character in "*?["):
        paths = sorted(item for item in glob.glob(os.path.expanduser(text)) if os.path.isfile(item))
        if not paths:
            raise SourceError(f"source: no file matches {text}")
        return SourceSpec("images", text, tuple(paths))
    if path.is_file():
        if path.suffix.lower() in IMAGE_SUFFIXES:
            return SourceSpec("images", str(path), (str(path),))
        return SourceSpec("video", str(path))
    raise SourceError(f"source: no such file, folder, device or URL: {text}")


class ImageFiles:
    """Photos in name order; an unreadable one is skipped and counted."""

    live = False
    native_rate = None
    stated_frames = None

    def __init__(self, paths: tuple[str, ...]):
        self.paths = paths
        self.position = 0
        # The files that could not be read when last tried: each is counted once however often
        # ``loop`` comes back to it, and one written out since is no longer counted.
        self._unreadable: set[str] = set()
        # "PATH: REASON" of the last file that could not be read (None: none so far)
        self.last_unreadable: str | None = None
        self._pending: np.ndarray | None = None  # read ahead by ``open``

    def open(self) -> bool:
        """Read ahead to the first photo OpenCV reads, kept for the next ``read``; False when
        none does (a folder of files still being written, or of files that are not images)."""
        self._pending = self.read()
        return self._pending is not None

    @property
    def unreadable(self) -> int:
        return len(self._unreadable)

    def read(self) -> np.ndarray | None:
        if self._pending is not None:
            image, self._pending = self._pending, None
            return image
        while self.position < len(self.paths):
            path = self.paths[self.position]
            self.position += 1
            try:
                image = read_image(path)
            except UnreadableImage as error:
                self._unreadable.add(path)
                self.last_unreadable = f"{path}: {error}"
                continue
            self._unreadable.discard(path)
            return image
        return None

    def rewind(self) -> bool:
        self.position, self._pending = 0, None
        return True

    def close(self) -> None:
        pass


class Capture:
    """cv2.VideoCapture of a device, a video file or a stream."""

    def __init__(self, spec: SourceSpec, width: int = 0, height: int = 0,
                 opener: Callable[..., "cv2.VideoCapture"] = cv2.VideoCapture):
        self.spec = spec
        self.live = spec.live
        self.width, self.height = width, height
        self._opener = opener
        self.unreadable = 0
        self._pending: np.ndarray | None = None
        self._capture = None
        self.native_rate: float | None = None
        self.stated_frames: int | None = None  # a video's frame count, as its container states it
        if not self.open():
            hint = (" (OPENCV_FFMPEG_LOGLEVEL=16 shows FFmpeg's reason)"
                    if FFMPEG_QUIET and spec.kind in ("video", "stream") else "")
            raise SourceError(f"source: cannot open {spec.kind} {spec.target}{hint}")

    def open(self) -> bool:
        """(Re)open; True once a first frame was read (kept for the next read)."""
        self.close()
        capture = self._opener(self.spec.target)
        if not capture.isOpened():
            capture.release()
            return False
        if self.spec.kind == "device" and self.width and self.height:
            capture.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
            capture.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)
        # A container or device that opens but yields nothing is as good as not there.
        ok, image = capture.read()
        if not ok or image is None:
            capture.release()
            return False
        rate = capture.get(cv2.CAP_PROP_FPS)
        self.native_rate = rate if math.isfinite(rate) and 0.0 < rate <= 1000.0 else None
        count = capture.get(cv2.CAP_PROP_FRAME_COUNT)
        self.stated_frames = int(count) if math.isfinite(count) and count > 0 else None
        self._capture, self._pending = capture, image
        return True

    def read(self) -> np.ndarray | None:
        if self._pending is not None:
            image, self._pending = self._pending, None
            return image
        if self._capture is None:
            return None
        ok, image = self._capture.read()
        return image if ok and image is not None else None

    def rewind(self) -> bool:
        if self._capture is not None and self._capture.set(cv2.CAP_PROP_POS_FRAMES, 0):
            return True
        return self.open()  # some containers cannot seek: start them again

    def close(self) -> None:
        if self._capture is not None:
            self._capture.release()
            self._capture = None


def open_source(text: str, width: int = 0, height: int = 0) -> tuple[SourceSpec, ImageFiles | Capture]:
    spec = parse_source(text)
    if spec.kind == "images":
        return spec, open_photos(spec)
    return spec, Capture(spec, width, height)


def open_photos(spec: SourceSpec) -> ImageFiles:
    """The photos of ``spec``, the first that OpenCV reads already read; SourceError when none
    does."""
    photos = ImageFiles(spec.paths)
    if not photos.open():
        raise SourceError(f"source: no file of {spec.target} is an image OpenCV reads "
                          f"({photos.unreadable} tried; {photos.last_unreadable})")
    return photos


class Pacer:
    """Due times at ``rate`` per second, from the first frame; late frames do not pile up."""

    def __init__(self):
        self._next: float | None = None

    def delay(self, rate: float | None, now: float) -> float:
        """Seconds to wait before the next frame (0 without a rate), and books that frame."""
        if not rate:
            self._next = None
            return 0.0
        period = 1.0 / rate
        if self._next is None or now - self._next > period:  # first frame, or fell behind
            self._next = now
        wait = max(0.0, self._next - now)
        self._next += period
        return wait

    def due(self, rate: float | None, now: float) -> bool:
        """For a live source that delivers at its own pace: whether this frame is to be sent."""
        if not rate:
            return True
        period = 1.0 / rate
        if self._next is None or now - self._next > period:
            self._next = now
        if now + 1e-4 < self._next:
            return False
        self._next += period
        return True


class FrameFeed:
    """Frames of one source at ``settings().rate_hz`` until the end, or ``stop``.

    ``settings`` is read for every frame, so ``rate_hz`` and ``loop`` can change live.
    """

    def __init__(self, spec: SourceSpec, reader: ImageFiles | Capture, settings: Callable,
                 stop: threading.Event, log=None, clock: Callable[[], float] = time.monotonic):
        self.spec, self.reader, self.settings = spec, reader, settings
        self.stop, self.log, self.clock = stop, log, clock
        self.frames = 0
        self.disconnects = 0      # times a live source stopped delivering
        self.reconnects = 0       # times it was opened again
        self.skipped = 0          # live frames not sent, to keep to rate_hz
        self.rewinds = 0          # times a file source started again (loop)
        self.ended = False
        self._since_rewind = 0
        self._pacer = Pacer()

    def rate(self) -> float | None:
        configured = self.settings().rate_hz
        if configured > 0:
            return configured
        if self.spec.kind == "video":
            return self.reader.native_rate or FALLBACK_VIDEO_RATE_HZ
        return None  # a device or stream paces itself; photos go as fast as they load

    def stats(self) -> dict:
        return {"frames": self.frames, "disconnects": self.disconnects, "reconnects": self.reconnects,
                "skipped_frames": self.skipped, "rewinds": self.rewinds,
                "unreadable_files": self.reader.unreadable}

    def _reconnect(self) -> bool:
        """Reopen a lost live source, with backoff, until it is back (True) or ``stop``."""
        self.disconnects += 1
        delay = RETRY_FIRST_S
        if self.log:
            self.log.warning("%s %s stopped delivering frames; reopening", self.spec.kind, self.spec.target)
        self.reader.close()
        while not self.stop.wait(delay):
            if self.reader.open():
                self.reconnects += 1
                self._pacer = Pacer()
                if self.log:
                    self.log.info("%s %s is back", self.spec.kind, self.spec.target)
                return True
            delay = min(2.0 * delay, RETRY_MAX_S)
        return False

    def _check_pass(self) -> None:
        """Warn when a video ended well before the frame count its container states: a
        damaged file ends as if it were whole (OpenCV's read just fails), which a user would
        take for the end of the recording. (A stated count may be an estimate: 5% slack.)"""
        stated = self.reader.stated_frames
        if self.log and self.spec.kind == "video" and stated and self._since_rewind < 0.95 * stated - 1:
            self.log.warning("video %s: %d of the %d frames its container states could be read; "
                             "the rest is damaged or missing", self.spec.target, self._since_rewind, stated)

    def _wait_for_slot(self) -> bool:
        """Wait for the next frame's time at ``rate()``; True when stopped first. A rate
        changed live during the wait ends it: the frame goes now and the new rate counts
        from it (at 0.01 Hz, the old wait would have lasted up to 100 s)."""
        rate = self.rate()
        due = self.clock() + self._pacer.delay(rate, self.clock())

        def remaining() -> float:
            if self.rate() != rate:
                self._pacer = Pacer()
                self._pacer.delay(self.rate(), self.clock())  # (books this frame, now)
                return 0.0
            return due - self.clock()

        return wait_out(self.stop, remaining)

    def __iter__(self) -> Iterator[np.ndarray]:
        while not self.stop.is_set():
            if not self.reader.live and self._wait_for_slot():
                return
            image = self.reader.read()
            # (A pass without one readable frame would loop forever: that ends too.)
            if image is None and not self.reader.live:
                self._check_pass()
            if (image is None and not self.reader.live and self.settings().loop and self._since_rewind
                    and self.reader.rewind()):
                # The slot booked above is the next pass's first frame's: booking another for it
                # lost one slot a pass (a single looped photo came at half of rate_hz).
                self._since_rewind = 0
                self.rewinds += 1
                image = self.reader.read()
            if image is None:
                if self.reader.live:
                    if not self._reconnect():
                        return
                    continue
                self.ended = True
                return
            if self.reader.live and not self._pacer.due(self.rate(), self.clock()):
                self.skipped += 1
                continue
            self.frames += 1
            self._since_rewind += 1
            yield image
