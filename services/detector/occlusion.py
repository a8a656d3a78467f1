"""Hidden parts: a second measurement of candidates partly hidden behind something straight
(part of step 6, see ``detector.py``).

A ball behind the edge of a wall, a door frame, a box or a post shows a disc cut by a chord:
its colour mask ends along a straight line inside its circle, and nothing of its colour lies
past that line. What lies past it is hidden, not missing, just as what lies past the frame
border is: so a candidate that fails its checks and whose mask ends so is measured again with
the far side of the line counted as neither colour nor not (``EXPLAINED``). Its fill, rim
support and evenness are then those of the part in view. The ball's outline on the frame is
not looked for (the occluder's edge is no part of it): its circle is the mask's.
"""

import dataclasses
import math

import cv2
import numpy as np

from balltrack.services.detector.checks import SURE_SIZE, CandidateMetrics, hue_in_range, judge
from balltrack.services.detector.measure import MaskMetrics, measure_mask
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, box_around, disc
from balltrack.services.detector.mask import EXPLAINED

# The mask's edge inside the circle (within INNER_SHARE of its radius, off its rim) is an
# occluder's when it lies on one straight line (within LINE_TOLERANCE px or that share of the
# radius) along CHORD_COVER of a chord at least CHORD_SHARE of the radius long.
INNER_SHARE = 0.85
CHORD_SHARE = 0.8
CHORD_COVER = 0.8
LINE_TOLERANCE = (1.5, 0.04)
LINE_ANGLE_STEP = math.radians(3.0)
# Past the line, at most this share of the disc may hold the colour: else the line is an edge
# within the object (a seam, a logo), not where it disappears from view.
HIDDEN_COLOUR = 0.05
# At least this share of the rim must be in view: a smaller segment of a disc is any shape with
# one round side.
MIN_IN_VIEW = 0.5
# A chord at least CHORD_SHARE r long within INNER_SHARE r hides at least about a fifth of
# the rim: there the rim is neither a colour edge nor a leak.
HIDDEN_RIM = 0.2
_KERNEL = np.ones((3, 3), np.uint8)


def measured_in_view(candidate: Candidate, metrics: CandidateMetrics, mask: np.ndarray,
                     config: DetectorConfig) -> CandidateMetrics:
    """``metrics`` of a candidate measured on ``mask``; for one that fails its checks but is
    clean and passes them measured on its part in view (see hidden_side_metrics), those,
    marked partly_hidden."""
    if not may_be_partly_hidden(metrics, config) or judge(metrics, config) is not None:
        return metrics
    in_view = hidden_side_metrics(candidate, mask)
    if in_view is None:
        return metrics
    # (judged on its part in view only, that part must be as plainly a ball as a clean one:
    # its rim in view a colour edge nearly all along, its disc full; a box's face behind the
    # same edge still shows its other straight sides)
    hidden = dataclasses.replace(metrics, mask=in_view, partly_hidden=True)
    return hidden if hidden.clean and judge(hidden, config) is not None else metrics


def may_be_partly_hidden(metrics: CandidateMetrics, config: DetectorConfig) -> bool:
    """Whether a measured candidate may be a ball partly hidden: large enough for a straight
    edge across it to mean something (SURE_SIZE), HIDDEN_RIM of its rim neither edge nor
    leak (the hidden part's), and its colour a ball's (which hiding does not change)."""
    on_mask, colour = metrics.mask, metrics.colour
    return (metrics.size >= SURE_SIZE and on_mask.support + on_mask.leak <= 1.0 - HIDDEN_RIM
            and colour.colourfulness >= config.min_colourfulness
            and hue_in_range(colour.colour_hue, config, config.hue_margin - 0.5))


