"""Pure ball-detection core (paper section 2.2), used by the detector service and offline tools.

The paper's pipeline, with the checks that make it hold up on real photos:

1. Brightness: the frame's reference level (99th percentile of V, at most 3x its median) is
   measured; a dark frame is scaled up to ``gain_target`` before anything else, so that the
   blur keeps the colour information that uint8 rounding would otherwise destroy.
2. Gaussian blur, then HSV; adaptive histogram equalisation (CLAHE) of V, which the
   ``v_min``/``v_max`` test uses, so that test is relative to the local brightness. Hue and
   saturation do not depend on brightness: a dark ball keeps its colour.
3. Colour mask: the HSV ranges, and a chroma (max - min channel, raw units) of at least
   ``min_chroma``, below which a pixel's hue is rounding or sensor noise (a dark grey floor).
4. Morphological opening and closing of the mask (specks out, seams and logos filled). In
   extremely dark frames (gain >= ``dark_gain``: colour 1-2 grey levels above black) steps 2-4
   work on wider averages instead (``dark_blur_kernel``, chroma floor ``dark_min_chroma``, no
   opening), and the outline search (8) looks further past the colour (a small lit cap).
5. Candidates per mask blob: its enclosing circle, and unless that circle is already a clean
   isolated ball, the Hough circle transform (cv2.HoughCircles with ``dp min_dist param1
   param2``, radii in ``min_radius..max_radius``) inside the blob's box, which splits touching
   balls and finds balls joined to other yellow-green things.
6. Each candidate is refined by a robust least-squares circle fit to the mask's boundary pixels
   (pixels on the frame border are ignored, so a ball cut by the edge keeps its true centre),
   then checked: the disc is mostly mask (fill), the rim is a mask edge over most of its
   visible length (edge support) and the more mask lies just around it (leak, outside), the
   more rim support it needs, so a round patch of a large yellow-green area (sunlit trees)
   fails; the blob is vivid enough (colourfulness); in very dark frames the mean colour of the
   disc must have the target's hue too.
7. Accepted balls are erased from the mask and their neighbours judged again (a ball touching
   a found one, a two-colour ball). Overlapping circles are suppressed; largest first.
8. Each accepted ball's circle is replaced by its outline located on the frame itself
   (``_silhouette``): along rays from the centre, the colour edge at its 50 % crossing, then a
   robust circle fit. The colour mask's edge lies where blur has spread the colour (radii
   0.5-1 px too large whatever the size, the more blurred the frame the more), and a strongly
   shaded side drags its centre towards the lit side; the 50 % crossing of the edge does not
   move with blur, and edges of shading are told from the outline (see ``_shading``). Balls
   smaller than ``small_radius`` are kept only when their outline is found; the others keep
   the mask's circle when it is not (clutter all round, too little of the rim in view).
9. Under a light with no ambient, a ball's unlit side is black: its colour is a lit cap, which
   the checks may reject. A few rejected candidates with something dark around them get a
   second look: if the frame shows an outline around the cap, with all the colour inside and
   a dark side within, the outline is the ball.

No zenoh here: arrays in, dataclasses out.

Example::

    import cv2
    from balltrack.services.detector.config import DetectorConfig
    from balltrack.services.detector.pipeline import BallDetector, annotate

    detector = BallDetector(DetectorConfig())
    image = cv2.imread("frame.jpg")
    result = detector.detect(image)          # result.detections: largest first
    cv2.imwrite("out.jpg", annotate(image, result.detections))
"""

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from balltrack.services.detector.config import DetectorConfig

# Hough circles per mask blob: beyond the strongest few they are duplicates or clutter.
HOUGH_CIRCLES_PER_BLOB = 4
HOUGH_CIRCLES_SCANNED = 40
# Below this chroma (raw units) single pixels' hues are rounding noise, so the hue of the
# candidate's mean colour is checked as well.
LOW_CHROMA = 6.0
# Fractional bits of the sub-pixel circles drawn for the checks.
FIXED_BITS = 4
# Circle refinement: (tolerance over radius, tolerance floor in pixels) of each fitting round.
REFINE_ROUNDS = ((0.35, 2.0), (0.2, 1.5), (0.12, 1.2))
# A candidate with a spread of its edge distance above CORNER_SPREAD (a square's is ~0.1, a
# ball's mostly below 0.06 and at most 0.09 on the real dev photos) that also leaks past its
# rim in places (corners) is a polygon, not a ball.
CORNER_SPREAD = 0.07
CORNER_LEAK = 0.08
# Samples along each ray when measuring how round a blob's edge is.
EDGE_STEPS = 25
# Mask value of an accepted ball's disc while its neighbours are judged: neither colour nor not.
EXPLAINED = 128
# Rounds of accepting balls and looking again around them.
MAX_ROUNDS = 3
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
# A candidate's colour may be a lit cap down to this share of min_radius (a ball under a light
# with no ambient: its dark side is found by the silhouette search, or it is dropped).
LIT_CAP_SHARE = 0.6
# Rejected candidates looked at again for a dark side (largest first, per frame). A dark side
# is at least DARK_SIDE_SHARE of the outline's disc outside the colour mask, on average at most
# DARK_SIDE_LEVEL times as bright as the lit (colour) part.
DARK_SIDE_ATTEMPTS = 3
DARK_SIDE_SHARE = 0.15
DARK_SIDE_LEVEL = 0.5
# Most wide rounds of the silhouette search (each from the last circle found, until it stops
# growing) before the narrow one.
SILHOUETTE_WIDE_ROUNDS = 3
# Rays of the wide and the narrow rounds (fewer for small balls: one per pixel of rim, >= 24).
WIDE_RAYS = 36
# Largest blur (Gaussian sigma, px) corrected for.
BLUR_LIMIT = 2.0
NARROW_RAYS = 90
# The search reaches this many times the colour mask's radius from its centre.
SILHOUETTE_REACH = 2.6
# Wide rounds look this many times the current radius (plus 2 px) from its centre; further in
# extremely dark frames, whose colour mask is only the brightest part of a lit cap (the
# outline of a ball whose other side is black lies further from it).
WIDE_REACH = 1.6
DARK_WIDE_REACH = 2.1


@dataclass(frozen=True)
class Detection:
    """One ball: centre (u, v) and radius in pixels of the input frame; score in [0, 1]."""

    u: float
    v: float
    radius_px: float
    score: float


@dataclass
class DetectionResult:
    """All balls found in one frame (largest first) and the colour mask (for ``image_tuning``)."""

    detections: list[Detection] = field(default_factory=list)
    mask: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))


@dataclass
class _Candidate:
    x: float
    y: float
    radius: float
    score: float = 0.0
    # A small candidate is kept only if its outline is found on the frame (see _outlines).
    needs_outline: bool = False


def _ellipse(size: int) -> np.ndarray | None:
    if size <= 1:
        return None
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))


