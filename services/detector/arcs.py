"""Outline arcs: circles proposed by the round stretches of a blob's outline (part of step 5,
see ``detector.py``).

A ball partly hidden behind another ball, or touching one of its colour, merges with it into
one blob, yet the part of its outline in view is still an arc of a circle. Where two balls
meet, the blob's outline turns inwards (a concave point, a defect of its convex hull); between
those points it runs along one ball's rim. So the outline is cut at its concave points and a
circle is fitted to each piece: a piece that is a long, even arc of a circle proposes that
circle, however little of the ball's disc the mask shows apart from its neighbours. Where the
mask has filled the meeting on one side, the outline of two balls is cut across the blob's
waist instead (see WAIST_ELONGATION).
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.fit import kasa
from balltrack.services.detector.geometry import Candidate
from balltrack.services.detector.jit import compiled

# A concave point cuts the outline when it lies at least ARC_CUT_DEPTH px (at processing size),
# or ARC_CUT_SHARE of the blob's equivalent radius, inside the blob's convex hull: a ragged
# mask edge dents it by a pixel or so.
ARC_CUT_DEPTH = 2.0
ARC_CUT_SHARE = 0.06
# A piece proposes its circle when at least ARC_MIN_POINTS outline pixels lie on it, within
# ARC_TOLERANCE of the radius (a ball's mask edge is even; a lobe of clutter is not), spanning
# at least ARC_MIN_SPAN radians round its centre (a short arc fits any circle).
ARC_MIN_POINTS = 12
ARC_TOLERANCE = 0.08
ARC_MIN_SPAN = math.radians(120)
# Rounds of fitting, each keeping the points within this share of the radius of the last circle.
ARC_ROUNDS = (0.25, 0.15, ARC_TOLERANCE)
# Two overlapping balls whose neck the mask's closing (or a shadow, a blur) has filled on one
# side leave at most one concave point, yet their blob is still WAIST_ELONGATION times longer
# than wide (one ball's disc is round) and has a waist where they meet: across its middle
# (WAIST_MIDDLE of its length each side of its centre) it is narrower, by WAIST_DEPTH, than
# at its widest on each side (two discs are; a wedge, a bar or an ellipse is not). Its outline
# is then cut across the waist into the two balls' rims.
WAIST_ELONGATION = 1.3
WAIST_MIDDLE = 0.25
WAIST_DEPTH = 1.1


def deepest_cut(points: np.ndarray, depth: float) -> int | None:
    """Index of the deepest concave point of an outline (closed, or open and closed by the
    chord between its ends) at least ``depth`` inside its convex hull; None when there is none."""
    cut = convexity_cut(np.ascontiguousarray(points, np.float64), float(depth))
    return None if cut < 0 else int(cut)


@compiled
def convexity_cut(points: np.ndarray, depth: float) -> int:
    """``deepest_cut`` of the (n x 2) float64 ``points``, -1 for none: the convex hull of the
    rounded points, then the deepest of the convexity defects between its vertices taken in
    order along the outline, as OpenCV's convexHull and convexityDefects give them, the ends of
    an open piece excluded (they are cuts already).

    (Three OpenCV calls and the numpy between them cost ~30 us per piece, ~2000 pieces on the
    145 development photos; this ~8 us.) The same cut as those calls on every outline of the
    development photos and renders; where an outline passes through a hull point twice (a
    one-pixel spur), which visit OpenCV makes the hull's vertex is left to its unstable sort:
    this takes the later one, as OpenCV did on all of those outlines.
    """
    count = points.shape[0]
    xs = np.empty(count, np.int64)
    ys = np.empty(count, np.int64)
    for index in range(count):
        xs[index] = np.int64(np.rint(points[index, 0]))
        ys[index] = np.int64(np.rint(points[index, 1]))
    # Andrew's monotone chain over the points by (x, y), later visits of a point first; only
    # the strict corners are vertices (OpenCV's hull has no points along its edges).
    low_x, low_y = xs.min(), ys.min()
    rows = ys.max() - low_y + 1
    keys = ((xs - low_x) * rows + (ys - low_y)) * count + (count - 1 - np.arange(count))
    order = np.argsort(keys)
    hull = np.empty(2 * count + 1, np.int64)
    size = 0
    for lower in (True, False):
        floor = 2 if lower else size + 1
        for step in range(count):
            index = order[step] if lower else order[count - 1 - step]
            if size > 0 and xs[hull[size - 1]] == xs[index] and ys[hull[size - 1]] == ys[index]:
                continue
            while size >= floor:
                first, second = hull[size - 2], hull[size - 1]
                turn = ((xs[second] - xs[first]) * (ys[index] - ys[first])
                        - (ys[second] - ys[first]) * (xs[index] - xs[first]))
                if turn > 0:
                    break
                size -= 1
            hull[size] = index
            size += 1
    size -= 1  # (the chain ends where it began)
    if size < 4:
        return -1
    vertices = np.sort(hull[:size])
    # Each hull edge's deepest point, as OpenCV measures it: distance to the edge's line in
    # float64, stored rounded to 1/256 px; the first of equally deep defects wins.
    best_depth, best_index = -1, -1
    current = vertices[size - 1]
    for edge in range(size):
        following = vertices[edge]
        start_x, start_y = float(xs[current]), float(ys[current])
        along_x, along_y = float(xs[following]) - start_x, float(ys[following]) - start_y
        scale = 0.0 if along_x == 0 and along_y == 0 else 1.0 / math.sqrt(along_x * along_x + along_y * along_y)
        deepest, deepest_distance = -1, 0.0
        index = current
        while True:
            index += 1
            if index >= count:
                index = 0
            if index == following:
                break
            distance = abs(-along_y * (float(xs[index]) - start_x) + along_x * (float(ys[index]) - start_y)) * scale
            if distance > deepest_distance:
                deepest, deepest_distance = index, distance
        if 0 < deepest < count - 1:
            fixed = int(np.rint(deepest_distance * 256.0))
            if fixed > best_depth:
                best_depth, best_index = fixed, deepest
        current = following
    if best_index < 0 or best_depth / 256.0 < depth:
        return -1
    return best_index


def cut_piece(piece: np.ndarray, depth: float) -> list[np.ndarray]:
    """An open piece of outline cut at its concave points, deepest first: the convex hull
    reports one concave point per hull edge, so balls in a row along one edge need cuts
    within cuts."""
    if len(piece) < 2 * ARC_MIN_POINTS:
        return [piece]
    cut = deepest_cut(piece, depth)
    if cut is None:
        return [piece]
    return cut_piece(piece[:cut + 1], depth) + cut_piece(piece[cut:], depth)


def outline_pieces(blob: np.ndarray) -> list[np.ndarray]:
    """The outline of the largest blob of a 0/255 image cut at its concave points, or across
    its waist when they leave fewer than two pieces (see WAIST_ELONGATION): a list of (n x 2)
    float arrays of pixel positions (in order along the outline unless cut at the waist); []
    when the outline has neither (a convex blob: its enclosing circle is proposed already)."""
    contours, _ = cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return []
    contour = max(contours, key=cv2.contourArea)
    if len(contour) < 2 * ARC_MIN_POINTS:
        return []
    points = contour.reshape(-1, 2).astype(np.float64)
    depth = max(ARC_CUT_DEPTH, ARC_CUT_SHARE * math.sqrt(cv2.contourArea(contour) / math.pi))
    first = deepest_cut(points, depth)
    pieces: list[np.ndarray] = []
    if first is not None:
        # (the closed outline opened at its deepest concave point, then cut further)
        opened = np.concatenate([points[first:], points[:first + 1]])
        pieces = [piece for piece in cut_piece(opened, depth) if len(piece) >= ARC_MIN_POINTS]
    if len(pieces) >= 2:
        return pieces
    return waist_pieces(points, blob) or pieces


def waist_pieces(points: np.ndarray, blob: np.ndarray) -> list[np.ndarray]:
    """The points of a blob's closed outline on either side of its waist (see
    WAIST_ELONGATION): two pieces; [] when the blob is not that elongated or has no waist."""
    moments = cv2.moments(blob, binaryImage=True)
    if moments["m00"] <= 0:
        return []
    centre_x, centre_y = moments["m10"] / moments["m00"], moments["m01"] / moments["m00"]
    angle = 0.5 * math.atan2(2.0 * moments["mu11"], moments["mu20"] - moments["mu02"])
    along_x, along_y = math.cos(angle), math.sin(angle)
    dx, dy = points[:, 0] - centre_x, points[:, 1] - centre_y
    along = dx * along_x + dy * along_y
    across = -dx * along_y + dy * along_x
    length = float(along.max() - along.min())
    width = float(across.max() - across.min())
    if length < WAIST_ELONGATION * width:
        return []
    # The blob's width at each step along its axis: how many of its pixels lie there.
    rows, columns = np.nonzero(blob)
    steps = np.rint((columns - centre_x) * along_x + (rows - centre_y) * along_y).astype(np.intp)
    first_step = int(steps.min())
    widths = np.bincount(steps - first_step).astype(np.float64)
    positions = np.arange(len(widths)) + first_step
    middle = np.abs(positions - 0.5 * (along.max() + along.min())) <= WAIST_MIDDLE * length
    if not middle.any():
        return []
    narrowest = int(np.argmin(np.where(middle, widths, np.inf)))
    if not (widths[:narrowest].max(initial=0.0) >= WAIST_DEPTH * widths[narrowest]
            and widths[narrowest + 1:].max(initial=0.0) >= WAIST_DEPTH * widths[narrowest]):
        return []
    waist = narrowest + first_step
    pieces = [points[along < waist - 0.5], points[along > waist + 0.5]]
    return [piece for piece in pieces if len(piece) >= ARC_MIN_POINTS]


@compiled
def arc_rounds(dx: np.ndarray, dy: np.ndarray, rounds: tuple, min_points: int,
               tolerance: float) -> tuple[bool, float, float, float, np.ndarray]:
    """``arc_circle``'s fit of points given about their mean: a Kasa circle through all, then a
    round for each of ``rounds`` on the points within that share of the radius of the last
    circle; (ok, x, y, radius, the points within ``tolerance`` of it). Not ok when a round keeps
    fewer than ``min_points``, a fit fails, or the last circle holds fewer than that or than
    half the points."""
    near = np.ones(dx.size, np.bool_)
    ok, x, y, radius = kasa(dx, dy, near)
    if not ok:
        return False, 0.0, 0.0, 0.0, near
    for share in rounds:
        count = 0
        for index in range(dx.size):
            near[index] = abs(np.hypot(dx[index] - x, dy[index] - y) - radius) <= max(1.0, share * radius)
            count += near[index]
        if count < min_points:
            return False, 0.0, 0.0, 0.0, near
        # (a round selects its points; a Kasa circle is the same from any origin)
        ok, x, y, radius = kasa(dx, dy, near)
        if not ok:
            return False, 0.0, 0.0, 0.0, near
    count = 0
    for index in range(dx.size):
        near[index] = abs(np.hypot(dx[index] - x, dy[index] - y) - radius) <= max(1.0, tolerance * radius)
        count += near[index]
    if count < max(min_points, 0.5 * dx.size):
        return False, 0.0, 0.0, 0.0, near
    return True, x, y, radius, near


def arc_circle(piece: np.ndarray) -> tuple[float, float, float] | None:
    """The circle a piece of outline is a long even arc of, or None."""
    mean_x, mean_y = float(piece[:, 0].mean()), float(piece[:, 1].mean())
    dx, dy = piece[:, 0] - mean_x, piece[:, 1] - mean_y
    ok, x, y, radius, near = arc_rounds(dx, dy, ARC_ROUNDS, ARC_MIN_POINTS, ARC_TOLERANCE)
    if not ok:
        return None
    # (numpy's arctan2, whose last bit the compiled one does not always match)
    angles = np.sort(np.arctan2(dy[near] - y, dx[near] - x))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * math.pi]))
    if 2 * math.pi - float(gaps.max()) < ARC_MIN_SPAN:
        return None
    return x + mean_x, y + mean_y, radius


def arc_proposals(blob: np.ndarray, left: int, top: int, min_radius: float,
                  max_radius: float) -> list[Candidate]:
    """Circles of the long even arcs of a blob's outline (``blob``: its 0/255 image, whose
    origin lies at (left, top) in the frame), radii within the limits, in frame coordinates;
    the arc's pixels are the mask's outermost, half a pixel inside its edge."""
    circles = []
    for piece in outline_pieces(blob):
        found = arc_circle(piece)
        if found is None:
            continue
        x, y, radius = found
        radius += 0.5
        if min_radius <= radius <= max_radius:
            circles.append(Candidate(x + left, y + top, radius))
    return circles
