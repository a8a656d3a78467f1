"""The pinhole camera model: intrinsics in pixels, as the contract's CameraInfo carries them,
with the ``plumb_bob`` lens' distortion coefficients. The locator inverts it; the camera
service's calibrations (``services/camera/calibration.py``) are checked by it."""

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from balltrack.common.messages import MAX_IMAGE_SIDE, shorten

DISTORTION_MODELS = ("plumb_bob", "", "none")


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels, as carried by the contract's CameraInfo, and the lens'
    ``plumb_bob`` distortion coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])`` (empty or all
    zero: an ideal pinhole)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion: tuple[float, ...] = ()

    def __post_init__(self):
        check_intrinsics(self.fx, self.fy, self.cx, self.cy, self.width, self.height, self.distortion)

    @property
    def distorted(self) -> bool:
        return any(value != 0.0 for value in self.distortion)

    @property
    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_fov(cls, width: int, height: int, h_fov: float) -> "Intrinsics":
        """Square pixels, principal point at ``(W/2, H/2)``, horizontal field of view ``h_fov``.

        The principal point matches the contract's normalisation ``x = (u - W/2) / (W/2)``.
        """
        if not 0.0 < h_fov < math.pi:
            raise ValueError(f"h_fov: must be in (0, pi), got {h_fov!r}")
        focal = (width / 2.0) / math.tan(h_fov / 2.0)
        return cls(focal, focal, width / 2.0, height / 2.0, int(width), int(height))

    @classmethod
    def from_camera_info(cls, info: Mapping) -> "Intrinsics":
        """From a decoded CameraInfo message (a dict with fx, fy, cx, cy, width, height, and
        optionally distortion_model and d)."""
        model = info.get("distortion_model", "")
        if model not in DISTORTION_MODELS:
            raise ValueError(f"distortion_model: {model!r} is not one of plumb_bob, none")
        distortion = tuple(float(value) for value in info.get("d", ())) if model == "plumb_bob" else ()
        return cls(float(info["fx"]), float(info["fy"]), float(info["cx"]), float(info["cy"]),
                   int(info["width"]), int(info["height"]), distortion)

    @property
    def h_fov(self) -> float:
        """Horizontal field of view (radians) from the left to the right image border."""
        return math.atan(self.cx / self.fx) + math.atan((self.width - self.cx) / self.fx)

    @property
    def v_fov(self) -> float:
        """Vertical field of view (radians) from the top to the bottom image border."""
        return math.atan(self.cy / self.fy) + math.atan((self.height - self.cy) / self.fy)


def check_intrinsics(fx: float, fy: float, cx: float, cy: float, width: int, height: int,
                     distortion: tuple[float, ...]) -> None:
    """ValueError naming the first number that no camera has: a focal length that is not a
    positive number of pixels, a principal point that is not finite, an empty or absurdly large
    image (the contract's CameraInfo bound), or
    distortion coefficients other than 0, 4, 5 or 8 finite numbers."""
    for name, value in (("fx", fx), ("fy", fy)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name}: must be a positive focal length in pixels, got {value!r}")
    for name, value in (("cx", cx), ("cy", cy)):
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value!r}")
    if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE):
        raise ValueError(f"image size (width x height) must be 1 to {MAX_IMAGE_SIDE} pixels a side, "
                         f"got {shorten(width, 20)}x{shorten(height, 20)}")
    if len(distortion) not in (0, 4, 5, 8) or not all(math.isfinite(value) for value in distortion):
        raise ValueError(f"distortion: expected 0, 4, 5 or 8 finite coefficients, got {distortion!r}")
