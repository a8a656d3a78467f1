"""Proposals: step 5 of the detector (see ``detector.py``), circles that may be balls.

Per mask blob: its enclosing circle, and unless that circle is already a clean isolated ball,
the Hough circle transform (cv2.HoughCircles with ``dp min_dist param1 param2``, radii in
``min_radius..max_radius``) inside the blob's box, which splits touching balls and finds balls
joined to other yellow-green things. Proposals are refined (``fit.py``) and checked
(``checks.py``) by the detector.
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate
from balltrack.services.detector.mask import ColourPlanes

# Hough circles per mask blob: beyond the strongest few they are duplicates or clutter.
HOUGH_CIRCLES_PER_BLOB = 4
HOUGH_CIRCLES_SCANNED = 40
_BOUNDARY_KERNEL = np.ones((3, 3), np.uint8)


@dataclass
class FrameSearch:
    """What the candidate search of one frame shares (all at processing size)."""

    planes: ColourPlanes
    boundary_x: np.ndarray  # mask boundary pixels (frame border excluded), in row order
    boundary_y: np.ndarray
    min_radius: float
    max_radius: float
    small_radius: float
    scale: float            # processing size / input size


def mask_blobs(mask: np.ndarray) -> list[np.ndarray]:
    """Outer contours of the colour mask's blobs."""
    # (found in the box around the mask's pixels, with a blank pixel more each way where the
    # frame has one: OpenCV copies the whole image it is given, most of it blank here)
    height, width = mask.shape
    left, top, box_width, box_height = cv2.boundingRect(mask)
    if not box_width:
        return []
    right, bottom = min(width, left + box_width + 1), min(height, top + box_height + 1)
    left, top = max(0, left - 1), max(0, top - 1)
    contours, _ = cv2.findContours(mask[top:bottom, left:right], cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_SIMPLE, offset=(left, top))
    return list(contours)


