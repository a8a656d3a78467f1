"""The learned detector: colour-mask proposals judged and refined by a small network.

Stages:

1. Colour mask: ``mask.py``'s (brightness normalisation, blur, HSV range, clean-up), so the
   target's colour stays a setting.
2. Proposals (``propose``), on the colour mask joined with its pale plane (the ball's hue
   at saturations down to ``pale_s_min``: felt washed out by direct sun): each blob's bounding
   circle, and the peaks of its distance transform, the centres of the largest discs that fit
   in it (touching balls, a ball beside clutter, a ball partly hidden).
3. Patches (``patches``): a square of ``CONTEXT`` radii around each proposal, resampled to
   ``PATCH`` x ``PATCH``, as four planes that carry no hue of their own: brightness (normalised
   per patch), chroma, the colour mask, and where the hue lies within the configured range
   (its middle or near an end). The network judges shape, shading and texture; which hue counts
   is the user's setting.
4. The network (``BallNetwork``, an ONNX model run by onnxruntime or OpenCV's dnn module) gives each patch the
   probability that a ball is centred on it and the correction of its centre and radius.
5. Suppression: best first, a circle whose centre lies inside a kept one's is dropped.

No zenoh and no torch here: training lives in ``balltrack.training``.
"""

import math
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import Detection, DetectionResult, shrunk_size
from balltrack.services.detector.mask import ColourMasker, check_image

# Side (px) of the square a proposal is resampled to, and its half-side in radii of the proposal:
# the ring beyond the rim shows whether the disc stands alone.
PATCH = 32
CONTEXT = 1.6
PLANES = 4
# The hue plane: a hue at the middle of the configured range, and one at either end of it.
HUE_MIDDLE = 128
HUE_SCALE = 50
# The committed model (written by ``balltrack train``).
MODEL_PATH = Path(__file__).with_name("models") / "ball_network.onnx"
# A distance-transform peak this close to the blob's bounding circle (in its radii, and in
# radius ratio) is that circle again.
SAME_PROPOSAL = 0.25
# The mask is searched at this fraction of the processed frame's size (cost), and at most this
# many of its distance-transform peaks are looked at.
SEARCH_SCALE = 2
PEAK_CANDIDATES = 400
# A distance-transform peak is a pixel at least as far from the mask's edge as its 8 neighbours.
PEAK_KERNEL = np.ones((3, 3), np.uint8)
# Proposals per frame (largest blobs first): bounds the network's work on cluttered frames.
MAX_PROPOSALS = 96
# The pale plane is speckled (grey surfaces have pixels of every hue at low saturation).
PALE_OPENING = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
# The model's metadata key for the width its training pictures were processed at: the detector
# shrinks wider frames to it (as to work_width), so that balls look to the network as they did.
WORK_WIDTH_KEY = "work_width"
# The stages ``LearnedDetector.stage_times`` adds up (seconds): steps 1, 2, 3 and 4-5 above.
STAGES = ("colour mask", "proposals", "patches", "network")
# Two detections are one ball when one's centre lies within this share of the larger radius of
# the other's.
SAME_BALL = 0.7


@dataclass(frozen=True)
class Proposal:
    """A circle to judge, in pixels of the frame as processed."""

    x: float
    y: float
    radius: float


