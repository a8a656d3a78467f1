"""Synthetic frames for the detector's tests, drawn with cv2/numpy.

Balls are shaded yellow-green discs drawn with sub-pixel accuracy (4x4 supersampled coverage)
on a textured grey floor; dark versions scale the whole frame down to a few pixel units, as the
simulator's dimmest lights do.
"""

import numpy as np

TENNIS_BGR = (40, 225, 190)  # yellow-green felt under white light (H ~36, S ~210)


def floor(width=640, height=480, seed=0):
    """A grey floor with tiles, a brightness gradient and sensor noise; float32 BGR."""
    generator = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    tiles = ((xs // 80 + ys // 80) % 2) * 18.0
    gradient = 20.0 * ys / max(height, 1)
    base = 95.0 + tiles + gradient
    image = np.repeat(base[..., None], 3, axis=2) + generator.normal(0, 4, (height, width, 3))
    image[..., 0] += 4  # a slightly bluish grey, as real floors are
    return image.astype(np.float32)


def coverage(shape, u, v, radius, samples=4):
    """Fraction of each pixel covered by the disc (pixel centres at integer coordinates)."""
    height, width = shape[:2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    total = np.zeros((height, width), np.float32)
    offsets = (np.arange(samples) + 0.5) / samples - 0.5
    for dy in offsets:
        for dx in offsets:
            total += ((xs + dx - u) ** 2 + (ys + dy - v) ** 2) <= radius * radius
    return total / (samples * samples)


def draw_ball(image, u, v, radius, colour=TENNIS_BGR, shade_floor=0.45):
    """A disc lit from the upper left (Lambert-like shading) blended in by its coverage."""
    height, width = image.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    nx, ny = (xs - u) / radius, (ys - v) / radius
    nz = np.sqrt(np.clip(1.0 - nx * nx - ny * ny, 0.0, 1.0))
    light = np.clip(0.35 + 0.65 * (-0.35 * nx - 0.35 * ny + 0.87 * nz), shade_floor, 1.0)
    ball = np.array(colour, np.float32)[None, None, :] * light[..., None]
    cover = coverage(image.shape, u, v, radius)[..., None]
    return image * (1.0 - cover) + ball * cover


def draw_box(image, x0, y0, x1, y1, colour):
    cover = np.zeros(image.shape[:2], np.float32)
    cover[y0:y1, x0:x1] = 1.0
    return image * (1.0 - cover[..., None]) + np.array(colour, np.float32) * cover[..., None]


def to_uint8(image, brightness=1.0):
    """The frame as a camera would store it, optionally under a dimmer light."""
    return np.clip(np.rint(image * brightness), 0, 255).astype(np.uint8)


def scene(balls, width=640, height=480, brightness=1.0, seed=0, distractors=()):
    image = floor(width, height, seed)
    for kind, *args in distractors:
        image = draw_box(image, *args) if kind == "box" else draw_ball(image, *args)
    for u, v, radius in balls:
        image = draw_ball(image, u, v, radius)
    return to_uint8(image, brightness)


def draw_lit_from_above(image, u, v, radius, colour=TENNIS_BGR):
    """A ball under a light from above with no ambient light: its lower part is black."""
    height, width = image.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    nx, ny = (xs - u) / radius, (ys - v) / radius
    nz = np.sqrt(np.clip(1.0 - nx * nx - ny * ny, 0.0, 1.0))
    light = np.clip(-0.8 * ny + 0.6 * nz, 0.0, 1.0)
    ball = np.array(colour, np.float32)[None, None, :] * light[..., None]
    cover = coverage(image.shape, u, v, radius)[..., None]
    return image * (1.0 - cover) + ball * cover


def pitch_dark_frame(balls=(), boxes=(), distractor_balls=()):
    """A render under a 0.01 diffuse light and no ambient: a grey floor at 1, a bright sky
    band (which does not set the gain), lit colours only 1-2 units above black, unlit sides 0.
    ``balls``: (u, v, radius) tennis balls lit from above; ``boxes``: (x0, y0, x1, y1, BGR)
    evenly lit; ``distractor_balls``: (u, v, radius, BGR) lit from above."""
    image = np.full((480, 640, 3), 1.0, np.float32)
    image[:120] = (175.0, 165.0, 160.0)
    for x0, y0, x1, y1, colour in boxes:
        image = draw_box(image, x0, y0, x1, y1, colour)
    for u, v, radius, colour in distractor_balls:
        image = draw_lit_from_above(image, u, v, radius, colour)
    for u, v, radius in balls:
        # tennis felt (0.7, 0.85, 0.15 RGB): mostly (1, 1, 0), (1, 2, 0) and some (2, 2, 0)
        image = draw_lit_from_above(image, u, v, radius, colour=(0.2, 1.9, 1.6))
    return to_uint8(image)
