"""What the camera service and recordings cost and carry, on this machine.

    python -m balltrack.experiments.io_throughput [--seconds 20] [--frames 300] [--small 20000]

1. Camera: a 640x480 MJPEG video (written here: a textured floor and a moving ball, 10 s at
   30 frames/s) played by ``balltrack run camera`` (default ``jpeg`` encoding) at its own 30
   frames/s, then with ``rate_hz=1000`` (as fast as it can): frames/s arriving at this
   program's subscriber and the service's CPU (% of one core) over ``--seconds``.
2. Record: ``balltrack record`` (a separate process, with and without the Foxglove channels)
   while this program puts ``--frames`` 640x480 ``bgr8`` frames (the video's pictures), then ``--small`` ``Ball3D``
   messages, as fast as the router takes them: messages/s and MB/s written, from the first put
   to the recorder's count reaching all of them (its ``--progress`` lines, 0.1 s apart).
3. Play: ``balltrack play --rate 0`` of each file: messages/s and MB/s arriving at this
   program's subscriber, first to last arrival.
"""

import argparse
import io
import math
import tempfile
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import zenoh

from balltrack.common.arguments import ArgumentParser, integer, number
from balltrack.common.messages import encode, header
from balltrack.common.session import open_session
from balltrack.common.terminal import exit_with
from balltrack.common.waiting import poll_until
from balltrack.deploy.command import Command
from balltrack.deploy.launcher import start_system
from balltrack.experiments.processes import cpu_seconds

WIDTH, HEIGHT, FPS = 640, 480, 30
VIDEO_SECONDS = 10


def scene_frame(index: int, floor: np.ndarray) -> np.ndarray:
    """A floor with texture (so JPEG and zstd have detail to keep) and a ball on a circle."""
    frame = floor.copy()
    angle = 2 * math.pi * index / (FPS * VIDEO_SECONDS)
    centre = (int(WIDTH / 2 + 200 * math.cos(angle)), int(HEIGHT / 2 + 120 * math.sin(angle)))
    cv2.circle(frame, centre, 30, (40, 220, 200), -1, cv2.LINE_AA)
    return frame


def textured_floor() -> np.ndarray:
    rng = np.random.default_rng(1)
    return cv2.GaussianBlur(rng.integers(60, 200, (HEIGHT, WIDTH, 3), dtype=np.uint8), (7, 7), 0)


def write_video(path: Path) -> None:
    """A 640x480 MJPEG video of :func:`scene_frame`, VIDEO_SECONDS long."""
    floor = textured_floor()
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (WIDTH, HEIGHT))
    for index in range(FPS * VIDEO_SECONDS):
        writer.write(scene_frame(index, floor))
    writer.release()


class Arrivals:
    """Counts messages and bytes on a key, with the first and last arrival times."""

    def __init__(self, session, key: str):
        self.count = self.bytes = 0
        self.first = self.last = None
        self._changed = threading.Condition()
        self._subscriber = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample) -> None:
        now = time.monotonic()
        with self._changed:
            self.count += 1
            self.bytes += len(sample.payload)
            self.first = self.first or now
            self.last = now
            self._changed.notify_all()

    def wait_count(self, count: int, timeout: float) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: self.count >= count, timeout)

    def reset(self) -> None:
        with self._changed:
            self.count = self.bytes = 0
            self.first = self.last = None

    def close(self) -> None:
        self._subscriber.undeclare()


def camera(endpoint: str, folder: Path, seconds: float, session) -> list[tuple[str, float, float]]:
    video = folder / "video.avi"
    write_video(video)
    rows = []
    arrivals = Arrivals(session, "camera/image_raw")
    try:
        for label, rate in (("30 frames/s (the video's own)", 0), ("as fast as it can (rate_hz=1000)", 1000)):
            service = Command(["run", "camera", "--connect", endpoint, "--set", f"source={video}",
                               "--set", "loop=true", "--set", f"rate_hz={rate}"], folder / f"camera-{rate}.log")
            try:
                if not arrivals.wait_count(FPS, 60):
                    raise RuntimeError(f"no frames from the camera: {service.output()[-500:]}")
                arrivals.reset()
                cpu_before, start = cpu_seconds(service.pid), time.monotonic()
                time.sleep(seconds)  # the measurement window itself
                elapsed = time.monotonic() - start
                rows.append((label, arrivals.count / elapsed, 100 * (cpu_seconds(service.pid) - cpu_before) / elapsed))
            finally:
                service.stop()
                arrivals.reset()
    finally:
        arrivals.close()
    return rows


