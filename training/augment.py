"""What lenses and sensors do to a picture, drawn at random: exposure, white balance, defocus,
motion blur, noise, specks and JPEG compression; and (``letterbox``) black bars. Each picture gets a fresh draw of every effect (most
of them mild, some strong), so the network never sees a render as clean as it was drawn."""

import dataclasses
import math

import cv2
import numpy as np


def exposure(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Gain (under- to over-exposed, clipping highlights), gamma and per-channel white balance."""
    gain = float(np.exp(rng.normal(0.0, 0.45)))
    gamma = float(np.exp(rng.normal(0.0, 0.2)))
    balance = np.exp(rng.normal(0.0, 0.08, 3))
    scaled = (image.astype(np.float32) / 255.0) * gain * balance
    return (np.clip(scaled, 0, 1) ** gamma * 255.0).astype(np.uint8)


def defocus(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    sigma = rng.uniform(0.5, 2.2)
    return cv2.GaussianBlur(image, (0, 0), sigma)


def motion_blur(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    length = int(rng.integers(3, 12))
    kernel = np.zeros((length, length), np.float32)
    angle = rng.uniform(0, math.pi)
    centre = (length - 1) / 2
    for step in np.linspace(-centre, centre, length * 2):
        kernel[int(round(centre + step * math.sin(angle))), int(round(centre + step * math.cos(angle)))] = 1
    return cv2.filter2D(image, -1, kernel / kernel.sum())


def noise(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    sigma = rng.uniform(1, 9)
    return np.clip(image + rng.normal(0, sigma, image.shape), 0, 255).astype(np.uint8)


def specks(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Impulse noise: a few per cent of the pixels black, white or of a random colour (dust,
    hot pixels, a dirty lens, a bad transmission)."""
    out = image.copy()
    chosen = rng.random(image.shape[:2]) < rng.uniform(0.002, 0.03)
    kind = rng.integers(0, 3, int(chosen.sum()))
    values = np.where(kind[:, None] == 0, 0, np.where(kind[:, None] == 1, 255,
                                                       rng.integers(0, 256, (len(kind), 3))))
    out[chosen] = values.astype(np.uint8)
    return out


def jpeg(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    quality = int(rng.integers(25, 95))
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    return cv2.imdecode(data, cv2.IMREAD_COLOR) if ok else image


# Each effect with the chance a picture gets it, in the order a camera applies them.
EFFECTS = ((exposure, 0.8), (defocus, 0.3), (motion_blur, 0.2), (noise, 0.5), (specks, 0.15), (jpeg, 0.7))


def letterbox(image: np.ndarray, balls: list, rng: np.random.Generator) -> tuple[np.ndarray, list]:
    """Black bars above and below (or at the sides), as a picture of a wider (or taller) aspect
    exported into this frame shows: the picture between them unchanged, ``balls`` (objects with
    u, v, radius, in_frame) cut by them as by the frame's edge."""
    height, width = image.shape[:2]
    out = image.copy()
    rows = rng.random() < 0.7
    bar = int(round(rng.uniform(0.05, 0.2) * (height if rows else width)))
    if rows:
        out[:bar], out[height - bar:] = 0, 0
        low, high = bar - 0.5, height - bar - 0.5
    else:
        out[:, :bar], out[:, width - bar:] = 0, 0
        low, high = bar - 0.5, width - bar - 0.5
    # (the share of each disc between the bars, on a grid of points over it)
    grid = np.linspace(-1, 1, 15)
    offsets = np.array([(x, y) for x in grid for y in grid if x * x + y * y <= 1])
    cut = []
    for ball in balls:
        along = (ball.v if rows else ball.u) + offsets[:, 1 if rows else 0] * ball.radius
        share = float(np.mean((along >= low) & (along <= high)))
        cut.append(dataclasses.replace(ball, in_frame=ball.in_frame * share))
    return out, cut


def augment(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A picture with a random draw of ``EFFECTS``."""
    for effect, chance in EFFECTS:
        if rng.random() < chance:
            image = effect(image, rng)
    return image
