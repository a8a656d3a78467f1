"""Camera service: a real camera (or a video, photos, a stream) as ``camera/image_raw``.

Publishes: ``camera/image_raw`` (Image, ``encoding`` jpeg by default; header stamp = wall time
of the read, seq = frame index from 0, frame_id "camera") and ``camera/camera_info``
(CameraInfo, intrinsics from ``calibration`` or the ideal pinhole of ``hfov``, with the
distortion model) with the first frame, with each frame whose size differs from the one before,
and then once a second; ``camera/camera_info`` is also answered as a query, as the simulator
does. Stats add ``frames``, ``disconnects`` and ``reconnects`` (a live source that stopped
delivering and was reopened), ``skipped_frames`` (live frames left out to keep to ``rate_hz``),
``rewinds`` and ``unreadable_files``.

A source that cannot be opened (photos none of which OpenCV reads too), or a calibration file
that cannot be read or does not fit the frames, is one line on stderr and exit status 2. The end
of a video or of the photos exits 0 (``loop`` starts them again; a video that ends well before
the frame count its container states is warned of: damaged); a device or stream that
disappears is reopened with backoff.

Example:
    balltrack run camera --set source=/dev/video0 --set width=640 --set height=480 \\
        --set calibration=camera.yaml
"""

import time

import zenoh

from balltrack.common import keys
from balltrack.common.config import ConfigError
from balltrack.common.images import bgr_to_message
from balltrack.common.memory import keep_freed_memory
from balltrack.common.messages import MessageError, encode, header
from balltrack.common.context import ServiceContext
from balltrack.common.runner import run_service
from balltrack.services.camera.calibration import CameraModel, pinhole, read_calibration
from balltrack.services.camera.config import LIVE_SETTINGS, CameraConfig
from balltrack.services.camera.source import FrameFeed, SourceError, open_source


def build(service: ServiceContext):
    config: CameraConfig = service.config
    try:
        calibration = read_calibration(config.calibration) if config.calibration else None
        spec, reader = open_source(config.source, config.width, config.height)
    except (SourceError, ValueError) as error:
        raise ConfigError(str(error)) from None
    started_with = config
    # Each frame's message is a new megabyte or more: kept, not faulted in again (common/memory.py).
    keep_freed_memory()
    images = service.publisher(keys.IMAGE_RAW, "Image")
    # Frames may be dropped when the link is congested (a late frame is worth less than the
    # next), but not the camera model that comes before a new frame size: a locator without it
    # locates that size's detections with the wrong intrinsics until the next one, a second on.
    infos = service.publisher(keys.CAMERA_INFO, "CameraInfo",
                              congestion_control=zenoh.CongestionControl.BLOCK)
    feed = FrameFeed(spec, reader, lambda: service.config, service.stop, service.log)
    models: dict[tuple[int, int], CameraModel] = {}
    latest: dict[str, dict] = {}

    def model_for(width: int, height: int) -> CameraModel:
        if (width, height) not in models:
            try:
                models[width, height] = (calibration.scaled_to(width, height) if calibration
                                         else pinhole(width, height, started_with.hfov))
            except ValueError as error:
                raise ConfigError(f"calibration: {error}") from None
            if calibration and (width, height) != (calibration.width, calibration.height):
                service.log.warning("frames are %dx%d, the calibration %dx%d: intrinsics scaled",
                                    width, height, calibration.width, calibration.height)
        return models[width, height]

    def on_camera_info_query(query) -> None:
        if "info" in latest:  # before the first frame the size is not known: no answer
            query.reply(query.key_expr, encode("CameraInfo", latest["info"]))

    service.queryable(keys.CAMERA_INFO, on_camera_info_query)
    service.live_settings = LIVE_SETTINGS
    service.stats.extra = feed.stats

    def loop(context: ServiceContext) -> None:
        next_info = 0.0
        announced_size = None
        try:
            for seq, image in enumerate(feed):
                started = time.perf_counter()
                stamp = time.time_ns()
                settings = context.config
                height, width = image.shape[:2]
                info = {"header": header(stamp, seq), **model_for(width, height).camera_info()}
                latest["info"] = info
                try:
                    message = bgr_to_message(image, stamp, seq, "camera", str(settings.encoding),
                                             settings.jpeg_quality)
                except MessageError as error:  # e.g. a photo larger than the contract allows
                    context.reject(context.keys(keys.IMAGE_RAW), f"frame {seq}: {error}")
                    continue
                # The camera_info first: a locator then knows the camera before the first
                # detection made from this frame reaches it, at once when the size changes
                # (photos of several sizes), not up to a second later.
                now = time.monotonic()
                if now >= next_info or (width, height) != announced_size:
                    infos.put(info)
                    next_info, announced_size = now + 1.0, (width, height)
                images.put(message)
                context.stats.record_duration(time.perf_counter() - started)
        finally:
            reader.close()
        if feed.ended:
            files = f"{reader.unreadable} unreadable file{'s' if reader.unreadable > 1 else ''}"
            context.log.info("end of %s %s after %d frames%s", spec.kind, spec.target, feed.frames,
                             f" ({files}, left out)" if reader.unreadable else "")
            context.stop.set()

    return loop


# The service's parameters (``balltrack run camera --help`` lists them); ``build`` wires it.
CONFIG = CameraConfig


def main(argv=None) -> int:
    return run_service("camera", CONFIG, build, argv, __doc__)
