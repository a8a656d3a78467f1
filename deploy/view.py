"""Live viewing: balltrack's keys shown in Rerun (``balltrack view``, :class:`RerunBridge`) or
republished for Foxglove (``balltrack view --foxglove``).

A :class:`FoxgloveBridge` subscribes on an open Zenoh session and logs, into a Foxglove context
(served over WebSocket by ``foxglove.start_server``, or written to MCAP by ``foxglove.open_mcap``),
the channels of ``deploy/foxglove_messages.py``: /image, /scene, /tf and /cmd_vel.

Subscribing to ``image_out`` is what makes the detector draw it, so the viewer costs the
detector one annotated frame per camera frame while it runs. Zenoh callbacks only decode and
hand over: showing (JPEG encoding of a raw frame, logging) happens on a thread of its own that
keeps only the newest frame and a bounded queue of the rest, so a slow viewer drops (and counts,
:attr:`Bridge.dropped`) rather than delaying the session's other callbacks, and drops what has
waited over MAX_AGE rather than showing the past. Malformed messages
are dropped and counted (:attr:`Bridge.rejected`).
"""

import collections
import threading
import time

import foxglove
import rerun as rr
from foxglove.channels import CompressedImageChannel, FrameTransformChannel, SceneUpdateChannel

from balltrack.common.images import image_to_bgr
from balltrack.common.keys import CMD_VEL, DETECTED_BALL_3D, GROUND_TRUTH, IMAGE_OUT, Keys
from balltrack.common.messages import MessageError, decode
from balltrack.deploy.foxglove_messages import (CMD_VEL_TOPIC, IMAGE_TOPIC, SCENE_TOPIC, TF_TOPIC, TWIST_SCHEMA,
                                                compressed_image, jpeg_of, located_scene, robot_transform,
                                                truth_scene, twist_json)

LAGS_KEPT = 100_000
# A live view shows the present: a queued message older than this (seconds) when its turn
# comes is dropped and counted, so a viewer slowed down (Rerun's server waits for its slowest
# web page) stays this close to now instead of drifting max_queued messages behind (a browser
# rendering in software on the robot's own 2 cores put its plots 20 s behind).
MAX_AGE = 0.5


