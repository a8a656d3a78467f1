"""Pure ball-detection core (paper section 2.2), used by the detector service and offline tools.

The paper's pipeline, with the checks that make it hold up on real photos; each stage is a
module of this package:

1-4. ``mask.py``: brightness normalisation of dark frames, blur, HSV and CLAHE, the colour
   mask (HSV ranges and a chroma floor) and its morphological clean-up; extremely dark frames
   are classified on wider averages.
5-6 run per mask blob in ``candidates.py``.
5. ``proposals.py``: candidates per mask blob, its enclosing circle and, unless that is already
   a clean isolated ball, Hough circles inside the blob's box and (``arcs.py``) the circles
   of the long round pieces of its outline between concave points or across its waist (a
   ball partly hidden behind another); ``front.py``: circles on the frame's brightness
   whose rim is an edge all round (a ball in front of another, in a blob with no waist).
   ``clusters.py`` reads a blob that is a cluster of touching balls as its member circles.
6. ``fit.py`` refines each candidate by a robust least-squares circle fit to the mask's
   boundary pixels (pixels on the frame border are ignored, so a ball cut by the edge keeps its
   true centre); ``measure.py`` measures it (fill, edge support, leak, colourfulness, hue of
   the mean colour, roundness) and ``checks.py`` judges it; ``highlight.py`` measures a large candidate
   that fails again with the pale, bright pixels around it joined to the mask (a washed-out
   highlight that leaves only a crescent of colour, whose outer arc's circle it proposes);
   ``occlusion.py`` one whose mask ends along a straight edge across its disc with the part
   past that edge hidden (a ball behind a wall).
7. Here: accepted balls are erased from the mask and their neighbours judged again (a ball
   touching a found one, a two-colour ball); what they leave of their blobs is searched as
   any blob is (the rest of a heap). Overlapping circles are suppressed; largest first.
8. ``outline.py``: each accepted ball's circle is replaced by its outline located on the frame
   itself, to a fraction of a pixel. Balls smaller than ``small_radius`` are kept only when
   their outline is found; the others keep the mask's circle when it is not (clutter all
   round, too little of the rim in view), and partly hidden balls keep it always.
9. ``dark.py``: a few rejected candidates with something dark around them get a second look
   for a ball whose unlit side is black.
10. ``pale.py``: a ball washed out by direct sun (saturation below ``s_min``) is found as a
   round blob, alone, of the ball's hue and far more colourful than its surroundings.

No zenoh here: arrays in, dataclasses out. ``annotate.py`` draws the detections;
``explain.py`` says why a place of a frame holds no ball (``detect_judged``'s candidates).

Example::

    import cv2
    from balltrack.services.detector.annotate import annotate
    from balltrack.services.detector.config import DetectorConfig
    from balltrack.services.detector.detector import BallDetector

    detector = BallDetector(DetectorConfig())
    image = cv2.imread("frame.jpg")
    result = detector.detect(image)          # result.detections: largest first
    cv2.imwrite("out.jpg", annotate(image, result.detections))
"""

import dataclasses
import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from balltrack.services.detector.candidates import contour_candidates
from balltrack.services.detector.checks import CandidateMetrics, judge
from balltrack.services.detector.measure import measure_mask
from balltrack.services.detector.clusters import Measured
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.dark import second_look
from balltrack.services.detector.front import may_overlap
from balltrack.services.detector.geometry import Candidate, circle_overlap
from balltrack.services.detector.mask import (EXPLAINED, ColourMasker, ColourPlanes, check_image,
                                              explained_radius)
from balltrack.services.detector.outline import DARK_WIDE_REACH, WIDE_REACH, silhouette
from balltrack.services.detector.pale import pale_balls
from balltrack.services.detector.proposals import FrameSearch, fill_holes, frame_search, leftover_blobs, leftover_search
from balltrack.services.detector.regions import Box

