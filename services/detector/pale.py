"""Washed-out balls: step 10 of the detector (see ``detector.py``).

In direct sun a ball's felt can wash out to a saturation far below ``s_min`` (39-52 on the
floor set's sunlit concrete, against 150 and more in shade), so the colour mask leaves it out;
and its chroma over the frame's bright level is about half the colourfulness floor, so no
candidate check would pass it either. What still tells it from the ground is what holds for any
ball seen plainly: a round blob, alone, brightly lit, of the ball's hue, far more colourful than
what lies around it (grey concrete's chroma is a fifth of such a ball's). Those are the only
evidence here, so each is asked for strictly (PALE_*), and only of blobs large enough for a
shape to mean something. The blobs are those of the colour mask joined with the pale plane
(hue in range, saturation ``pale_s_min`` up to ``s_min``; see ``mask.py``), once the balls
already found are erased from it. Frames whose sample may hold such a ball are done whole
(``regions.pale_in_sample``).
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.checks import hue_in_range
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, box_around, rim_directions
from balltrack.services.detector.mask import ColourPlanes, ellipse_kernel, explained_radius
from balltrack.services.detector.measure import mean_hue

# Below this radius (px of the frame as processed) a blob's outline is too few pixels for its
# roundness to be evidence.
PALE_MIN_RADIUS = 8.0
# At least this share of the blob is pale (the rest is the colour mask's: a ball's shaded side
# may keep its colour). A blob mostly in the colour mask had its chance in steps 5-9.
PALE_MIN_SHARE = 0.5
# The blob covers at least this share of its enclosing disc (a highlight or a seam may leave a
# notch) ...
PALE_MIN_FILL = 0.65
# ... and reaches its circle (lies at PALE_RIM_DEPTH of its radius) on at least this share of
# it: a ball's blob keeps much of its round edge even where a highlight or shade takes a piece
# (the floor set's washed-out balls 0.28-0.86), a square's reaches its enclosing circle only at
# its corners (0.19).
PALE_MIN_RIM = 0.25
PALE_RIM_DEPTH = 0.9
PALE_RIM_SAMPLES = 64
# Nothing of the colour mask or the pale plane lies in the ring 1.15-1.45 radii around it, but
# for this share (a ball alone, not a patch of a pale surface).
PALE_RING = (1.15, 1.45)
PALE_MAX_OUTSIDE = 0.05
# Washed out means brightly lit: its mean brightest channel is at least this share of the
# frame's reference level (in shadow, the pale plane holds the hue noise of dark grey).
PALE_MIN_BRIGHTNESS = 0.6
# Its mean chroma is at least this many times the ring's (a grey floor's is 3-10 against the
# ball's 25-40; a pale-yellow surface's is the ball's own).
PALE_MIN_CONTRAST = 2.5


def pale_balls(planes: ColourPlanes, balls: list[Candidate], config: DetectorConfig) -> list[Candidate]:
    """The washed-out balls of a frame's planes, besides ``balls`` (those already found, in
    pixels of the frame as processed); [] when the pale plane is off."""
    smallest_area = PALE_MIN_FILL * math.pi * PALE_MIN_RADIUS ** 2
    if planes.pale is None or cv2.countNonZero(planes.pale) < PALE_MIN_SHARE * smallest_area:
        return []
    blobs = cv2.bitwise_or(planes.mask, planes.pale)
    for ball in balls:
        cv2.circle(blobs, (int(round(ball.x)), int(round(ball.y))), explained_radius(ball.radius), 0, -1)
    for operation, size in ((cv2.MORPH_OPEN, config.open_kernel), (cv2.MORPH_CLOSE, config.close_kernel)):
        kernel = ellipse_kernel(size)
        if kernel is not None:
            blobs = cv2.morphologyEx(blobs, operation, kernel)
    # (outlines, not labelled components: OpenCV's components with their statistics took ~1.9
    # ms on a 640x480 photo's planes, its outlines ~0.26 ms)
    contours, _ = cv2.findContours(blobs, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    found = []
    for contour in contours:
        _, _, width, height = cv2.boundingRect(contour)
        if max(width, height) < 2 * PALE_MIN_RADIUS:
            continue  # (the cheap test first: most blobs are specks)
        area = cv2.contourArea(contour)
        if area < 0.5 * smallest_area:
            continue
        (x, y), radius = cv2.minEnclosingCircle(contour)
        # (a polygon through the outline's pixel centres holds about half its outline's length
        # less than the blob's pixel count: this far below PALE_MIN_FILL it is no disc)
        if radius >= PALE_MIN_RADIUS and area >= (PALE_MIN_FILL - 0.15) * math.pi * radius ** 2:
            ball = judged(planes, blobs, contour, x, y, radius, config)
            if ball is not None:
                found.append(ball)
    return found


def judged(planes: ColourPlanes, blobs: np.ndarray, contour: np.ndarray, x: float, y: float, radius: float,
           config: DetectorConfig) -> Candidate | None:
    """The blob of outline ``contour`` (one of ``blobs``), of enclosing circle (x, y, radius),
    as a washed-out ball scored by its fill, when it is one (see PALE_*); else None."""
    height, width = blobs.shape
    window = box_around(x, y, PALE_RING[1] * radius + 1, width, height)
    if window is None:
        return None
    blob = np.zeros((window[0].stop - window[0].start, window[1].stop - window[1].start), np.uint8)
    cv2.drawContours(blob, [contour], -1, 255, -1, offset=(-window[1].start, -window[0].start))
    area = cv2.countNonZero(blob)
    if cv2.countNonZero(planes.pale[window] & blob) < PALE_MIN_SHARE * area:
        return None
    rows = np.arange(window[0].start, window[0].stop, dtype=np.float32)[:, None] - np.float32(y)
    columns = np.arange(window[1].start, window[1].stop, dtype=np.float32)[None, :] - np.float32(x)
    distance = rows * rows + columns * columns
    disc = distance <= radius * radius
    ring = (distance >= (PALE_RING[0] * radius) ** 2) & (distance <= (PALE_RING[1] * radius) ** 2)
    inside = (blob > 0) & disc
    fill = float(np.count_nonzero(inside)) / max(1, int(np.count_nonzero(disc)))
    ring_count = int(np.count_nonzero(ring))
    if fill < PALE_MIN_FILL or ring_count == 0:
        return None
    cos, sin = rim_directions(PALE_RIM_SAMPLES)[:2]
    rim_rows = np.rint(y + PALE_RIM_DEPTH * radius * sin).astype(int) - window[0].start
    rim_columns = np.rint(x + PALE_RIM_DEPTH * radius * cos).astype(int) - window[1].start
    inside_window = ((rim_rows >= 0) & (rim_rows < blob.shape[0]) & (rim_columns >= 0)
                     & (rim_columns < blob.shape[1]))
    rim = float(np.count_nonzero(blob[rim_rows[inside_window], rim_columns[inside_window]])) / PALE_RIM_SAMPLES
    if rim < PALE_MIN_RIM:
        return None
    if np.count_nonzero(blobs[window][ring]) > PALE_MAX_OUTSIDE * ring_count:
        return None
    colours = planes.frame[window][inside]
    if float(colours.max(axis=1).mean()) < PALE_MIN_BRIGHTNESS * planes.reference:
        return None
    chroma = planes.chroma[window]
    if float(chroma[inside].mean()) < PALE_MIN_CONTRAST * max(1.0, float(chroma[ring].mean())):
        return None
    if not hue_in_range(mean_hue(colours.mean(axis=0)), config, config.hue_margin):
        return None
    return Candidate(x, y, radius, score=round(fill, 4))
