"""Live viewing: balltrack's keys shown in Rerun (``balltrack view``, :class:`RerunBridge`) or
republished for Foxglove (``balltrack view --foxglove``).

A :class:`FoxgloveBridge` subscribes on an open Zenoh session and logs, into a Foxglove context
(served over WebSocket by ``foxglove.start_server``, or written to MCAP by ``foxglove.open_mcap``):

    /image             CompressedImage (JPEG)   the detector's annotated frame (``image_out``)
    /scene             SceneUpdate              one sphere per located ball (``detected_ball_3d``,
                                                camera_optical frame) and the true balls (world)
    /tf                FrameTransform           world -> base_link from ``sim/ground_truth``
    /cmd_vel           JSON                     the follower's Twist, for plots

Subscribing to ``image_out`` is what makes the detector draw it, so the viewer costs the
detector one annotated frame per camera frame while it runs. Zenoh callbacks only decode and
hand over: JPEG encoding of a raw frame happens on a thread of its own that keeps only the
newest frame, so a slow viewer drops frames rather than delaying the session's other callbacks.
Malformed messages are dropped and counted (:attr:`FoxgloveBridge.rejected`).
"""

import collections
import math
import threading

import cv2
import foxglove
import rerun as rr
from foxglove.channels import CompressedImageChannel, FrameTransformChannel, SceneUpdateChannel
from foxglove.messages import (Color, CompressedImage, FrameTransform, Pose, Quaternion, SceneEntity,
                               SceneUpdate, SpherePrimitive, Timestamp, Vector3)

from balltrack.common.images import image_to_bgr
from balltrack.common.keys import CMD_VEL, DETECTED_BALL_3D, GROUND_TRUTH, IMAGE_OUT, Keys
from balltrack.common.messages import MessageError, decode

DETECTED_COLOUR = Color(r=0.8, g=1.0, b=0.2, a=0.9)  # the tennis ball's yellow-green
TRUE_COLOUR = Color(r=0.3, g=0.6, b=1.0, a=0.4)      # ground truth: translucent blue
DETECTED_DIAMETER = 0.067  # a tennis ball; Ball3D carries no radius

TWIST_SCHEMA = {
    "type": "object",
    "properties": {
        "stamp": {"type": "integer"},
        "linear": {"type": "array", "items": {"type": "number"}},
        "angular": {"type": "array", "items": {"type": "number"}},
    },
}


def timestamp(nanoseconds: int) -> Timestamp:
    return Timestamp(nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000)


def yaw_quaternion(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _point(x: float, y: float, z: float) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(w=1.0))


class Bridge:
    """Subscribes to ``namespace``'s keys on ``session`` and hands each decoded message to a
    ``show_*`` method of a subclass (a viewer) until :meth:`close`: ``show_jpeg`` (the annotated
    frame, JPEG bytes), ``show_ball`` (Ball3D), ``show_truth`` (GroundTruth), ``show_twist``."""

    def __init__(self, session, namespace: str = "", jpeg_quality: int = 80):
        self.keys = Keys(namespace)
        self.jpeg_quality = jpeg_quality
        self.rejected = 0
        self.handled = 0  # valid messages passed to a show_* method
        self._newest_frame: dict | None = None
        self._closing = False
        self._frame_ready = threading.Condition()
        self._encoder = threading.Thread(target=self._encode_frames, name="view-encoder", daemon=True)
        self._encoder.start()
        self._subscribers = []
        handlers = {IMAGE_OUT: ("Image", self._on_image), DETECTED_BALL_3D: ("Ball3D", self.show_ball),
                    GROUND_TRUTH: ("GroundTruth", self.show_truth), CMD_VEL: ("Twist", self.show_twist)}
        try:
            for key, (message, handler) in handlers.items():
                self._subscribers.append(session.declare_subscriber(
                    self.keys(key), self._decoding(message, handler)))
        except Exception:
            self.close()
            raise

    def _decoding(self, message: str, handler):
        def on_sample(sample):
            try:
                decoded = decode(message, sample.payload.to_bytes())
            except MessageError:
                self.rejected += 1
                return
            handler(decoded)
            self.handled += 1
        return on_sample

    def _on_image(self, image: dict) -> None:
        if image["encoding"] == "jpeg":  # already compressed: passed on as is, no re-encoding
            self.show_jpeg(image["header"], bytes(image["data"]))
            return
        with self._frame_ready:
            self._newest_frame = image
            self._frame_ready.notify()

    def _encode_frames(self) -> None:
        while True:
            with self._frame_ready:
                self._frame_ready.wait_for(lambda: self._newest_frame is not None or self._closing)
                if self._closing:
                    return
                image, self._newest_frame = self._newest_frame, None
            try:
                bgr = image_to_bgr(image)
            except MessageError:
                self.rejected += 1
                continue
            ok, buffer = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
            if ok:
                self.show_jpeg(image["header"], buffer.tobytes())

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
        with self._frame_ready:
            self._closing = True
            self._frame_ready.notify()
        self._encoder.join(timeout=5)