class Bridge:
    """Subscribes to ``namespace``'s keys on ``session`` and hands each decoded message to a
    ``show_*`` method of a subclass (a viewer) until :meth:`close`: ``show_jpeg`` (the annotated
    frame, JPEG bytes), ``show_ball`` (Ball3D), ``show_truth`` (GroundTruth), ``show_twist``."""

    def __init__(self, session, namespace: str = "", jpeg_quality: int = 80, max_queued: int = 256):
        self.keys = Keys(namespace)
        self.jpeg_quality = jpeg_quality
        self.rejected = 0
        self.dropped = 0  # the viewer was more than max_queued messages or MAX_AGE behind
        self.handled = 0  # valid messages passed to a show_* method
        self.skipped_frames = 0  # a newer frame came before the viewer had shown this one
        # Seconds from a message's arrival to the end of its show_* call, the newest LAGS_KEPT.
        self.lags: collections.deque = collections.deque(maxlen=LAGS_KEPT)
        # (show method, message, arrival); the newest frame waits apart, only it is shown
        self._queued: collections.deque = collections.deque()
        self._max_queued = max_queued
        self._newest_frame: tuple[dict, float] | None = None
        self._closing = False
        self._ready = threading.Condition()
        self._worker = threading.Thread(target=self._show_queued, name="view-worker", daemon=True)
        self._worker.start()
        self._subscribers = []
        handlers = {IMAGE_OUT: ("Image", None), DETECTED_BALL_3D: ("Ball3D", self.show_ball),
                    GROUND_TRUTH: ("GroundTruth", self.show_truth), CMD_VEL: ("Twist", self.show_twist)}
        try:
            for key, (message, handler) in handlers.items():
                self._subscribers.append(session.declare_subscriber(
                    self.keys(key), self._decoding(message, handler)))
        except Exception:
            self.close()
            raise

    def _decoding(self, message: str, handler):
        # Zenoh's callback only decodes and queues: a viewer that blocks (Rerun's server waits
        # for its slowest web viewer) must not hold up the session's other callbacks.
        def on_sample(sample):
            arrival = time.monotonic()
            try:
                decoded = decode(message, sample.payload.to_bytes())
            except MessageError:
                self.rejected += 1
                return
            with self._ready:
                if handler is None:
                    self.skipped_frames += self._newest_frame is not None
                    self._newest_frame = (decoded, arrival)
                elif len(self._queued) >= self._max_queued:
                    self.dropped += 1
                    return
                else:
                    self._queued.append((handler, decoded, arrival))
                self._ready.notify()
        return on_sample

    def _show_queued(self) -> None:
        while True:
            with self._ready:
                self._ready.wait_for(lambda: self._queued or self._newest_frame is not None or self._closing)
                if self._closing:
                    return
                if self._queued:
                    handler, message, arrival = self._queued.popleft()
                    if time.monotonic() - arrival > MAX_AGE:
                        self.dropped += 1
                        continue
                else:
                    (message, arrival), self._newest_frame = self._newest_frame, None
                    handler = self.show_image
            try:
                handler(message)
            except MessageError:
                self.rejected += 1
                continue
            self.handled += 1
            self.lags.append(time.monotonic() - arrival)

    def show_image(self, image: dict) -> None:
        """The annotated frame; by default as JPEG bytes to :meth:`show_jpeg`."""
        jpeg = jpeg_of(image, self.jpeg_quality)  # a JPEG frame passes as it is
        if jpeg is not None:
            self.show_jpeg(image["header"], jpeg)

    def show_jpeg(self, header: dict, data: bytes) -> None:
        raise NotImplementedError

    def show_ball(self, ball: dict) -> None:
        raise NotImplementedError

    def show_truth(self, truth: dict) -> None:
        raise NotImplementedError

    def show_twist(self, twist: dict) -> None:
        raise NotImplementedError

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()
        self._subscribers = []
        with self._ready:
            self._closing = True
            self._ready.notify()
        self._worker.join(timeout=5)


class FoxgloveBridge(Bridge):
    """Republishes balltrack's keys as Foxglove messages (``deploy/foxglove_messages.py``) into
    ``context`` (the SDK's default context when None): served by ``foxglove.start_server``, or
    written by ``foxglove.open_mcap``."""

    def __init__(self, session, namespace: str = "", context: foxglove.Context | None = None,
                 jpeg_quality: int = 80):
        self.image = CompressedImageChannel(IMAGE_TOPIC, context=context)
        self.scene = SceneUpdateChannel(SCENE_TOPIC, context=context)
        self.transform = FrameTransformChannel(TF_TOPIC, context=context)
        self.cmd_vel = foxglove.Channel(CMD_VEL_TOPIC, schema=TWIST_SCHEMA, context=context)
        super().__init__(session, namespace, jpeg_quality)

    def show_jpeg(self, header: dict, data: bytes) -> None:
        self.image.log(compressed_image(header, data))

    def show_ball(self, ball: dict) -> None:
        self.scene.log(located_scene(ball))

    def show_truth(self, truth: dict) -> None:
        self.transform.log(robot_transform(truth))
        self.scene.log(truth_scene(truth))

    def show_twist(self, twist: dict) -> None:
        self.cmd_vel.log(twist_json(twist))


PATH_POINTS = 20_000  # the robot path kept for the line strip (over 10 min at 30 Hz)
RATE_WINDOW_NS = 1_000_000_000


# Plot colours away from the ball's yellow-green, so that colour on screen means the ball.
SERIES_COLOURS = {"plots/located_balls_hz": (80, 150, 255), "plots/ball_distance_m": (255, 120, 60),
                  "plots/cmd_vel/linear_x": (230, 60, 200), "plots/cmd_vel/angular_z": (60, 200, 230)}


