"""Colour edges along rays from a ball's centre: the measurements of step 8, the sub-pixel
outline (``outline.py``, see ``detector.py``).

The frame is sampled along rays (``ray_profiles``), within the patch (``allowed_samples``); an
edge is a significant peak of the colour gradient along a ray (``edge_peaks``), located at the
50 % crossing between the levels on either side of it (``crossing_edges``, which blur does not
move); an edge into a darker version of the ball's colour, or into black, is shading rather
than the outline (``is_shading``). Compiled (see ``jit.py``): a few dozen rays of a few dozen
samples each, where numpy's overhead per call was most of the time.
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.jit import compiled

# An edge is a local maximum of the colour gradient along the ray of at least EDGE_SIGNIFICANT
# of that ray's strongest; rays whose strongest gradient is below EDGE_FLOOR of the median
# ray's see no edge (a dark side against a dark background).
EDGE_SIGNIFICANT = 0.45
EDGE_FLOOR = 0.3
# Shading, not an outline: past the edge the colour is the ball's colour times less than
# SHADING_SHARE, off that axis by at most SHADING_TOLERANCE of its brightness, or it is
# nearly black (``dark``: the silhouette's DARK_SHARE of the frame's reference level).
SHADING_SHARE = 0.9
SHADING_TOLERANCE = 0.12


@compiled
def median(values):
    """The median of a 1-D array without NaNs, as np.median takes it (the mean of the two
    middle values in the array's own type)."""
    ordered = np.sort(values)
    middle = ordered.size // 2
    if ordered.size % 2:
        return ordered[middle]
    return (ordered[middle - 1] + ordered[middle]) / np.float32(2.0)


def ray_profiles(patch: np.ndarray, x: float, y: float, radii: np.ndarray,
                 directions: np.ndarray) -> np.ndarray:
    """Colours (rays x radii x 3, float32) sampled bilinearly along rays from (x, y) in
    ``patch``."""
    map_x = (x + directions[0][:, None] * radii[None, :]).astype(np.float32)
    map_y = (y + directions[1][:, None] * radii[None, :]).astype(np.float32)
    values = cv2.remap(patch, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return values.reshape(map_x.shape + (-1,))


@compiled
def axis_bounds(position, direction, last):
    """Distances along a ray (from ``position``, ``direction`` along one axis) at which it is
    at the axis's first pixel and at its last (``last``), in order; a ray parallel to the
    axis crosses neither: all of it lies between them, or none."""
    if abs(direction) < 1e-9:
        if 0.0 <= position <= last:
            return -np.inf, np.inf
        return np.inf, -np.inf
    low, high = (0.0 - position) / direction, (last - position) / direction
    return min(low, high), max(low, high)


@compiled
def ray_bounds(height, width, x, y, directions):
    """Per ray from (x, y) (``directions``: rows cos, sin), the distances along it at which
    it enters and leaves a patch of ``height`` x ``width``."""
    rays = directions.shape[1]
    enter, leave = np.empty(rays), np.empty(rays)
    for ray in range(rays):
        enter_x, leave_x = axis_bounds(x, directions[0, ray], width - 1.0)
        enter_y, leave_y = axis_bounds(y, directions[1, ray], height - 1.0)
        enter[ray], leave[ray] = max(enter_x, enter_y), min(leave_x, leave_y)
    return enter, leave


@compiled
def allowed_samples(height, width, x, y, radii, directions, start, stop, margin):
    """Rays x radii: the samples from ``start`` to ``stop`` along each ray from (x, y) that
    lie at least ``margin`` inside a patch of ``height`` x ``width``."""
    rays = directions.shape[1]
    allowed = np.zeros((rays, radii.size), np.bool_)
    # A centre at least stop + margin from every side: no ray leaves the patch before
    # stop + margin (a unit ray's exit is at least the distance to the nearest side) nor
    # entered it after start - margin (its entry is behind the centre).
    inside = margin <= start and min(x, y, width - 1.0 - x, height - 1.0 - y) - margin >= stop
    enter, leave = (np.empty(0), np.empty(0)) if inside else ray_bounds(height, width, x, y, directions)
    for ray in range(rays):
        first, last = start, stop
        if not inside:
            first, last = max(start, enter[ray] + margin), min(stop, leave[ray] - margin)
        for sample in range(radii.size):
            allowed[ray, sample] = first <= np.float64(radii[sample]) <= last
    return allowed


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
    floor = EDGE_FLOOR * np.float64(median(strongest)) if rays else 0.0
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
    quantum, dark = np.float32(quantum), np.float32(dark)
    for ray in range(rays):
        last = -1
        for sample in range(count):
            if peak[ray, sample]:
                last = sample
                if not found[ray] and not is_shading(profiles, ray, sample, colour, colour_norm, half,
                                                     quantum, dark):
                    first[ray], found[ray] = sample, True
        if last >= 0:
            outermost[ray] = last
    return first, found, outermost


@compiled
def crossing_edges(profiles, index, half, rays):
    """Sub-sample position (in samples) of the 50 % crossing between the levels ``half``
    samples inside and outside the edge at ``index`` along each of ``rays``, whether it is
    well defined, and the contrast between those levels."""
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
        for offset in range(width):
            level = profiles[ray, min(max(index[edge] - half + offset, 0), count - 1)]
            share[offset] = ((level[0] - outer[0]) * blue + (level[1] - outer[1]) * green
                             + (level[2] - outer[2]) * red) / scale
            if share[offset] >= np.float32(0.5):
                last = offset
        # the outermost sample still at least half way to the inside level, and the next one
        last = min(last, width - 2)
        drop = share[last] - share[last + 1]
        fraction = np.float32(0.0)
        if drop > np.float32(1e-6):
            fraction = (share[last] - np.float32(0.5)) / drop
        position[edge] = index[edge] - half + last + min(max(fraction, np.float32(0.0)), np.float32(1.0))
        defined[edge] = norm > np.float32(1e-6) and not share[width - 1] >= np.float32(0.5)
        contrast[edge] = np.sqrt(norm)
    return position, defined, contrast


@compiled
def edge_widths(gradient, contrast, rays, index, step):
    """Per edge (at ``index`` along ``rays``), the blur (Gaussian sigma, px) of a step of its
    ``contrast``: a blurred step of contrast C has the steepest slope C / (sigma sqrt(2 pi))."""
    widths = np.empty(rays.size, np.float32)
    for edge in range(rays.size):
        slope = gradient[rays[edge], index[edge]] / np.float32(2 * step)
        widths[edge] = contrast[edge] / max(slope, np.float32(1e-6)) / np.float32(math.sqrt(2 * math.pi))
    return widths
