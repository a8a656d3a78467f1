"""Washed-out highlights: a second measurement of candidates whose lit side the colour mask
misses (part of step 6, see ``detector.py``).

Where strong light falls on a ball, its felt turns pale: the saturation of a highlight drops
below ``s_min`` while its brightness rises towards white, so the colour mask holds only the
ball's rim (a ring or a crescent) and the candidate fails the fill check. A highlight is
still part of the ball: it is paler and brighter than the ball's colour around it, and it ends
where the ball does. So a large candidate that fails its checks is measured again on the
colour mask joined with the pale, bright pixels around it; white clutter around a yellow-green
patch (paper, a wall, the sky) goes on past the circle and fails that measurement's leak and
outside checks, as a large area of colour does.
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.checks import SURE_SIZE, CandidateMetrics, MaskMetrics, measure_mask
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, box_around, disc
from balltrack.services.detector.mask import EXPLAINED, ColourPlanes, hue_mask

# Below this saturation (0-255) a pixel is near white and its hue is noise; paler pixels
# above it must have the target's hue (a highlight on the felt keeps it).
NEAR_WHITE = 25
# The candidates looked at again: at least SURE_SIZE times small_radius (a highlight on a
# few pixels of colour cannot be told from a glint on clutter), failing on their fill.
HIGHLIGHT_SIZE = SURE_SIZE


def needs_highlight(metrics: CandidateMetrics, config: DetectorConfig) -> bool:
    """Whether a measured candidate may be a ball whose highlight the colour mask misses."""
    return metrics.size >= HIGHLIGHT_SIZE and metrics.mask.fill < config.min_fill_ratio


def pale_pixels(patch_bgr: np.ndarray, config: DetectorConfig, brightness: float) -> np.ndarray:
    """Boolean plane of a BGR patch: pixels below the colour range's saturation, at least
    ``brightness`` bright (V, 0-255), and either near white or of the target's hue."""
    kernel = config.blur_kernel
    blurred = cv2.GaussianBlur(patch_bgr, (kernel, kernel), 0) if kernel > 1 else patch_bgr
    hsv = cv2.cvtColor(blurred, cv2.COLOR_BGR2HSV)
    hue, saturation, value = (cv2.extractChannel(hsv, channel) for channel in range(3))
    hue_ok = hue_mask(hue, config) == 255
    return (saturation < config.s_min) & (value >= brightness) & ((saturation < NEAR_WHITE) | hue_ok)


def highlight_metrics(candidate: Candidate, mask: np.ndarray, planes: ColourPlanes,
                      config: DetectorConfig) -> MaskMetrics | None:
    """How the circle sits on ``mask`` joined with the pale pixels at least as bright as the
    ball's colour in it (its mean V); None when it holds no colour or cannot be judged."""
    height, width = mask.shape
    x, y, radius = candidate.x, candidate.y, candidate.radius
    # (everything measure_mask reads: rim samples, the outer ring, the edge rays to 1.5 r)
    box = box_around(x, y, 1.6 * radius + 4, width, height)
    if box is None:
        return None
    left, top = box[1].start, box[0].start
    patch_mask = mask[box]
    patch = planes.frame[box]
    colour = disc(patch_mask.shape, x - left, y - top, 0.85 * radius)
    np.bitwise_and(colour, planes.mask[box], out=colour)
    if not cv2.countNonZero(colour):
        return None
    value = np.max(patch, axis=2)
    brightness = cv2.mean(value, colour)[0]
    joined = patch_mask.copy()
    joined[pale_pixels(patch, config, math.ceil(brightness)) & (patch_mask == 0)] = 255
    # (accepted balls stay explained: a highlight is no reason to measure them again)
    joined[patch_mask == EXPLAINED] = EXPLAINED
    return measure_mask(Candidate(x - left, y - top, radius), joined)