def rerun_blueprint():
    """The layout: the annotated frame large on the left; the world (true balls, the robot and
    its path) and the time plots on the right."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="camera", name="annotated frame"),
            rrb.Vertical(rrb.Spatial3DView(origin="world", name="world (ground truth)"),
                         rrb.TimeSeriesView(origin="plots/cmd_vel", name="cmd_vel"),
                         rrb.TimeSeriesView(origin="plots", contents=["$origin/located_balls_hz",
                                                                     "$origin/ball_distance_m"],
                                            name="located balls")),
            column_shares=[3, 2]),
        collapse_panels=True)


class RerunBridge(Bridge):
    """Logs balltrack's keys into the Rerun ``recording`` on the simulated-time timeline
    ``sim_time``: the annotated frame (``camera/image``, BGR pixels), the true balls and the robot's position
    and path in the world frame (``world/...``, from ground truth), cmd_vel and the rate of
    located balls as time plots (``plots/...``)."""

    def __init__(self, session, recording: rr.RecordingStream, namespace: str = "", jpeg_quality: int = 80):
        self.recording = recording
        self._path: collections.deque = collections.deque(maxlen=PATH_POINTS)
        self._located: collections.deque = collections.deque()  # stamps of the last second's balls
        self._lock = threading.Lock()
        for path, colour in SERIES_COLOURS.items():
            rr.log(path, rr.SeriesLines(colors=[colour], names=[path.rsplit("/", 1)[1]]), static=True,
                   recording=recording)
        super().__init__(session, namespace, jpeg_quality)

    def _at(self, stamp: int) -> None:
        # Rerun's time is per thread: set it before every log, as callbacks come from several.
        rr.set_time("sim_time", duration=stamp / 1e9, recording=self.recording)

    def show_image(self, image: dict) -> None:
        # Pixels, not JPEG: the web viewer decodes JPEG in the page, which a browser without a
        # GPU (software rendering) did not finish for minutes; a 320x240 frame is 230 kB.
        self._at(image["header"]["stamp"])
        rr.log("camera/image", rr.Image(image_to_bgr(image), color_model="BGR"), recording=self.recording)

    def show_ball(self, ball: dict) -> None:
        stamp = ball["header"]["stamp"]
        with self._lock:
            self._located.append(stamp)
            while self._located and self._located[0] <= stamp - RATE_WINDOW_NS:
                self._located.popleft()
            rate = len(self._located) * 1e9 / RATE_WINDOW_NS
        self._at(stamp)
        rr.log("plots/located_balls_hz", rr.Scalars([rate]), recording=self.recording)
        rr.log("plots/ball_distance_m", rr.Scalars([ball["distance"]]), recording=self.recording)

    def show_truth(self, truth: dict) -> None:
        robot = truth["robot"]
        with self._lock:
            self._path.append((robot["x"], robot["y"], 0.0))
            path = list(self._path)
        self._at(truth["header"]["stamp"])
        if truth["balls"]:
            rr.log("world/balls", rr.Points3D([ball["position"] for ball in truth["balls"]],
                                              # a few pixels whatever the zoom: 3 cm is a dot
                                              radii=rr.Radius.ui_points(8),
                                              colors=[(204, 255, 51)] * len(truth["balls"])),
                   recording=self.recording)
        rr.log("world/robot", rr.Transform3D(translation=path[-1],
                                             rotation=rr.RotationAxisAngle(axis=(0, 0, 1), radians=robot["yaw"])),
               rr.Points3D([(0.0, 0.0, 0.05)], radii=[0.08], colors=[(80, 150, 255)]),
               recording=self.recording)
        rr.log("world/path", rr.LineStrips3D([path], colors=[(80, 150, 255)], radii=[0.01]),
               recording=self.recording)

    def show_twist(self, twist: dict) -> None:
        self._at(twist["header"]["stamp"])
        rr.log("plots/cmd_vel/linear_x", rr.Scalars([twist["linear"][0]]), recording=self.recording)
        rr.log("plots/cmd_vel/angular_z", rr.Scalars([twist["angular"][2]]), recording=self.recording)
