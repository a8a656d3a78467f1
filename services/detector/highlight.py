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

When the highlight covers nearly all of the ball, the colour left is a crescent on its shaded
side, whose enclosing circle and Hough circles (within the crescent's box) are not the ball's:
such a blob proposes the circle of its outer arc, the ball's rim (``crescent_candidates``).
"""

import dataclasses
import math

import cv2
import numpy as np

from balltrack.services.detector.checks import SURE_SIZE, CandidateMetrics, judge
from balltrack.services.detector.measure import NO_COLOUR, MaskMetrics, colour_stats, measure_mask
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.fit import robust_circle
from balltrack.services.detector.geometry import Candidate, box_around, brightest_channel, disc, gaussian_blur
from balltrack.services.detector.mask import EXPLAINED, ColourPlanes, hue_mask

# Below this saturation (0-255) a pixel is near white and its hue is noise; paler pixels
# above it must have the target's hue (a highlight on the felt keeps it).
NEAR_WHITE = 25
# The candidates looked at again: at least SURE_SIZE times small_radius (a highlight on a
# few pixels of colour cannot be told from a glint on clutter), failing on their fill.
HIGHLIGHT_SIZE = SURE_SIZE
# A highlight across most of a ball leaves a crescent of colour, which no blob's enclosing
# circle or Hough circle within its box finds. Its convex hull is the crescent's outer arc,
# the ball's rim, closed by the chord between its horns: at least CRESCENT_POINTS of the hull's
# vertices lie within CRESCENT_TOLERANCE (of the radius) of one circle, CRESCENT_SPAN round it,
# and the blob covers at most CRESCENT_COVER of that circle (more: a disc with a notch, whose
# enclosing circle is proposed already).
CRESCENT_POINTS = 10
CRESCENT_TOLERANCE = ((0.1, 1.5), (0.05, 1.0))
CRESCENT_SPAN = math.radians(120)
CRESCENT_COVER = 0.5
# The middle of the disc (this share of its radius) must be the highlight.
CRESCENT_MIDDLE = 0.3


def needs_highlight(metrics: CandidateMetrics, config: DetectorConfig) -> bool:
    """Whether a measured candidate may be a ball whose highlight the colour mask misses.

    (Joining the highlight only adds mask: the leak and outside only grow, and the rim's
    support is at most 1 - leak. A candidate whose leak and outside already fail judge's rim
    support or outside check fails them joined as well, and is not measured again.)
    """
    on_mask = metrics.mask
    return (metrics.size >= HIGHLIGHT_SIZE and on_mask.fill < config.min_fill_ratio
            and on_mask.outside <= config.max_outside_ratio
            and 1.0 - on_mask.leak >= config.min_edge_support + on_mask.leak + on_mask.outside)


def pale_pixels(patch_bgr: np.ndarray, config: DetectorConfig, brightness: float) -> np.ndarray:
    """Boolean plane of a BGR patch: pixels below the colour range's saturation, at least
    ``brightness`` bright (V, 0-255), and either near white or of the target's hue."""
    hsv = cv2.cvtColor(gaussian_blur(patch_bgr, config.blur_kernel), cv2.COLOR_BGR2HSV)
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
    value = brightest_channel(patch)
    brightness = cv2.mean(value, colour)[0]
    joined = patch_mask.copy()
    joined[pale_pixels(patch, config, math.ceil(brightness)) & (patch_mask == 0)] = 255
    # (accepted balls stay explained: a highlight is no reason to measure them again)
    joined[patch_mask == EXPLAINED] = EXPLAINED
    return measure_mask(Candidate(x - left, y - top, radius), joined)


def crescent_candidates(contour: np.ndarray, mask: np.ndarray, planes: ColourPlanes, small_radius: float,
                        max_radius: float, config: DetectorConfig) -> list[tuple[Candidate, CandidateMetrics]]:
    """The circle of a crescent blob's outer arc (see crescent_circle), measured on ``mask``
    (with its highlight when that makes it pass); [] when the blob is no crescent."""
    circle = crescent_circle(contour, small_radius, max_radius)
    if circle is None or not pale_middle(circle, contour, planes, config):
        return []
    on_mask = measure_mask(circle, mask)
    if on_mask is None:
        return []
    size = circle.radius / small_radius
    # (a crescent fails on its fill unless its highlight is joined: when that cannot save it,
    # its colour need not be measured)
    if on_mask.fill < config.min_fill_ratio and not needs_highlight(CandidateMetrics(on_mask, NO_COLOUR, size),
                                                                    config):
        return []
    metrics = CandidateMetrics(on_mask, colour_stats(circle, planes), size=size)
    if needs_highlight(metrics, config) and judge(metrics, config) is None:
        joined = highlight_metrics(circle, mask, planes, config)
        if joined is not None:
            highlighted = dataclasses.replace(metrics, mask=joined, highlighted=True)
            if judge(highlighted, config) is not None:
                metrics = highlighted
    return [(circle, metrics)]


def pale_middle(circle: Candidate, contour: np.ndarray, planes: ColourPlanes, config: DetectorConfig) -> bool:
    """Whether the middle of a crescent's circle (within CRESCENT_MIDDLE of its radius) is its
    highlight: mostly pale pixels at least as bright as the crescent's colour. (Else the joined
    highlight cannot fill the disc: a cheap look before measuring it.)"""
    height, width = planes.mask.shape
    middle = box_around(circle.x, circle.y, CRESCENT_MIDDLE * circle.radius, width, height)
    if middle is None:
        return False
    left, top, blob_width, blob_height = cv2.boundingRect(contour)
    blob = (slice(top, top + blob_height), slice(left, left + blob_width))
    brightness = cv2.mean(brightest_channel(planes.frame[blob]), cv2.inRange(planes.mask[blob], 255, 255))[0]
    pale = pale_pixels(planes.frame[middle], config, math.ceil(brightness))
    return np.count_nonzero(pale) >= 0.5 * pale.size


def crescent_circle(contour: np.ndarray, small_radius: float, max_radius: float) -> Candidate | None:
    """The circle of a crescent blob's outer arc (see CRESCENT_POINTS), when the blob is one
    and the circle is large enough to be looked at with its highlight; else None.

    Fitted to the hull's vertices, then to the outline's pixels near it: not refined on the
    mask's boundary as other proposals are, whose pixels near the circle include the
    crescent's inner arc and would pull it inwards.
    """
    # (an arc of CRESCENT_SPAN or more has an enclosing circle of at least sin(span / 2) of its
    # radius: a blob too full of that circle cannot cover at most CRESCENT_COVER of its own)
    _, enclosing = cv2.minEnclosingCircle(contour)
    area = cv2.contourArea(contour)
    if area > CRESCENT_COVER * math.pi * (enclosing / math.sin(CRESCENT_SPAN / 2)) ** 2:
        return None
    hull = cv2.convexHull(contour).reshape(-1, 2).astype(np.float64)
    if len(hull) < CRESCENT_POINTS:
        return None
    px, py = hull[:, 0], hull[:, 1]
    fitted = robust_circle(px, py, float(px.mean()), float(py.mean()), float(enclosing),
                           ((0.5, 3.0),) + CRESCENT_TOLERANCE, geometric=False)
    if fitted is None:
        return None
    centre_x, centre_y, radius, on_circle = fitted
    if (np.count_nonzero(on_circle) < CRESCENT_POINTS
            or area > CRESCENT_COVER * math.pi * radius * radius
            or not HIGHLIGHT_SIZE * small_radius <= radius <= max_radius):
        return None
    angles = np.sort(np.arctan2(py[on_circle] - centre_y, px[on_circle] - centre_x))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * math.pi]))
    if 2 * math.pi - float(gaps.max()) < CRESCENT_SPAN:
        return None
    outline = contour.reshape(-1, 2).astype(np.float64)
    refined = robust_circle(outline[:, 0], outline[:, 1], centre_x, centre_y, radius, CRESCENT_TOLERANCE,
                            geometric=True)
    if refined is not None:
        centre_x, centre_y, radius = refined[:3]
    # (outline pixels are the mask's outermost, half a pixel inside its edge)
    return Candidate(float(centre_x), float(centre_y), float(radius) + 0.5)