def _fit_circle(dx: np.ndarray, dy: np.ndarray) -> tuple[float, float, float] | None:
    """Algebraic (Kasa) least-squares circle through points given relative to a point near
    their centre: returns its centre (relative to the same point) and radius, or None."""
    # dx^2 + dy^2 = a dx + b dy + c  ->  centre (a/2, b/2), radius^2 = c + (a^2 + b^2) / 4
    squared = dx * dx + dy * dy
    m00, m01, m11 = float(dx @ dx), float(dx @ dy), float(dy @ dy)
    m02, m12, m22 = float(dx.sum()), float(dy.sum()), float(dx.size)
    t0, t1, t2 = float(dx @ squared), float(dy @ squared), float(squared.sum())
    # Cramer's rule on the symmetric 3x3 normal equations.
    c00, c01, c02 = m11 * m22 - m12 * m12, m02 * m12 - m01 * m22, m01 * m12 - m02 * m11
    determinant = m00 * c00 + m01 * c01 + m02 * c02
    if abs(determinant) < 1e-9:
        return None
    c11, c12, c22 = m00 * m22 - m02 * m02, m01 * m02 - m00 * m12, m00 * m11 - m01 * m01
    a = (c00 * t0 + c01 * t1 + c02 * t2) / determinant
    b = (c01 * t0 + c11 * t1 + c12 * t2) / determinant
    c = (c02 * t0 + c12 * t1 + c22 * t2) / determinant
    centre_x, centre_y = a / 2.0, b / 2.0
    radius_squared = c + centre_x * centre_x + centre_y * centre_y
    if not math.isfinite(radius_squared) or radius_squared <= 0:
        return None
    return centre_x, centre_y, math.sqrt(radius_squared)


@functools.lru_cache(maxsize=128)
def _rim_directions(samples: int) -> np.ndarray:
    """Rows cos, sin, cos, sin of ``samples`` evenly spaced angles (cached: used per circle)."""
    angles = np.linspace(0.0, 2 * math.pi, samples, endpoint=False)
    cos, sin = np.cos(angles), np.sin(angles)
    return np.stack([cos, sin, cos, sin])


def _box(x: float, y: float, reach: float, width: int, height: int) -> tuple[slice, slice] | None:
    """Rows and columns of the frame within ``reach`` of (x, y); None when empty."""
    left, right = max(0, int(math.floor(x - reach))), min(width, int(math.ceil(x + reach)) + 1)
    top, bottom = max(0, int(math.floor(y - reach))), min(height, int(math.ceil(y + reach)) + 1)
    if left >= right or top >= bottom:
        return None
    return slice(top, bottom), slice(left, right)


def _fixed(x: float, y: float) -> tuple[int, int]:
    return int(round(x * (1 << FIXED_BITS))), int(round(y * (1 << FIXED_BITS)))


def _fixed_radius(radius: float) -> int:
    return max(0, int(round(radius * (1 << FIXED_BITS))))


def _disc(shape: tuple[int, int], x: float, y: float, radius: float) -> np.ndarray:
    """uint8 0/255 image of a filled disc (sub-pixel centre and radius)."""
    image = np.zeros(shape[:2], np.uint8)
    cv2.circle(image, _fixed(x, y), _fixed_radius(radius), 255, -1, cv2.LINE_8, FIXED_BITS)
    return image


def _edge_spread(x: float, y: float, radius: float, mask: np.ndarray, samples: int) -> float:
    """Spread (standard deviation over the radius) of the distance from the centre to the
    mask's edge, along the rays that leave the mask between 0.7 r and 1.5 r.

    About 0.03 for a ball's disc, 0.1 for a square; rays without such an edge (a touching
    neighbour, the other colour of a two-colour ball, the frame border) are left out.
    """
    height, width = mask.shape
    steps = np.linspace(0.7 * radius, 1.5 * radius, EDGE_STEPS)
    directions = _rim_directions(samples)
    columns = np.rint(x + directions[0][:, None] * steps[None, :]).astype(np.intp)
    rows = np.rint(y + directions[1][:, None] * steps[None, :]).astype(np.intp)
    inside = ((columns >= 0) & (columns < width) & (rows >= 0) & (rows < height)).all(axis=1)
    if np.count_nonzero(inside) < 6:
        return 0.0
    values = mask[rows[inside], columns[inside]]
    on = values == 255
    first_off = np.argmin(on, axis=1)
    # The ray starts in the mask, leaves it, and meets no explained (accepted ball) pixel first.
    edges = steps[first_off]
    valid = (on[:, 0] & ~on.all(axis=1) & ~(values == EXPLAINED).any(axis=1)
             & (edges >= 0.85 * radius))
    if np.count_nonzero(valid) < 6:
        return 0.0
    return float(np.std(edges[valid])) / radius


def _hue(bgr) -> float:
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


def _circle_overlap(first: _Candidate, second: _Candidate) -> float:
    """Intersection area of two circles divided by the smaller circle's area."""
    distance = math.hypot(first.x - second.x, first.y - second.y)
    r1, r2 = first.radius, second.radius
    if distance >= r1 + r2:
        return 0.0
    small = min(r1, r2)
    if distance <= abs(r1 - r2):
        return 1.0
    def clamped_acos(value: float) -> float:
        return math.acos(max(-1.0, min(1.0, value)))

    part1 = r1 * r1 * clamped_acos((distance ** 2 + r1 ** 2 - r2 ** 2) / (2 * distance * r1))
    part2 = r2 * r2 * clamped_acos((distance ** 2 + r2 ** 2 - r1 ** 2) / (2 * distance * r2))
    part3 = 0.5 * math.sqrt(max(0.0, (-distance + r1 + r2) * (distance + r1 - r2)
                                * (distance - r1 + r2) * (distance + r1 + r2)))
    return (part1 + part2 - part3) / (math.pi * small * small)


