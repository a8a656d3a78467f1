"""What the demo watches, from a subscriber of its own: message counts, arrival times (the
latencies: see ``demo.py``'s docstring), the data of its figures, the referee's verdict, and the
video of the detector's annotated frames."""

import queue
import sys
import threading
import time
from pathlib import Path

import numpy as np

from balltrack.common import keys as key_table
from balltrack.common.keys import Keys
from balltrack.common.messages import MessageError, decode, unpack_sharing_bins
from balltrack.common.referee import Referee

# Keys whose messages are counted (image_tuning is left out: subscribing to it would make the
# detector compute the colour mask for nobody).
COUNTED_KEYS = (key_table.IMAGE_RAW, key_table.CAMERA_INFO, key_table.DETECTED_BALL,
                key_table.DETECTED_BALLS, key_table.DETECTED_BALL_3D, key_table.CMD_VEL,
                key_table.IMAGE_OUT, key_table.CLOCK, key_table.GROUND_TRUTH)

def percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


class VideoWriter(threading.Thread):
    """Writes ``image_out`` frames (with the 3D estimate of the same frame) to an mp4 file.

    Frames come from a bounded queue so the subscriber callback never blocks; a frame that
    skips sequence numbers (the detector dropped frames under load) is repeated so the video
    keeps the simulation's timing."""

    def __init__(self, path: Path, fps: float, estimates: dict):
        super().__init__(name="demo-video", daemon=True)
        self.path = path
        self.fps = fps
        self.frames: queue.Queue = queue.Queue(maxsize=60)
        self.estimates = estimates
        self.written = 0
        self.picture = None
        self.picture_distance = 0.6  # frame.png: the first frame with the ball this close
        self._writer = None
        self._last_seq = None
        self.failed = 0
        self.last_image = None

    def offer(self, message: dict) -> None:
        try:
            self.frames.put_nowait(message)
        except queue.Full:
            pass

    def run(self) -> None:
        import cv2

        from balltrack.common.images import image_to_bgr

        while True:
            message = self.frames.get()
            if message is None:
                break
            try:
                self._write(message, cv2, image_to_bgr)
            except Exception as error:  # one bad frame must not end the video
                if not self.failed:
                    print(f"demo: video frame skipped: {error!r}", file=sys.stderr)
                self.failed += 1
        if self._writer is not None:
            self._writer.release()

    def _write(self, message: dict, cv2, image_to_bgr) -> None:
        image = np.array(image_to_bgr(message))  # a writable copy: the overlay draws on it
        seq = message["header"]["seq"]
        estimate = self.estimates.get(seq)
        if estimate is not None:
            text = (f"ball x {estimate['x']:+.2f}  y {estimate['y']:+.2f}  z {estimate['z']:.2f}  "
                    f"d {estimate['distance']:.2f} m")
            height = image.shape[0]
            cv2.rectangle(image, (0, height - 30), (image.shape[1], height), (0, 0, 0), -1)
            cv2.putText(image, text, (10, height - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                        (255, 255, 255), 1, cv2.LINE_AA)
            if estimate["distance"] <= self.picture_distance and self.picture is None:
                self.picture = image.copy()
        if self._writer is None:
            height, width = image.shape[:2]
            self._writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"),
                                           self.fps, (width, height))
        repeats = 1 if self._last_seq is None else max(1, min(seq - self._last_seq, 10))
        self._last_seq = seq
        for _ in range(repeats):
            self._writer.write(image)
            self.written += 1
        self.last_image = image

    def finish(self) -> None:
        try:
            self.frames.put(None, timeout=10)
        except queue.Full:
            pass
        self.join(30)