# Rounds of accepting balls and looking again around them.
MAX_ROUNDS = 3
# A ball holds no other ball: a circle mostly (half its area) inside a passing one of at least
# this many times its radius is part of it (a patch between a logo's letters, a piece of rim).
CONTAINED_RATIO = 3.0
# The stages ``BallDetector.stage_times`` adds up (seconds), in the order they run: steps 1-4,
# 5-6, 7, 8-9 and 10 of the pipeline above.
STAGES = ("colour mask", "blobs", "acceptance", "outline", "washed out")


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


@dataclass(frozen=True)
class JudgedCandidate:
    """A circle the detector measured and judged, in pixels of the input frame; ``score`` is
    None when it failed a check (``checks.failed_checks`` says which)."""

    u: float
    v: float
    radius_px: float
    score: float | None
    metrics: CandidateMetrics


class BallDetector:
    """Finds balls of the configured colour in BGR frames of any size.

    Keeps nothing of a frame after the call but scratch planes it reuses; those and its OpenCV
    CLAHE object are not meant to be shared between threads: use one detector per thread.
    Build a new one to change the configuration.
    """

    def __init__(self, config: DetectorConfig | None = None):
        self.config = config if config is not None else DetectorConfig()
        self._masker = ColourMasker(self.config)
        # When a list, every judged candidate is appended as (candidate, metrics, score).
        self._debug: list | None = None
        # When a dict, each call adds the seconds it spent in each of STAGES (profiling: which
        # stage a speed-up must come from; see experiments/detector_speed.py).
        self.stage_times: dict[str, float] | None = None
        # When a list, each blob searched in steps 5-6 appends the longer side of its box (px of
        # the frame as processed) and the seconds its search took (profiling: which blobs the
        # "blobs" stage spends its time on; see experiments/detector_speed.py).
        self.blob_times: list[tuple[int, float]] | None = None
        # Per acceptance round, a frame-size plane kept from call to call for its mask with the
        # accepted balls erased, and the box (left, top, right, bottom) outside which it is
        # still zero (see _explained_plane).
        self._explained_planes: list[np.ndarray] = []
        self._explained_boxes: list[Box] = []

    # ----------------------------------------------------------------------------- public
    def detect(self, image_bgr: np.ndarray, regions: list[Box] | None = None) -> DetectionResult:
        """Detect balls in one frame; ``image_bgr`` is uint8 HxWx3 (HxW grey is accepted).

        ``regions``: boxes (left, top, right, bottom; px of the frame as processed, see
        ``work_size``) to compute the colour mask in, in place of those its coarse search finds
        (``regions.py``); for analysis: ``experiments/detector_speed.py`` times the detector
        with the boxes of each frame's own mask blobs, the most a coarse search could save.
        Frames the regions do not apply to (small, odd-sized, pitch dark) ignore them."""
        started = time.perf_counter()
        image = check_image(image_bgr)
        height, width = image.shape[:2]
        work_size = self.work_size(width, height)
        scale = scale_y = 1.0
        work = image
        if work_size is not None:
            scale, scale_y = work_size[0] / width, work_size[1] / height  # (the work height is rounded)
            work = cv2.resize(image, work_size, interpolation=cv2.INTER_AREA)

        planes = self._masker.planes(work, regions)
        self._lap("colour mask", started)
        candidates = self._find_candidates(planes, scale)
        detections = [Detection(*in_input_frame(c, scale, scale_y), score=round(c.score, 4))
                      for c in candidates]
        mask = planes.mask
        if scale != 1.0:
            mask = cv2.resize(mask, (width, height), interpolation=cv2.INTER_NEAREST)
        return DetectionResult(detections=detections, mask=mask)

    def work_size(self, width: int, height: int) -> tuple[int, int] | None:
        """The (width, height) a frame of this size is shrunk to before processing; None when
        it is processed at its own size (see ``work_width``)."""
        return shrunk_size(width, height, self.config.work_width)

    def detect_judged(self, image_bgr: np.ndarray) -> tuple[DetectionResult, list[JudgedCandidate]]:
        """``detect``, and every candidate circle it judged on the way, once each (its last
        judgement), in pixels of the input frame: what explains a ball that was not found
        (see ``explain.py``)."""
        self._debug = []
        try:
            result = self.detect(image_bgr)
            judged = self._debug
        finally:
            self._debug = None
        height, width = check_image(image_bgr).shape[:2]
        work_size = self.work_size(width, height) or (width, height)
        scale, scale_y = work_size[0] / width, work_size[1] / height
        last = {id(candidate): (candidate, metrics, score) for candidate, metrics, score in judged}
        return result, [JudgedCandidate(*in_input_frame(c, scale, scale_y), score=score, metrics=metrics)
                        for c, metrics, score in last.values()]

    def colour_mask(self, image_bgr: np.ndarray) -> np.ndarray:
        """The cleaned uint8 (0/255) colour mask of a frame, at the frame's size."""
        return self._masker.planes(check_image(image_bgr)).mask

    # ------------------------------------------------------------------------- candidates
    def _lap(self, stage: str, started: float) -> float:
        """Add the time since ``started`` to ``stage`` when profiling; returns the time now."""
        now = time.perf_counter()
        if self.stage_times is not None:
            self.stage_times[stage] = self.stage_times.get(stage, 0.0) + now - started
        return now

    def _find_candidates(self, planes: ColourPlanes, scale: float) -> list[Candidate]:
        started = time.perf_counter()
        contours, shape_mask = fill_holes(planes.mask, planes.extent)
        if not contours:
            started = self._lap("blobs", started)
            return self._with_pale([], planes, started)
        search = frame_search(planes, self.config, scale, shape_mask)
        measured: list[Measured] = []
        for contour in contours:
            blob_started = time.perf_counter()
            measured.extend(contour_candidates(contour, search, shape_mask, self.config))
            if self.blob_times is not None:
                _, _, blob_width, blob_height = cv2.boundingRect(contour)
                self.blob_times.append((max(blob_width, blob_height), time.perf_counter() - blob_started))
        self._lap("blobs", started)
        return self._with_pale(self._accept(measured, search), planes, time.perf_counter())

    def _with_pale(self, balls: list[Candidate], planes: ColourPlanes, started: float) -> list[Candidate]:
        """``balls`` and the washed-out balls found besides them (step 10, see pale.py), largest
        first, at most max_detections."""
        if len(balls) < self.config.max_detections:
            balls = sorted(balls + pale_balls(planes, balls, self.config), key=lambda c: c.radius, reverse=True)
        self._lap("washed out", started)
        return balls[:self.config.max_detections]

    def _accept(self, measured: list[Measured], search: FrameSearch) -> list[Candidate]:
        """Accept candidates best first, then look again around each accepted ball.

        Mask belonging to an accepted ball is not clutter for the balls around it, so after
        each round the accepted balls are erased from the mask: candidates near them are
        measured again, and what is left of their blobs (a ball touching a found one, e.g. a
        two-colour ball against a plain one, the rest of a heap of balls) is searched again as
        any blob is: once its found balls are gone, the rest of a heap may be a plain cluster
        or pair of balls, which its enclosing circle alone would take for one.
        """
        config = self.config
        started = time.perf_counter()
        for candidate, metrics in measured:
            candidate.score = judge(metrics, config) or 0.0
        pending = sorted(without_contained(measured), key=acceptance_order, reverse=True)
        accepted: list[Candidate] = []
        explained, explained_box = search.mask, search.planes.extent
        still: list[Measured] = []
        for _round in range(MAX_ROUNDS):
            newly: list[Candidate] = []
            still = []
            for candidate, metrics in pending:
                score = judge(metrics, config)
                if self._debug is not None:
                    self._debug.append((candidate, metrics, score))
                if score is not None and all(may_overlap(candidate, other) for other in accepted + newly):
                    candidate.score = score
                    candidate.needs_outline = metrics.size < 1.0
                    candidate.partly_hidden = metrics.partly_hidden
                    newly.append(candidate)
                else:
                    still.append((candidate, metrics))
            accepted.extend(newly)
            if not newly or len(accepted) >= config.max_detections:
                break
            explained, explained_box = self._explained_plane(_round, explained, explained_box, newly)
            pending = []
            for candidate, metrics in still:
                if any(math.hypot(candidate.x - ball.x, candidate.y - ball.y)
                       < 1.5 * candidate.radius + ball.radius + 3 for ball in newly):
                    remeasured = measure_mask(candidate, explained)
                    if remeasured is None:
                        continue
                    # (on the colour mask alone: a highlight joined to it is measured once)
                    metrics = dataclasses.replace(metrics, mask=remeasured, highlighted=False, partly_hidden=False)
                pending.append((candidate, metrics))
            pending.extend(self._leftover_candidates(newly, explained, search))
            pending.sort(key=acceptance_order, reverse=True)
        accepted.sort(key=lambda c: c.score, reverse=True)
        accepted = accepted[:config.max_detections]
        started = self._lap("acceptance", started)
        accepted = self._outlines(accepted, still, explained, search)
        self._lap("outline", started)
        accepted.sort(key=lambda c: c.radius, reverse=True)
        return accepted

    def _explained_plane(self, round_index: int, mask: np.ndarray, box: Box | None,
                         balls: list[Candidate]) -> tuple[np.ndarray, Box]:
        """``mask`` with ``balls`` marked EXPLAINED, in the detector's own plane for this
        acceptance round, and the box outside which that plane is zero. ``box``: (left, top,
        right, bottom) outside which ``mask`` is zero (None: anywhere).

        Reused call after call: a fresh frame-size copy in every call costs a page fault per
        4 KB once other code in the process has handed freed memory back to the system (75 per
        640x480 call beside the plain pipeline). Only the box is copied, and only what the
        plane's last use wrote is cleared: a regions mask is zero but for a few boxes, and
        copying all of it moved ~0.6 MB through the caches (~0.13 ms a demo frame 33 ms after
        the last). One plane per round, not one for all: a candidate measured on an earlier
        round's plane may read it later (MeasuredOnFirstRead).
        """
        height, width = mask.shape
        planes, written = self._explained_planes, self._explained_boxes
        while len(planes) <= round_index:
            planes.append(np.empty((0, 0), np.uint8))
            written.append((0, 0, 0, 0))
        plane = planes[round_index]
        if plane.shape != mask.shape:
            plane = planes[round_index] = np.zeros_like(mask)
        left, top, right, bottom = box if box is not None else (0, 0, width, height)
        old_left, old_top, old_right, old_bottom = written[round_index]
        plane[old_top:old_bottom, old_left:old_right] = 0
        plane[top:bottom, left:right] = mask[top:bottom, left:right]
        for ball in balls:
            x, y, radius = int(round(ball.x)), int(round(ball.y)), explained_radius(ball.radius)
            cv2.circle(plane, (x, y), radius, EXPLAINED, -1)
            left, top = max(0, min(left, x - radius)), max(0, min(top, y - radius))
            right, bottom = min(width, max(right, x + radius + 1)), min(height, max(bottom, y + radius + 1))
        written[round_index] = (left, top, right, bottom)
        return plane, written[round_index]

    def _outlines(self, accepted: list[Candidate], rejected: list[Measured],
                  explained: np.ndarray, search: FrameSearch) -> list[Candidate]:
        """Every accepted ball's circle replaced by its outline found on the frame (see
        outline.silhouette); then rejected candidates with a dark side looked at again (see
        dark.second_look)."""
        planes = search.planes
        reach = DARK_WIDE_REACH if planes.dark else WIDE_REACH
        kept: list[Candidate] = []
        for ball in accepted:
            outline = None if ball.partly_hidden else silhouette(
                planes.frame, planes.mask, planes.gain, planes.reference, ball,
                [other for other in accepted if other is not ball], reach)
            if outline is not None:
                ball.x, ball.y, ball.radius = outline
            elif ball.needs_outline:
                continue
            if ball.radius >= search.min_radius:
                kept.append(ball)
        return second_look(rejected, kept, explained, search, self.config, reach, self._debug)

    def _leftover_candidates(self, balls: list[Candidate], explained: np.ndarray,
                             search: FrameSearch) -> list[Measured]:
        """The candidates of the mask pieces left next to freshly accepted balls (see
        _contour_candidates), judged."""
        results: list[Measured] = []
        blobs = leftover_blobs(balls, explained)
        if blobs:
            search = leftover_search(search, explained)
        for contour in blobs:
            found = contour_candidates(contour, search, explained, self.config)
            for candidate, metrics in found:
                candidate.score = judge(metrics, self.config) or 0.0
            results.extend(found)
        return results


