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
are dropped and counted (:attr:`Bridge.rejected`). The Rerun bridge's show_* methods only gather:
a third thread sends what was gathered ``update_rate_hz`` times a second, so for it "shown"
(:attr:`Bridge.lags`) means gathered for the next update.
"""

import collections
import math
import threading
import time

import cv2
import foxglove
import rerun as rr
from foxglove.channels import CompressedImageChannel, FrameTransformChannel, SceneUpdateChannel

from balltrack.common.images import image_to_bgr
from balltrack.common.keys import CMD_VEL, DETECTED_BALL_3D, GROUND_TRUTH, IMAGE_OUT, Keys
from balltrack.common.messages import MessageError, decode
from balltrack.deploy.foxglove_messages import (CMD_VEL_TOPIC, IMAGE_TOPIC, SCENE_TOPIC, TF_TOPIC, TWIST_SCHEMA,
                                                compressed_image, jpeg_of, located_scene, robot_transform,
                                                truth_scene, twist_json)
from balltrack.deploy.view_config import RerunViewConfig
from balltrack.services.detector.detector import shrunk_size

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


PATH_POINTS = 5_000  # the robot's path kept for the line strip, its oldest points dropped first
RATE_WINDOW_NS = 1_000_000_000
# Seconds an update may wait for Rerun's server to take it (the server drops old data past its
# memory limit, so it takes everything at once in practice).
FLUSH_WAIT = 1.0


# Plot colours away from the ball's yellow-green, so that colour on screen means the ball.
SERIES_COLOURS = {"plots/located_balls_hz": (80, 150, 255), "plots/ball_distance_m": (255, 120, 60),
                  "plots/cmd_vel/linear_x": (230, 60, 200), "plots/cmd_vel/angular_z": (60, 200, 230)}


def rerun_blueprint(config: RerunViewConfig | None = None, robots: list[str] | None = None):
    """The layout: the annotated frame large on the left; the world (true balls, the robot and
    its path) and the time plots (the last ``plot_window_s`` of them) on the right. With
    ``robots`` (namespaces), that layout once per robot, each in a tab named after it, over the
    entities under ``<robot>/``."""
    import rerun.blueprint as rrb

    config = config or RerunViewConfig()
    window = rrb.VisibleTimeRange("sim_time", start=rrb.TimeRangeBoundary.cursor_relative(seconds=-config.plot_window_s),
                                  end=rrb.TimeRangeBoundary.cursor_relative())

    def layout(prefix: str, name: str | None):
        return rrb.Horizontal(
            rrb.Spatial2DView(origin=f"{prefix}camera", name="annotated frame"),
            rrb.Vertical(rrb.Spatial3DView(origin=f"{prefix}world", name="world (ground truth)"),
                         rrb.TimeSeriesView(origin=f"{prefix}plots/cmd_vel", name="cmd_vel", time_ranges=window),
                         rrb.TimeSeriesView(origin=f"{prefix}plots", contents=["$origin/located_balls_hz",
                                                                                "$origin/ball_distance_m"],
                                            name="located balls", time_ranges=window)),
            column_shares=[3, 2], name=name)

    if robots:
        return rrb.Blueprint(rrb.Tabs(*(layout(f"{robot}/", robot) for robot in robots)), collapse_panels=True)
    return rrb.Blueprint(layout("", None), collapse_panels=True)


class RerunBridge(Bridge):
    """Logs balltrack's keys into the Rerun ``recording`` on the simulated-time timeline
    ``sim_time``: the annotated frame (``camera/image``, BGR pixels, at most ``frame_width``
    wide), the true balls and the robot's position and path in the world frame (``world/...``,
    from ground truth), cmd_vel and the rate of located balls as time plots (``plots/...``).

    What comes in is gathered, and sent ``update_rate_hz`` times a second all at once: the
    newest frame and world, and every plot point since the last update (each at its own time).
    A page paints once for each batch of data it receives, and one rendering in software (no
    GPU) takes a large part of a second to paint at any size of data: fed as things come (a
    frame, a world, a plot point, each at its own moment), it never finishes one paint before
    the next is due, and shows each change only after several."""

    def __init__(self, session, recording: rr.RecordingStream, namespace: str = "",
                 config: RerunViewConfig | None = None, entity_prefix: str = ""):
        self.recording = recording
        # Several robots in one recording: each bridge's entities under its robot's name.
        self.prefix = entity_prefix
        self.config = config or RerunViewConfig()
        self._path: collections.deque = collections.deque(maxlen=PATH_POINTS)
        self._located: collections.deque = collections.deque()  # stamps of the last second's balls
        # What the next update sends (under _pending): the newest frame and ground truth not
        # sent yet, and each series' points (stamp in ns, value) since the last update.
        self._pending = threading.Lock()
        self._frame: dict | None = None
        self._truth: dict | None = None
        self._points: dict[str, list[tuple[int, float]]] = {path: [] for path in SERIES_COLOURS}
        for path, colour in SERIES_COLOURS.items():
            rr.log(self.prefix + path, rr.SeriesLines(colors=[colour], names=[path.rsplit("/", 1)[1]]),
                   static=True, recording=recording)
        self._stop_updates = threading.Event()
        self._updater = threading.Thread(target=self._update_regularly, name="view-updates", daemon=True)
        self._updater.start()
        try:
            super().__init__(session, namespace)
        except Exception:
            self._stop_updates.set()
            raise

    def _update_regularly(self) -> None:
        while not self._stop_updates.wait(1.0 / self.config.update_rate_hz):
            self.update()

    def update(self) -> None:
        """Send what was gathered since the last update."""
        with self._pending:
            frame, truth, self._frame, self._truth = self._frame, self._truth, None, None
            points = {path: series for path, series in self._points.items() if series}
            self._points = {path: [] for path in SERIES_COLOURS}
            path = list(self._path)
        if frame is not None:
            self._show_frame(frame)
        if truth is not None:
            self._show_world(truth, path)
        for series, values in points.items():
            rr.send_columns(self.prefix + series, indexes=[rr.TimeColumn("sim_time", duration=[stamp / 1e9 for stamp, _ in values])],
                            columns=rr.Scalars.columns(scalars=[value for _, value in values]),
                            recording=self.recording)
        # At once: Rerun's batcher would otherwise hold an update up to its flush tick (0.2 s).
        self.recording.flush(timeout_sec=FLUSH_WAIT)

    def _show_frame(self, frame: dict) -> None:
        try:
            picture = image_to_bgr(frame)
        except MessageError:  # pixels that do not match the message's size
            self.rejected += 1
            return
        size = shrunk_size(picture.shape[1], picture.shape[0], self.config.frame_width)
        if size is not None:
            picture = cv2.resize(picture, size, interpolation=cv2.INTER_AREA)
        self._at(frame["header"]["stamp"])
        # Pixels, not JPEG (rr.EncodedImage): the web viewer decodes JPEG in the page, and one
        # rendering in software showed its loading mark in place of every frame.
        rr.log(self.prefix + "camera/image", rr.Image(picture, color_model="BGR"), recording=self.recording)

    def _at(self, stamp: int) -> None:
        rr.set_time("sim_time", duration=stamp / 1e9, recording=self.recording)

    def show_image(self, image: dict) -> None:
        with self._pending:
            self.skipped_frames += self._frame is not None
            self._frame = image

    def show_ball(self, ball: dict) -> None:
        stamp = ball["header"]["stamp"]
        self._located.append(stamp)
        while self._located and self._located[0] <= stamp - RATE_WINDOW_NS:
            self._located.popleft()
        with self._pending:
            self._points["plots/located_balls_hz"].append((stamp, len(self._located) * 1e9 / RATE_WINDOW_NS))
            self._points["plots/ball_distance_m"].append((stamp, ball["distance"]))

    def show_truth(self, truth: dict) -> None:
        robot = truth["robot"]
        position = (robot["x"], robot["y"], 0.0)
        with self._pending:
            if not self._path or math.dist(self._path[-1], position) >= self.config.path_step_m:
                self._path.append(position)
            self._truth = truth

    def show_twist(self, twist: dict) -> None:
        stamp = twist["header"]["stamp"]
        with self._pending:
            self._points["plots/cmd_vel/linear_x"].append((stamp, twist["linear"][0]))
            self._points["plots/cmd_vel/angular_z"].append((stamp, twist["angular"][2]))

    def _show_world(self, truth: dict, path: list) -> None:
        robot = truth["robot"]
        self._at(truth["header"]["stamp"])
        if truth["balls"]:
            rr.log(self.prefix + "world/balls", rr.Points3D([ball["position"] for ball in truth["balls"]],
                                              # a few pixels whatever the zoom: 3 cm is a dot
                                              radii=rr.Radius.ui_points(8),
                                              colors=[(204, 255, 51)] * len(truth["balls"])),
                   recording=self.recording)
        rr.log(self.prefix + "world/robot", rr.Transform3D(translation=(robot["x"], robot["y"], 0.0),
                                             rotation=rr.RotationAxisAngle(axis=(0, 0, 1), radians=robot["yaw"])),
               rr.Points3D([(0.0, 0.0, 0.05)], radii=[0.08], colors=[(80, 150, 255)]),
               recording=self.recording)
        rr.log(self.prefix + "world/path", rr.LineStrips3D([path], colors=[(80, 150, 255)], radii=[0.01]),
               recording=self.recording)

    def close(self) -> None:
        super().close()
        self._stop_updates.set()
        self._updater.join(timeout=5)
        self.update()