class Observer:
    """This program's own subscriber: counts, arrival times, data for the figures, the referee."""

    def __init__(self, session, namespace: str, referee: Referee, video: VideoWriter | None):
        self.keys = Keys(namespace)
        self.referee = referee
        self.video = video
        self.lock = threading.Lock()
        self.counts = {key: 0 for key in COUNTED_KEYS if key != key_table.IMAGE_OUT or video}
        self.image_arrival: dict[int, float] = {}
        self.detection_arrival: dict[int, float] = {}
        self.ball_arrival: dict[int, float] = {}
        self.command_arrival: dict[int, float] = {}
        self.estimates: list[tuple[float, dict]] = []  # (sim stamp s, Ball3D)
        self.estimate_by_seq: dict[int, dict] = video.estimates if video else {}
        self.commands: list[tuple[float, dict]] = []
        self.truths: list[tuple[float, dict]] = []
        self.latest_truth: tuple[float, float, dict] | None = None  # (sim s, wall arrival, truth)
        self.start: float | None = None  # sim time at which the scenario (re)started
        self.reached = threading.Event()
        self.simulator_stats: dict = {}
        self.stats: dict[str, dict] = {}
        self._entities = []
        handlers = {key_table.IMAGE_RAW: self._on_image, key_table.DETECTED_BALL: self._on_detection,
                    key_table.DETECTED_BALL_3D: self._on_ball,
                    key_table.CMD_VEL: self._on_command, key_table.GROUND_TRUTH: self._on_truth,
                    key_table.IMAGE_OUT: self._on_image_out}
        for key in self.counts:
            self._entities.append(session.declare_subscriber(
                self.keys(key), self._counting(key, handlers.get(key))))
        self._entities.append(session.declare_subscriber(self.keys("*/stats"), self._on_stats))

    def close(self) -> None:
        for entity in self._entities:
            try:
                entity.undeclare()
            except Exception:
                pass

    def _counting(self, key: str, handler):
        def on_sample(sample):
            arrival = time.monotonic()
            with self.lock:
                self.counts[key] += 1
            if handler is not None:
                try:
                    handler(sample.payload.to_bytes(), arrival)
                except (MessageError, KeyError, TypeError, ValueError):
                    pass
        return on_sample

    def _on_image(self, payload: bytes, arrival: float) -> None:
        # (only the header is needed: the pixels are not copied again, beside the detector's work)
        seq = unpack_sharing_bins(payload)["header"]["seq"]
        with self.lock:
            self.image_arrival.setdefault(seq, arrival)

    def _on_detection(self, payload: bytes, arrival: float) -> None:
        seq = decode("Ball2D", payload)["header"]["seq"]
        with self.lock:
            self.detection_arrival.setdefault(seq, arrival)

    def _on_ball(self, payload: bytes, arrival: float) -> None:
        ball = decode("Ball3D", payload)
        seq = ball["header"]["seq"]
        with self.lock:
            self.ball_arrival.setdefault(seq, arrival)
            self.estimate_by_seq[seq] = ball
            if self.start is not None:
                self.estimates.append((ball["header"]["stamp"] / 1e9 - self.start, ball))

    def _sim_now(self, arrival: float) -> float | None:
        if self.latest_truth is None:
            return None
        stamp, wall, _ = self.latest_truth
        return stamp + (arrival - wall)

    def _on_command(self, payload: bytes, arrival: float) -> None:
        twist = decode("Twist", payload)
        with self.lock:
            now = self._sim_now(arrival)
            tick = twist.get("time")
            # The follower's tick time when it runs on simulated time, else the arrival time.
            t = tick / 1e9 if isinstance(tick, int) and now is not None and abs(tick / 1e9 - now) < 5 else now
            if twist.get("mode") != "search":
                self.command_arrival.setdefault(twist["header"]["seq"], arrival)
            if self.start is not None and t is not None:
                self.commands.append((t - self.start, twist))

    def _on_truth(self, payload: bytes, arrival: float) -> None:
        truth = decode("GroundTruth", payload)
        stamp = truth["header"]["stamp"] / 1e9
        with self.lock:
            self.latest_truth = (stamp, arrival, truth)
            if self.start is None:
                return
            t = stamp - self.start
            self.truths.append((t, truth))
            if self.referee.update(t, truth):
                self.reached.set()

    def _on_image_out(self, payload: bytes, arrival: float) -> None:
        self.video.offer(decode("Image", payload))

    def _on_stats(self, sample) -> None:
        try:
            stats = decode("Stats", sample.payload.to_bytes())
        except MessageError:
            return
        with self.lock:
            self.stats[stats["service"]] = stats

    def begin(self, sim_time: float) -> None:
        """The scenario (re)started at ``sim_time``: counts and figures start from here."""
        with self.lock:
            self.start = sim_time
            self.counts = {key: 0 for key in self.counts}
            self.detection_arrival.clear()
            self.ball_arrival.clear()
            self.command_arrival.clear()
            self.estimates.clear()
            self.commands.clear()
            self.truths.clear()

    def latencies(self) -> dict:
        with self.lock:
            result = {}
            # (detected_ball: the detector's share of the way to detected_ball_3d, the rest is
            # the locator and its two hops through the router)
            for name, arrivals in (("detected_ball", self.detection_arrival),
                                   ("detected_ball_3d", self.ball_arrival), ("cmd_vel", self.command_arrival)):
                values = [1000 * (arrival - self.image_arrival[seq]) for seq, arrival in arrivals.items()
                          if seq in self.image_arrival and arrival >= self.image_arrival[seq]]
                result[name] = {"p50_ms": percentile(values, 50), "p99_ms": percentile(values, 99),
                                "count": len(values)}
            return result
