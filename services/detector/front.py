"""Balls in front of other balls: circles found on the frame's brightness, not on the mask.

A ball partly hiding another of the same colour makes one mask blob with them, often a capsule
with no waist or concave point, so nothing in the mask's shape tells where one ball ends (see
arcs.py for the blobs that do have a waist). The frame does show it: the front ball's rim is an
edge in brightness all round, against the ground on its free side and against the ball behind
(shading, the shadow it casts on it, the behind ball's other light) where the colour goes on.

So inside a blob that is not one clean ball, circles are looked for on the frame's brightness
gradient (Hough) and kept only as a ball in front when their whole rim is such an edge
(FRONT_RIM_EDGES of it, the gradient across the rim, not along it), their disc is colour
(FRONT_FILL) and a good part of their rim is the blob's own outline (FRONT_MASK_SUPPORT: the
ball is one of the blob's, not a pattern on it). The ball behind is then what the front ball
leaves of the blob, searched as any rest of a blob is (see BallDetector._accept).
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.checks import CandidateMetrics
from balltrack.services.detector.measure import colour_stats, measure_mask
from balltrack.services.detector.geometry import Candidate, box_around, circle_overlap, disc, rim_directions
from balltrack.services.detector.jit import compiled
from balltrack.services.detector.proposals import FrameSearch

# The front ball's rim is a brightness edge along this share of its length at least: a ball's
# outline is crisp all round, while a circle that Hough strings through texture, a logo or a
# lamp's reflection is an edge along some arcs only.
FRONT_RIM_EDGES = 0.8
# A rim sample is an edge where the brightness changes across the rim by at least this share of
# the frame's reference level per pixel (about 8 grey levels across a 3-pixel edge in a
# normally lit frame; the boundary between two balls of one colour is a faint shading edge).
EDGE_STEP = 0.03
# At least this much of the front ball's rim is the blob's outline (the rest runs over the ball
# behind it), and its disc is all colour.
FRONT_MASK_SUPPORT = 0.35
FRONT_FILL = 0.9
# Hough on the frame's brightness: lower thresholds than on the mask, whose edges are binary; a
# shading edge between two balls is faint, the rim check above does the judging.
FRONT_CANNY = 60
FRONT_ACCUMULATOR = 15
FRONT_CIRCLES = 4
# Hough's cost grows with the patch, its edges and its radius range: a blob larger than this
# (px, at processing size) is searched shrunk to it (and judged there), for balls of at least
# the smallest searched radius at that size. A ball and the one behind it make a blob about two
# balls long and one wide, whose balls keep about twice that radius at this size; full detail
# in heaps and yellow-green areas made photos ~15 % slower at the median (at 128 x 128).
FRONT_SEARCH_AREA = 48 * 48
# A ball's face is smooth shading next to its outline: an edge counts only where it is this many
# times the median gradient inside the circle (0.7 r), so that grass, gravel or a patterned
# cloth, edges everywhere, makes no rim of its own.
FRONT_CONTRAST = 2.0
# Accepted balls overlap by less than OVERLAP (of the smaller one's disc): two circles sharing
# more are two readings of one ball. A ball behind one in front of it is hidden as far as it
# lies behind it, so next to a ball found in front it may be overlapped up to BEHIND_OVERLAP:
# what shows of it is judged as a ball on its own (the front ball's disc explained), and a
# ball hidden further shows a sliver no circle can be told from, while two readings of one
# ball overlap nearly wholly.
OVERLAP = 0.3
BEHIND_OVERLAP = 0.75
# Median first: the impulse noise of some cameras' JPEGs makes rings of gradient of its own.
_MEDIAN_KERNEL = 3
_BLUR_KERNEL = (5, 5)


def front_balls(contour: np.ndarray, search: FrameSearch, mask: np.ndarray,
                smallest: float) -> list[tuple[Candidate, CandidateMetrics]]:
    """Balls in front of others in one blob (its contour) of ``mask``, measured on it, none
    smaller than ``smallest`` (px); their metrics' ``front_edges`` is the share of their rim
    that is a brightness edge on the frame."""
    # (a ball in front of another and the one behind it: room for two balls, each mostly seen;
    # the frame inside a piece that found balls leave of a blob was searched with the blob)
    if mask is not search.mask or cv2.contourArea(contour) < 2 * 0.8 * math.pi * smallest * smallest:
        return []
    left, top, blob_width, blob_height = cv2.boundingRect(contour)
    largest = min(search.max_radius, 0.55 * min(blob_width, blob_height) + 2)
    if largest <= smallest:
        return []
    height, width = mask.shape
    pad = 4
    x0, y0 = max(0, left - pad), max(0, top - pad)
    x1, y1 = min(width, left + blob_width + pad), min(height, top + blob_height + pad)
    shrink = min(1.0, math.sqrt(FRONT_SEARCH_AREA / float((y1 - y0) * (x1 - x0))))
    # (a ball is told from clutter at ``smallest`` px and more: so too at the searched size)
    if largest * shrink <= smallest:
        return []
    patch = search.planes.frame[y0:y1, x0:x1]
    if shrink < 1.0:
        patch = cv2.resize(patch, None, fx=shrink, fy=shrink, interpolation=cv2.INTER_AREA)
    grey = cv2.GaussianBlur(cv2.medianBlur(cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY), _MEDIAN_KERNEL),
                            _BLUR_KERNEL, 0)
    circles = cv2.HoughCircles(grey, cv2.HOUGH_GRADIENT, dp=1.0, minDist=max(2.0, smallest),
                               param1=FRONT_CANNY, param2=FRONT_ACCUMULATOR,
                               minRadius=int(math.ceil(smallest)), maxRadius=int(math.ceil(largest * shrink)))
    if circles is None:
        return []
    # (Sobel's 3x3 kernel weighs a one-pixel step 8 times; an edge is steeper in a shrunk patch)
    levels = grey.astype(np.float32) / 8.0
    gradient_x = cv2.Sobel(levels, cv2.CV_32F, 1, 0)
    gradient_y = cv2.Sobel(levels, cv2.CV_32F, 0, 1)
    magnitude = cv2.magnitude(gradient_x, gradient_y)
    step = EDGE_STEP * search.planes.reference / shrink
    found: list[tuple[Candidate, CandidateMetrics]] = []
    for cx, cy, radius in circles[0][:FRONT_CIRCLES]:
        cx, cy, radius = float(cx), float(cy), float(radius)
        # (the plain step first: most circles fail it, and the face's median costs more)
        if rim_edge_share(gradient_x, gradient_y, cx, cy, radius, step) < FRONT_RIM_EDGES:
            continue
        face = inner_gradient(magnitude, cx, cy, 0.7 * radius)
        edges = rim_edge_share(gradient_x, gradient_y, cx, cy, radius, max(step, FRONT_CONTRAST * face))
        if edges < FRONT_RIM_EDGES:
            continue
        circle = Candidate(cx / shrink + x0, cy / shrink + y0, radius / shrink, in_front=True)
        on_mask = measure_mask(circle, mask)
        if on_mask is None or on_mask.fill < FRONT_FILL or on_mask.support < FRONT_MASK_SUPPORT:
            continue
        found.append((circle, CandidateMetrics(mask=on_mask, colour=colour_stats(circle, search.planes),
                                               size=circle.radius / search.small_radius,
                                               front_edges=edges)))
    return found


def rim_edge_share(gradient_x: np.ndarray, gradient_y: np.ndarray, x: float, y: float,
                   radius: float, step: float) -> float:
    """Share of a circle's rim samples (inside the gradient planes) where the brightness changes
    across the rim by at least ``step`` per pixel, within a pixel of the rim either way (the
    circle Hough returns is good to about a pixel)."""
    samples = int(min(96, max(24, 2 * math.pi * radius)))
    directions = rim_directions(samples)
    return rim_edges(np.ascontiguousarray(gradient_x), np.ascontiguousarray(gradient_y), float(x), float(y),
                     float(radius), float(step), directions[0], directions[1])


@compiled
def rim_edges(gradient_x: np.ndarray, gradient_y: np.ndarray, x: float, y: float, radius: float,
              step: float, cos: np.ndarray, sin: np.ndarray) -> float:
    """``rim_edge_share`` over the rim samples in the directions ``cos``, ``sin``: at each, the
    steepest change across the rim of the three points one pixel in, on and one pixel out.
    (~45 numpy calls on a few dozen values took ~0.23 ms per circle.)"""
    height, width = gradient_x.shape
    samples = cos.size
    steep = 0
    for index in range(samples):
        strongest = 0.0
        inside = False
        for offset in (-1.0, 0.0, 1.0):
            column = int(np.rint(x + (radius + offset) * cos[index]))
            row = int(np.rint(y + (radius + offset) * sin[index]))
            if 0 <= column < width and 0 <= row < height:
                inside = True
                across = abs(np.float64(gradient_x[row, column]) * cos[index]
                             + np.float64(gradient_y[row, column]) * sin[index])
                strongest = max(strongest, across)
        # (a sample outside the planes is no edge, whatever the step: it may be 0)
        if inside:
            steep += strongest >= step
    return steep / samples


def inner_gradient(magnitude: np.ndarray, x: float, y: float, radius: float) -> float:
    """Median gradient magnitude over the disc of ``radius`` around (x, y) (inside the plane)."""
    box = box_around(x, y, radius, magnitude.shape[1], magnitude.shape[0])
    if box is None:
        return 0.0
    inside = disc(magnitude[box].shape, x - box[1].start, y - box[0].start, radius) > 0
    values = magnitude[box][inside]
    return float(np.median(values)) if values.size else 0.0


def may_overlap(first: Candidate, second: Candidate) -> bool:
    """Whether two circles may both be accepted balls, by how much they overlap (see OVERLAP)."""
    limit = BEHIND_OVERLAP if first.in_front or second.in_front else OVERLAP
    return circle_overlap(first, second) < limit
