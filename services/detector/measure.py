"""Step 6's measurements of a candidate circle (see ``detector.py``): how it sits on the colour
mask (``measure_mask``: fill, edge support, leak, the mask around it, the evenness of its edge)
and the colour of its disc on the frame (``colour_stats``). ``checks.py`` judges what they
measure.
"""

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from balltrack.services.detector.geometry import (FIXED_BITS, Candidate, box_around, brightest_channel, disc,
                                                  fixed_point, fixed_radius, rim_directions)
from balltrack.services.detector.jit import compiled
from balltrack.services.detector.mask import EXPLAINED, ColourPlanes

# A ball's own lit side: this share of its colour pixels are at most that bright (V, the
# brightest channel); the brightest few are glints and specular spots, not lit felt.
LIT_SIDE_SHARE = 0.9
# Samples along each ray when measuring how round a blob's edge is.
EDGE_STEPS = 25
# measure_mask's areas around a circle: the disc of 0.85 r and the ring from 1.15 r + 1 to 1.45 r + 2.
INSIDE = 2
RING = 1


class MeasuredOnFirstRead:
    """A frozen dataclass's field that may be given a function of no arguments instead of its
    value: the function is called, once, when the field is first read. (Most candidates fail a
    cheaper check before ``judge`` reads their spread.)"""

    def __set_name__(self, owner: type, name: str) -> None:
        self._slot = "_" + name

    def __get__(self, instance, owner=None):
        if instance is None:
            raise AttributeError(self._slot)  # (the dataclass field has no default)
        value = instance.__dict__[self._slot]
        if callable(value):
            value = value()
            instance.__dict__[self._slot] = value
        return value

    def __set__(self, instance, value) -> None:
        instance.__dict__[self._slot] = value


@dataclass(frozen=True)
class MaskMetrics:
    """How a circle sits on the colour mask (all fractions 0-1 but ``spread``)."""

    visible: float   # rim inside the frame and not explained (by an accepted ball)
    support: float   # of that rim: mask just inside, not just outside
    leak: float      # of that rim: mask just outside (the mask goes on past the rim)
    fill: float      # mask fraction of the disc of 0.85 r
    outside: float   # mask fraction of the ring from 1.15 r to 1.45 r
    # spread of the mask edge's distance from the centre, over the radius (see edge_spread)
    spread: float = MeasuredOnFirstRead()  # type: ignore[assignment]
    leak_runs: int = 0  # separate stretches of the rim where the mask goes on past it


@dataclass(frozen=True)
class ColourMetrics:
    """The colour of a circle's disc."""

    colourfulness: float  # mean chroma of its mask pixels over the frame's reference level
    mean_hue: float       # OpenCV hue (0-180) of the mean colour of the whole disc; -1: grey
    mean_chroma: float    # chroma (raw units, max - min channel) of that mean colour
    colour_hue: float     # hue of the mean colour of its mask pixels only; -1: grey
    # The same mean chroma over the disc's own lit side (its mask pixels' LIT_SIDE_SHARE
    # brightness level) where that is below the frame's reference level (measured when read).
    # A ball in shade beside a brightly lit area (a white wall, a window) is dull next to the
    # frame's bright level, but its felt is as vivid as ever next to the light that reaches it,
    # which its lit side shows. Leaves in shade are vivid by this measure too: it serves only
    # a candidate whose shape alone makes it plainly a ball (see judge).
    lit_colourfulness: float = MeasuredOnFirstRead()  # type: ignore[assignment]


NO_COLOUR = ColourMetrics(colourfulness=0.0, mean_hue=-1.0, mean_chroma=0.0, colour_hue=-1.0,
                          lit_colourfulness=0.0)


