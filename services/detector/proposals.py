"""Proposals: step 5 of the detector (see ``detector.py``), circles that may be balls.

The shape of each blob is judged with its small holes filled (``fill_holes``): a logo, a seam
or a blown-out highlight is not the ball's colour but is still the ball. Per mask blob: its
enclosing circle, and unless that circle is already a clean isolated ball,
the Hough circle transform (cv2.HoughCircles with ``dp min_dist param1 param2``, radii in
``min_radius..max_radius``) inside the blob's box, which splits touching balls and finds balls
joined to other yellow-green things. Proposals are refined (``fit.py``), measured
(``measure.py``) and judged (``checks.py``) by the detector.
"""

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np

from balltrack.services.detector.measure import lit_level
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate
from balltrack.services.detector.mask import EXPLAINED, ColourPlanes, explained_radius

# Hough circles per mask blob: beyond the strongest few they are duplicates or clutter.
HOUGH_CIRCLES_PER_BLOB = 4
HOUGH_CIRCLES_SCANNED = 40
# A hole of a blob is filled when it is at most this share of the blob's outline area: a
# ball's logo or highlight is a fraction of it, the opening of a ring is most of it.
HOLE_SHARE = 0.5
# A mask piece left next to an accepted ball's cleared disc counts as touching it within this
# many pixels of the disc's edge (see leftover_blobs).
LEFTOVER_TOUCH = 2
_BOUNDARY_KERNEL = np.ones((3, 3), np.uint8)
# Touching balls of one colour are one blob with no edge between them. Their proposals: the
# blob's largest inscribed discs, one after another (at most CLUSTER_BALLS, none under
# CLUSTER_SMALLEST of the first's radius: balls of one kind, near each other, are about one
# size; each erases CLUSTER_ERASE times its radius), besides Hough's circles. A set of them
# is a cluster of balls only if it covers CLUSTER_COVER of the blob: a row of discs covers ~78 %
# of a tube or strip, a heap of balls nearly all of itself.
CLUSTER_BALLS = 8
CLUSTER_SMALLEST = 0.5
CLUSTER_COVER = 0.85
CLUSTER_ERASE = 1.2
# A blob judged next to its own lit side covers at least this share of its enclosing circle:
# a ball's disc with a ragged edge or a notch of shade does.
LIT_ROUND_BLOB = 0.75


@dataclass
class FrameSearch:
    """What the candidate search of one frame shares (all at processing size)."""

    planes: ColourPlanes    # colour planes (their mask: the colour alone, for colour statistics)
    mask: np.ndarray        # the colour mask with its blobs' small holes filled, for shapes
    boundary_x: np.ndarray  # mask boundary pixels (frame border excluded), in row order
    boundary_y: np.ndarray
    min_radius: float
    max_radius: float
    small_radius: float
    scale: float            # processing size / input size


def mask_box(mask: np.ndarray, extent: tuple[int, int, int, int] | None = None) -> tuple[int, int, int, int]:
    """``cv2.boundingRect(mask)``, read only within ``extent`` (left, top, right, bottom), outside
    which the mask is known to be empty: the whole frame's scan costs more than a blob's."""
    if extent is None:
        return cv2.boundingRect(mask)
    left, top, right, bottom = extent
    if left >= right or top >= bottom:
        return 0, 0, 0, 0
    part_left, part_top, box_width, box_height = cv2.boundingRect(mask[top:bottom, left:right])
    if not box_width:
        return 0, 0, 0, 0
    return part_left + left, part_top + top, box_width, box_height