def propose(mask: np.ndarray, min_radius: float, max_radius: float,
            limit: int = MAX_PROPOSALS) -> list[Proposal]:
    """Proposals from a 0/255 mask (see the module's step 2), largest first. The mask is
    searched at 1 / SEARCH_SCALE of its size; circles are given at its own."""
    height, width = mask.shape[:2]
    small = cv2.resize(mask, (max(1, width // SEARCH_SCALE), max(1, height // SEARCH_SCALE)),
                       interpolation=cv2.INTER_AREA)
    small = cv2.threshold(small, 127, 255, cv2.THRESH_BINARY)[1]
    min_small, max_small = min_radius / SEARCH_SCALE, max_radius / SEARCH_SCALE
    _, _, stats, _ = cv2.connectedComponentsWithStats(small, connectivity=8, ltype=cv2.CV_16U)
    stats = stats[1:]
    sides = np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    radii = sides / 2.0
    keep = ((sides >= 2.0 * min_small * 0.8) & (radii <= max_small * 1.2)
            & (stats[:, cv2.CC_STAT_AREA] >= math.pi * min_small * min_small * 0.5))
    stats, radii = stats[keep], radii[keep]
    circles = np.stack([stats[:, 0] + stats[:, 2] / 2.0 - 0.5, stats[:, 1] + stats[:, 3] / 2.0 - 0.5, radii], axis=1)
    # Distance-transform peaks, best first, each outside the discs of those already taken;
    # only the PEAK_CANDIDATES highest are looked at (a wide blob's ridge is many pixels long).
    distance = cv2.distanceTransform(small, cv2.DIST_L2, 3)
    peaks = (distance >= max(min_small, 1.0)) & (distance >= cv2.dilate(distance, PEAK_KERNEL))
    rows, columns = np.nonzero(peaks)
    values = distance[rows, columns]
    if len(values) > PEAK_CANDIDATES:
        highest = np.argpartition(-values, PEAK_CANDIDATES)[:PEAK_CANDIDATES]
        rows, columns, values = rows[highest], columns[highest], values[highest]
    order = np.argsort(-values, kind="stable")
    rows, columns, values = rows[order].astype(np.float32), columns[order].astype(np.float32), values[order]
    alive = values <= max_small
    taken = []
    while alive.any() and len(taken) < limit:
        index = int(np.argmax(alive))
        x, y, radius = float(columns[index]), float(rows[index]), float(values[index])
        taken.append((x, y, radius))
        alive &= (columns - x) ** 2 + (rows - y) ** 2 > radius * radius
    circles = circles[np.argsort(-circles[:, 2], kind="stable")][:limit]
    if taken:
        peaks = np.array(taken, np.float64)
        # (a peak at a blob's own bounding circle is that circle again)
        offsets = np.abs(peaks[:, None, :2] - circles[None, :, :2]).max(axis=2) / circles[None, :, 2]
        ratios = np.abs(np.log(peaks[:, None, 2] / circles[None, :, 2]))
        again = ((offsets <= SAME_PROPOSAL) & (ratios <= SAME_PROPOSAL)).any(axis=1)
        circles = np.concatenate([circles, peaks[~again]])
    circles = circles[np.argsort(-circles[:, 2], kind="stable")][:limit]
    # (a pixel of the small mask covers SEARCH_SCALE of the mask's, centre on centre)
    return [Proposal(SEARCH_SCALE * (float(x) + 0.5) - 0.5, SEARCH_SCALE * (float(y) + 0.5) - 0.5,
                     SEARCH_SCALE * float(radius)) for x, y, radius in circles]


def feature_planes(frame_bgr: np.ndarray, chroma: np.ndarray, mask: np.ndarray,
                   hue_range: tuple[int, int]) -> np.ndarray:
    """The planes patches are cut from, H x W x PLANES uint8: brightness, chroma (max - min
    channel), the colour mask, and where each pixel's hue lies in the configured range
    (HUE_MIDDLE at its middle, HUE_MIDDLE -+ HUE_SCALE at its ends, clipped). None of them
    carries a hue of its own: the last is relative to the range the user set."""
    low, high = hue_range
    width = (high - low) % 180 or 180
    hue = cv2.extractChannel(cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2HSV), 0)
    # (hue distance from the range's middle, through the wrap at 180, in half-widths of the range)
    offset = cv2.subtract(hue, np.full_like(hue, round((low + width / 2.0) % 180)), dtype=cv2.CV_16S)
    offset = (offset + 270) % 180 - 90
    position = np.clip(HUE_MIDDLE + offset * (HUE_SCALE / (width / 2.0)), 0, 255).astype(np.uint8)
    return cv2.merge((cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2GRAY), chroma, mask, position))