def hidden_side_metrics(candidate: Candidate, mask: np.ndarray) -> MaskMetrics | None:
    """How the circle sits on ``mask`` with what lies past a straight occluding edge across its
    disc counted as hidden; None when its mask ends along no such edge."""
    height, width = mask.shape
    x, y, radius = candidate.x, candidate.y, candidate.radius
    # (everything measure_mask reads: rim samples, the outer ring, the edge rays to 1.5 r)
    box = box_around(x, y, 1.6 * radius + 4, width, height)
    # (the mask's edge inside the disc, found in a box just around it: a pixel more each way
    # where the frame has one, so that its erosion is the whole mask's)
    inner = box_around(x, y, INNER_SHARE * radius + 2, width, height)
    if box is None or inner is None:
        return None
    left, top = box[1].start, box[0].start
    centre_x, centre_y = x - left, y - top
    part = cv2.inRange(mask[inner], 255, 255)
    edge = cv2.subtract(part, cv2.erode(part, _KERNEL))
    edge &= disc(part.shape, x - inner[1].start, y - inner[0].start, INNER_SHARE * radius)
    points = cv2.findNonZero(edge)
    if points is None or len(points) < CHORD_SHARE * radius:
        return None
    # (in the coordinates of the measuring box)
    points = (points.reshape(-1, 2) + (inner[1].start - left, inner[0].start - top)).astype(np.float32)
    tolerance = max(LINE_TOLERANCE[0], LINE_TOLERANCE[1] * radius)
    line = straightest_line(points, tolerance)
    if line is None:
        return None
    normal_x, normal_y, offset = line
    # The occluder's edge runs straight across the disc: its pixels cover the chord (within
    # INNER_SHARE r), a long one, all along (a row of balls' flat underside is bumpy).
    distance = centre_x * normal_x + centre_y * normal_y - offset
    half_chord = math.sqrt(max(0.0, (INNER_SHARE * radius) ** 2 - distance * distance))
    if 2 * half_chord < CHORD_SHARE * radius:
        return None
    on_line = np.abs(points[:, 0] * normal_x + points[:, 1] * normal_y - offset) <= tolerance
    # (positions along the line, from the foot of the centre's perpendicular)
    along = ((points[on_line, 0] - centre_x) * -normal_y + (points[on_line, 1] - centre_y) * normal_x)
    covered = np.unique(np.floor(along[np.abs(along) <= half_chord])).size
    if covered < CHORD_COVER * 2 * half_chord:
        return None
    # The hidden side: the one with (next to) no colour in the disc.
    patch = mask[box]
    colour = cv2.inRange(patch, 255, 255)
    rows, columns = np.mgrid[0:patch.shape[0], 0:patch.shape[1]]
    signed = columns * normal_x + rows * normal_y - offset
    inside = disc(patch.shape, centre_x, centre_y, radius) > 0
    colour_on = colour > 0
    shares = []
    for side in (signed > 0, signed < 0):
        total = np.count_nonzero(inside & side)
        shares.append(np.count_nonzero(inside & side & colour_on) / total if total else 1.0)
    if min(shares) > HIDDEN_COLOUR:
        return None
    # (past a margin: the line's own pixels are the mask's edge)
    hidden = signed > tolerance if shares[0] < shares[1] else signed < -tolerance
    marked = patch.copy()
    marked[hidden] = EXPLAINED
    metrics = measure_mask(Candidate(centre_x, centre_y, radius), marked)
    if metrics is None or metrics.visible < MIN_IN_VIEW:
        return None
    return metrics


def straightest_line(points: np.ndarray, tolerance: float) -> tuple[float, float, float] | None:
    """The line through most of ``points`` (within about ``tolerance``), refined by least
    squares on them: its unit normal (x, y) and offset (normal . any point on it); None for
    fewer than two points."""
    if len(points) < 2:
        return None
    # (every LINE_ANGLE_STEP of direction, the points' offsets along its normal counted in
    # bins of the tolerance's width, two neighbouring bins together: the fullest pair holds
    # the line)
    angles = np.arange(0.0, math.pi, LINE_ANGLE_STEP)
    offsets = points.astype(np.float64) @ np.stack([np.cos(angles), np.sin(angles)])
    bins = np.floor(offsets / (2 * tolerance)).astype(np.int64)
    lowest = bins.min(axis=0)
    span = int((bins - lowest).max()) + 2
    counts = np.bincount((np.arange(len(angles)) * span + (bins - lowest)).ravel(),
                         minlength=len(angles) * span).reshape(len(angles), span)
    pairs = counts[:, :-1] + counts[:, 1:]
    index, first = np.unravel_index(int(np.argmax(pairs)), pairs.shape)
    band = bins[:, index] - lowest[index]
    near = (band >= first) & (band <= first + 1)
    for _round in range(2):  # (then once more on the points within the tolerance of that fit)
        direction_x, direction_y, line_x, line_y = cv2.fitLine(points[near], cv2.DIST_L2, 0, 0.01, 0.01).ravel()
        normal_x, normal_y = float(-direction_y), float(direction_x)
        offset = normal_x * float(line_x) + normal_y * float(line_y)
        near = np.abs(points[:, 0] * normal_x + points[:, 1] * normal_y - offset) <= tolerance
        if np.count_nonzero(near) < 2:
            break
    return normal_x, normal_y, offset
