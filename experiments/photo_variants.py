"""Altered copies of labelled photos, to see how the detector's photo scores hold up on scenes a
little unlike the development sets (``real_photos --variants``).

The development sets are small, and larger sets that the project never sees judge the detector.
A detector that generalises keeps its recall and false-positive rate when a photo is mirrored,
taken from a little further away, exposed differently, white-balanced warmer or colder,
compressed harder, noisier or speckled; one fitted to the development photos' particulars
does not. Each variant is a pure function of an image and its labelled boxes (the boxes moved
with the image). Nothing here is tuned on: the variants are fixed and only reported.

``NUDGES`` are changes no one would see (exposure by 1-3 %, the frame moved by a pixel or two),
as two shots of one scene differ: a detector whose decisions keep a margin from its thresholds
gives about the same figures on each (``real_photos.nudged``).
"""

from typing import Callable

import cv2
import numpy as np

Boxes = list[dict]
Variant = Callable[[np.ndarray, Boxes], tuple[np.ndarray, Boxes]]

# Seed of the noise variant (the same noise on every run).
NOISE_SEED = 11


def mirrored(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
    """Left and right swapped: nothing about a ball depends on the side it is on."""
    width = image.shape[1]
    return cv2.flip(image, 1), [{**box, "x": width - box["x"] - box["w"]} for box in boxes]


def scaled(factor: float) -> Variant:
    """The photo at ``factor`` of its size (INTER_AREA): the same scene seen from further away;
    balls that shrink below the counted size drop out of the count."""
    def variant(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
        height, width = image.shape[:2]
        size = (max(8, round(width * factor)), max(8, round(height * factor)))
        return (cv2.resize(image, size, interpolation=cv2.INTER_AREA),
                [{key: box[key] * factor for key in ("x", "y", "w", "h")} for box in boxes])
    return variant


def shifted(columns: int, rows: int) -> Variant:
    """The frame moved: its first ``columns`` columns and ``rows`` rows cut off (the camera
    turned by as many pixels)."""
    def variant(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
        return (np.ascontiguousarray(image[rows:, columns:]),
                [{**box, "x": box["x"] - columns, "y": box["y"] - rows} for box in boxes])
    return variant


def exposed(gain: float) -> Variant:
    """Every channel times ``gain`` (clipped at 255): under- or overexposure."""
    def variant(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
        return cv2.convertScaleAbs(image, alpha=gain), boxes
    return variant


def white_balanced(red: float, blue: float) -> Variant:
    """Red and blue channels times ``red`` and ``blue``: a warmer or colder light or white balance."""
    def variant(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
        balanced = image.astype(np.float32) * np.array([blue, 1.0, red], np.float32)
        return np.clip(np.rint(balanced), 0, 255).astype(np.uint8), boxes
    return variant


def recompressed(quality: int) -> Variant:
    """The photo JPEG-encoded again at ``quality``: blockier, with colour bleeding at edges."""
    def variant(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
        ok, buffer = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:
            raise ValueError("JPEG encoding failed")
        return cv2.imdecode(buffer, cv2.IMREAD_COLOR), boxes
    return variant


def noisy(sigma: float) -> Variant:
    """Gaussian sensor noise of ``sigma`` grey levels per channel (seeded: the same each run)."""
    def variant(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
        noise = np.random.default_rng(NOISE_SEED).normal(0.0, sigma, image.shape)
        return np.clip(np.rint(image + noise), 0, 255).astype(np.uint8), boxes
    return variant


def speckled(share: float) -> Variant:
    """``share`` of the pixels turned black or white, half each (seeded: the same each run):
    impulse noise, as dead and hot pixels or a noisy transmission leave, and as most photos
    of tennis_floor_dev already carry (in 32 of its 49, 1-3 % of the pixels are more than 90
    grey levels from their 3x3 median)."""
    def variant(image: np.ndarray, boxes: Boxes) -> tuple[np.ndarray, Boxes]:
        draw = np.random.default_rng(NOISE_SEED).random(image.shape[:2])
        speckles = image.copy()
        speckles[draw < share / 2] = 0
        speckles[(draw >= share / 2) & (draw < share)] = 255
        return speckles, boxes
    return variant


VARIANTS: dict[str, Variant] = {
    "mirrored": mirrored,
    "smaller 0.75": scaled(0.75),
    "darker 0.6": exposed(0.6),
    "brighter 1.4": exposed(1.4),
    "warmer": white_balanced(red=1.1, blue=0.9),
    "colder": white_balanced(red=0.9, blue=1.1),
    "jpeg 40": recompressed(40),
    "noise 6": noisy(6.0),
    "specks 2%": speckled(0.02),
}

NUDGES: dict[str, Variant] = {
    **{f"exposure x{gain:g}": exposed(gain) for gain in (0.97, 0.98, 0.99, 1.01, 1.02, 1.03)},
    **{f"moved {columns},{rows} px": shifted(columns, rows)
       for columns, rows in ((1, 0), (0, 1), (1, 1), (2, 0), (0, 2), (2, 2))},
}
