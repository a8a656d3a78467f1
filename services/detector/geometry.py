"""Circles on pixel grids, shared by every stage of the detector: the candidate circle, the box
of frame around it, sub-pixel discs drawn for the checks, rays around a centre, overlaps.

Pure numpy/OpenCV; no stage logic here.
"""

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

# Fractional bits of the sub-pixel circles drawn for the checks.
FIXED_BITS = 4
# gaussian_blur's choice of OpenCV filter: larger parts are blurred as a separable filter.
SEPARABLE_BLUR_PIXELS = 256 * 256


@dataclass
class Candidate:
    """A circle that may be a ball: centre (x, y) and radius in pixels of the processed frame."""

    x: float
    y: float
    radius: float
    score: float = 0.0
    # A small candidate is kept only if its outline is found on the frame (see
    # BallDetector._outlines).
    needs_outline: bool = False
    # Partly hidden behind something straight: its outline is not looked for (see occlusion.py).
    partly_hidden: bool = False
    # Found in front of another ball by its rim on the frame (see front.py).
    in_front: bool = False


@functools.lru_cache(maxsize=128)
def rim_directions(samples: int) -> np.ndarray:
    """Rows cos, sin, cos, sin of ``samples`` evenly spaced angles (cached: used per circle)."""
    angles = np.linspace(0.0, 2 * math.pi, samples, endpoint=False)
    cos, sin = np.cos(angles), np.sin(angles)
    return np.stack([cos, sin, cos, sin])


def box_around(x: float, y: float, reach: float, width: int,
               height: int) -> tuple[slice, slice] | None:
    """Rows and columns of the frame within ``reach`` of (x, y); None when empty."""
    left, right = max(0, int(math.floor(x - reach))), min(width, int(math.ceil(x + reach)) + 1)
    top, bottom = max(0, int(math.floor(y - reach))), min(height, int(math.ceil(y + reach)) + 1)
    if left >= right or top >= bottom:
        return None
    return slice(top, bottom), slice(left, right)


def fixed_point(x: float, y: float) -> tuple[int, int]:
    """A sub-pixel point in OpenCV's fixed-point drawing units (FIXED_BITS fractional bits)."""
    return int(round(x * (1 << FIXED_BITS))), int(round(y * (1 << FIXED_BITS)))


def fixed_radius(radius: float) -> int:
    """A sub-pixel radius in OpenCV's fixed-point drawing units (never negative)."""
    return max(0, int(round(radius * (1 << FIXED_BITS))))


@functools.lru_cache(maxsize=None)
def _gaussian_weights(kernel: int) -> np.ndarray:
    return cv2.getGaussianKernel(kernel, 0)


def gaussian_blur(image: np.ndarray, kernel: int) -> np.ndarray:
    """``cv2.GaussianBlur(image, (kernel, kernel), 0)`` (the same weights and border), within
    one grey level: ``kernel`` <= 1 returns ``image`` itself.

    Parts of more than SEPARABLE_BLUR_PIXELS pixels are filtered as a separable filter on the
    weights in floating point: OpenCV's GaussianBlur with ``sigma`` 0 takes a fixed-point path
    that slows down on parts larger than the CPU's cache, 1.09 against 0.57 ms on a 640x480
    photo, 0.35 against 0.24 ms on 400x300, but 0.07 against 0.08 ms on 200x200 (5x5, BGR).
    """
    if kernel <= 1:
        return image
    if image.shape[0] * image.shape[1] <= SEPARABLE_BLUR_PIXELS:
        return cv2.GaussianBlur(image, (kernel, kernel), 0)
    weights = _gaussian_weights(kernel)
    return cv2.sepFilter2D(image, -1, weights, weights)


def brightest_channel(image_bgr: np.ndarray) -> np.ndarray:
    """The brightest of each pixel's three channels (HSV's V) of a BGR image or a part of one.

    (OpenCV's per-channel maximum: numpy's ``max(axis=2)`` reduces over the three channels
    pixel by pixel and is ~20x slower, 2.4 ms on a 200x200 patch on this project's machines.)
    """
    return cv2.max(cv2.max(cv2.extractChannel(image_bgr, 0), cv2.extractChannel(image_bgr, 1)),
                   cv2.extractChannel(image_bgr, 2))


def disc(shape: tuple[int, ...], x: float, y: float, radius: float) -> np.ndarray:
    """uint8 0/255 image of a filled disc (sub-pixel centre and radius)."""
    image = np.zeros(shape[:2], np.uint8)
    cv2.circle(image, fixed_point(x, y), fixed_radius(radius), 255, -1, cv2.LINE_8, FIXED_BITS)
    return image


def circle_overlap(first: Candidate, second: Candidate) -> float:
    """Intersection area of two circles divided by the smaller circle's area."""
    distance = math.hypot(first.x - second.x, first.y - second.y)
    r1, r2 = first.radius, second.radius
    if distance >= r1 + r2:
        return 0.0
    small = min(r1, r2)
    if distance <= abs(r1 - r2):
        return 1.0

    def clamped_acos(value: float) -> float:
        return math.acos(max(-1.0, min(1.0, value)))

    part1 = r1 * r1 * clamped_acos((distance ** 2 + r1 ** 2 - r2 ** 2) / (2 * distance * r1))
    part2 = r2 * r2 * clamped_acos((distance ** 2 + r2 ** 2 - r1 ** 2) / (2 * distance * r2))
    part3 = 0.5 * math.sqrt(max(0.0, (-distance + r1 + r2) * (distance + r1 - r2)
                                * (distance - r1 + r2) * (distance + r1 + r2)))
    return (part1 + part2 - part3) / (math.pi * small * small)