def _ray_profiles(patch: np.ndarray, x: float, y: float, radii: np.ndarray,
                  directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Colours (rays x radii x 3, float32) sampled bilinearly along rays from (x, y) in
    ``patch``, and per ray the distances along it at which it enters and leaves the patch."""
    map_x = (x + directions[0][:, None] * radii[None, :]).astype(np.float32)
    map_y = (y + directions[1][:, None] * radii[None, :]).astype(np.float32)
    height, width = patch.shape[:2]
    values = cv2.remap(patch, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    enter = np.full(directions.shape[1], -np.inf)
    leave = np.full(directions.shape[1], np.inf)
    for position, direction, size in ((x, directions[0], width), (y, directions[1], height)):
        with np.errstate(divide="ignore", invalid="ignore"):
            low, high = (0.0 - position) / direction, (size - 1.0 - position) / direction
        flat = np.abs(direction) < 1e-9
        low = np.where(flat, np.where(0.0 <= position <= size - 1.0, -np.inf, np.inf), low)
        high = np.where(flat, np.where(0.0 <= position <= size - 1.0, np.inf, -np.inf), high)
        enter = np.maximum(enter, np.minimum(low, high))
        leave = np.minimum(leave, np.maximum(low, high))
    return values.reshape(map_x.shape + (-1,)), enter, leave


def _edge_peaks(profiles: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Significant colour-gradient peaks along each ray (rays x samples, only where
    ``allowed``), whether each ray sees an edge at all, and the gradient (per sample step)."""
    rays, count = profiles.shape[:2]
    difference = profiles[:, 2:] - profiles[:, :-2]
    gradient = np.zeros((rays, count), np.float32)
    gradient[:, 1:-1] = np.sqrt(np.einsum("ijk,ijk->ij", difference, difference))
    gradient[~allowed] = 0.0
    strongest = gradient.max(axis=1)
    floor = EDGE_FLOOR * float(np.median(strongest)) if rays else 0.0
    peak = np.zeros((rays, count), bool)
    middle = gradient[:, 1:-1]
    peak[:, 1:-1] = ((middle >= gradient[:, :-2]) & (middle >= gradient[:, 2:])
                     & (middle >= EDGE_SIGNIFICANT * strongest[:, None]))
    return peak, peak.any(axis=1) & (strongest > max(floor, 1e-3)), gradient


def _shading(profiles: np.ndarray, rays: np.ndarray, index: np.ndarray, colour: np.ndarray,
             half: int, quantum: float, dark: float) -> np.ndarray:
    """Whether edges (at ``index`` along ``rays``) are shading rather than an outline: going
    outwards the colour darkens into a darker version of the ball's ``colour`` (within
    ``quantum``, the frame's rounding step) or into near black (below ``dark``)."""
    count = profiles.shape[1]
    inner = profiles[rays, np.maximum(index - half, 0)]
    outer = profiles[rays, np.minimum(index + half, count - 1)]
    brightness_in = np.sqrt((inner * inner).sum(axis=1))
    brightness_out = np.sqrt((outer * outer).sum(axis=1))
    share = (outer @ colour) / max(float(colour @ colour), 1e-6)
    off_axis = outer - share[:, None] * colour
    off_axis = np.sqrt((off_axis * off_axis).sum(axis=1))
    ball_like = (share < SHADING_SHARE) & (off_axis <= SHADING_TOLERANCE * brightness_out + quantum)
    return (brightness_out < brightness_in) & (ball_like | (brightness_out < dark))


def _crossings(profiles: np.ndarray, index: np.ndarray,
               half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-sample position (in samples) of the 50 % crossing between the levels ``half``
    samples inside and outside each ray's edge ``index``, whether it is well defined, and the
    contrast between those levels."""
    rays, count = profiles.shape[:2]
    rows = np.arange(rays)
    offsets = np.arange(-half, half + 1)
    window = np.clip(index[:, None] + offsets[None, :], 0, count - 1)
    values = profiles[rows[:, None], window]                      # rays x (2 half + 1) x 3
    level_in, level_out = values[:, 0], values[:, -1]
    contrast = level_in - level_out
    norm = np.einsum("ij,ij->i", contrast, contrast)
    share = np.einsum("ijk,ik->ij", values - level_out[:, None, :], contrast)
    share /= np.maximum(norm, 1e-9)[:, None]
    above = share >= 0.5
    # the outermost sample still at least half way to the inside level, and the next one
    last = np.minimum(above.shape[1] - 1 - np.argmax(above[:, ::-1], axis=1), above.shape[1] - 2)
    s0, s1 = share[rows, last], share[rows, last + 1]
    fraction = np.where(s0 - s1 > 1e-6, (s0 - 0.5) / np.maximum(s0 - s1, 1e-6), 0.0)
    position = index + offsets[last] + np.clip(fraction, 0.0, 1.0)
    return position, (norm > 1e-6) & ~above[:, -1], np.sqrt(norm)


def _geometric_circle(px: np.ndarray, py: np.ndarray, x: float, y: float, radius: float,
                      iterations: int = 3) -> tuple[float, float, float]:
    """Gauss-Newton refinement of a circle on the geometric distances of points to it."""
    for _ in range(iterations):
        dx, dy = px - x, py - y
        distance = np.maximum(np.hypot(dx, dy), 1e-9)
        ux, uy = dx / distance, dy / distance
        residual = distance - radius
        # normal equations of the Jacobian (-ux, -uy, -1)
        normal = np.array([[ux @ ux, ux @ uy, ux.sum()], [ux @ uy, uy @ uy, uy.sum()],
                           [ux.sum(), uy.sum(), float(ux.size)]])
        gradient = np.array([ux @ residual, uy @ residual, residual.sum()])
        try:
            delta = np.linalg.solve(normal, gradient)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(delta)):
            break
        x, y, radius = x + float(delta[0]), y + float(delta[1]), radius + float(delta[2])
        if float(np.abs(delta).sum()) < 1e-3:
            break
    return x, y, radius


def _robust_circle(px: np.ndarray, py: np.ndarray, x: float, y: float, radius: float,
                   rounds: tuple, geometric: bool) -> tuple[float, float, float, np.ndarray] | None:
    """Circle through the points near (x, y, radius), in rounds of ever tighter tolerance
    (algebraic fits, then optionally a geometric one); also returns which points lie on it."""
    for tolerance_ratio, tolerance_floor in rounds:
        residual = np.hypot(px - x, py - y) - radius
        keep = np.abs(residual) < max(tolerance_floor, tolerance_ratio * radius)
        if np.count_nonzero(keep) < 8:
            return None
        fitted = _fit_circle(px[keep] - x, py[keep] - y)
        if fitted is None:
            return None
        x, y, radius = x + fitted[0], y + fitted[1], fitted[2]
    if geometric:
        x, y, radius = _geometric_circle(px[keep], py[keep], x, y, radius)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(radius) and radius > 0):
            return None
    residual = np.hypot(px - x, py - y) - radius
    return x, y, radius, np.abs(residual) < max(rounds[-1][1], rounds[-1][0] * radius)


def _silhouette(frame: np.ndarray, mask: np.ndarray, planes_gain: float, reference: float,
                ball: "_Candidate", others: list,
                wide_reach: float = WIDE_REACH) -> tuple[float, float, float] | None:
    """The ball's outline located on the frame itself, to a fraction of a pixel.

    Along rays from the centre, the colour edges from just inside the colour mask's circle
    outwards are located at their 50 % crossing (so blur, which spreads the colour mask, does
    not move them) and a circle is fitted to them robustly. Wide rounds, each from the last
    circle, look for the outline either as each ray's first edge that is not shading (a ball
    in front of other edges) or as its outermost edge (a dark side that the colour mask
    misses); the hypothesis that more rays agree on wins (about as many: the larger circle,
    if it fits about as closely). A narrow round then takes each
    ray's edge nearest the circle. None when too few rays see an edge, when they see it on
    one side only, or when the result does not contain most of the colour mask's circle.

    Rays are used only within the frame (a ball cut by its edge keeps the visible arc) and not
    towards ``others`` (touching balls); a ray whose edge has colour-mask pixels just past it
    (yellow-green clutter touching the ball) is left out.
    """
    height, width = mask.shape
    x0, y0, r0 = ball.x, ball.y, ball.radius
    reach = SILHOUETTE_REACH * r0 + 6
    box = _box(x0, y0, reach, width, height)
    if box is None:
        return None
    left, top = box[1].start, box[0].start
    patch = frame[box].astype(np.float32)
    patch_mask = mask[box]
    # The ball's colour: the mean of its lit, colour-mask part.
    disc = _disc(patch_mask.shape, x0 - left, y0 - top, 0.85 * r0) & cv2.inRange(patch_mask, 255, 255)
    if not cv2.countNonZero(disc):
        return None
    colour = np.array(cv2.mean(patch, disc)[:3], np.float32)
    dark = DARK_SHARE * reference

    x, y, radius = x0 - left, y0 - top, r0
    wide_rounds = 0
    while True:
        wide = wide_rounds < SILHOUETTE_WIDE_ROUNDS
        samples = int(min(WIDE_RAYS if wide else NARROW_RAYS, max(24, round(2 * math.pi * radius))))
        directions = _rim_directions(samples)
        cos, sin = directions[0], directions[1]
        if wide:  # from just inside the circle to well past it
            start = radius - min(EDGE_MARGIN + 0.15 * radius, 0.4 * radius)
            stop, step = wide_reach * radius + 2, max(RAY_STEP, radius / 60.0)
            rounds = ((0.3, 2.0), (0.1, 1.0))
        else:  # a narrow band around the circle found
            band = max(1.5, 0.15 * radius)
            start, stop, step = radius - band, radius + band, RAY_STEP
            rounds = ((0.08, 1.0), (0.05, 0.6), (0.03, 0.45))
        half = max(1, int(round(min(EDGE_HALF_WIDTH, 0.3 * radius) / step)))
        radii = np.arange(max(0.0, start - half * step), stop + (half + 1) * step, step,
                          dtype=np.float32)
        profiles, enter, leave = _ray_profiles(patch, x, y, radii, directions)
        # Only the part of each ray inside the frame (a ball cut by the frame's edge), with
        # room for the levels around an edge.
        margin = (half + 1) * step
        allowed = ((radii[None, :] >= np.maximum(start, enter + margin)[:, None])
                   & (radii[None, :] <= np.minimum(stop, leave - margin)[:, None]))
        usable = allowed.any(axis=1)
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
        one_sided = max(0.7, math.hypot(cos[usable].mean(), sin[usable].mean()) + 0.1) if in_view else 0.7
        peak, has_edge, gradient = _edge_peaks(profiles, allowed)
        if wide:
            ray_index, sample_index = np.nonzero(peak)
            outline = peak.copy()
            outline[ray_index, sample_index] = ~_shading(profiles, ray_index, sample_index, colour,
                                                         half, planes_gain, dark)
            first = np.argmax(outline, axis=1)
            outermost = peak.shape[1] - 1 - np.argmax(peak[:, ::-1], axis=1)
            choices = [(first, outline.any(axis=1))]
            if np.count_nonzero((first != outermost) & has_edge) >= 0.15 * samples:
                choices.append((outermost, has_edge))
        else:
            away = np.where(peak, np.abs(radii - radius)[None, :], np.inf)
            choices = [(np.argmin(away, axis=1), has_edge)]
        fits = []
        for index, found in choices:
            position, defined, contrast = _crossings(profiles, index, half)
            rho = radii[0] + position * step
            px, py = x + cos * rho, y + sin * rho
            # The colour mask must not go on past the edge (clutter touching the ball).
            beyond = rho + max(2.0, 0.12 * radius)
            bx = np.clip(np.rint(x + cos * beyond), 0, patch.shape[1] - 1).astype(np.intp)
            by = np.clip(np.rint(y + sin * beyond), 0, patch.shape[0] - 1).astype(np.intp)
            good = usable & has_edge & found & defined & (patch_mask[by, bx] != 255)
            if np.count_nonzero(good) < max(8, 0.35 * in_view):
                continue
            fitted = _robust_circle(px[good], py[good], x, y, radius, rounds, geometric=not wide)
            if fitted is None:
                continue
            keep = fitted[3]
            if (np.count_nonzero(keep) < max(8, 0.3 * in_view)
                    or math.hypot(cos[good][keep].mean(), sin[good][keep].mean()) > one_sided
                    or not 0.5 * radius < fitted[2] < 2.0 * radius + 2):
                continue  # the edge seen on too few rays, or on one side only
            residual = np.hypot(px[good][keep] - fitted[0], py[good][keep] - fitted[1]) - fitted[2]
            # Edge width: a blurred step of contrast C has the steepest slope C / (sigma sqrt(2 pi)).
            slope = gradient[np.arange(samples), index][good][keep] / (2 * step)
            width = contrast[good][keep] / np.maximum(slope, 1e-6) / math.sqrt(2 * math.pi)
            fits.append((fitted[:3], np.count_nonzero(keep), float(np.sqrt(np.mean(residual * residual))),
                         float(np.median(width))))
        # The hypothesis most rays agree on; among about equally good ones the larger circle
        # (the outline is the outermost circle; shading edges inside a small ball fit too).
        best = None
        if fits:
            most = max(fit[1] for fit in fits)
            tightest = min(fit[2] for fit in fits if fit[1] >= most / 1.05)
            chosen = max((fit for fit in fits if fit[1] >= most / 1.05 and fit[2] <= 1.5 * tightest + 0.05),
                         key=lambda fit: fit[0][2])
            best, sigma = chosen[0], chosen[3]
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
    x, y = x + left, y + top
    # The colour mask's circle is the outline or a lit part inside it (a dark side it misses).
    shift = math.hypot(x - x0, y - y0)
    if not (0.85 * r0 - 1.0 <= radius <= 2.2 * r0 + 2.0 and shift + 0.7 * r0 <= radius + 1.0):
        return None
    return x, y, radius


def _dark_side(frame: np.ndarray, mask: np.ndarray, ball: "_Candidate") -> bool:
    """Whether the disc of ``ball`` holds a dark side: a good part of it out of the colour
    mask and clearly darker than the part in it (not a hole, a logo or a box's corner)."""
    height, width = mask.shape
    box = _box(ball.x, ball.y, ball.radius, width, height)
    if box is None:
        return False
    disc = _disc(mask[box].shape, ball.x - box[1].start, ball.y - box[0].start, 0.95 * ball.radius)
    lit = cv2.inRange(mask[box], 255, 255) & disc
    unlit = cv2.bitwise_not(cv2.inRange(mask[box], 255, 255)) & disc
    total, lit_count = cv2.countNonZero(disc), cv2.countNonZero(lit)
    if not total or not lit_count or cv2.countNonZero(unlit) < DARK_SIDE_SHARE * total:
        return False
    patch = frame[box]
    brightness = np.maximum(np.maximum(patch[:, :, 0], patch[:, :, 1]), patch[:, :, 2])
    return cv2.mean(brightness, unlit)[0] <= DARK_SIDE_LEVEL * cv2.mean(brightness, lit)[0]


def _dark_around(frame: np.ndarray, mask: np.ndarray, ball: "_Candidate") -> bool:
    """Whether at least DARK_SIDE_SHARE of the ring just around ``ball`` (r to 1.5 r) is at
    most DARK_SIDE_LEVEL times as bright as the colour inside it: where a dark side may be."""
    height, width = mask.shape
    outer = 1.5 * ball.radius + 1
    box = _box(ball.x, ball.y, outer, width, height)
    if box is None:
        return False
    x, y = ball.x - box[1].start, ball.y - box[0].start
    shape = mask[box].shape
    inner = _disc(shape, x, y, ball.radius)
    lit = cv2.inRange(mask[box], 255, 255) & inner
    ring = _disc(shape, x, y, outer) & cv2.bitwise_not(inner)
    ring_count = cv2.countNonZero(ring)
    if not ring_count or not cv2.countNonZero(lit):
        return False
    patch = frame[box]
    brightness = np.maximum(np.maximum(patch[:, :, 0], patch[:, :, 1]), patch[:, :, 2])
    level = DARK_SIDE_LEVEL * cv2.mean(brightness, lit)[0]
    dark = cv2.inRange(brightness, 0, max(0.0, level)) & ring
    return cv2.countNonZero(dark) >= DARK_SIDE_SHARE * ring_count


@dataclass
class _Planes:
    """Per-frame images shared by the candidate checks (all at processing size)."""

    mask: np.ndarray        # cleaned colour mask, 0/255
    frame: np.ndarray       # the BGR frame after the dark-frame gain, before the blur
    gain: float             # that gain
    chroma: np.ndarray      # max - min channel after gain and blur (= S * V / 255), uint8
    reference: float        # the frame's reference level on the ``value`` scale
    dark: bool = False      # an extremely dark frame (gain >= dark_gain: averaged colour)


@dataclass
class _Search:
    """What the candidate search of one frame shares (all at processing size)."""

    planes: _Planes
    boundary_x: np.ndarray  # mask boundary pixels (frame border excluded), in row order
    boundary_y: np.ndarray
    min_radius: float
    max_radius: float
    small_radius: float
    scale: float            # processing size / input size


class BallDetector:
    """Finds balls of the configured colour in BGR frames of any size.

    Holds no per-frame state, but its OpenCV CLAHE object is not meant to be shared between
    threads: use one detector per thread. Build a new one to change the configuration.
    """

    def __init__(self, config: DetectorConfig | None = None):
        self.config = config if config is not None else DetectorConfig()
        cfg = self.config
        self._clahe = (cv2.createCLAHE(clipLimit=cfg.clahe_clip_limit,
                                       tileGridSize=(cfg.clahe_tile_grid, cfg.clahe_tile_grid))
                       if cfg.clahe_clip_limit > 0 else None)
        self._open_kernel = _ellipse(cfg.open_kernel)
        self._close_kernel = _ellipse(cfg.close_kernel)
        self._boundary_kernel = np.ones((3, 3), np.uint8)
        # When a list, every judged candidate is appended as (candidate, metrics, score).
        self._debug: list | None = None

    # ----------------------------------------------------------------------------- public
    def detect(self, image_bgr: np.ndarray) -> DetectionResult:
        """Detect balls in one frame; ``image_bgr`` is uint8 HxWx3 (HxW grey is accepted)."""
        image = self._check_image(image_bgr)
        height, width = image.shape[:2]
        cfg = self.config
        scale = 1.0
        work = image
        if cfg.work_width and width > cfg.work_width:
            scale = cfg.work_width / width
            work_size = (cfg.work_width, max(8, round(height * scale)))
            work = cv2.resize(image, work_size, interpolation=cv2.INTER_AREA)

        planes = self._colour_planes(work)
        candidates = self._find_candidates(planes, scale)
        detections = [Detection(u=c.x / scale, v=c.y / scale, radius_px=c.radius / scale,
                                score=round(c.score, 4)) for c in candidates]
        mask = planes.mask
        if scale != 1.0:
            mask = cv2.resize(mask, (width, height), interpolation=cv2.INTER_NEAREST)
        return DetectionResult(detections=detections, mask=mask)

    def colour_mask(self, image_bgr: np.ndarray) -> np.ndarray:
        """The cleaned uint8 (0/255) colour mask of a frame, at the frame's size."""
        return self._colour_planes(self._check_image(image_bgr)).mask

    # ------------------------------------------------------------------------ colour mask
    @staticmethod
    def _check_image(image_bgr: np.ndarray) -> np.ndarray:
        if not isinstance(image_bgr, np.ndarray) or image_bgr.dtype != np.uint8:
            raise ValueError("image must be a uint8 numpy array")
        if image_bgr.ndim == 3 and image_bgr.shape[2] == 1:
            image_bgr = image_bgr[:, :, 0]
        if image_bgr.ndim == 2:
            image_bgr = cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)
        if image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
            raise ValueError(f"image must be HxWx3 BGR, got shape {image_bgr.shape}")
        if image_bgr.shape[0] < 8 or image_bgr.shape[1] < 8:
            raise ValueError(f"image too small: {image_bgr.shape[1]}x{image_bgr.shape[0]}")
        return image_bgr

    def _colour_planes(self, image_bgr: np.ndarray) -> _Planes:
        cfg = self.config
        reference = self._reference_level(image_bgr)
        gain = 1.0
        if cfg.max_gain > 1.0:
            gain = float(min(cfg.max_gain, max(1.0, cfg.gain_target / reference)))
        # Dark frames are scaled up before the blur, so that the blur's averaging keeps the
        # sub-unit colour information that uint8 rounding would otherwise destroy.
        gained = cv2.convertScaleAbs(image_bgr, alpha=gain) if gain > 1.0 else image_bgr
        # Extremely dark frames (gain of at least dark_gain): the colour is only a grey level
        # or two above black, so single pixels' hue and chroma are rounding noise; colour is
        # classified on wider averages instead (dark_blur_kernel), with its own chroma floor,
        # and no opening (the averaged mask has no specks, and a small lit cap would not
        # survive it).
        dark = cfg.dark_gain > 0 and gain >= cfg.dark_gain
        kernel = cfg.dark_blur_kernel if dark else cfg.blur_kernel
        min_chroma = cfg.dark_min_chroma if dark else cfg.min_chroma
        blurred = gained
        if kernel > 1:
            blurred = cv2.GaussianBlur(gained, (kernel, kernel), 0)
        hsv = cv2.cvtColor(blurred, cv2.COLOR_BGR2HSV)
        # (three extractChannel calls are several times faster than one cv2.split here)
        hue, saturation, value = (cv2.extractChannel(hsv, channel) for channel in range(3))
        # Adaptive histogram equalisation: v_min/v_max apply to locally normalised brightness,
        # so a ball in a shadow keeps its dark side in the mask.
        equalised = self._equalise(value)

        if cfg.h_min <= cfg.h_max:
            mask = cv2.inRange(hue, cfg.h_min, cfg.h_max)
        else:  # a hue range that wraps through 0 (red)
            mask = cv2.inRange(hue, cfg.h_min, 179) | cv2.inRange(hue, 0, cfg.h_max)
        mask &= cv2.inRange(saturation, cfg.s_min, cfg.s_max)
        mask &= cv2.inRange(equalised, cfg.v_min, cfg.v_max)
        # chroma (max - min channel) = S * V / 255; raw units are these over the gain
        chroma = cv2.multiply(saturation, value, scale=1.0 / 255.0)
        if min_chroma > 0:
            mask &= cv2.inRange(chroma, min(255, math.ceil(min_chroma * gain - 0.5)), 255)
        if self._open_kernel is not None and not dark:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._open_kernel)
        if self._close_kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, self._close_kernel)
        return _Planes(mask=mask, frame=gained, gain=gain, chroma=chroma,
                       reference=min(255.0, reference * gain), dark=dark)

    def _equalise(self, value: np.ndarray) -> np.ndarray:
        """CLAHE of the value channel; on a half-size copy for frames wider than 320 px.

        The result only feeds the v_min/v_max test, which needs local brightness, not detail,
        and CLAHE is the costliest step of the colour mask at full size.
        """
        if self._clahe is None:
            return value
        height, width = value.shape
        if width <= 320 or height < 64:
            return self._clahe.apply(value)
        small = cv2.resize(value, (width // 2, height // 2), interpolation=cv2.INTER_AREA)
        return cv2.resize(self._clahe.apply(small), (width, height), interpolation=cv2.INTER_LINEAR)

    @staticmethod
    def _reference_level(image_bgr: np.ndarray) -> float:
        """The frame's bright level: 99th percentile of V, but at most 3x its median.

        The cap keeps a small bright area (the sky above a dimly lit floor, a lamp) from
        setting the level of a dark frame. Measured on a 1/4-size nearest-neighbour sample.
        """
        height, width = image_bgr.shape[:2]
        small = cv2.resize(image_bgr, (max(1, width // 4), max(1, height // 4)),
                           interpolation=cv2.INTER_NEAREST)
        value = np.maximum(np.maximum(small[:, :, 0], small[:, :, 1]), small[:, :, 2]).ravel()
        last = value.size - 1
        ranks = [last // 2, int(0.99 * last)]
        median, bright = np.partition(value, ranks)[ranks]
        return float(max(1.0, min(float(bright), 3.0 * float(median))))

    # ------------------------------------------------------------------------- candidates
    def _find_candidates(self, planes: _Planes, scale: float) -> list[_Candidate]:
        cfg = self.config
        mask = planes.mask
        height, width = mask.shape
        min_radius = max(1.0, cfg.min_radius * scale)
        max_radius = (cfg.max_radius * scale) if cfg.max_radius else min(width, height) / 2.0
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if not contours:
            return []
        boundary = cv2.subtract(mask, cv2.erode(mask, self._boundary_kernel))
        # Pixels on the frame border are the frame's edge, not the ball's.
        boundary[0, :] = boundary[-1, :] = 0
        boundary[:, 0] = boundary[:, -1] = 0
        points = cv2.findNonZero(boundary)
        points = np.zeros((0, 2), np.float64) if points is None else points.reshape(-1, 2).astype(np.float64)
        search = _Search(planes, points[:, 0].copy(), points[:, 1].copy(), min_radius, max_radius,
                         max(1.0, cfg.small_radius * scale), scale)

        measured: list[tuple[_Candidate, dict]] = []
        for contour in contours:
            found = self._blob_candidates(contour, search, mask)
            if found is None:
                continue
            measured.extend(found)
            if any(metrics["clean"] for _, metrics in found):
                continue  # one isolated round blob: nothing for Hough to split
            measured.extend(self._hough_candidates(cv2.boundingRect(contour), search))
        return self._accept(measured, search)

    def _blob_candidates(self, contour: np.ndarray, search: _Search,
                         mask: np.ndarray) -> list[tuple[_Candidate, dict]] | None:
        """The blob's enclosing circle, refined and measured; None when the blob cannot be or
        hold a ball (too small, too big, or too dull in colour)."""
        cfg = self.config
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
        if blob_chroma < 0.7 * cfg.min_colourfulness * planes.reference:
            return None
        (x, y), radius = cv2.minEnclosingCircle(contour)
        if area < 0.3 * math.pi * radius * radius:
            return []  # elongated or ragged: not one ball by itself (Hough may split it)
        return self._measure_proposals([_Candidate(float(x), float(y), float(radius))], search, mask)

    def _hough_candidates(self, box: tuple[int, int, int, int],
                          search: _Search) -> list[tuple[_Candidate, dict]]:
        """Hough circles inside one blob's box: they split touching balls and find balls joined
        to other yellow-green things. Each blob gets its own few strongest circles."""
        cfg = self.config
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
        circles = cv2.HoughCircles(smooth, cv2.HOUGH_GRADIENT, dp=cfg.dp,
                                   minDist=max(1.0, cfg.min_dist * search.scale),
                                   param1=cfg.param1, param2=cfg.param2,
                                   minRadius=max(1, int(math.floor(search.min_radius))),
                                   maxRadius=max(2, int(math.ceil(roi_max_radius))))
        if circles is None:
            return []
        proposals: list[_Candidate] = []
        for cx, cy, r in circles[0][:HOUGH_CIRCLES_SCANNED]:
            circle = _Candidate(float(cx) + x0, float(cy) + y0, float(r))
            # Hough returns many near-concentric variants of a strong circle; keep the
            # strongest of each and look further down the list for other balls.
            if all(math.hypot(circle.x - other.x, circle.y - other.y)
                   >= 0.5 * max(circle.radius, other.radius) for other in proposals):
                proposals.append(circle)
                if len(proposals) >= HOUGH_CIRCLES_PER_BLOB:
                    break
        return self._measure_proposals(proposals, search, mask)

    def _measure_proposals(self, proposals: list[_Candidate], search: _Search,
                           mask: np.ndarray) -> list[tuple[_Candidate, dict]]:
        """Refine each proposal on the mask boundary, then measure it on ``mask``."""
        results: list[tuple[_Candidate, dict]] = []
        fitted_circles: list[_Candidate] = []
        for proposal in proposals:
            candidate = self._refine(proposal, search)
            if candidate is None:
                continue
            # (the colour of a ball with a dark side, no ambient light, may be a smaller cap)
            if not (LIT_CAP_SHARE * search.min_radius <= candidate.radius <= search.max_radius):
                continue
            if any(math.hypot(candidate.x - other.x, candidate.y - other.y) < 0.1 * other.radius + 0.5
                   and abs(candidate.radius - other.radius) < 0.1 * other.radius + 0.5
                   for other in fitted_circles):
                continue  # converged onto a circle already measured
            fitted_circles.append(candidate)
            metrics = self._measure(candidate, mask)
            if metrics is None:
                continue
            metrics.update(self._colour_stats(candidate, search.planes))
            metrics["size"] = candidate.radius / search.small_radius
            metrics["clean"] = (metrics["leak"] <= 0.05 and metrics["outside"] <= 0.05
                                and metrics["support"] >= 0.8 and metrics["fill"] >= 0.85)
            results.append((candidate, metrics))
        return results

    def _accept(self, measured: list[tuple[_Candidate, dict]], search: _Search) -> list[_Candidate]:
        """Accept candidates best first, then look again around each accepted ball.

        Mask belonging to an accepted ball is not clutter for the balls around it, so after
        each round the accepted balls are erased from the mask: candidates near them are
        measured again, and what is left of their blobs (a ball touching a found one, e.g. a
        two-colour ball against a plain one) is searched again for enclosing circles.
        """
        cfg = self.config
        for candidate, metrics in measured:
            candidate.score = self._judge(metrics) or 0.0
        pending = sorted(measured, key=lambda item: item[0].score, reverse=True)
        accepted: list[_Candidate] = []
        explained = search.planes.mask
        for _round in range(MAX_ROUNDS):
            newly: list[_Candidate] = []
            still: list[tuple[_Candidate, dict]] = []
            for candidate, metrics in pending:
                score = self._judge(metrics)
                if self._debug is not None:
                    self._debug.append((candidate, metrics, score))
                if score is not None and all(_circle_overlap(candidate, other) < 0.3
                                             for other in accepted + newly):
                    candidate.score = score
                    candidate.needs_outline = metrics["size"] < 1.0
                    newly.append(candidate)
                else:
                    still.append((candidate, metrics))
            accepted.extend(newly)
            if not newly or len(accepted) >= cfg.max_detections:
                break
            explained = explained.copy()
            for ball in newly:
                cv2.circle(explained, (int(round(ball.x)), int(round(ball.y))),
                           int(math.ceil(ball.radius * 1.08 + 1)), EXPLAINED, -1)
            pending = []
            for candidate, metrics in still:
                if any(math.hypot(candidate.x - ball.x, candidate.y - ball.y)
                       < 1.5 * candidate.radius + ball.radius + 3 for ball in newly):
                    remeasured = self._measure(candidate, explained)
                    if remeasured is None:
                        continue
                    metrics = {**metrics, **remeasured}
                pending.append((candidate, metrics))
            pending.extend(self._leftover_candidates(newly, explained, search))
            pending.sort(key=lambda item: item[0].score, reverse=True)
        accepted.sort(key=lambda c: c.score, reverse=True)
        accepted = accepted[:cfg.max_detections]
        accepted = self._outlines(accepted, still, explained, search)
        accepted.sort(key=lambda c: c.radius, reverse=True)
        return accepted

    def _outlines(self, accepted: list[_Candidate], rejected: list[tuple[_Candidate, dict]],
                  explained: np.ndarray, search: _Search) -> list[_Candidate]:
        """Every accepted ball's circle replaced by its outline found on the frame (see
        _silhouette); then rejected candidates with a dark side looked at again.

        Under a light with no ambient, a ball's unlit side is black: its colour is a lit cap
        whose rim is part circle, part shading, which the candidate checks take for a corner
        or a ragged blob. If the frame shows an outline around the cap, with all the colour
        inside it (no leak past its rim, the rim a colour edge over min_edge_support of it) and
        a dark side within it (_dark_side), the outline is the ball; its score is the mean of
        its fill and rim support, which a dark side lowers (it is not held to min_score).
        """
        cfg = self.config
        planes = search.planes
        reach = DARK_WIDE_REACH if planes.dark else WIDE_REACH
        kept: list[_Candidate] = []
        for ball in accepted:
            outline = _silhouette(planes.frame, planes.mask, planes.gain, planes.reference, ball,
                                  [other for other in accepted if other is not ball], reach)
            if outline is not None:
                ball.x, ball.y, ball.radius = outline
            elif ball.needs_outline:
                continue
            if ball.radius >= search.min_radius:
                kept.append(ball)
        attempts = 0
        for candidate, metrics in sorted(rejected, key=lambda item: item[0].radius, reverse=True):
            if attempts >= DARK_SIDE_ATTEMPTS or len(kept) >= cfg.max_detections:
                break
            if (metrics["colourfulness"] < cfg.min_colourfulness
                    or any(_circle_overlap(candidate, other) >= 0.3 for other in kept)):
                continue
            # (a cheap look first: is there anything dark around the colour at all?)
            if not _dark_around(planes.frame, planes.mask, candidate):
                continue
            attempts += 1
            outline = _silhouette(planes.frame, planes.mask, planes.gain, planes.reference,
                                  candidate, kept, reach)
            if outline is None:
                continue
            ball = _Candidate(*outline)
            if (ball.radius < search.min_radius
                    or any(_circle_overlap(ball, other) >= 0.3 for other in kept)
                    or not _dark_side(planes.frame, planes.mask, ball)):
                continue
            measured = self._measure(ball, explained)
            if (measured is None or measured["leak"] > 0.05 or measured["outside"] > 0.05
                    or measured["support"] < cfg.min_edge_support
                    or measured["visible"] < max(cfg.min_visible_fraction,
                                                 min(1.0, search.small_radius / ball.radius))):
                continue
            ball.score = max(0.0, min(1.0, (measured["fill"] + measured["support"]) / 2.0))
            if self._debug is not None:
                self._debug.append((ball, {**metrics, **measured, "dark_side": True}, ball.score))
            kept.append(ball)
        return kept

    def _leftover_candidates(self, balls: list[_Candidate], explained: np.ndarray,
                             search: _Search) -> list[tuple[_Candidate, dict]]:
        """Enclosing circles of the mask pieces left next to freshly accepted balls."""
        height, width = explained.shape
        results: list[tuple[_Candidate, dict]] = []
        for ball in balls:
            reach = 3.2 * ball.radius + 4
            x0, y0 = max(0, int(ball.x - reach)), max(0, int(ball.y - reach))
            x1, y1 = min(width, int(ball.x + reach) + 1), min(height, int(ball.y + reach) + 1)
            if x0 >= x1 or y0 >= y1:
                continue
            leftover = cv2.inRange(explained[y0:y1, x0:x1], 255, 255)
            contours, _ = cv2.findContours(leftover, cv2.RETR_EXTERNAL,
                                           cv2.CHAIN_APPROX_SIMPLE, offset=(x0, y0))
            for contour in contours:
                found = self._blob_candidates(contour, search, explained)
                if found:
                    for candidate, metrics in found:
                        candidate.score = self._judge(metrics) or 0.0
                    results.extend(found)
        return results

    @staticmethod
    def _refine(proposal: _Candidate, search: _Search) -> _Candidate | None:
        """Fit a circle to the mask boundary pixels near the proposal, in rounds that keep
        only the pixels ever closer to the current circle (robust to other edges nearby)."""
        x, y, radius = proposal.x, proposal.y, proposal.radius
        reach = 1.6 * radius + 3
        # The boundary pixels are sorted by row: the rows in reach are one slice.
        first, last = np.searchsorted(search.boundary_y, (y - reach, y + reach))
        xs, ys = search.boundary_x[first:last], search.boundary_y[first:last]
        near_columns = (xs > x - reach) & (xs < x + reach)
        if np.count_nonzero(near_columns) < 6:
            return None
        xs = xs[near_columns] - x  # relative to the proposal's centre
        ys = ys[near_columns] - y
        centre_x = centre_y = 0.0
        for tolerance_ratio, tolerance_floor in REFINE_ROUNDS:
            tolerance = max(tolerance_floor, tolerance_ratio * radius)
            dx, dy = xs - centre_x, ys - centre_y
            squared = dx * dx + dy * dy
            near = (squared > max(0.0, radius - tolerance) ** 2) & (squared < (radius + tolerance) ** 2)
            if np.count_nonzero(near) < 6:
                return None
            fitted = _fit_circle(dx[near], dy[near])
            if fitted is None:
                return None
            shift_x, shift_y, new_radius = fitted
            if not (0.6 * radius <= new_radius <= 1.6 * radius):
                return None
            centre_x, centre_y = centre_x + shift_x, centre_y + shift_y
            moved = abs(shift_x) + abs(shift_y) + abs(new_radius - radius)
            radius = new_radius
            if moved < 0.05 and tolerance_ratio <= REFINE_ROUNDS[1][0]:
                break  # converged
        # Boundary pixels are the mask's outermost pixels, half a pixel inside its true edge.
        return _Candidate(x + centre_x, y + centre_y, radius + 0.5)

    @staticmethod
    def _measure(candidate: _Candidate, mask: np.ndarray) -> dict | None:
        """Mask statistics of a circle; None when too little of it can be judged.

        ``mask`` is 255 (colour), 0 (not) or EXPLAINED (an accepted ball's disc: neither).
        ``visible``: fraction of the rim that is inside the frame and not explained;
        ``support``: fraction of that rim where just inside is mask and just outside is not;
        ``leak``: fraction where the mask goes on past the rim; ``fill``: mask fraction of the
        disc (0.85 r); ``outside``: mask fraction of the ring from 1.15 r to 1.45 r.
        """
        height, width = mask.shape
        x, y, radius = candidate.x, candidate.y, candidate.radius
        samples = int(min(96, max(24, 2 * math.pi * radius)))
        offset = max(1.5, 0.15 * radius)
        # Rows: inner x, inner y, outer x, outer y of each rim sample.
        points = np.rint(np.array([[x], [y], [x], [y]])
                         + np.array([[radius - offset], [radius - offset], [radius + offset],
                                     [radius + offset]]) * _rim_directions(samples)).astype(np.intp)
        in_frame = ((points >= 0) & (points < np.array([[width], [height], [width], [height]]))).all(axis=0)
        points = points[:, in_frame]
        inner, outer = mask[points[1], points[0]], mask[points[3], points[2]]
        known = (inner != EXPLAINED) & (outer != EXPLAINED)
        known_count = int(np.count_nonzero(known))
        if known_count < 4:
            return None
        inner_on, outer_on = inner[known] == 255, outer[known] == 255
        roundness = _edge_spread(x, y, radius, mask, samples)

        outer_radius = 1.45 * radius + 2
        box = _box(x, y, outer_radius, width, height)
        if box is None:
            return None
        patch = mask[box]
        disc = _disc(patch.shape, x - box[1].start, y - box[0].start, 0.85 * radius)
        ring = _disc(patch.shape, x - box[1].start, y - box[0].start, outer_radius)
        cv2.circle(ring, _fixed(x - box[1].start, y - box[0].start), _fixed_radius(1.15 * radius + 1), 0, -1,
                   cv2.LINE_8, FIXED_BITS)
        on = cv2.inRange(patch, 255, 255)
        usable = cv2.bitwise_not(cv2.inRange(patch, EXPLAINED, EXPLAINED))
        disc &= usable
        ring &= usable
        disc_count = cv2.countNonZero(disc)
        if disc_count == 0:
            return None
        ring_count = cv2.countNonZero(ring)
        return {
            "visible": known_count / samples,
            "support": float(np.count_nonzero(inner_on & ~outer_on)) / known_count,
            "leak": float(np.count_nonzero(outer_on)) / known_count,
            "fill": cv2.countNonZero(on & disc) / disc_count,
            "outside": cv2.countNonZero(on & ring) / ring_count if ring_count else 0.0,
            "spread": roundness,
        }

    @staticmethod
    def _colour_stats(candidate: _Candidate, planes: _Planes) -> dict:
        """Colour of a circle: ``colourfulness``, the mean chroma of its mask pixels over the
        frame's reference level, and the hue and chroma (raw units) of the mean colour of its
        whole disc."""
        height, width = planes.mask.shape
        x, y, radius = candidate.x, candidate.y, candidate.radius
        box = _box(x, y, 0.85 * radius, width, height)
        empty = {"colourfulness": 0.0, "mean_hue": -1.0, "mean_chroma": 0.0}
        if box is None:
            return empty
        disc = _disc((box[0].stop - box[0].start, box[1].stop - box[1].start),
                     x - box[1].start, y - box[0].start, 0.85 * radius)
        selected = cv2.inRange(planes.mask[box], 255, 255) & disc
        if not cv2.countNonZero(selected):
            return empty
        # Averaging the unblurred disc recovers the hue that uint8 rounding hides in a very
        # dark frame (a dim orange box can round to yellow pixel by pixel). Grey floor or
        # black shade inside the disc does not move the hue of the mean.
        mean_bgr = cv2.mean(planes.frame[box], disc)[:3]
        return {"colourfulness": cv2.mean(planes.chroma[box], selected)[0] / planes.reference,
                "mean_hue": _hue(mean_bgr),
                "mean_chroma": (max(mean_bgr) - min(mean_bgr)) / planes.gain}

    def _hue_in_range(self, hue: float) -> bool:
        low, high = self.config.h_min - 0.5, self.config.h_max + 0.5
        if low <= high:
            return low <= hue <= high
        return hue >= low or hue <= high

    def _judge(self, metrics: dict) -> float | None:
        """Score in [0, 1] of a measured circle, or None when a check fails.

        The more mask lies around the circle (leak, outside), the more of its rim must be a
        clean edge: a ball touching another keeps most of its rim, a round patch cut out of a
        large yellow-green area (sunlit trees) does not.
        """
        cfg = self.config
        clutter = metrics["leak"] + metrics["outside"]
        # A circle cut by the frame edge must still show as much rim as a whole ball of
        # small_radius has: a few pixels of arc at the border prove nothing. A ball smaller
        # than that must be whole, and have its outline found (see _outlines).
        if (metrics["visible"] < max(cfg.min_visible_fraction, min(1.0, 1.0 / metrics["size"]))
                or metrics["fill"] < cfg.min_fill_ratio
                or metrics["support"] < cfg.min_edge_support + clutter
                or metrics["outside"] > cfg.max_outside_ratio
                or metrics["colourfulness"] < cfg.min_colourfulness):
            return None
        if metrics["mean_chroma"] < LOW_CHROMA and not self._hue_in_range(metrics["mean_hue"]):
            return None
        # Corners: the edge's distance from the centre varies and the blob pokes out of the
        # circle in places (a box face); a ball's edge is even, its neighbours add no spread.
        if metrics["spread"] > CORNER_SPREAD and metrics["leak"] > CORNER_LEAK:
            return None
        score = (metrics["fill"] + metrics["support"] - clutter) / 2.0
        score = max(0.0, min(1.0, score))
        if score < cfg.min_score:
            return None
        return score


def annotate(image_bgr: np.ndarray, detections: list[Detection]) -> np.ndarray:
    """A copy of the frame with each detection's circle, centre and label drawn (``image_out``)."""
    if image_bgr.ndim == 2:
        canvas = cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)
    else:
        canvas = image_bgr.copy()
    height, width = canvas.shape[:2]
    thickness = max(1, round(min(width, height) / 240))
    font_scale = max(0.35, min(width, height) / 800)
    for index, detection in enumerate(detections):
        centre = (int(round(detection.u)), int(round(detection.v)))
        colour = (0, 0, 255) if index == 0 else (0, 200, 255)
        cv2.circle(canvas, centre, max(1, int(round(detection.radius_px))), colour, thickness, cv2.LINE_AA)
        cv2.circle(canvas, centre, max(1, thickness), colour, -1, cv2.LINE_AA)
        label = f"{index} r={detection.radius_px:.0f} s={detection.score:.2f}"
        origin = (max(0, centre[0] - int(detection.radius_px)),
                  max(12, centre[1] - int(detection.radius_px) - 4))
        cv2.putText(canvas, label, origin, cv2.FONT_HERSHEY_SIMPLEX, font_scale, (0, 0, 0),
                    thickness + 2, cv2.LINE_AA)
        cv2.putText(canvas, label, origin, cv2.FONT_HERSHEY_SIMPLEX, font_scale, colour,
                    thickness, cv2.LINE_AA)
    return canvas