class FoxgloveBridge(Bridge):
    """Republishes balltrack's keys as Foxglove messages into ``context`` (the SDK's default
    context when None): served by ``foxglove.start_server``, or written by ``foxglove.open_mcap``."""

    def __init__(self, session, namespace: str = "", context: foxglove.Context | None = None,
                 jpeg_quality: int = 80):
        self.image = CompressedImageChannel("/image", context=context)
        self.scene = SceneUpdateChannel("/scene", context=context)
        self.transform = FrameTransformChannel("/tf", context=context)
        self.cmd_vel = foxglove.Channel("/cmd_vel", schema=TWIST_SCHEMA, context=context)
        super().__init__(session, namespace, jpeg_quality)

    def show_jpeg(self, header: dict, data: bytes) -> None:
        self.image.log(CompressedImage(timestamp=timestamp(header["stamp"]), frame_id=header["frame_id"],
                                       data=data, format="jpeg"))

    def show_ball(self, ball: dict) -> None:
        header = ball["header"]
        sphere = SpherePrimitive(pose=_point(ball["x"], ball["y"], ball["z"]),
                                 size=Vector3(x=DETECTED_DIAMETER, y=DETECTED_DIAMETER, z=DETECTED_DIAMETER),
                                 color=DETECTED_COLOUR)
        entity = SceneEntity(timestamp=timestamp(header["stamp"]), frame_id=header["frame_id"],
                             id="detected_ball", spheres=[sphere])
        self.scene.log(SceneUpdate(entities=[entity]))

    def show_truth(self, truth: dict) -> None:
        stamp, robot = truth["header"]["stamp"], truth["robot"]
        self.transform.log(FrameTransform(timestamp=timestamp(stamp), parent_frame_id="world",
                                          child_frame_id="base_link",
                                          translation=Vector3(x=robot["x"], y=robot["y"], z=0.0),
                                          rotation=yaw_quaternion(robot["yaw"])))
        spheres = [SpherePrimitive(pose=_point(*ball["position"]),
                                   size=Vector3(x=2 * ball["radius"], y=2 * ball["radius"], z=2 * ball["radius"]),
                                   color=TRUE_COLOUR) for ball in truth["balls"]]
        entity = SceneEntity(timestamp=timestamp(stamp), frame_id="world", id="true_balls", spheres=spheres)
        self.scene.log(SceneUpdate(entities=[entity]))

    def show_twist(self, twist: dict) -> None:
        self.cmd_vel.log({"stamp": twist["header"]["stamp"], "linear": list(twist["linear"]),
                          "angular": list(twist["angular"])})


PATH_POINTS = 20_000  # the robot path kept for the line strip (over 10 min at 30 Hz)
RATE_WINDOW_NS = 1_000_000_000


class RerunBridge(Bridge):
    """Logs balltrack's keys into the Rerun ``recording`` on the simulated-time timeline
    ``sim_time``: the annotated frame (``camera/image``), the true balls and the robot's position
    and path in the world frame (``world/...``, from ground truth), cmd_vel and the rate of
    located balls as time plots (``plots/...``)."""

    def __init__(self, session, recording: rr.RecordingStream, namespace: str = "", jpeg_quality: int = 80):
        self.recording = recording
        self._path: collections.deque = collections.deque(maxlen=PATH_POINTS)
        self._located: collections.deque = collections.deque()  # stamps of the last second's balls
        self._lock = threading.Lock()
        super().__init__(session, namespace, jpeg_quality)

    def _at(self, stamp: int) -> None:
        # Rerun's time is per thread: set it before every log, as callbacks come from several.
        rr.set_time("sim_time", duration=stamp / 1e9, recording=self.recording)

    def show_jpeg(self, header: dict, data: bytes) -> None:
        self._at(header["stamp"])
        rr.log("camera/image", rr.EncodedImage(contents=data, media_type="image/jpeg"),
               recording=self.recording)

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
                                              radii=[ball["radius"] for ball in truth["balls"]],
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