def shrunk_size(width: int, height: int, work_width: int) -> tuple[int, int] | None:
    """The (width, height) a frame of this size is shrunk to for ``work_width`` (0: none), its
    aspect kept; None when it is processed at its own size."""
    if not work_width or width <= work_width:
        return None
    return work_width, max(8, round(height * work_width / width))


def in_input_frame(candidate: Candidate, scale: float, scale_y: float) -> tuple[float, float, float]:
    """A candidate's centre and radius in pixels of the input frame, from those of the frame
    shrunk by ``scale`` (x and radius) and ``scale_y`` (y)."""
    # (whole coordinates are pixel centres, and a shrunk pixel's centre is the centre of the
    # input pixels it averages: half a shrunk pixel in, less half an input pixel)
    return (candidate.x + 0.5) / scale - 0.5, (candidate.y + 0.5) / scale_y - 0.5, candidate.radius / scale


def acceptance_order(item: Measured) -> tuple[bool, float]:
    """Sort key of candidates, best first: balls of at least small_radius before smaller ones,
    then by score. A few pixels of colour prove less than a whole ball does, so a speck
    on a ball's rim, however well it scores, must not suppress the ball by overlap."""
    candidate, metrics = item
    return metrics.size >= 1.0, candidate.score


def without_contained(measured: list[Measured]) -> list[Measured]:
    """``measured`` without the circles that lie mostly inside a passing (scored) candidate of
    at least CONTAINED_RATIO times their radius: pieces of one ball's mask (between a logo's
    letters, cut off its rim by a seam) would otherwise outscore and, by overlap, suppress the
    whole ball."""
    passing = [candidate for candidate, _ in measured if candidate.score > 0]
    return [(candidate, metrics) for candidate, metrics in measured
            if not any(outer.radius >= CONTAINED_RATIO * candidate.radius
                       and circle_overlap(candidate, outer) >= 0.5 for outer in passing)]