def fill_holes(mask: np.ndarray,
               extent: tuple[int, int, int, int] | None = None) -> tuple[list[np.ndarray], np.ndarray]:
    """Outer contours of the mask's blobs, and the mask with each hole filled that is at most
    HOLE_SHARE of its blob's outline area (``mask`` itself when there is none). ``extent``: see
    ``mask_box``."""
    # (found in the box around the mask's pixels, with a blank pixel more each way where the
    # frame has one: OpenCV copies the whole image it is given, most of it blank here)
    height, width = mask.shape
    left, top, box_width, box_height = mask_box(mask, extent)
    if not box_width:
        return [], mask
    right, bottom = min(width, left + box_width + 1), min(height, top + box_height + 1)
    left, top = max(0, left - 1), max(0, top - 1)
    contours, hierarchy = cv2.findContours(mask[top:bottom, left:right], cv2.RETR_CCOMP,
                                           cv2.CHAIN_APPROX_SIMPLE, offset=(left, top))
    if not contours:
        return [], mask
    links = hierarchy[0]  # per contour: next, previous, first child, parent
    outer = [contour for contour, link in zip(contours, links) if link[3] < 0]
    holes = [contour for contour, link in zip(contours, links)
             if link[3] >= 0 and cv2.contourArea(contour) <= HOLE_SHARE * cv2.contourArea(contours[link[3]])]
    if not holes:
        return outer, mask
    filled = mask.copy()
    cv2.drawContours(filled, holes, -1, 255, cv2.FILLED)
    return outer, filled