def record_and_play(endpoint: str, folder: Path, frames: int, small: int, session) -> list[tuple]:
    floor = textured_floor()
    streams = {
        "frames": ("camera/image_raw", [encode("Image", {"header": header(index, index), "width": WIDTH,
                                                         "height": HEIGHT, "encoding": "bgr8",
                                                         "data": scene_frame(index, floor).tobytes()})
                                        for index in range(frames)]),
        "small": ("detected_ball_3d", [encode("Ball3D", {"header": header(index, index), "x": 0.1, "y": 0.2,
                                                          "z": 1.5, "distance": 1.52}) for index in range(small)]),
    }
    rows = []
    for foxglove in (True, False):
        for name, (key, payloads) in streams.items():
            path = folder / f"{name}-{'foxglove' if foxglove else 'msgpack'}.mcap"
            recorder = Command(["record", "-o", str(path), key, "--progress", "0.1", "--connect", endpoint,
                                *([] if foxglove else ["--no-foxglove"])], folder / f"{path.stem}.log")
            recorder.wait_for("recording")
            publisher = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
            if not poll_until(lambda: publisher.matching_status.matching, 30, interval=0.02):
                raise RuntimeError("the recorder never subscribed")  # (its subscription not routed)
            start = time.monotonic()
            for payload in payloads:
                publisher.put(payload)
            recorder.wait_for(rf"^balltrack record: {len(payloads)} messages written", timeout=600)
            elapsed = time.monotonic() - start
            publisher.undeclare()
            recorder.stop()
            megabytes = sum(map(len, payloads)) / 1e6
            label = f"record {name}{' + Foxglove channels' if foxglove else ''}"
            rows.append((label, len(payloads) / elapsed, megabytes / elapsed))
            if foxglove:
                continue  # play once per stream, from the msgpack-only file
            arrivals = Arrivals(session, key)
            try:
                player = Command(["play", str(path), "--rate", "0", "--connect", endpoint], folder / f"play-{name}.log")
                arrived = arrivals.wait_count(len(payloads), 600)
                player.stop()
                span = (arrivals.last - arrivals.first) if arrivals.first else float("nan")
                label = f"play {name}" + ("" if arrived else f" ({arrivals.count}/{len(payloads)} arrived)")
                rows.append((label, arrivals.count / span, arrivals.bytes / 1e6 / span))
            finally:
                arrivals.close()
    return rows


def main(argv=None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.io_throughput", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=number(above=0), default=20.0, help="camera measurement window")
    parser.add_argument("--frames", type=integer(minimum=1), default=300, help="640x480 bgr8 frames recorded and played")
    parser.add_argument("--small", type=integer(minimum=1), default=20000, help="Ball3D messages recorded and played")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="balltrack-io-") as folder, \
            start_system(Path(folder) / "run", services=(), output=io.StringIO()) as system:
        session = open_session([system.endpoint], open_timeout=10)
        try:
            camera_rows = camera(system.endpoint, Path(folder), args.seconds, session)
            recording_rows = record_and_play(system.endpoint, Path(folder), args.frames, args.small, session)
        finally:
            session.close()
    print(f"camera service, 640x480 MJPEG video, {args.seconds:g} s each")
    for label, rate, cpu in camera_rows:
        print(f"  {label:<40} {rate:>7.1f} frames/s   CPU {cpu:>5.1f} % of a core")
    print(f"recordings ({args.frames} frames of 640x480 bgr8, {args.small} Ball3D)")
    for label, rate, megabytes in recording_rows:
        print(f"  {label:<40} {rate:>9.0f} messages/s {megabytes:>8.1f} MB/s")
    return 0


if __name__ == "__main__":
    exit_with(main)