def patches(features: np.ndarray, proposals: list[Proposal]) -> np.ndarray:
    """The network's input for each proposal: N x PLANES x PATCH x PATCH float32 (see the
    module's step 3): a square of CONTEXT radii around it, resampled; parts beyond the frame
    are zero. Brightness is normalised per patch, chroma and mask scaled to 0-1, the hue
    position to -1..1 across the range."""
    cut = np.zeros((len(proposals), PATCH, PATCH, PLANES), np.uint8)
    height, width = features.shape[:2]
    for index, proposal in enumerate(proposals):
        half = CONTEXT * proposal.radius
        left, top = int(round(proposal.x - half)), int(round(proposal.y - half))
        side = max(2, int(round(2 * half)) + 1)
        right, bottom = left + side, top + side
        inside = features[max(0, top):min(height, bottom), max(0, left):min(width, right)]
        if inside.size == 0:
            continue
        if left < 0 or top < 0 or right > width or bottom > height:
            inside = cv2.copyMakeBorder(inside, max(0, -top), max(0, bottom - height), max(0, -left),
                                        max(0, right - width), cv2.BORDER_CONSTANT, value=0)
        cut[index] = cv2.resize(inside, (PATCH, PATCH),
                                interpolation=cv2.INTER_AREA if side > PATCH else cv2.INTER_LINEAR)
    out = cut.transpose(0, 3, 1, 2).astype(np.float32)
    brightness = out[:, 0]
    mean = brightness.mean(axis=(1, 2), keepdims=True)
    spread = brightness.std(axis=(1, 2), keepdims=True)
    out[:, 0] = (brightness - mean) / (spread + 8.0)
    out[:, 1:3] *= 1.0 / 255.0
    out[:, 3] = (out[:, 3] - HUE_MIDDLE) / HUE_SCALE
    return out


class BallNetwork:
    """The ONNX network: patches in, (probability, dx, dy, log radius ratio) out; dx and dy are
    in radii of the proposal. ``runtime``: onnxruntime (the default: about twice as fast as
    OpenCV's dnn module on this network's batches, one thread each) or opencv."""

    RUNTIMES = ("onnxruntime", "opencv")

    def __init__(self, path: Path | str = MODEL_PATH, runtime: str = "onnxruntime"):
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no model (train one with `balltrack train`)")
        if runtime not in self.RUNTIMES:
            raise ValueError(f"runtime: one of {', '.join(self.RUNTIMES)}, got {runtime!r}")
        self.path, self.runtime = path, runtime
        if runtime == "onnxruntime":
            import onnxruntime

            options = onnxruntime.SessionOptions()
            # (one thread, as the rest of the detector: the other core is the camera's and Zenoh's)
            options.intra_op_num_threads = options.inter_op_num_threads = 1
            self._session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
            self._input = self._session.get_inputs()[0].name
            metadata = self._session.get_modelmeta().custom_metadata_map
        else:
            self._net = cv2.dnn.readNetFromONNX(str(path))
            import onnxruntime

            metadata = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"]
                                                    ).get_modelmeta().custom_metadata_map
        # The width the model's pictures were processed at (0: not recorded).
        self.work_width = int(metadata.get(WORK_WIDTH_KEY, 0))

    def __call__(self, batch: np.ndarray) -> np.ndarray:
        if len(batch) == 0:
            return np.zeros((0, 4), np.float32)
        if self.runtime == "onnxruntime":
            out = self._session.run(None, {self._input: np.ascontiguousarray(batch, np.float32)})[0]
        else:
            self._net.setInput(batch)
            out = self._net.forward()
        out = np.array(out, np.float32).reshape(len(batch), 4)
        out[:, 0] = 1.0 / (1.0 + np.exp(-out[:, 0]))
        return out


@dataclass(frozen=True)
class LearnedBall:
    """A ball the network accepted, in pixels of the frame as processed."""

    x: float
    y: float
    radius: float
    score: float


def refine(proposals: list[Proposal], outputs: np.ndarray) -> list[LearnedBall]:
    """Each proposal moved and resized as the network says, with its probability."""
    return [LearnedBall(p.x + float(dx) * p.radius, p.y + float(dy) * p.radius,
                        p.radius * math.exp(float(np.clip(log_ratio, -1.5, 1.5))), float(probability))
            for p, (probability, dx, dy, log_ratio) in zip(proposals, outputs)]


