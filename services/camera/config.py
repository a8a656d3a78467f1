"""Settings of the camera service: where frames come from, how fast, how they are sent, and the
camera's calibration.

Example ``camera.toml``::

    source = "/dev/video0"
    width = 640
    height = 480
    calibration = "camera.yaml"
"""

import enum
import math
from dataclasses import dataclass

from balltrack.common.config import ConfigError, check_fields, param


class Encoding(enum.StrEnum):
    # Member names equal their values (see services/simulator/config.py).
    jpeg = "jpeg"
    bgr8 = "bgr8"
    rgb8 = "rgb8"


@dataclass
class CameraConfig:
    """One camera's settings; the defaults open the first video device at its own size and rate."""

    # OpenCV opens all of them (cv2.VideoCapture; photos decoded by common.images.read_image, in
    # name order).
    source: str = param("0", "a device index (`0`) or path (`/dev/video0`), a video file or its URL "
                             "(`http://host/clip.mp4`), a folder or glob of images (`photos/*.jpg`), or "
                             "a live stream URL (`rtsp://...`, `http://host/video.mjpg`)")
    rate_hz: float = param(0.0, "frames per second published; 0 = the source's own: a video's frame rate, "
                                "a device's native rate, photos as fast as they load; can be changed live",
                           low=0.01, off=0, high=1000)
    loop: bool = param(False, "start a video or the photos again at the end (else the service exits 0 "
                              "there); can be changed live")
    # Devices choose the nearest size they have; files are never resized.
    width: int = param(0, "frame width asked of a device (px); 0 = its default", low=0, high=8192)
    height: int = param(0, "frame height asked of a device (px); 0 = its default", low=0, high=8192)
    encoding: Encoding = param(Encoding.jpeg, "published image encoding: `jpeg`, `bgr8` or `rgb8`; can be "
                                              "changed live")
    jpeg_quality: int = param(90, "JPEG quality (1-100); can be changed live", low=1, high=100)
    # Written by `balltrack calibrate`, or by ROS's camera_calibration.
    calibration: str = param("", "camera calibration file (ROS camera_info YAML: camera_matrix, plumb_bob "
                                 "distortion); empty = an ideal pinhole with `hfov`")
    # The simulator's camera and the paper's have 1.089 rad.
    hfov: float = param(1.089, "horizontal field of view (rad) of the ideal pinhole used without a "
                               "calibration file", above=0, below=math.pi)

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.source.strip():
            raise ConfigError("source: empty (a device index, a path or a URL)")
        if (self.width == 0) != (self.height == 0):
            raise ConfigError(f"width/height: give both or neither, got {self.width}x{self.height}")

    def preflight(self) -> None:
        """The source names something that exists, one of its photos reads when it names
        photos, and the calibration file reads (see ``common.runner.preflight``); the service
        opens both again when it starts (a device or stream only then)."""
        from balltrack.services.camera.calibration import read_calibration
        from balltrack.services.camera.source import SourceError, open_photos, parse_source

        try:
            spec = parse_source(self.source)
            if spec.kind == "images":
                open_photos(spec)
            if self.calibration:
                read_calibration(self.calibration)
        except (SourceError, ValueError) as error:
            raise ConfigError(str(error)) from None


# What a running camera can change through camera/config; the rest takes a restart.
LIVE_SETTINGS = {"rate_hz", "loop", "encoding", "jpeg_quality"}
