"""Dark sides: step 9 of the detector (see ``detector.py``), the second look at rejected
candidates.

Under a light with no ambient, a ball's unlit side is black: its colour is a lit cap whose rim
is part circle, part shading, which the candidate checks take for a corner or a ragged blob. A
few rejected candidates with something dark around them (``dark_around``) get a second look:
if the frame shows an outline around the cap (``outline.silhouette``), with all the colour
inside it, a dark side within it (``dark_side``) and the lit part of its rim a colour edge
(``lit_rim_support``), the outline is the ball.

(The colour mask of extremely dark frames, whose colour is a grey level or two above black, is
``mask.py``'s: it switches to wider averages at ``dark_gain``.)
"""

import dataclasses

import cv2
import numpy as np

from balltrack.services.detector.checks import CandidateMetrics, hue_in_range
from balltrack.services.detector.measure import measure_mask, rim_points
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, box_around, circle_overlap, disc
from balltrack.services.detector.mask import EXPLAINED
from balltrack.services.detector.outline import silhouette
from balltrack.services.detector.proposals import FrameSearch

# Rejected candidates looked at again for a dark side (largest first, per frame). A dark side
# is at least DARK_SIDE_SHARE of the outline's disc outside the colour mask, on average at most
# DARK_SIDE_LEVEL times as bright as the lit (colour) part.
DARK_SIDE_ATTEMPTS = 3
DARK_SIDE_SHARE = 0.15
DARK_SIDE_LEVEL = 0.5
# The ring around a rejected candidate where a dark side is looked for, in its radii. In pitch-
# dark frames the colour is only the brightest part of the lit cap and the ball's far rim lies
# up to about twice the cap's radius from its centre: there the ring reaches as far as the
# outline search does (``wide_reach``).
AROUND_REACH = 1.5


def _brightness(patch: np.ndarray) -> np.ndarray:
    """Per pixel the brightest channel (HSV's V) of a BGR patch."""
    return np.maximum(np.maximum(patch[:, :, 0], patch[:, :, 1]), patch[:, :, 2])


def dark_side(frame: np.ndarray, mask: np.ndarray, ball: Candidate) -> bool:
    """Whether the disc of ``ball`` holds a dark side: a good part of it out of the colour
    mask and clearly darker than the part in it (not a hole, a logo or a box's corner)."""
    height, width = mask.shape
    box = box_around(ball.x, ball.y, ball.radius, width, height)
    if box is None:
        return False
    inside = disc(mask[box].shape, ball.x - box[1].start, ball.y - box[0].start, 0.95 * ball.radius)
    lit = cv2.inRange(mask[box], 255, 255) & inside
    unlit = cv2.bitwise_not(cv2.inRange(mask[box], 255, 255)) & inside
    total, lit_count = cv2.countNonZero(inside), cv2.countNonZero(lit)
    if not total or not lit_count or cv2.countNonZero(unlit) < DARK_SIDE_SHARE * total:
        return False
    brightness = _brightness(frame[box])
    return cv2.mean(brightness, unlit)[0] <= DARK_SIDE_LEVEL * cv2.mean(brightness, lit)[0]


def dark_around(frame: np.ndarray, mask: np.ndarray, ball: Candidate,
                reach: float = AROUND_REACH) -> bool:
    """Whether at least DARK_SIDE_SHARE of the ring around ``ball`` (r to ``reach`` r) is at
    most DARK_SIDE_LEVEL times as bright as the colour inside it: where a dark side may be."""
    height, width = mask.shape
    outer = reach * ball.radius + 1
    box = box_around(ball.x, ball.y, outer, width, height)
    if box is None:
        return False
    x, y = ball.x - box[1].start, ball.y - box[0].start
    shape = mask[box].shape
    inner = disc(shape, x, y, ball.radius)
    lit = cv2.inRange(mask[box], 255, 255) & inner
    ring = disc(shape, x, y, outer) & cv2.bitwise_not(inner)
    ring_count = cv2.countNonZero(ring)
    if not ring_count or not cv2.countNonZero(lit):
        return False
    brightness = _brightness(frame[box])
    level = DARK_SIDE_LEVEL * cv2.mean(brightness, lit)[0]
    dark = cv2.inRange(brightness, 0, max(0.0, level)) & ring
    return cv2.countNonZero(dark) >= DARK_SIDE_SHARE * ring_count