def boundary_points(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows (float64, in row order) of the mask's boundary pixels, leaving out
    the frame's border: there the mask's edge is the frame's, not the ball's."""
    height, width = mask.shape
    # Only the box around the mask's pixels is searched, with a pixel more each way (blank,
    # or the frame's border), so its erosion is the whole mask's.
    left, top, box_width, box_height = cv2.boundingRect(mask)
    if not box_width:
        return np.zeros(0, np.float64), np.zeros(0, np.float64)
    right, bottom = min(width, left + box_width + 1), min(height, top + box_height + 1)
    left, top = max(0, left - 1), max(0, top - 1)
    part = mask[top:bottom, left:right]
    boundary = cv2.subtract(part, cv2.erode(part, _BOUNDARY_KERNEL))
    if top == 0:
        boundary[0, :] = 0
    if bottom == height:
        boundary[-1, :] = 0
    if left == 0:
        boundary[:, 0] = 0
    if right == width:
        boundary[:, -1] = 0
    points = cv2.findNonZero(boundary)
    if points is None:
        return np.zeros(0, np.float64), np.zeros(0, np.float64)
    points = points.reshape(-1, 2).astype(np.float64)
    return points[:, 0] + left, points[:, 1] + top


def frame_search(planes: ColourPlanes, config: DetectorConfig, scale: float) -> FrameSearch:
    """The search of one frame: its boundary pixels and the radius limits at processing size."""
    height, width = planes.mask.shape
    min_radius = max(1.0, config.min_radius * scale)
    max_radius = (config.max_radius * scale) if config.max_radius else min(width, height) / 2.0
    boundary_x, boundary_y = boundary_points(planes.mask)
    return FrameSearch(planes, boundary_x, boundary_y, min_radius, max_radius,
                       max(1.0, config.small_radius * scale), scale)


def blob_proposals(contour: np.ndarray, search: FrameSearch, mask: np.ndarray,
                   config: DetectorConfig) -> list[Candidate] | None:
    """The blob's enclosing circle; [] when the blob is elongated or ragged (not one ball by
    itself, but Hough may split it); None when it cannot be or hold a ball (too small, too big,
    or too dull in colour)."""
    left, top, blob_width, blob_height = cv2.boundingRect(contour)
    extent = max(blob_width, blob_height)
    # A ball cut by the frame edge or half another colour still spans about its diameter
    # one way and covers at least ~30% of its disc.
    if extent < 1.2 * search.min_radius or extent > 2.6 * search.max_radius + 4:
        return None
    area = cv2.contourArea(contour)
    if area < 0.3 * math.pi * search.min_radius ** 2:
        return None
    # Cheap early exit for dull blobs (leaves in shade, pale dry leaves): the mean chroma
    # of the mask pixels in the blob's box, looser than the final per-ball check since
    # the blob may hold more than a ball.
    box = (slice(top, top + blob_height), slice(left, left + blob_width))
    planes = search.planes
    blob_chroma = cv2.mean(planes.chroma[box], cv2.inRange(mask[box], 255, 255))[0]
    if blob_chroma < 0.7 * config.min_colourfulness * planes.reference:
        return None
    (x, y), radius = cv2.minEnclosingCircle(contour)
    if area < 0.3 * math.pi * radius * radius:
        return []
    return [Candidate(float(x), float(y), float(radius))]


def hough_proposals(box: tuple[int, int, int, int], search: FrameSearch,
                    config: DetectorConfig) -> list[Candidate]:
    """Hough circles inside one blob's box (left, top, width, height): they split touching
    balls and find balls joined to other yellow-green things. Each blob gets its own few
    strongest circles."""
    mask = search.planes.mask
    height, width = mask.shape
    left, top, blob_width, blob_height = box
    extent = max(blob_width, blob_height)
    if extent < 2.5 * search.min_radius:
        return []
    touches_border = (left == 0 or top == 0 or left + blob_width >= width
                      or top + blob_height >= height)
    # A whole ball fits inside the blob's box both ways; one cut by the frame edge may not.
    limit = extent if touches_border else min(blob_width, blob_height)
    roi_max_radius = min(search.max_radius, 0.55 * limit + 2)
    if roi_max_radius <= search.min_radius:
        return []
    pad = 4
    x0, y0 = max(0, left - pad), max(0, top - pad)
    x1, y1 = min(width, left + blob_width + pad), min(height, top + blob_height + pad)
    # A smoothed mask gives Hough's gradient directions less jitter than a binary one.
    smooth = cv2.GaussianBlur(mask[y0:y1, x0:x1], (5, 5), 0)
    circles = cv2.HoughCircles(smooth, cv2.HOUGH_GRADIENT, dp=config.dp,
                               minDist=max(1.0, config.min_dist * search.scale),
                               param1=config.param1, param2=config.param2,
                               minRadius=max(1, int(math.floor(search.min_radius))),
                               maxRadius=max(2, int(math.ceil(roi_max_radius))))
    if circles is None:
        return []
    proposals: list[Candidate] = []
    for cx, cy, r in circles[0][:HOUGH_CIRCLES_SCANNED]:
        circle = Candidate(float(cx) + x0, float(cy) + y0, float(r))
        # Hough returns many near-concentric variants of a strong circle; keep the
        # strongest of each and look further down the list for other balls.
        if all(math.hypot(circle.x - other.x, circle.y - other.y)
               >= 0.5 * max(circle.radius, other.radius) for other in proposals):
            proposals.append(circle)
            if len(proposals) >= HOUGH_CIRCLES_PER_BLOB:
                break
    return proposals


def leftover_blobs(balls: list[Candidate], explained: np.ndarray) -> list[np.ndarray]:
    """Contours of the mask pieces (value 255 of ``explained``) left within reach of freshly
    accepted balls, whose discs ``explained`` has marked as neither colour nor not."""
    height, width = explained.shape
    contours_found: list[np.ndarray] = []
    for ball in balls:
        reach = 3.2 * ball.radius + 4
        x0, y0 = max(0, int(ball.x - reach)), max(0, int(ball.y - reach))
        x1, y1 = min(width, int(ball.x + reach) + 1), min(height, int(ball.y + reach) + 1)
        if x0 >= x1 or y0 >= y1:
            continue
        leftover = cv2.inRange(explained[y0:y1, x0:x1], 255, 255)
        contours, _ = cv2.findContours(leftover, cv2.RETR_EXTERNAL,
                                       cv2.CHAIN_APPROX_SIMPLE, offset=(x0, y0))
        contours_found.extend(contours)
    return contours_found
