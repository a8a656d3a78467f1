"""Detector service: camera frames -> balls (paper section 2.2).

Subscribes: ``camera/image_raw`` (Image: bgr8, rgb8, mono8 or jpeg; any size). Only the newest
frame is processed; frames that arrive while one is being processed replace each other and
are counted in ``dropped`` (no queue builds up under overload).
Publishes: ``detected_balls`` (Ball2DArray, every frame), ``detected_ball`` (Ball2D, the largest
ball, on frames with one), and, only while someone subscribes to them, ``image_out`` (the frame
with the detections drawn) and ``image_tuning`` (the colour mask).

Example:
    balltrack run detector --connect tcp/127.0.0.1:7447 --set v_min=30 --set param2=12
"""

import functools

import cv2

from balltrack.common import keys
from balltrack.common.images import bgr_to_message, image_to_bgr
from balltrack.common.memory import keep_freed_memory
from balltrack.common.messages import MessageError
from balltrack.common.context import ServiceContext
from balltrack.common.runner import run_service
from balltrack.services.detector.annotate import annotate
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import build_detector, compile_kernels
from balltrack.services.detector.mask import MIN_IMAGE_SIDE


def ball_fields(detection, width: int, height: int) -> dict:
    """The contract's Ball2D fields of one detection (normalised x, y and apparent size z)."""
    clip = lambda value: max(-1.0, min(1.0, value))  # noqa: E731 - a centre on the border edge
    return {"x": clip((detection.u - width / 2) / (width / 2)),
            "y": clip((detection.v - height / 2) / (height / 2)),
            "z": 2.0 * detection.radius_px / width, "u": float(detection.u), "v": float(detection.v),
            "radius_px": float(detection.radius_px), "image_width": width, "image_height": height,
            "score": float(detection.score)}


def use_threads(config: DetectorConfig) -> None:
    """Give OpenCV the configured number of threads (process-wide: services sharing the process
    share it)."""
    cv2.setNumThreads(config.threads if config.threads > 0 else -1)  # (-1: OpenCV's default)


@functools.cache
def kernels_ready() -> float:
    """Compile the detector's kernels once per process (one serving several robots builds a
    detector per robot); the seconds it took."""
    return compile_kernels()


def build(service: ServiceContext):
    # Before the first frame (and before the service counts as alive): no frame waits for numba.
    service.log.info("detector kernels ready in %.1f s", kernels_ready())
    # A frame's megabytes are not faulted in again for the next one (see common/memory.py).
    keep_freed_memory()
    largest = service.publisher(keys.DETECTED_BALL, "Ball2D")
    every = service.publisher(keys.DETECTED_BALLS, "Ball2DArray")
    annotated = service.publisher(keys.IMAGE_OUT, "Image")
    tuning = service.publisher(keys.IMAGE_TUNING, "Image")
    detector = {"core": build_detector(service.config)}
    use_threads(service.config)

    def on_config_change(config: DetectorConfig) -> None:
        use_threads(config)
        detector.update(core=build_detector(config))

    service.on_config_change(on_config_change)

    def on_frame(frame: dict) -> None:
        if min(frame["width"], frame["height"]) < MIN_IMAGE_SIDE:
            # (a valid Image, but not one to find balls in: rejected as bad input, not as a bug)
            raise MessageError(f"{frame['width']}x{frame['height']}: the detector takes frames of at least "
                               f"{MIN_IMAGE_SIDE}x{MIN_IMAGE_SIDE} pixels")
        image = image_to_bgr(frame)
        result = detector["core"].detect(image)
        height, width = image.shape[:2]
        header = frame["header"]
        balls = [ball_fields(detection, width, height) for detection in result.detections]
        # detected_ball goes first: a lockstep simulator takes detected_balls as the frame's
        # answer, so by then the follower has its detection ahead of the next clock tick.
        if balls:
            largest.put({"header": header, **balls[0]})
        every.put({"header": header, "balls": balls})
        if annotated.wanted:
            annotated.put(bgr_to_message(annotate(image, result.detections), header["stamp"],
                                         header["seq"], header["frame_id"]))
        if tuning.wanted:
            tuning.put(bgr_to_message(result.mask, header["stamp"], header["seq"],
                                      header["frame_id"], encoding="mono8"))

    service.subscribe_latest(keys.IMAGE_RAW, "Image", on_frame)
    return None


# The service's parameters (``balltrack run detector --help`` lists them); ``build`` wires it.
CONFIG = DetectorConfig


def main(argv=None) -> int:
    return run_service("detector", CONFIG, build, argv, __doc__)