def compile_kernels() -> float:
    """Compile the detector's compiled functions (see ``jit.py``), or load them from numba's
    cache, by detecting balls in two drawn frames that take every compiled path a frame takes:
    one ball alone and two touching, and a dark frame with a lamp (brightened up to white).
    Returns the seconds it took (10-40 s compiling, ~0.3 s from the cache on this project's
    2-core machines). A service calls it before its first frame
    and ``deploy/setup.sh`` once per install, so that no frame waits for the compiler."""
    started = time.perf_counter()
    frame = np.full((240, 320, 3), (70, 80, 90), np.uint8)
    for centre, radius in (((150, 120), 30), ((235, 130), 18), ((262, 130), 18)):
        cv2.circle(frame, centre, radius, (40, 200, 180), -1, cv2.LINE_AA)
    # and a dark one with a lamp in it, brightened with the lamp's pixels kept short of white
    dark = np.full((240, 320, 3), (4, 5, 6), np.uint8)
    cv2.circle(dark, (60, 60), 8, (200, 210, 220), -1)
    cv2.circle(dark, (200, 150), 25, (3, 14, 12), -1, cv2.LINE_AA)
    detector = BallDetector()
    for image in (frame, dark):
        detector.detect(image)
    return time.perf_counter() - started


def build_detector(config: DetectorConfig | None = None):
    """The detector ``config.method`` names: a :class:`BallDetector` (rules) or a
    ``learned.LearnedDetector``; both have ``detect(image_bgr) -> DetectionResult``."""
    config = config if config is not None else DetectorConfig()
    if config.method == "learned":
        from balltrack.services.detector.learned import LearnedDetector

        return LearnedDetector(config)
    return BallDetector(config)