def lit_rim_support(frame: np.ndarray, mask: np.ndarray, ball: Candidate) -> float:
    """The share of the rim's *lit* part that is a colour edge (colour just inside, none just
    outside), the rim sampled as ``measure.measure_mask`` does.

    A ball's outline under a distant light is half lit (outline and terminator are great
    circles of the sphere, crossing at two opposite points), and on the dark half nothing is a
    colour edge. In a pitch-dark frame the averaged colour fades before the terminator, so it
    reaches the outline over less than that half and the whole rim's support is a third or so,
    whatever the ball. Rim samples whose inside is dark (at most DARK_SIDE_LEVEL times as bright
    as the colour within the disc) are the dark side and left out; the rest must be colour
    edges as the rim of any ball is.
    """
    height, width = mask.shape
    x, y, radius = ball.x, ball.y, ball.radius
    points = rim_points(x, y, radius, width, height)
    box = box_around(x, y, radius, width, height)
    if box is None or points.shape[1] == 0:
        return 0.0
    inside = disc(mask[box].shape, x - box[1].start, y - box[0].start, radius)
    lit = cv2.inRange(mask[box], 255, 255) & inside
    if not cv2.countNonZero(lit):
        return 0.0
    level = DARK_SIDE_LEVEL * cv2.mean(_brightness(frame[box]), lit)[0]
    inner, outer = mask[points[1], points[0]], mask[points[3], points[2]]
    inner_brightness = _brightness(frame)[points[1], points[0]]
    known = (inner != EXPLAINED) & (outer != EXPLAINED)
    lit_side = known & ((inner == 255) | (inner_brightness > level))
    if np.count_nonzero(lit_side) < DARK_SIDE_SHARE * np.count_nonzero(known):
        return 0.0  # (next to no lit rim: nothing to judge the outline by)
    edges = lit_side & (inner == 255) & (outer != 255)
    return float(np.count_nonzero(edges)) / float(np.count_nonzero(lit_side))


def second_look(rejected: list[tuple[Candidate, CandidateMetrics]], kept: list[Candidate],
                explained: np.ndarray, search: FrameSearch, config: DetectorConfig,
                wide_reach: float,
                judged: list | None = None) -> list[Candidate]:
    """``kept`` with the balls found around rejected candidates' dark sides added (largest
    candidate first, at most DARK_SIDE_ATTEMPTS outline searches, up to max_detections).

    A ball's score is the mean of its fill and rim support, which a dark side lowers (it is
    not held to min_score). ``explained``: the colour mask with accepted balls marked; each
    ball found is appended to ``judged`` (when a list) as (ball, metrics, score).
    """
    planes = search.planes
    attempts = 0
    for candidate, metrics in sorted(rejected, key=lambda item: item[0].radius, reverse=True):
        if attempts >= DARK_SIDE_ATTEMPTS or len(kept) >= config.max_detections:
            break
        # (the colour judged as checks.judge does: vivid, and its hue hue_margin inside the
        # range; a lit cap is no plain ball by shape, and wood, skin, lamps and orange light
        # beside something dark sit at the range's orange end)
        if (metrics.colour.colourfulness < config.min_colourfulness
                or (config.hue_margin > 0
                    and not hue_in_range(metrics.colour.colour_hue, config, config.hue_margin - 0.5))
                or any(circle_overlap(candidate, other) >= 0.3 for other in kept)):
            continue
        # (a cheap look first: is there anything dark around the colour at all?)
        if not dark_around(planes.frame, planes.mask, candidate,
                           wide_reach if planes.dark else AROUND_REACH):
            continue
        attempts += 1
        outline = silhouette(planes.frame, planes.mask, planes.gain, planes.reference,
                             candidate, kept, wide_reach)
        if outline is None:
            continue
        ball = Candidate(*outline)
        if (ball.radius < search.min_radius
                or any(circle_overlap(ball, other) >= 0.3 for other in kept)
                or not dark_side(planes.frame, planes.mask, ball)):
            continue
        # All the colour inside the outline (no leak past its rim), the rim a colour edge: in
        # pitch-dark frames its lit part only, as the averaged colour fades well before the
        # terminator there (elsewhere the colour reaches the outline over about the lit half
        # of the rim, and the whole rim's support is the stricter test against clutter).
        measured = measure_mask(ball, explained)
        support = (lit_rim_support(planes.frame, explained, ball) if planes.dark
                   else measured.support if measured is not None else 0.0)
        if (measured is None or measured.leak > 0.05 or measured.outside > 0.05
                or support < config.min_edge_support
                or measured.visible < max(config.min_visible_fraction,
                                          min(1.0, search.small_radius / ball.radius))):
            continue
        ball.score = max(0.0, min(1.0, (measured.fill + measured.support) / 2.0))
        if judged is not None:
            judged.append((ball, dataclasses.replace(metrics, mask=measured, dark_side=True),
                           ball.score))
        kept.append(ball)
    return kept
