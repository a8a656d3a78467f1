"""The sub-pixel outline: step 8 of the detector (see ``detector.py``).

Each accepted ball's circle is replaced by its outline located on the frame itself: along rays
from the centre, the colour edge at its 50 % crossing, then a robust circle fit. The colour
mask's edge lies where blur has spread the colour (radii 0.5-1 px too large whatever the size,
the more blurred the frame the more), and a strongly shaded side drags its centre towards the
lit side; the 50 % crossing of the edge does not move with blur, and edges of shading are told
from the outline (the edges along rays: ``edges.py``). Each round of the search is compiled
(``outline_round``, see ``jit.py``).
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.edges import (allowed_samples, crossing_edges, edge_peaks, edge_widths,
                                               median, outline_edges, ray_profiles)
from balltrack.services.detector.fit import robust_rounds
from balltrack.services.detector.geometry import Candidate, box_around, disc, rim_directions
from balltrack.services.detector.jit import compiled

# Silhouette refinement of accepted balls (radial edge profiles of the frame itself, see
# edges.py): sample spacing along a ray (px).
RAY_STEP = 0.5
# Half width (px; at most 30 % of the radius) of the profile around an edge whose levels set
# its 50 % crossing.
EDGE_HALF_WIDTH = 1.5
# Edges are looked for from this far (px, plus 15 % of the radius, at most 40 % of it) inside
# the current circle.
EDGE_MARGIN = 2.5
# Nearly black, past an edge (which is then shading, see edges.is_shading): below this share of
# the frame's reference level.
DARK_SHARE = 0.03
# Most wide rounds of the silhouette search (each from the last circle found, until it stops
# growing) before the narrow one.
SILHOUETTE_WIDE_ROUNDS = 3
# Rays of the wide and the narrow rounds (fewer for small balls: one per pixel of rim, >= 24).
WIDE_RAYS = 36
NARROW_RAYS = 90
# Largest blur (Gaussian sigma, px) corrected for.
BLUR_LIMIT = 2.0
# Tolerance rounds (over radius, floor in px) of the wide and the narrow rounds' robust fits.
WIDE_FIT_ROUNDS = ((0.3, 2.0), (0.1, 1.0))
NARROW_FIT_ROUNDS = ((0.08, 1.0), (0.05, 0.6), (0.03, 0.45))
# The search reaches this many times the colour mask's radius from its centre.
SILHOUETTE_REACH = 2.6
# Wide rounds look this many times the current radius (plus 2 px) from its centre; further in
# extremely dark frames, whose colour mask is only the brightest part of a lit cap (the
# outline of a ball whose other side is black lies further from it).
WIDE_REACH = 1.6
DARK_WIDE_REACH = 2.1


# Outcomes of a round of the silhouette search (outline_round).
FAILED, GOING_ON, FOUND, FOUND_REUSED = 0, 1, 2, 3
ROUND_OUTCOMES = {GOING_ON: "wide", FOUND: "narrow", FOUND_REUSED: "narrow on the wide round's edges"}
WIDE_FIT_TABLE = np.array(WIDE_FIT_ROUNDS)
NARROW_FIT_TABLE = np.array(NARROW_FIT_ROUNDS)


@compiled
def seen_all_round(cos, sin, in_view, one_sided):
    """Whether edges seen along rays of these directions are enough of the ``in_view`` rays
    and not on one side only (their mean direction at most ``one_sided``)."""
    count = cos.size
    return (count >= max(8, 0.3 * in_view)
            and math.hypot(cos.sum() / count, sin.sum() / count) <= one_sided)


@compiled
def narrow_fit(px, py, widths, directions, x, y, radius, in_view, one_sided):
    """The narrow round's fit on edges a wide round located (points ``px``, ``py`` along ray
    ``directions``, rows cos and sin, with their ``widths``, see edge_widths), from the circle
    it found: the robust geometric circle through them, corrected for blur, as (ok, x, y,
    radius); ok False when too few edges lie on it or they lie on one side only."""
    ok, fitted_x, fitted_y, fitted_radius, kept = robust_rounds(px, py, x, y, radius, NARROW_FIT_TABLE, True)
    if not ok or not 0.5 * radius < fitted_radius < 2.0 * radius + 2:
        return False, x, y, radius
    if not seen_all_round(directions[0][kept], directions[1][kept], in_view, one_sided):
        return False, x, y, radius
    # The 50 % contour of a disc blurred by sigma lies sigma^2 / 2r inside its edge.
    sigma = median(widths[kept])
    return True, fitted_x, fitted_y, fitted_radius + min(sigma, BLUR_LIMIT) ** 2 / (2.0 * fitted_radius)


@compiled
def hypothesis_edges(profiles, radii, patch_mask, x, y, radius, step, half, directions, index, rays):
    """The edges of one outline hypothesis (at ``index`` along ``rays``) located at their 50 %
    crossing: their points, contrasts, and which are good (a defined crossing with no colour
    mask just past it: yellow-green clutter touching the ball)."""
    position, defined, contrast = crossing_edges(profiles, index, half, rays)
    height, width = patch_mask.shape
    beyond = max(2.0, 0.12 * radius)
    px, py = np.empty(rays.size), np.empty(rays.size)
    good = np.empty(rays.size, np.bool_)
    for edge in range(rays.size):
        cos, sin = directions[0, rays[edge]], directions[1, rays[edge]]
        rho = np.float64(radii[0]) + position[edge] * step
        px[edge], py[edge] = x + cos * rho, y + sin * rho
        column = int(min(max(np.rint(x + cos * (rho + beyond)), 0.0), width - 1.0))
        row = int(min(max(np.rint(y + sin * (rho + beyond)), 0.0), height - 1.0))
        good[edge] = defined[edge] and patch_mask[row, column] != 255
    return px, py, contrast, good


@compiled
def outline_round(profiles, radii, directions, x, y, radius, start, stop, step, half, wide,
                  wide_rounds, others, colour, gain, dark, patch_mask, reuse_edges):
    """One round of the silhouette search (see ``silhouette``) on the ray ``profiles``
    sampled at ``radii`` along ``directions`` from (x, y): its outcome (FAILED, GOING_ON,
    FOUND, FOUND_REUSED), the circle found and the count of wide rounds made.

    ``others``: rows (x, y, radius) of the other balls, in the patch's pixels; ``reuse_edges``:
    False for a narrow round of its own after the wide ones, never on their edges."""
    samples, count = profiles.shape[0], profiles.shape[1]
    height, width = patch_mask.shape
    centre_x, centre_y, centre_radius = x, y, radius
    # Only the part of each ray inside the frame (a ball cut by the frame's edge), with room
    # for the levels around an edge; no ray towards another ball (it sees that one's colour).
    allowed = allowed_samples(height, width, x, y, radii, directions, start, stop, (half + 1) * step)
    usable = np.zeros(samples, np.bool_)
    for ray in range(samples):
        for sample in range(count):
            if allowed[ray, sample]:
                usable[ray] = True
                break
    for other in range(others.shape[0]):
        dx, dy = others[other, 0] - x, others[other, 1] - y
        distance = math.hypot(dx, dy)
        if 1e-6 < distance < stop + 1.15 * others[other, 2] + 1:
            bearing = math.cos(math.asin(min(1.0, (1.15 * others[other, 2] + 1) / distance)))
            for ray in range(samples):
                if not (directions[0, ray] * dx + directions[1, ray] * dy) / distance < bearing:
                    usable[ray] = False
    in_view = 0
    sum_cos = sum_sin = 0.0
    for ray in range(samples):
        if usable[ray]:
            in_view += 1
            sum_cos += directions[0, ray]
            sum_sin += directions[1, ray]
        else:
            allowed[ray, :] = False
    # (the rays in view of a ball cut by the frame's edge all point one way)
    one_sided = 0.7
    if in_view:
        one_sided = max(0.7, math.hypot(sum_cos / in_view, sum_sin / in_view) + 0.1)
    peak, has_edge, gradient = edge_peaks(profiles, allowed)
    # A wide round of a ball in full view sampled as finely as a narrow round samples: its
    # edges may serve the narrow fit (see below).
    reusable = reuse_edges and wide and step == RAY_STEP and in_view == samples

    # The hypotheses: per ray the index of its edge and whether it has one.
    if wide:
        first, found, outermost = outline_edges(profiles, peak, colour, half, gain, dark)
        differing = 0
        for ray in range(samples):
            differing += first[ray] != outermost[ray] and has_edge[ray]
        hypotheses = 2 if differing >= 0.15 * samples else 1
        rounds = WIDE_FIT_TABLE
    else:  # each ray's edge nearest the circle
        # (one hypothesis: ``outermost`` only gives the variables the wide round's types)
        first, found, outermost = np.zeros(samples, np.int64), has_edge, np.zeros(samples, np.int64)
        target = np.float32(radius)
        for ray in range(samples):
            nearest = np.inf
            for sample in range(count):
                if peak[ray, sample] and abs(radii[sample] - target) < nearest:
                    nearest, first[ray] = abs(radii[sample] - target), sample
        hypotheses = 1
        rounds = NARROW_FIT_TABLE

    # Each hypothesis's circle: from the rays that may count, the robust fit of its good edges.
    fit_x, fit_y, fit_radius = np.zeros(2), np.zeros(2), np.zeros(2)
    fit_kept, fit_spread, fit_sigma = np.zeros(2, np.int64), np.zeros(2), np.zeros(2)
    fitted = np.zeros(2, np.bool_)
    least = max(8, 0.35 * in_view)
    for hypothesis in range(hypotheses):
        index, has = (first, found) if hypothesis == 0 else (outermost, has_edge)
        rays = np.flatnonzero(usable & has_edge & has)
        if rays.size < least:
            continue
        index = index[rays]
        px, py, contrast, good = hypothesis_edges(profiles, radii, patch_mask, x, y, radius, step,
                                                  half, directions, index, rays)
        if np.count_nonzero(good) < least:
            continue
        ok, circle_x, circle_y, circle_radius, on_circle = robust_rounds(
            px[good], py[good], x, y, radius, rounds, not wide)
        if not ok:
            continue
        keep = np.flatnonzero(good)[on_circle]
        if (not seen_all_round(directions[0][rays[keep]], directions[1][rays[keep]], in_view, one_sided)
                or not 0.5 * radius < circle_radius < 2.0 * radius + 2):
            continue  # the edge seen on too few rays, or on one side only
        fitted[hypothesis] = True
        fit_x[hypothesis], fit_y[hypothesis], fit_radius[hypothesis] = circle_x, circle_y, circle_radius
        fit_kept[hypothesis] = keep.size
        # (how closely a fit follows its edges only tells hypotheses apart)
        if hypotheses > 1:
            residual = np.hypot(px[good][on_circle] - circle_x, py[good][on_circle] - circle_y) - circle_radius
            fit_spread[hypothesis] = math.sqrt((residual * residual).sum() / residual.size)
        # (only the narrow round's result is corrected for blur)
        if not wide:
            fit_sigma[hypothesis] = median(edge_widths(gradient, contrast[keep], rays[keep], index[keep], step))

    # The hypothesis most rays agree on; among about equally good ones the larger circle (the
    # outline is the outermost circle; shading edges inside a small ball fit too).
    if not fitted.any():
        return FAILED, x, y, radius, wide_rounds
    chosen = 0 if fitted[0] else 1
    if fitted[0] and fitted[1]:
        most = max(fit_kept[0], fit_kept[1])
        tightest = np.inf
        for hypothesis in range(2):
            if fit_kept[hypothesis] >= most / 1.05:
                tightest = min(tightest, fit_spread[hypothesis])
        chosen = -1
        for hypothesis in range(2):
            if (fit_kept[hypothesis] >= most / 1.05 and fit_spread[hypothesis] <= 1.5 * tightest + 0.05
                    and (chosen < 0 or fit_radius[hypothesis] > fit_radius[chosen])):
                chosen = hypothesis
    grown = fit_radius[chosen] - radius
    x, y, radius = fit_x[chosen], fit_y[chosen], fit_radius[chosen]
    if not wide:
        # The 50 % contour of a disc blurred by sigma lies sigma^2 / 2r inside its edge.
        return FOUND, x, y, radius + min(fit_sigma[chosen], BLUR_LIMIT) ** 2 / (2.0 * radius), wide_rounds
    # Each wide round starts from the last circle, reaching further into a dark side; once the
    # circle stops growing (no dark side, or all of it), the narrow round.
    wide_rounds = SILHOUETTE_WIDE_ROUNDS if grown < 0.05 * radius + 0.3 else wide_rounds + 1
    # The last wide round's circle was fitted to its edges: when they are reusable, the narrow
    # fit is made on them instead of new rays (the edges are points of the outline whichever
    # centre the rays came from). Not for a ball cut by the frame's edge or beside another:
    # the part of the rim in view needs the narrow round's denser rays.
    if wide_rounds >= SILHOUETTE_WIDE_ROUNDS and reusable:
        index, has = (first, found) if chosen == 0 else (outermost, has_edge)
        rays = np.flatnonzero(usable & has_edge & has)
        index = index[rays]
        px, py, contrast, good = hypothesis_edges(profiles, radii, patch_mask, centre_x, centre_y,
                                                  centre_radius, step, half, directions, index, rays)
        good_rays = np.flatnonzero(good)
        ok, refined_x, refined_y, refined_radius = narrow_fit(
            px[good], py[good], edge_widths(gradient, contrast[good_rays], rays[good_rays], index[good_rays], step),
            directions[:2, rays[good_rays]], x, y, radius, in_view, one_sided)
        if ok:
            return FOUND_REUSED, refined_x, refined_y, refined_radius, wide_rounds
    return GOING_ON, x, y, radius, wide_rounds


def silhouette(frame: np.ndarray, mask: np.ndarray, gain: float, reference: float,
               ball: Candidate, others: list[Candidate], wide_reach: float = WIDE_REACH,
               reuse_edges: bool = True, trace: list | None = None) -> tuple[float, float, float] | None:
    """The ball's outline located on the frame itself, to a fraction of a pixel.

    Along rays from the centre, the colour edges from just inside the colour mask's circle
    outwards are located at their 50 % crossing (so blur, which spreads the colour mask, does
    not move them) and a circle is fitted to them robustly. Wide rounds, each from the last
    circle, look for the outline either as each ray's first edge that is not shading (a ball
    in front of other edges) or as its outermost edge (a dark side that the colour mask
    misses); the hypothesis that more rays agree on wins (about as many: the larger circle,
    if it fits about as closely). A narrow round then takes each
    ray's edge nearest the circle; for a ball in full view whose last wide round sampled as
    finely as a narrow one (radius up to 30 px), the narrow round's fit is made on that
    round's edges instead (``narrow_fit``: a round fewer, radii within 1 % of a narrow
    round's on the renders). None when too few rays see an edge, when they see it on one side
    only, or when the result does not contain most of the colour mask's circle.

    Rays are used only within the frame (a ball cut by its edge keeps the visible arc) and not
    towards ``others`` (touching balls); a ray whose edge has colour-mask pixels just past it
    (yellow-green clutter touching the ball) is left out.

    ``frame``: the BGR frame after the dark-frame ``gain`` (whose rounding step tells shading
    from an outline); ``reference``: its reference level (near black is below DARK_SHARE of
    it); ``mask``: its colour mask; ``wide_reach``: WIDE_REACH or, in extremely dark frames,
    DARK_WIDE_REACH; ``reuse_edges``: False for a narrow round of its own in every case;
    ``trace``: a list, to which each round's kind is appended (ROUND_OUTCOMES). Returns the
    outline's (x, y, radius) in the frame's pixels.
    """
    height, width = mask.shape
    x0, y0, r0 = ball.x, ball.y, ball.radius
    reach = SILHOUETTE_REACH * r0 + 6
    box = box_around(x0, y0, reach, width, height)
    if box is None:
        return None
    left, top = box[1].start, box[0].start
    patch = frame[box].astype(np.float32)
    # (contiguous: one compiled signature of outline_round, whether or not the box spans the
    # frame's width, so no frame waits for the compiler; see detector.compile_kernels)
    patch_mask = np.ascontiguousarray(mask[box])
    # The ball's colour: the mean of its lit, colour-mask part.
    # (a boolean AND: OpenCV's per-call overhead exceeds the work on a patch this small)
    lit = disc(patch_mask.shape, x0 - left, y0 - top, 0.85 * r0)
    np.bitwise_and(lit, patch_mask == 255, out=lit)
    if not cv2.countNonZero(lit):
        return None
    colour = np.array(cv2.mean(patch, lit)[:3], np.float32)
    near = np.array([(other.x - left, other.y - top, other.radius) for other in others], np.float64).reshape(-1, 3)

    x, y, radius = x0 - left, y0 - top, r0
    wide_rounds = 0
    while True:
        wide = wide_rounds < SILHOUETTE_WIDE_ROUNDS
        samples = int(min(WIDE_RAYS if wide else NARROW_RAYS, max(24, round(2 * math.pi * radius))))
        directions = rim_directions(samples)
        if wide:  # from just inside the circle to well past it
            start = radius - min(EDGE_MARGIN + 0.15 * radius, 0.4 * radius)
            stop, step = wide_reach * radius + 2, max(RAY_STEP, radius / 60.0)
        else:  # a narrow band around the circle found
            band = max(1.5, 0.15 * radius)
            start, stop, step = radius - band, radius + band, RAY_STEP
        half = max(1, int(round(min(EDGE_HALF_WIDTH, 0.3 * radius) / step)))
        radii = np.arange(max(0.0, start - half * step), stop + (half + 1) * step, step,
                          dtype=np.float32)
        profiles = ray_profiles(patch, x, y, radii, directions)
        outcome, x, y, radius, wide_rounds = outline_round(
            profiles, radii, directions, x, y, radius, start, stop, step, half, wide, wide_rounds,
            near, colour, gain, DARK_SHARE * reference, patch_mask, reuse_edges)
        if trace is not None and outcome != FAILED:
            trace.append(ROUND_OUTCOMES[outcome])
        if outcome == FAILED:
            return None
        if outcome != GOING_ON:
            break
    x, y = x + left, y + top
    # The colour mask's circle is the outline or a lit part inside it (a dark side it misses).
    shift = math.hypot(x - x0, y - y0)
    if not (0.85 * r0 - 1.0 <= radius <= 2.2 * r0 + 2.0 and shift + 0.7 * r0 <= radius + 1.0):
        return None
    return x, y, radius
