"""Training samples: the learned detector's own proposals on pictures with known balls, as
network inputs with labels and corrections.

Pictures come from randomised renders (``scenes.py``, then ``augment.py``) and from photo sets
whose README allows training on them (``TRAINABLE_SETS``). Each picture is run through the
detector's own stages 1-3 (``services/detector/learned.py``) with the colour range its target
is configured with, so the network learns on exactly the proposals it will judge. A proposal is

- a ball (1) when its centre lies within ``POSITIVE_OFFSET`` radii of a ball that is mostly in
  view and its radius is within ``POSITIVE_RATIO`` of the ball's; its correction is the move
  and resize onto that ball;
- left out (-1) when it is near a ball without meeting that (a mostly hidden ball, an
  off-centre circle on a ball): neither answer is wrong there;
- not a ball (0) otherwise: clutter of the target's colour, a group of touching balls taken
  whole, a piece of a ball.

Besides the mask's proposals, every ball in view is proposed again a little off its centre and
size (``JITTERED``), so that the corrections are learned on more than the mask's own errors.
"""

import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from balltrack.experiments.real_photos import TRAINABLE_SETS
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.learned import PATCH, PLANES, LearnedDetector, Proposal, patches
from balltrack.training.augment import augment, letterbox
from balltrack.training.scenes import MIN_VISIBLE, Ball, World

POSITIVE_OFFSET = 0.5
POSITIVE_RATIO = (0.55, 1.8)
# Near a ball (in its radii) but not a ball proposal: left out.
NEAR = 1.0
# A ball cut by the frame edge is one to find when this share of its disc is in the frame.
MIN_IN_FRAME = 0.35
# The smallest ball (radius, px) taught as one.
MIN_BALL_RADIUS = 3.0
JITTERED = 2
# The width pictures are processed at (the detector's work_width) unless told otherwise.
WORK_WIDTH = DetectorConfig().work_width
# Share of the renders shown letterboxed (see augment.letterbox).
LETTERBOXED = 0.1
# Pictures drawn from one world before a new one is built.
PICTURES_PER_WORLD = 40


@dataclass
class Samples:
    """Network inputs (N x PLANES x PATCH x PATCH, float16), labels (N: 1, 0, -1) and
    corrections (N x 3: dx, dy in radii of the proposal, log radius ratio)."""

    inputs: np.ndarray
    labels: np.ndarray
    corrections: np.ndarray

    @staticmethod
    def empty() -> "Samples":
        return Samples(np.zeros((0, PLANES, PATCH, PATCH), np.float16), np.zeros(0, np.int8),
                       np.zeros((0, 3), np.float32))

    @staticmethod
    def join(parts: list["Samples"]) -> "Samples":
        parts = [part for part in parts if len(part.labels)] or [Samples.empty()]
        return Samples(np.concatenate([p.inputs for p in parts]), np.concatenate([p.labels for p in parts]),
                       np.concatenate([p.corrections for p in parts]))

    def save(self, path: Path) -> None:
        np.savez(path, inputs=self.inputs, labels=self.labels, corrections=self.corrections)

    @staticmethod
    def load(path: Path) -> "Samples":
        with np.load(path) as data:
            return Samples(data["inputs"], data["labels"], data["corrections"])


def label(proposals: list[Proposal], balls: list[Ball]) -> tuple[np.ndarray, np.ndarray]:
    """Labels and corrections of proposals (see the module doc)."""
    labels = np.zeros(len(proposals), np.int8)
    corrections = np.zeros((len(proposals), 3), np.float32)
    for index, proposal in enumerate(proposals):
        best, best_offset = None, math.inf
        for ball in balls:
            offset = math.hypot(proposal.x - ball.u, proposal.y - ball.v) / ball.radius
            if offset < best_offset:
                best, best_offset = ball, offset
        if best is None or best_offset >= NEAR:
            continue
        ratio = proposal.radius / best.radius
        findable = best.visible >= MIN_VISIBLE and best.in_frame >= MIN_IN_FRAME and best.radius >= MIN_BALL_RADIUS
        if findable and best_offset < POSITIVE_OFFSET and POSITIVE_RATIO[0] <= ratio <= POSITIVE_RATIO[1]:
            labels[index] = 1
            corrections[index] = ((best.u - proposal.x) / proposal.radius, (best.v - proposal.y) / proposal.radius,
                                  math.log(best.radius / proposal.radius))
        elif 0.5 <= ratio <= 2.0 or not findable:
            labels[index] = -1
    return labels, corrections


def jittered(balls: list[Ball], rng: np.random.Generator) -> list[Proposal]:
    """Each findable ball proposed ``JITTERED`` times a little off its centre and size."""
    out = []
    for ball in balls:
        if ball.visible < MIN_VISIBLE or ball.in_frame < MIN_IN_FRAME or ball.radius < MIN_BALL_RADIUS:
            continue
        for _ in range(JITTERED):
            angle, offset = rng.uniform(0, 2 * math.pi), rng.uniform(0, 0.35) * ball.radius
            out.append(Proposal(ball.u + offset * math.cos(angle), ball.v + offset * math.sin(angle),
                                ball.radius * float(np.exp(rng.uniform(-0.3, 0.3)))))
    return out