@compiled
def ray_edges(x: float, y: float, radius: float, mask: np.ndarray, cos: np.ndarray, sin: np.ndarray,
              steps: np.ndarray) -> tuple[int, np.ndarray]:
    """``edge_spread``'s rays: how many lie wholly in the frame, and the distance (one of
    ``steps``) at which each of those that starts in the mask leaves it, with no explained
    (accepted ball) pixel on it and the edge at least 0.85 r out, in ray order. (Numpy's
    version made a dozen calls on 96 x 25 arrays per candidate, ~0.13 ms.)"""
    height, width = mask.shape
    edges = np.empty(cos.size)
    count = in_frame = 0
    columns = np.empty(steps.size, np.intp)
    rows = np.empty(steps.size, np.intp)
    for ray in range(cos.size):
        whole = True
        for step in range(steps.size):
            columns[step] = np.intp(np.rint(x + cos[ray] * steps[step]))
            rows[step] = np.intp(np.rint(y + sin[ray] * steps[step]))
            if not (0 <= columns[step] < width and 0 <= rows[step] < height):
                whole = False
        if not whole:
            continue
        in_frame += 1
        first_off = -1
        explained = False
        for step in range(steps.size):
            value = mask[rows[step], columns[step]]
            if value != 255 and first_off < 0:
                first_off = step
            if value == EXPLAINED:
                explained = True
        if first_off > 0 and not explained and steps[first_off] >= 0.85 * radius:
            edges[count] = steps[first_off]
            count += 1
    return in_frame, edges[:count]


def edge_spread(x: float, y: float, radius: float, mask: np.ndarray, samples: int) -> float:
    """Spread (standard deviation over the radius) of the distance from the centre to the
    mask's edge, along the rays that leave the mask between 0.7 r and 1.5 r.

    About 0.03 for a ball's disc, 0.1 for a square; rays without such an edge (a touching
    neighbour, the other colour of a two-colour ball, the frame border) are left out, and
    with fewer than 6 rays left the spread is 0.
    """
    steps = evenly_spaced(0.7 * radius, 1.5 * radius, EDGE_STEPS)
    directions = rim_directions(samples)
    in_frame, edges = ray_edges(x, y, radius, np.ascontiguousarray(mask), directions[0], directions[1], steps)
    if in_frame < 6 or edges.size < 6:
        return 0.0
    # (np.std's own steps, without its wrappers' overhead)
    deviation = edges - np.add.reduce(edges) / edges.size
    return float(np.sqrt(np.add.reduce(deviation * deviation) / edges.size)) / radius


def evenly_spaced(start: float, stop: float, count: int) -> np.ndarray:
    """``np.linspace(start, stop, count)``, computed as it does, without its wrapper's overhead
    (per measured circle)."""
    values = np.arange(float(count)) * ((stop - start) / (count - 1)) + start
    values[-1] = stop
    return values


def well_inside(x: float, y: float, reach: float, width: int, height: int) -> bool:
    """Whether every pixel rounded from within ``reach`` of (x, y) lies in a frame of
    ``width`` x ``height`` (with a pixel to spare for rounding)."""
    return reach + 1.0 <= min(x, y, width - 1.0 - x, height - 1.0 - y)


def rim_samples(radius: float) -> int:
    """How many points of a circle's rim the checks sample: about one per pixel, 24 to 96."""
    return int(min(96, max(24, 2 * math.pi * radius)))


def rim_points(x: float, y: float, radius: float, width: int, height: int) -> np.ndarray:
    """Pixel pairs just inside and just outside a circle's rim, those in a ``width`` x
    ``height`` frame: rows inner x, inner y, outer x, outer y, one column per rim sample."""
    samples = rim_samples(radius)
    offset = max(1.5, 0.15 * radius)
    points = np.rint(np.array([[x], [y], [x], [y]])
                     + np.array([[radius - offset], [radius - offset], [radius + offset],
                                 [radius + offset]]) * rim_directions(samples)).astype(np.intp)
    if not well_inside(x, y, radius + offset, width, height):
        in_frame = ((points >= 0) & (points < np.array([[width], [height], [width], [height]]))).all(axis=0)
        points = points[:, in_frame]
    return points