def boundary_points(mask: np.ndarray,
                    extent: tuple[int, int, int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows (float64, in row order) of the mask's boundary pixels, leaving out
    the frame's border: there the mask's edge is the frame's, not the ball's. ``extent``: see
    ``mask_box``."""
    height, width = mask.shape
    # Only the box around the mask's pixels is searched, with a pixel more each way (blank,
    # or the frame's border), so its erosion is the whole mask's.
    left, top, box_width, box_height = mask_box(mask, extent)
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


def frame_search(planes: ColourPlanes, config: DetectorConfig, scale: float,
                 mask: np.ndarray | None = None) -> FrameSearch:
    """The search of one frame: its boundary pixels and the radius limits at processing size.
    ``mask``: the shape mask (default the colour mask; its filled holes lie inside its blobs, so
    within the colour mask's extent)."""
    mask = planes.mask if mask is None else mask
    height, width = mask.shape
    min_radius = max(1.0, config.min_radius * scale)
    max_radius = (config.max_radius * scale) if config.max_radius else min(width, height) / 2.0
    boundary_x, boundary_y = boundary_points(mask, planes.extent)
    return FrameSearch(planes, mask, boundary_x, boundary_y, min_radius, max_radius,
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
    colour = cv2.inRange(mask[box], 255, 255)
    blob_chroma = cv2.mean(planes.chroma[box], colour)[0]
    floor = 0.7 * config.min_colourfulness
    (x, y), radius = cv2.minEnclosingCircle(contour)
    if blob_chroma < floor * planes.reference:
        # A ball in shade may be vivid only next to its own lit side (see
        # measure.ColourMetrics.lit_colourfulness), which makes a ball only of a candidate
        # plainly one by its shape: a round blob by itself (LIT_ROUND_BLOB), its enclosing
        # circle the one proposal, nothing for Hough to split.
        if (area < LIT_ROUND_BLOB * math.pi * radius * radius
                or blob_chroma < floor * lit_level(planes.frame[box], colour)):
            return None
    elif area < 0.3 * math.pi * radius * radius:
        return []
    return [Candidate(float(x), float(y), float(radius))]


def hough_proposals(box: tuple[int, int, int, int], search: FrameSearch,
                    config: DetectorConfig) -> list[Candidate]:
    """Hough circles inside one blob's box (left, top, width, height): they split touching
    balls and find balls joined to other yellow-green things. Each blob gets its own few
    strongest circles."""
    mask = search.mask
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


def blob_image(contour: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The blob's pixels of ``mask`` (0/255) on a canvas one pixel wider than its box all
    round, and the canvas's origin (left, top) in the frame."""
    left, top, blob_width, blob_height = cv2.boundingRect(contour)
    blob = np.zeros((blob_height + 2, blob_width + 2), np.uint8)
    cv2.drawContours(blob, [contour], -1, 255, cv2.FILLED, offset=(1 - left, 1 - top))
    blob &= cv2.copyMakeBorder(mask[top:top + blob_height, left:left + blob_width],
                               1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    return blob, left - 1, top - 1


def inscribed_discs(contour: np.ndarray, search: FrameSearch,
                    taken: list[Candidate]) -> list[Candidate]:
    """The largest inscribed discs, one after another (see CLUSTER_BALLS), of what the
    ``taken`` circles leave of the blob, largest first, in frame coordinates; they propose the
    balls of a cluster of touching balls."""
    blob, left, top = blob_image(contour, search.mask)
    # A ball cut by the frame edge goes on past it: the frame's border is not the blob's edge
    # (as for the circle fit), and the distance transform counts no distance to the image's
    # own border, so the canvas loses its blank margin there.
    height, width = search.mask.shape
    first_row, first_column = (1 if top + 1 == 0 else 0), (1 if left + 1 == 0 else 0)
    last_row = blob.shape[0] - (1 if top + blob.shape[0] - 1 == height else 0)
    last_column = blob.shape[1] - (1 if left + blob.shape[1] - 1 == width else 0)
    blob = np.ascontiguousarray(blob[first_row:last_row, first_column:last_column])
    left, top = left + first_column, top + first_row
    area = cv2.countNonZero(blob)
    for circle in taken:
        cv2.circle(blob, (int(round(circle.x - left)), int(round(circle.y - top))),
                   explained_radius(circle.radius), 0, -1)
    discs: list[Candidate] = []
    while len(discs) < CLUSTER_BALLS and cv2.countNonZero(blob) > (1.0 - CLUSTER_COVER) * area:
        distance = cv2.distanceTransform(blob, cv2.DIST_L2, 5)
        _, radius, _, (x, y) = cv2.minMaxLoc(distance)
        if radius < max(search.min_radius, CLUSTER_SMALLEST * (discs[0].radius if discs else 0.0)):
            break
        # (distance to the nearest pixel off the blob: the disc reaches half a pixel further)
        discs.append(Candidate(float(x + left), float(y + top), float(radius) + 0.5))
        cv2.circle(blob, (x, y), int(math.ceil(CLUSTER_ERASE * radius + 1)), 0, -1)
    return discs


def blob_cover(contour: np.ndarray, mask: np.ndarray, discs: list[Candidate]) -> float:
    """Fraction of the blob's pixels in one of ``discs`` (drawn ``explained_radius`` wide: a
    mask's edge is ragged)."""
    blob, left, top = blob_image(contour, mask)
    covered = np.zeros_like(blob)
    for disc in discs:
        cv2.circle(covered, (int(round(disc.x - left)), int(round(disc.y - top))),
                   explained_radius(disc.radius), 255, -1)
    return cv2.countNonZero(blob & covered) / max(1, cv2.countNonZero(blob))


def leftover_blobs(balls: list[Candidate], explained: np.ndarray) -> list[np.ndarray]:
    """Contours of the mask pieces (value 255 of ``explained``) that touch the disc of a freshly
    accepted ball, which ``explained`` has marked as neither colour nor not.

    Only a piece touching the disc was part of the ball's blob and so is new: a piece apart
    from it was a blob of its own from the start and has been proposed already (this search
    re-proposing it let a speck far from the ball through on the cleared mask)."""
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
                                       cv2.CHAIN_APPROX_NONE, offset=(x0, y0))
        # (the disc was drawn explained_radius(r) px in radius; its neighbours' edge pixels lie a
        # pixel beyond, and the piece's outline a further pixel for the mask's raggedness)
        touching = explained_radius(ball.radius) + LEFTOVER_TOUCH
        for contour in contours:
            points = contour.reshape(-1, 2).astype(np.float32)
            nearest = float(np.min(np.hypot(points[:, 0] - ball.x, points[:, 1] - ball.y)))
            if nearest <= touching:
                contours_found.append(contour)
    return contours_found


def leftover_search(search: FrameSearch, explained: np.ndarray) -> FrameSearch:
    """``search`` without the mask boundary pixels inside accepted balls' discs (EXPLAINED in
    ``explained``): a found ball's outline is its own, and circles fitted to what it leaves of
    its blob (a ball behind it, the rest of a heap) would otherwise be pulled onto it."""
    keep = explained[search.boundary_y.astype(np.intp), search.boundary_x.astype(np.intp)] != EXPLAINED
    return dataclasses.replace(search, boundary_x=search.boundary_x[keep], boundary_y=search.boundary_y[keep])