def picture_samples(image: np.ndarray, balls: list[Ball], hue_range: tuple[int, int],
                    rng: np.random.Generator, work_width: int = WORK_WIDTH) -> Samples:
    """The samples of one picture whose target has ``hue_range``, processed at ``work_width``."""
    detector = LearnedDetector(DetectorConfig(h_min=hue_range[0], h_max=hue_range[1], work_width=work_width),
                               network=_NO_NETWORK)
    work, scale, scale_y = detector.work_frame(image)
    if scale != 1.0:
        balls = [Ball(ball.u * scale, ball.v * scale_y, ball.radius * scale, ball.in_frame, ball.visible)
                 for ball in balls]
    proposals, features = detector.proposals(work)
    proposals = proposals + jittered(balls, rng)
    labels, corrections = label(proposals, balls)
    return Samples(patches(features, proposals).astype(np.float16), labels, corrections)


class _NoNetwork:
    """Stands in for the network while samples are made (only stages 1-3 run)."""

    def __call__(self, batch: np.ndarray) -> np.ndarray:
        raise RuntimeError("samples are made without a network")


_NO_NETWORK = _NoNetwork()


def render_samples(pictures: int, seed: int, shadow_share: float = 0.25, progress=None,
                   work_width: int = WORK_WIDTH) -> Samples:
    """Samples of ``pictures`` randomised renders (a new world every PICTURES_PER_WORLD)."""
    rng = np.random.default_rng(seed)
    parts: list[Samples] = []
    world = None
    try:
        for index in range(pictures):
            if index % PICTURES_PER_WORLD == 0:
                if world is not None:
                    world.close()
                world = World(rng, shadows=rng.random() < shadow_share)
            picture = world.picture()
            image, balls = picture.image, picture.balls
            if rng.random() < LETTERBOXED:
                image, balls = letterbox(image, balls, rng)
            parts.append(picture_samples(augment(image, rng), balls, picture.hue_range, rng, work_width))
            if progress is not None:
                progress(1)
    finally:
        if world is not None:
            world.close()
    return Samples.join(parts)


def target_hue_range(image: np.ndarray, balls: list[Ball], width: int = 25) -> tuple[int, int] | None:
    """The colour range a user would set for a photo's balls: ``width`` hues around the median
    hue of their saturated inner pixels; None when they are not colourful (a white ball)."""
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    inside = np.zeros(image.shape[:2], np.uint8)
    for ball in balls:
        cv2.circle(inside, (int(round(ball.u)), int(round(ball.v))), max(1, int(ball.radius * 0.6)), 255, -1)
    pixels = hsv[inside > 0]
    pixels = pixels[(pixels[:, 1] >= 80) & (pixels[:, 2] >= 60)]
    if len(pixels) < 20 or len(pixels) < 0.3 * np.count_nonzero(inside):
        return None
    # (the circular median: hues are rotated so that the largest gap in them is the seam)
    hues = np.sort(pixels[:, 0].astype(int))
    gaps = np.diff(np.concatenate([hues, hues[:1] + 180]))
    shift = int(hues[(int(np.argmax(gaps)) + 1) % len(hues)])
    centre = (int(np.median((hues - shift) % 180)) + shift) % 180
    return (centre - width // 2) % 180, (centre + width - width // 2) % 180


def photo_balls(boxes: list[dict], width: int, height: int) -> list[Ball]:
    """A labelled photo's boxes as balls; a box on the frame edge is a cut ball whose full size
    is its longer side."""
    balls = []
    for box in boxes:
        radius = max(box["w"], box["h"]) / 2.0
        u, v = box["x"] + box["w"] / 2.0 - 0.5, box["y"] + box["h"] / 2.0 - 0.5
        if box["w"] < box["h"] and box["x"] <= 1:
            u = box["x"] + box["w"] - radius - 0.5
        elif box["w"] < box["h"] and box["x"] + box["w"] >= width - 1:
            u = box["x"] + radius - 0.5
        if box["h"] < box["w"] and box["y"] <= 1:
            v = box["y"] + box["h"] - radius - 0.5
        elif box["h"] < box["w"] and box["y"] + box["h"] >= height - 1:
            v = box["y"] + radius - 0.5
        in_frame = min(1.0, box["w"] * box["h"] / (4 * radius * radius) * 4 / math.pi)
        balls.append(Ball(u, v, radius, in_frame=min(1.0, in_frame), visible=1.0))
    return balls


def photo_samples(folder: Path, copies: int, seed: int, progress=None, work_width: int = WORK_WIDTH) -> Samples:
    """Samples of a trainable photo set: each photo ``copies`` times, flipped at random and with
    a fresh draw of the camera effects after the first."""
    if folder.name not in TRAINABLE_SETS:
        raise ValueError(f"{folder}: not a set that may be trained on (those are {', '.join(TRAINABLE_SETS)})")
    rng = np.random.default_rng(seed)
    labels = json.loads((folder / "labels.json").read_text())
    parts = []
    for name in sorted(labels):
        image = cv2.imread(str(folder / name), cv2.IMREAD_COLOR)
        if image is None:
            continue
        height, width = image.shape[:2]
        balls = photo_balls(labels[name], width, height)
        hue_range = target_hue_range(image, balls) if balls else None
        if hue_range is None:
            continue
        for copy in range(copies):
            picture, flipped = image, balls
            if copy and rng.random() < 0.5:
                picture = cv2.flip(image, 1)
                flipped = [Ball(width - 1 - b.u, b.v, b.radius, b.in_frame, b.visible) for b in balls]
            if copy:
                picture = augment(picture, rng)
            parts.append(picture_samples(picture, flipped, hue_range, rng, work_width))
        if progress is not None:
            progress(1)
    return Samples.join(parts)
