"""The sub-pixel outline: step 8 of the detector (see ``detector.py``).

Each accepted ball's circle is replaced by its outline located on the frame itself: along rays
from the centre, the colour edge at its 50 % crossing, then a robust circle fit. The colour
mask's edge lies where blur has spread the colour (radii 0.5-1 px too large whatever the size,
the more blurred the frame the more), and a strongly shaded side drags its centre towards the
lit side; the 50 % crossing of the edge does not move with blur, and edges of shading are told
from the outline (see ``is_shading``).
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.fit import robust_circle
from balltrack.services.detector.geometry import Candidate, box_around, disc, rim_directions
from balltrack.services.detector.jit import compiled

# Silhouette refinement of accepted balls (radial edge profiles of the frame itself):
# sample spacing along a ray (px); an edge is a local maximum of the colour gradient along the
# ray of at least EDGE_SIGNIFICANT of that ray's strongest; rays whose strongest gradient is
# below EDGE_FLOOR of the median ray's see no edge (a dark side against a dark background).
RAY_STEP = 0.5
EDGE_SIGNIFICANT = 0.45
EDGE_FLOOR = 0.3
# Half width (px; at most 30 % of the radius) of the profile around an edge whose levels set
# its 50 % crossing.
EDGE_HALF_WIDTH = 1.5
# Edges are looked for from this far (px, plus 15 % of the radius, at most 40 % of it) inside
# the current circle.
EDGE_MARGIN = 2.5
# Shading, not an outline: past the edge the colour is the ball's colour times less than
# SHADING_SHARE, off that axis by at most SHADING_TOLERANCE of its brightness, or it is
# nearly black (below DARK_SHARE of the frame's reference level).
SHADING_SHARE = 0.9
SHADING_TOLERANCE = 0.12
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


def median(values: np.ndarray) -> float:
    """``float(np.median(values))`` of a 1-D array without NaNs, a few times faster on the
    few dozen values of a ray search (np.median's overhead dominates there)."""
    count = values.size
    middle = count // 2
    if count % 2:
        return float(np.partition(values, middle)[middle])
    # (the mean of the two middle values, as np.median takes it: in the array's own type;
    # their sum over two is what ndarray.mean computes, without its wrapper's overhead)
    return float(np.partition(values, (middle - 1, middle))[middle - 1:middle + 1].sum() / 2)


def ray_profiles(patch: np.ndarray, x: float, y: float, radii: np.ndarray,
                 directions: np.ndarray) -> np.ndarray:
    """Colours (rays x radii x 3, float32) sampled bilinearly along rays from (x, y) in
    ``patch``."""
    map_x = (x + directions[0][:, None] * radii[None, :]).astype(np.float32)
    map_y = (y + directions[1][:, None] * radii[None, :]).astype(np.float32)
    values = cv2.remap(patch, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return values.reshape(map_x.shape + (-1,))


def ray_bounds(shape: tuple[int, ...], x: float, y: float,
               directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per ray from (x, y), the distances along it at which it enters and leaves a patch of
    ``shape``."""
    height, width = shape[:2]
    # Both axes at once (rows x, y): where each ray crosses the patch's first and last pixel.
    position = np.array([[x], [y]])
    inside = np.array([[0.0 <= x <= width - 1.0], [0.0 <= y <= height - 1.0]])
    axis_directions = directions[:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        low = (0.0 - position) / axis_directions
        high = (np.array([[width - 1.0 - x], [height - 1.0 - y]])) / axis_directions
    # (a ray parallel to an axis crosses neither of its sides: all or none of it is inside)
    flat = np.abs(axis_directions) < 1e-9
    low = np.where(flat, np.where(inside, -np.inf, np.inf), low)
    high = np.where(flat, np.where(inside, np.inf, -np.inf), high)
    return np.minimum(low, high).max(axis=0), np.maximum(low, high).min(axis=0)


def allowed_samples(shape: tuple[int, ...], x: float, y: float, radii: np.ndarray,
                    directions: np.ndarray, start: float, stop: float, margin: float) -> np.ndarray:
    """Rays x radii: the samples from ``start`` to ``stop`` along each ray from (x, y) that
    lie at least ``margin`` inside a patch of ``shape``."""
    height, width = shape[:2]
    # A centre at least stop + margin from every side: no ray leaves the patch before
    # stop + margin (a unit ray's exit is at least the distance to the nearest side) nor
    # entered it after start - margin (its entry is behind the centre), so the bounds need
    # not be computed; the comparisons are the general case's, in float64 like it.
    radii = radii.astype(np.float64)
    if margin <= start and min(x, y, width - 1.0 - x, height - 1.0 - y) - margin >= stop:
        along = (radii >= start) & (radii <= stop)
        return np.repeat(along[None, :], directions.shape[1], axis=0)
    enter, leave = ray_bounds(shape, x, y, directions)
    return ((radii[None, :] >= np.maximum(start, enter + margin)[:, None])
            & (radii[None, :] <= np.minimum(stop, leave - margin)[:, None]))


@compiled
def sorted_median(values):
    """The median of a 1-D float32 array without NaNs, as ``median`` takes it (the mean of
    the two middle values in the array's own type)."""
    ordered = np.sort(values)
    middle = ordered.size // 2
    if ordered.size % 2:
        return ordered[middle]
    return (ordered[middle - 1] + ordered[middle]) / np.float32(2.0)


@compiled
def edge_peaks(profiles, allowed):
    """Significant colour-gradient peaks along each ray (rays x samples, only where
    ``allowed``), whether each ray sees an edge at all, and the gradient (per sample step)."""
    rays, count = profiles.shape[0], profiles.shape[1]
    gradient = np.zeros((rays, count), np.float32)
    strongest = np.zeros(rays, np.float32)
    for ray in range(rays):
        for sample in range(1, count - 1):
            if allowed[ray, sample]:
                blue = profiles[ray, sample + 1, 0] - profiles[ray, sample - 1, 0]
                green = profiles[ray, sample + 1, 1] - profiles[ray, sample - 1, 1]
                red = profiles[ray, sample + 1, 2] - profiles[ray, sample - 1, 2]
                value = np.sqrt(blue * blue + green * green + red * red)
                gradient[ray, sample] = value
                strongest[ray] = max(strongest[ray], value)
    floor = EDGE_FLOOR * np.float64(sorted_median(strongest)) if rays else 0.0
    floor = np.float32(max(floor, 1e-3))
    significant = np.float32(EDGE_SIGNIFICANT)
    peak = np.zeros((rays, count), np.bool_)
    has_edge = np.zeros(rays, np.bool_)
    for ray in range(rays):
        least = significant * strongest[ray]
        for sample in range(1, count - 1):
            value = gradient[ray, sample]
            if value >= gradient[ray, sample - 1] and value >= gradient[ray, sample + 1] and value >= least:
                peak[ray, sample] = True
                has_edge[ray] = True
        has_edge[ray] = has_edge[ray] and strongest[ray] > floor
    return peak, has_edge, gradient


@compiled
def is_shading(profiles, ray, index, colour, colour_norm, half, quantum, dark):
    """Whether the edge at ``index`` along ``ray`` is shading rather than an outline: going
    outwards the colour darkens into a darker version of the ball's ``colour`` (within
    ``quantum``, the frame's rounding step) or into near black (below ``dark``).
    ``colour_norm``: max(colour . colour, 1e-6)."""
    count = profiles.shape[1]
    inner, outer = profiles[ray, max(index - half, 0)], profiles[ray, min(index + half, count - 1)]
    brightness_in = np.sqrt(inner[0] * inner[0] + inner[1] * inner[1] + inner[2] * inner[2])
    brightness_out = np.sqrt(outer[0] * outer[0] + outer[1] * outer[1] + outer[2] * outer[2])
    share = (outer[0] * colour[0] + outer[1] * colour[1] + outer[2] * colour[2]) / colour_norm
    blue = outer[0] - share * colour[0]
    green = outer[1] - share * colour[1]
    red = outer[2] - share * colour[2]
    off_axis = np.sqrt(blue * blue + green * green + red * red)
    ball_like = (share < np.float32(SHADING_SHARE)
                 and off_axis <= np.float32(SHADING_TOLERANCE) * brightness_out + quantum)
    return brightness_out < brightness_in and (ball_like or brightness_out < dark)


@compiled
def outline_edges(profiles, peak, colour, half, quantum, dark):
    """Per ray, a wide round's two outline hypotheses: its first edge that is not shading
    (index, and whether there is one) and its outermost edge (see ``silhouette``)."""
    rays, count = peak.shape
    colour_norm = np.float32(max(np.float64(colour[0] * colour[0] + colour[1] * colour[1]
                                            + colour[2] * colour[2]), 1e-6))
    first = np.zeros(rays, np.int64)
    found = np.zeros(rays, np.bool_)
    outermost = np.full(rays, count - 1, np.int64)
    for ray in range(rays):
        last = -1
        for sample in range(count):
            if peak[ray, sample]:
                last = sample
                if not found[ray] and not is_shading(profiles, ray, sample, colour, colour_norm, half,
                                                     np.float32(quantum), np.float32(dark)):
                    first[ray], found[ray] = sample, True
        if last >= 0:
            outermost[ray] = last
    return first, found, outermost


@compiled
def crossing_edges(profiles, index, half, rays):
    """``crossings`` of the edges at ``index`` along ``rays``."""
    count, width = profiles.shape[1], 2 * half + 1
    position = np.empty(rays.size)
    defined = np.empty(rays.size, np.bool_)
    contrast = np.empty(rays.size, np.float32)
    share = np.empty(width, np.float32)
    for edge in range(rays.size):
        ray = rays[edge]
        inner = profiles[ray, min(max(index[edge] - half, 0), count - 1)]
        outer = profiles[ray, min(max(index[edge] + half, 0), count - 1)]
        blue, green, red = inner[0] - outer[0], inner[1] - outer[1], inner[2] - outer[2]
        norm = blue * blue + green * green + red * red
        scale = max(norm, np.float32(1e-9))
        last = width - 1  # (no sample above half way: only when the contrast is nil)
        above = False
        for offset in range(width):
            level = profiles[ray, min(max(index[edge] - half + offset, 0), count - 1)]
            share[offset] = ((level[0] - outer[0]) * blue + (level[1] - outer[1]) * green
                             + (level[2] - outer[2]) * red) / scale
            if share[offset] >= np.float32(0.5):
                last, above = offset, True
        # the outermost sample still at least half way to the inside level, and the next one
        last = min(last, width - 2)
        drop = share[last] - share[last + 1]
        fraction = (share[last] - np.float32(0.5)) / max(drop, np.float32(1e-6)) if drop > np.float32(1e-6) else np.float32(0.0)
        position[edge] = index[edge] - half + last + min(max(fraction, np.float32(0.0)), np.float32(1.0))
        defined[edge] = norm > np.float32(1e-6) and not share[width - 1] >= np.float32(0.5)
        contrast[edge] = np.sqrt(norm)
    return position, defined, contrast


def crossings(profiles: np.ndarray, index: np.ndarray, half: int,
              rays: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-sample position (in samples) of the 50 % crossing between the levels ``half``
    samples inside and outside the edge ``index`` of each ray (of ``rays`` only, when given),
    whether it is well defined, and the contrast between those levels."""
    if rays is None:
        rays = np.arange(profiles.shape[0])
    return crossing_edges(np.ascontiguousarray(profiles, np.float32), np.asarray(index, np.int64),
                          int(half), np.asarray(rays, np.int64))


def edge_widths(gradient: np.ndarray, contrast: np.ndarray, rays: np.ndarray, index: np.ndarray,
                step: float) -> np.ndarray:
    """Per edge (at ``index`` along ``rays``), the blur (Gaussian sigma, px) of a step of its
    ``contrast``: a blurred step of contrast C has the steepest slope C / (sigma sqrt(2 pi))."""
    slope = gradient[rays, index] / (2 * step)
    return contrast / np.maximum(slope, 1e-6) / math.sqrt(2 * math.pi)


def seen_all_round(directions: np.ndarray, in_view: int, one_sided: float) -> bool:
    """Whether edges seen along these ray ``directions`` (rows cos, sin) are enough of the
    ``in_view`` rays and not on one side only (their mean direction at most ``one_sided``)."""
    count = directions.shape[1]
    return (count >= max(8, 0.3 * in_view)
            and math.hypot(np.add.reduce(directions[0]) / count,
                           np.add.reduce(directions[1]) / count) <= one_sided)


def narrow_fit(px: np.ndarray, py: np.ndarray, widths: np.ndarray, directions: np.ndarray,
               x: float, y: float, radius: float, in_view: int,
               one_sided: float) -> tuple[float, float, float] | None:
    """The narrow round's fit on edges a wide round located (points ``px``, ``py`` along ray
    ``directions``, with their ``widths``, see edge_widths), from the circle it found: the
    robust geometric circle through them, corrected for blur; None when too few edges lie on
    it or they lie on one side only."""
    fitted = robust_circle(px, py, x, y, radius, NARROW_FIT_ROUNDS, geometric=True)
    if fitted is None or not 0.5 * radius < fitted[2] < 2.0 * radius + 2:
        return None
    kept = fitted[3]
    if not seen_all_round(directions[:, kept], in_view, one_sided):
        return None
    # The 50 % contour of a disc blurred by sigma lies sigma^2 / 2r inside its edge.
    sigma = median(widths[kept])
    return fitted[0], fitted[1], fitted[2] + min(sigma, BLUR_LIMIT) ** 2 / (2.0 * fitted[2])


def silhouette(frame: np.ndarray, mask: np.ndarray, gain: float, reference: float,
               ball: Candidate, others: list[Candidate],
               wide_reach: float = WIDE_REACH) -> tuple[float, float, float] | None:
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
    DARK_WIDE_REACH. Returns the outline's (x, y, radius) in the frame's pixels.
    """
    height, width = mask.shape
    x0, y0, r0 = ball.x, ball.y, ball.radius
    reach = SILHOUETTE_REACH * r0 + 6
    box = box_around(x0, y0, reach, width, height)
    if box is None:
        return None
    left, top = box[1].start, box[0].start
    patch = frame[box].astype(np.float32)
    patch_mask = mask[box]
    # The ball's colour: the mean of its lit, colour-mask part.
    # (a boolean AND: OpenCV's per-call overhead exceeds the work on a patch this small)
    lit = disc(patch_mask.shape, x0 - left, y0 - top, 0.85 * r0)
    np.bitwise_and(lit, patch_mask == 255, out=lit)
    if not cv2.countNonZero(lit):
        return None
    colour = np.array(cv2.mean(patch, lit)[:3], np.float32)
    dark = DARK_SHARE * reference

    x, y, radius = x0 - left, y0 - top, r0
    last_pixel = np.array([[patch.shape[1] - 1], [patch.shape[0] - 1]])
    wide_rounds = 0
    while True:
        wide = wide_rounds < SILHOUETTE_WIDE_ROUNDS
        samples = int(min(WIDE_RAYS if wide else NARROW_RAYS, max(24, round(2 * math.pi * radius))))
        directions = rim_directions(samples)
        cos, sin = directions[0], directions[1]
        if wide:  # from just inside the circle to well past it
            start = radius - min(EDGE_MARGIN + 0.15 * radius, 0.4 * radius)
            stop, step = wide_reach * radius + 2, max(RAY_STEP, radius / 60.0)
            rounds = WIDE_FIT_ROUNDS
        else:  # a narrow band around the circle found
            band = max(1.5, 0.15 * radius)
            start, stop, step = radius - band, radius + band, RAY_STEP
            rounds = NARROW_FIT_ROUNDS
        half = max(1, int(round(min(EDGE_HALF_WIDTH, 0.3 * radius) / step)))
        radii = np.arange(max(0.0, start - half * step), stop + (half + 1) * step, step,
                          dtype=np.float32)
        profiles = ray_profiles(patch, x, y, radii, directions)
        centre = np.array([[x], [y]])
        # Only the part of each ray inside the frame (a ball cut by the frame's edge), with
        # room for the levels around an edge.
        allowed = allowed_samples(patch.shape, x, y, radii, directions, start, stop, (half + 1) * step)
        usable = np.logical_or.reduce(allowed, axis=1)
        for other in others:  # rays towards another ball see its colour, not this outline
            dx, dy = other.x - left - x, other.y - top - y
            distance = math.hypot(dx, dy)
            if 1e-6 < distance < stop + 1.15 * other.radius + 1:
                half_angle = math.asin(min(1.0, (1.15 * other.radius + 1) / distance))
                bearing = math.cos(half_angle)
                usable &= (cos * dx + sin * dy) / distance < bearing
        allowed &= usable[:, None]
        in_view = np.count_nonzero(usable)
        # (the rays in view of a ball cut by the frame's edge all point one way)
        one_sided = 0.7
        if in_view:
            one_sided = max(0.7, math.hypot(np.add.reduce(cos[usable]) / in_view,
                                            np.add.reduce(sin[usable]) / in_view) + 0.1)
        peak, has_edge, gradient = edge_peaks(profiles, allowed)
        # A wide round of a ball in full view sampled as finely as a narrow round samples:
        # its edges may serve the narrow fit (see below).
        reusable = wide and step == RAY_STEP and in_view == samples
        if wide:
            first, found, outermost = outline_edges(profiles, peak, colour, half, gain, dark)
            choices = [(first, found)]
            if np.count_nonzero((first != outermost) & has_edge) >= 0.15 * samples:
                choices.append((outermost, has_edge))
        else:
            away = np.where(peak, np.abs(radii - radius)[None, :], np.inf)
            choices = [(np.argmin(away, axis=1), has_edge)]
        # Only rays that may count: a ray's edge is used when all of these hold and its
        # crossing is defined with no colour mask past it.
        selected = []
        for index, found in choices:
            rays = np.flatnonzero(usable & has_edge & found)
            if rays.size >= max(8, 0.35 * in_view):
                selected.append((index[rays], rays))
        fits = []
        if selected:
            # (the hypotheses' edges located in one pass: per-call overhead dominates here)
            all_index = np.concatenate([index for index, _ in selected])
            all_rays = np.concatenate([rays for _, rays in selected])
            position, defined, all_contrast = crossings(profiles, all_index, half, all_rays)
            rho = radii[0] + position * step
            # (rows x, y: both coordinates in one operation each)
            all_directions = directions[:2, all_rays]
            all_px, all_py = centre + all_directions * rho
            # The colour mask must not go on past the edge (clutter touching the ball).
            beyond = np.rint(centre + all_directions * (rho + max(2.0, 0.12 * radius)))
            bx, by = np.minimum(np.maximum(beyond, 0), last_pixel).astype(np.intp)
            all_good = defined & (patch_mask[by, bx] != 255)
        start_at = 0
        for index, rays in selected:
            part = slice(start_at, start_at + rays.size)
            start_at += rays.size
            good, ray_directions, contrast = all_good[part], all_directions[:, part], all_contrast[part]
            if np.count_nonzero(good) < max(8, 0.35 * in_view):
                continue
            px, py = all_px[part][good], all_py[part][good]
            fitted = robust_circle(px, py, x, y, radius, rounds, geometric=not wide)
            if fitted is None:
                continue
            good_rays = np.flatnonzero(good)
            keep = good_rays[fitted[3]]
            if (not seen_all_round(ray_directions[:, keep], in_view, one_sided)
                    or not 0.5 * radius < fitted[2] < 2.0 * radius + 2):
                continue  # the edge seen on too few rays, or on one side only
            # (how closely a fit follows its edges only tells hypotheses apart)
            spread = None
            if len(choices) > 1:
                residual = np.hypot(px[fitted[3]] - fitted[0], py[fitted[3]] - fitted[1]) - fitted[2]
                spread = float(np.sqrt(np.add.reduce(residual * residual) / residual.size))
            # (only the narrow round's result is corrected for blur)
            sigma = edges = None
            if not wide:
                sigma = median(edge_widths(gradient, contrast[keep], rays[keep], index[keep], step))
            elif reusable:
                # (their widths are measured only for the hypothesis chosen, see below)
                edges = (px, py, (contrast[good_rays], rays[good_rays], index[good_rays]),
                         ray_directions[:, good_rays])
            fits.append((fitted[:3], keep.size, spread, sigma, edges))
        # The hypothesis most rays agree on; among about equally good ones the larger circle
        # (the outline is the outermost circle; shading edges inside a small ball fit too).
        best = edges = None
        if len(fits) == 1:
            best, sigma, edges = fits[0][0], fits[0][3], fits[0][4]
        elif fits:
            most = max(fit[1] for fit in fits)
            tightest = min(fit[2] for fit in fits if fit[1] >= most / 1.05)
            chosen = max((fit for fit in fits if fit[1] >= most / 1.05 and fit[2] <= 1.5 * tightest + 0.05),
                         key=lambda fit: fit[0][2])
            best, sigma, edges = chosen[0], chosen[3], chosen[4]
        if best is None:
            return None
        grown = best[2] - radius
        x, y, radius = best[:3]
        if not wide:
            # The 50 % contour of a disc blurred by sigma lies sigma^2 / 2r inside its edge.
            radius += min(sigma, BLUR_LIMIT) ** 2 / (2.0 * radius)
            break
        # Each wide round starts from the last circle, reaching further into a dark side;
        # once the circle stops growing (no dark side, or all of it), the narrow round.
        wide_rounds = SILHOUETTE_WIDE_ROUNDS if grown < 0.05 * radius + 0.3 else wide_rounds + 1
        # The last wide round's circle was fitted to its edges: when they are reusable, the
        # narrow fit is made on them instead of new rays (the edges are points of the outline
        # whichever centre the rays came from). Not for a ball cut by the frame's edge or
        # beside another: the part of the rim in view needs the narrow round's denser rays.
        if wide_rounds >= SILHOUETTE_WIDE_ROUNDS and edges is not None:
            px, py, (contrast, rays, index), ray_directions = edges
            refined = narrow_fit(px, py, edge_widths(gradient, contrast, rays, index, step),
                                 ray_directions, x, y, radius, in_view, one_sided)
            if refined is not None:
                x, y, radius = refined
                break
    x, y = x + left, y + top
    # The colour mask's circle is the outline or a lit part inside it (a dark side it misses).
    shift = math.hypot(x - x0, y - y0)
    if not (0.85 * r0 - 1.0 <= radius <= 2.2 * r0 + 2.0 and shift + 0.7 * r0 <= radius + 1.0):
        return None
    return x, y, radius