def suppress(balls: list[LearnedBall], min_score: float, limit: int) -> list[LearnedBall]:
    """Balls of at least ``min_score``, best first, without a second detection of one ball."""
    kept: list[LearnedBall] = []
    for ball in sorted((b for b in balls if b.score >= min_score), key=lambda b: b.score, reverse=True):
        if all(math.hypot(ball.x - other.x, ball.y - other.y) > SAME_BALL * max(ball.radius, other.radius)
               for other in kept):
            kept.append(ball)
            if len(kept) >= limit:
                break
    return kept


class LearnedDetector:
    """Finds balls of the configured colour with the learned network (see the module doc).
    One instance per thread (its masker holds OpenCV objects)."""

    def __init__(self, config: DetectorConfig | None = None, network: BallNetwork | None = None):
        self.config = config if config is not None else DetectorConfig()
        self._masker = ColourMasker(self.config)
        self.network = network if network is not None else BallNetwork()
        # When a dict, each call adds the seconds it spent in each of STAGES (profiling, see
        # experiments/detector_speed.py).
        self.stage_times: dict[str, float] | None = None

    def work_frame(self, image_bgr: np.ndarray) -> tuple[np.ndarray, float, float]:
        """The frame as processed (shrunk to ``work_width``, or to the model's own when that is
        narrower) and its x and y scales."""
        image = check_image(image_bgr)
        height, width = image.shape[:2]
        limits = [limit for limit in (self.config.work_width, getattr(self.network, "work_width", 0)) if limit]
        size = shrunk_size(width, height, min(limits) if limits else 0)
        if size is None:
            return image, 1.0, 1.0
        return cv2.resize(image, size, interpolation=cv2.INTER_AREA), size[0] / width, size[1] / height

    def proposals(self, work: np.ndarray) -> tuple[list[Proposal], np.ndarray]:
        """Proposals of a processed frame and the planes patches are cut from."""
        started = time.perf_counter()
        planes = self._masker.planes(work, whole=True)
        searched = planes.mask
        if planes.pale is not None:
            searched = cv2.morphologyEx(planes.mask | planes.pale, cv2.MORPH_OPEN, PALE_OPENING)
        features = feature_planes(planes.frame, planes.chroma, planes.mask,
                                  (self.config.h_min, self.config.h_max))
        started = self._lap("colour mask", started)
        max_radius = self.config.max_radius or min(work.shape[:2]) / 2.0
        proposals = propose(searched, self.config.min_radius, max_radius)
        self._lap("proposals", started)
        return proposals, features

    def _lap(self, stage: str, started: float) -> float:
        """Add the time since ``started`` to ``stage`` when profiling; returns the time now."""
        now = time.perf_counter()
        if self.stage_times is not None:
            self.stage_times[stage] = self.stage_times.get(stage, 0.0) + now - started
        return now

    def detect(self, image_bgr: np.ndarray) -> DetectionResult:
        """Balls in pixels of the input frame, largest first, and the colour mask (at the
        frame's size)."""
        image = check_image(image_bgr)
        work, scale, scale_y = self.work_frame(image)
        proposals, features = self.proposals(work)
        started = time.perf_counter()
        batch = patches(features, proposals)
        started = self._lap("patches", started)
        outputs = self.network(batch)
        found = suppress(refine(proposals, outputs), self.config.min_score, self.config.max_detections)
        detections = sorted((Detection(u=(b.x + 0.5) / scale - 0.5, v=(b.y + 0.5) / scale_y - 0.5,
                                       radius_px=b.radius / scale, score=round(b.score, 4)) for b in found),
                            key=lambda detection: detection.radius_px, reverse=True)
        mask = np.ascontiguousarray(features[..., 2])
        if scale != 1.0:
            mask = cv2.resize(mask, image.shape[1::-1], interpolation=cv2.INTER_NEAREST)
        self._lap("network", started)
        return DetectionResult(detections=detections, mask=mask)