@compiled
def rim_counts(mask: np.ndarray, x: float, y: float, inner_radius: float, outer_radius: float,
               cos: np.ndarray, sin: np.ndarray) -> tuple[int, int, int, int]:
    """``measure_mask``'s rim: of the pairs of pixels at ``inner_radius`` and ``outer_radius``
    along each direction (``rim_points``' pairs, those in the frame), the pairs with neither
    pixel explained (known), those of them with mask inside and not outside (support), with
    mask outside (leak), and the separate runs of leaking pairs round the circle."""
    height, width = mask.shape
    known = support = leak = runs = 0
    first_out = last_out = False
    for index in range(cos.size):
        inner_x = np.intp(np.rint(x + inner_radius * cos[index]))
        inner_y = np.intp(np.rint(y + inner_radius * sin[index]))
        outer_x = np.intp(np.rint(x + outer_radius * cos[index]))
        outer_y = np.intp(np.rint(y + outer_radius * sin[index]))
        if not (0 <= inner_x < width and 0 <= inner_y < height and 0 <= outer_x < width
                and 0 <= outer_y < height):
            continue
        inner, outer = mask[inner_y, inner_x], mask[outer_y, outer_x]
        if inner == EXPLAINED or outer == EXPLAINED:
            continue
        out = outer == 255
        if out:
            leak += 1
            if known > 0 and not last_out:
                runs += 1
        elif inner == 255:
            support += 1
        if known == 0:
            first_out = out
        last_out = out
        known += 1
    if leak:  # (the pairs run round the circle: the last is next to the first)
        runs = max(1, runs + (1 if first_out and not last_out else 0))
    return known, support, leak, runs


@compiled
def area_counts(patch: np.ndarray, areas: np.ndarray) -> tuple[int, int, int, int]:
    """Of a mask patch's pixels in ``areas``' INSIDE and RING: how many are usable (not
    EXPLAINED), and how many of those are mask (255), in one pass: (inside, inside on mask,
    ring, ring on mask). (A dozen whole-patch numpy calls did this, ~0.1 ms for a ball of
    55 px radius.)"""
    inside = inside_on = ring = ring_on = 0
    for row in range(patch.shape[0]):
        for column in range(patch.shape[1]):
            area = areas[row, column]
            value = patch[row, column]
            if area == 0 or value == EXPLAINED:
                continue
            if area == INSIDE:
                inside += 1
                inside_on += value == 255
            else:
                ring += 1
                ring_on += value == 255
    return inside, inside_on, ring, ring_on


def measure_mask(candidate: Candidate, mask: np.ndarray) -> MaskMetrics | None:
    """How a circle sits on ``mask`` (see MaskMetrics); None when too little of it can be judged.

    ``mask`` is 255 (colour), 0 (not) or EXPLAINED (an accepted ball's disc: neither).
    """
    height, width = mask.shape
    x, y, radius = candidate.x, candidate.y, candidate.radius
    samples = rim_samples(radius)
    offset = max(1.5, 0.15 * radius)
    directions = rim_directions(samples)
    known_count, support_count, leak_count, leak_runs = rim_counts(
        np.ascontiguousarray(mask), x, y, radius - offset, radius + offset, directions[0], directions[1])
    if known_count < 4:
        return None
    # (measured when read: ``mask`` is not changed once candidates are measured on it)
    roundness = functools.partial(edge_spread, x, y, radius, mask, samples)

    outer_radius = 1.45 * radius + 2
    box = box_around(x, y, outer_radius, width, height)
    if box is None:
        return None
    patch = mask[box]
    centre_x, centre_y = x - box[1].start, y - box[0].start
    # One plane for both areas: the ring from 1.15 r + 1 to outer_radius is RING, the disc of
    # 0.85 r inside it INSIDE (each drawn as a disc of its own would be).
    areas = np.zeros(patch.shape, np.uint8)
    centre = fixed_point(centre_x, centre_y)
    cv2.circle(areas, centre, fixed_radius(outer_radius), RING, -1, cv2.LINE_8, FIXED_BITS)
    cv2.circle(areas, centre, fixed_radius(1.15 * radius + 1), 0, -1, cv2.LINE_8, FIXED_BITS)
    cv2.circle(areas, centre, fixed_radius(0.85 * radius), INSIDE, -1, cv2.LINE_8, FIXED_BITS)
    # (contiguous, as ``areas`` is: one compiled signature, whichever view the patch is)
    inside_count, inside_on, ring_count, ring_on = area_counts(np.ascontiguousarray(patch), areas)
    if inside_count == 0:
        return None
    return MaskMetrics(
        visible=known_count / samples,
        support=support_count / known_count,
        leak=leak_count / known_count,
        fill=inside_on / inside_count,
        outside=ring_on / ring_count if ring_count else 0.0,
        spread=roundness,
        leak_runs=leak_runs)


def mean_hue(bgr) -> float:
    """OpenCV hue (0-180) of one BGR colour (floats); -1 for grey."""
    blue, green, red = (float(channel) for channel in bgr)
    high, low = max(blue, green, red), min(blue, green, red)
    if high - low <= 1e-6:
        return -1.0
    if high == red:
        degrees = 60.0 * (green - blue) / (high - low)
    elif high == green:
        degrees = 120.0 + 60.0 * (blue - red) / (high - low)
    else:
        degrees = 240.0 + 60.0 * (red - green) / (high - low)
    return (degrees % 360.0) / 2.0


@compiled
def disc_colour_sums(patch: np.ndarray, mask: np.ndarray, chroma: np.ndarray, inside: np.ndarray):
    """The exact sums ``colour_stats`` averages, in one pass over a disc's patch: of the
    pixels in ``inside`` (non-zero), their count and B, G, R sums; of those on the colour
    mask (255), the same, and their chroma's sum. (Six OpenCV calls and a boolean plane did
    this, ~0.1 ms a candidate.)"""
    inside_count = selected_count = chroma_sum = 0
    inside_blue = inside_green = inside_red = selected_blue = selected_green = selected_red = 0
    for row in range(patch.shape[0]):
        for column in range(patch.shape[1]):
            if inside[row, column] == 0:
                continue
            blue = np.int64(patch[row, column, 0])
            green = np.int64(patch[row, column, 1])
            red = np.int64(patch[row, column, 2])
            inside_count += 1
            inside_blue += blue
            inside_green += green
            inside_red += red
            if mask[row, column] == 255:
                selected_count += 1
                selected_blue += blue
                selected_green += green
                selected_red += red
                chroma_sum += chroma[row, column]
    inside_sums = (inside_blue, inside_green, inside_red)
    selected_sums = (selected_blue, selected_green, selected_red)
    return inside_count, inside_sums, selected_count, selected_sums, chroma_sum


def colour_stats(candidate: Candidate, planes: ColourPlanes) -> ColourMetrics:
    """The colour of a circle's disc (see ColourMetrics); NO_COLOUR when it holds no mask."""
    height, width = planes.mask.shape
    x, y, radius = candidate.x, candidate.y, candidate.radius
    box = box_around(x, y, 0.85 * radius, width, height)
    if box is None:
        return NO_COLOUR
    inside = disc((box[0].stop - box[0].start, box[1].stop - box[1].start),
                  x - box[1].start, y - box[0].start, 0.85 * radius)
    # (contiguous copies of the patches: one compiled signature whatever views they are)
    patch = np.ascontiguousarray(planes.frame[box])
    mask = np.ascontiguousarray(planes.mask[box])
    (inside_count, inside_sums, selected_count, selected_sums,
     chroma_sum) = disc_colour_sums(patch, mask, np.ascontiguousarray(planes.chroma[box]), inside)
    if not selected_count:
        return NO_COLOUR
    # Averaging the unblurred disc recovers the hue that uint8 rounding hides in a very
    # dark frame (a dim orange box can round to yellow pixel by pixel). Grey floor or
    # black shade inside the disc does not move the hue of the mean.
    # (the means as cv2.mean makes them: the exact sums times the count's reciprocal)
    mean_bgr = tuple(float(total) * (1.0 / inside_count) for total in inside_sums)
    chroma = float(chroma_sum) * (1.0 / selected_count)

    def lit_colourfulness() -> float:
        selected = np.bitwise_and(inside, mask == 255)
        return chroma / min(planes.reference, lit_level(patch, selected))

    return ColourMetrics(colourfulness=chroma / planes.reference,
                         mean_hue=mean_hue(mean_bgr),
                         mean_chroma=(max(mean_bgr) - min(mean_bgr)) / planes.gain,
                         colour_hue=mean_hue(tuple(float(total) * (1.0 / selected_count)
                                                   for total in selected_sums)),
                         lit_colourfulness=lit_colourfulness)


def lit_level(patch_bgr: np.ndarray, selected: np.ndarray) -> float:
    """The brightness (V, 0-255) of the lit side of the ``selected`` pixels of a BGR patch:
    LIT_SIDE_SHARE of them are at most this bright; at least 1."""
    value = brightest_channel(patch_bgr)[selected > 0]
    rank = int(LIT_SIDE_SHARE * (value.size - 1))
    return max(1.0, float(np.partition(value, rank)[rank]))
