"""Detector cost per 640x480 frame, the balltrack detector against the paper's plain pipeline.

Both run on the same frames in one run, calls alternating (plain, balltrack, plain, ...) so
that whatever else loads the machine loads both alike: simulator renders (chase, multi,
distractors scenarios) and real photos made the 640x480 frames a 4:3 camera would give
(``camera_frame``; every folder of ``--photos``, by default $BALLTRACK_PHOTOS, else ../shared/data
beside the repository, when it exists).
Wall and CPU time per call, median and 90th percentile, the cores called directly (no
transport). OpenCV runs single-threaded (``cv2.setNumThreads(1)``, ``--threads`` to change
it): the goals are a balltrack detector (the configured method's) twice as fast as the plain
pipeline on the renders and 1.5 times as fast on every photo set, on one thread, ratio (wall
p50) = plain / balltrack; on this 2-core machine OpenCV's own threads would share the cores with
everything else. The detector of the other method (learned or rules) takes its turn in the same
calls, and its figures are reported beside (no goal reads them).

The plain pipeline is the paper's (section 2.2): Gaussian blur 5, HSV, CLAHE on V, ``inRange``
with the detector's HSV ranges, ``HoughCircles`` on the mask with the detector's Hough
parameters, no checks.

The renders are timed once more with the machine idle for a frame period (33 ms) before each
call, as a service is between a camera's frames (``PACED_PAUSE``): what a call costs there, with
the caches gone cold, which the demo's latency is made of. No goal reads it.

The photos are timed once more with the balltrack detector shrinking them first to the widths
of ``SHRUNK_WIDTHS`` (its ``work_width``), beside the plain pipeline at full size in the same
calls: what processing fewer pixels would buy (no goal reads it). And with the detector's colour
mask computed only in boxes around that mask's own blobs, found beforehand (``OwnBlobRegions``):
what a coarse colour search that found exactly the ball-coloured blobs and nothing else would
give, the most any such search could save (no goal reads it either).

It then splits the balltrack detector's time by stage (``BallDetector.stage_times``): colour
mask, blobs, acceptance, outline, washed out, over every frame and over the middle fifth of the frames,
the ones its p50 reads; and the plain pipeline's, into its colour mask and its Hough transform
(on the photos the mask is most of it, and the goal leaves the balltrack detector half of it).
The balltrack detector's blobs stage is split once more by blob size (``blob_split``,
``BallDetector.blob_times``): blobs per frame and the time of each, by the longer side of its box.

Example::

    balltrack experiment detector_speed --photos ../shared/data
"""

import dataclasses
import math
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from balltrack.common.arguments import ArgumentParser
from balltrack.common.images import UnreadableImage, read_image
from balltrack.common.terminal import exit_with
from balltrack.services.detector.config import DetectorConfig, Method
from balltrack.services.detector.detector import STAGES, BallDetector, build_detector, compile_kernels
from balltrack.services.detector.learned import STAGES as LEARNED_STAGES
from balltrack.services.detector.regions import Box, blob_boxes

GOAL_RATIO = 2.0
GOAL_SET_RATIO = 1.5
# (width, height) of the frames timed: the issue's, and the simulator camera's.
FRAME_SIZE = (640, 480)
# The renders are timed a second time with the machine idle this long before each call, as a
# service is between frames of a 30 Hz camera. Back to back, a call finds its code and data in
# the CPU's caches from the call before; after a frame period they have gone cold, and each call
# costs more (the balltrack detector's p50 on the renders: 2.26 and 2.55 ms back to back, 2.85
# and 3.30 ms so, in two runs on this project's 2-core machines). The demo's calls are so.
PACED_PAUSE = 1.0 / 30.0


# The photos are timed once more with the balltrack detector shrinking them to these widths
# first (``work_width``), beside the plain pipeline at 640 in the same calls: what processing
# fewer pixels buys (no goal reads it; the photo scores at a width: ``python -m
# balltrack.experiments.real_photos DATA --set work_width=W``).
SHRUNK_WIDTHS = (480, 320)


# The "blobs" stage is split by blob size, the longer side of a blob's box (px): below each
# of these. Large blobs cost the most each; how much of that is their pixels and how much the
# number of steps their search takes is what the split shows.
BLOB_SIZE_LIMITS = (16, 32, 64, 128)


# The plain pipeline's stages, as ``PlainDetector.stage_times`` adds them up: the colour mask
# (blur, HSV, CLAHE, inRange) and the Hough transform on it.
PLAIN_STAGES = ("colour mask", "Hough")


class OwnBlobRegions:
    """The balltrack detector with its colour mask computed only in the boxes of that mask's own
    blobs (``own_blob_boxes``), found beforehand, untimed, for each of ``frames``: as if its
    coarse colour search (``services/detector/regions.py``) found the ball-coloured blobs
    exactly. On the photos that search finds colour that the mask's blur, brightness test and
    opening then leave out, so often that most photos are done whole; this bounds what a better
    search could save. Frames are told apart by identity: only those given are known."""

    def __init__(self, config: DetectorConfig, frames: list[np.ndarray]):
        self.detector = BallDetector(config)
        self._boxes = {id(frame): self._work_boxes(frame) for frame in frames}

    def _work_boxes(self, frame: np.ndarray) -> list[Box]:
        """``own_blob_boxes`` of the frame's mask, in pixels of the frame as the detector
        processes it (see ``BallDetector.work_size``)."""
        height, width = frame.shape[:2]
        mask = self.detector.detect(frame).mask
        work_size = self.detector.work_size(width, height)
        if work_size is not None:
            mask = cv2.resize(mask, work_size, interpolation=cv2.INTER_NEAREST)
        return own_blob_boxes(mask)

    def detect(self, frame: np.ndarray):
        return self.detector.detect(frame, regions=self._boxes[id(frame)])


def own_blob_boxes(mask: np.ndarray) -> list[Box]:
    """The boxes the coarse search would give if it found exactly ``mask``'s blobs: their
    bounding boxes with its margin, merged as it merges its own (``regions.blob_boxes``)."""
    height, width = mask.shape
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return blob_boxes(map(cv2.boundingRect, contours), 1, width, height)


class PlainDetector:
    """The paper's pipeline without this project's checks, for comparison only."""

    def __init__(self, config: DetectorConfig):
        self.config = config
        self._clahe = cv2.createCLAHE(clipLimit=config.clahe_clip_limit or 2.0,
                                      tileGridSize=(config.clahe_tile_grid, config.clahe_tile_grid))
        # When a dict, each call adds the seconds it spent in each of PLAIN_STAGES (as
        # BallDetector.stage_times).
        self.stage_times: dict[str, float] | None = None

    def detect(self, image_bgr: np.ndarray) -> list[tuple[float, float, float]]:
        config = self.config
        started = time.perf_counter()
        blurred = cv2.GaussianBlur(image_bgr, (5, 5), 0)
        hsv = cv2.cvtColor(blurred, cv2.COLOR_BGR2HSV)
        hue, saturation, value = cv2.split(hsv)
        value = self._clahe.apply(value)
        mask = cv2.inRange(cv2.merge((hue, saturation, value)),
                           (config.h_min, config.s_min, config.v_min),
                           (config.h_max, config.s_max, config.v_max))
        max_radius = config.max_radius or min(mask.shape) // 2
        masked = time.perf_counter()
        circles = cv2.HoughCircles(mask, cv2.HOUGH_GRADIENT, dp=config.dp, minDist=config.min_dist,
                                   param1=config.param1, param2=config.param2,
                                   minRadius=config.min_radius, maxRadius=max_radius)
        if self.stage_times is not None:
            for stage, seconds in zip(PLAIN_STAGES, (masked - started, time.perf_counter() - masked)):
                self.stage_times[stage] = self.stage_times.get(stage, 0.0) + seconds
        return [] if circles is None else [tuple(map(float, circle)) for circle in circles[0]]


def simulator_frames(count: int) -> list[np.ndarray]:
    from balltrack.services.simulator.config import SimulatorConfig
    from balltrack.services.simulator.sim import Simulation

    frames = []
    for scenario in ("chase", "multi", "distractors"):
        with Simulation(SimulatorConfig(scenario=scenario)) as simulation:
            for frame in range(count // 3):
                simulation.set_command(0.1, 0.4, simulation.time)
                simulation.step_frame()
                frames.append(cv2.cvtColor(simulation.render(), cv2.COLOR_RGB2BGR))
    return frames


def photo_paths(folder: Path) -> list[Path]:
    """The .jpg and .png files under ``folder``, searched recursively, sorted; but those of the
    sets the learned detector is trained on, unless ``folder`` is one (see
    ``real_photos.photo_sets``)."""
    from balltrack.experiments.real_photos import TRAINABLE_SETS

    return sorted(path for pattern in ("*.jpg", "*.png") for path in folder.rglob(pattern)
                  if photo_set_name(folder, path) not in TRAINABLE_SETS or folder.name in TRAINABLE_SETS)


def named_photo_frames(folder: Path) -> list[tuple[Path, np.ndarray]]:
    """Each readable photo under ``folder`` (see photo_paths) with its path, as a 640x480
    frame (``camera_frame``)."""
    frames = []
    for path in photo_paths(folder):
        try:
            frames.append((path, camera_frame(read_image(path))))
        except UnreadableImage:
            continue  # (a .jpg that is not one: not a photo to time)
    return frames


def camera_frame(image: np.ndarray, size: tuple[int, int] = FRAME_SIZE) -> np.ndarray:
    """A photo as a landscape camera of ``size`` (width, height) would see it, with nothing
    stretched: a portrait photo turned a quarter, its middle cut to the frame's aspect, then
    resized.

    Squeezing a 960x1280 portrait photo into 640x480 made its balls ellipses 1.8 times as
    tall as wide, which no camera delivers: the detector's shape checks then fail and it
    searches each blob's outline, while the plain pipeline's cost does not depend on shape.
    """
    height, width = image.shape[:2]
    if height > width:
        image = cv2.rotate(image, cv2.ROTATE_90_CLOCKWISE)
        height, width = width, height
    target_width, target_height = size
    # (integer cross-multiplication: the cut is whole pixels, centred)
    if width * target_height > height * target_width:
        kept = height * target_width // target_height
        image = image[:, (width - kept) // 2:(width - kept) // 2 + kept]
    elif width * target_height < height * target_width:
        kept = width * target_height // target_width
        image = image[(height - kept) // 2:(height - kept) // 2 + kept]
    shrinking = image.shape[1] >= target_width
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA if shrinking else cv2.INTER_LINEAR)


def photo_set_name(folder: Path, path: Path) -> str:
    """The set a photo under ``folder`` belongs to: its first folder below ``folder`` (the
    folder's own name for photos directly in it)."""
    parts = path.relative_to(folder).parts
    return parts[0] if len(parts) > 1 else folder.name


def figures(wall: list[float], cpu: list[float]) -> dict[str, float]:
    return {"wall_p50_ms": statistics.median(wall), "wall_p90_ms": p90(wall),
            "cpu_p50_ms": statistics.median(cpu), "cpu_p90_ms": p90(cpu)}


def p90(values: list[float]) -> float:
    """The 90th percentile (the one value of a set of one photo timed once)."""
    return statistics.quantiles(values, n=10)[-1] if len(values) > 1 else values[0]


def measure(detectors: dict, frames: list[np.ndarray], repeats: int, pause: float = 0.0,
            groups: list[str] | None = None) -> dict[str, dict[str, float]]:
    """Per detector, the figures of at least ``repeats`` calls, the detectors taking turns on
    each frame; ``pause``: seconds idle before each call (see PACED_PAUSE). ``groups``: a
    group name per frame; the result then also holds, under ``by_group``, each group's figures
    per detector, from the same calls.

    The calls make whole passes over ``frames``, so that every frame counts as often: the
    photos come sorted by folder, and 100 calls on 145 of them timed the first 100 only (the
    10 of real_tennis_dev, on which the plain pipeline's Hough takes up to 400 ms, and none of
    45 indoor photos)."""
    times = {name: ([], []) for name in detectors}
    calls = calls_for(repeats, len(frames))
    for index in range(calls):
        frame = frames[index % len(frames)]
        # Alternate who goes first too: the second call of a pair finds the frame in cache.
        order = list(detectors.items()) if index % 2 == 0 else list(reversed(detectors.items()))
        for name, detector in order:
            if pause:
                time.sleep(pause)  # (not a wait for anything: the gap between camera frames)
            started_wall, started_cpu = time.perf_counter(), time.process_time()
            detector.detect(frame)
            times[name][0].append((time.perf_counter() - started_wall) * 1000)
            times[name][1].append((time.process_time() - started_cpu) * 1000)
    result = {name: figures(*measured) for name, measured in times.items()}
    if groups is not None:
        result["by_group"] = {}
        for group in dict.fromkeys(groups):
            # (call i was on frame i mod the frame count, for every detector)
            mine = [call for call in range(calls) if groups[call % len(frames)] == group]
            result["by_group"][group] = {name: figures([wall[call] for call in mine], [cpu[call] for call in mine])
                                         for name, (wall, cpu) in times.items()}
    return result


def calls_for(repeats: int, frame_count: int) -> int:
    """Calls per detector that ``measure`` makes: whole passes over the frames, at least ``repeats``."""
    return max(1, math.ceil(repeats / frame_count)) * frame_count


NAME = "detector_speed"
# The columns of the speed tables (rows from ``recorded``).
SPEED_HEADERS = ["frames", "count", "plain p50 / p90 (ms)", "balltrack p50 / p90 (ms)", "plain / balltrack"]
TITLE = "Detector speed against the paper's plain pipeline"


def stage_breakdown(detector: BallDetector | PlainDetector, frames: list[np.ndarray], passes: int = 3,
                    stages: tuple[str, ...] = STAGES,
                    blobs: list[tuple[int, float]] | None = None) -> dict[str, dict[str, float]]:
    """Where a detector's time goes: per stage of ``stages`` (those its ``stage_times`` adds
    up), its mean ms per frame over every frame (``all``) and over the middle fifth of the
    frames by their total time (``middle``: the frames a p50 reads). ``passes`` passes over the
    frames in turn (a frame again at once would find its data in the caches), each frame's call
    of median total time; one detector alone (this splits the time, the ratio is measured
    apart). ``blobs``: a list to extend with the ``blob_times`` of those same calls (a
    BallDetector's; see ``blob_split``)."""
    calls: list[list[tuple[float, dict[str, float], list | None]]] = [[] for _ in frames]
    try:
        for _ in range(passes):
            for index, frame in enumerate(frames):
                detector.stage_times = {}
                if blobs is not None:
                    detector.blob_times = []
                detector.detect(frame)
                calls[index].append((sum(detector.stage_times.values()), detector.stage_times,
                                     detector.blob_times if blobs is not None else None))
    finally:
        detector.stage_times = None
        if blobs is not None:
            detector.blob_times = None
    per_frame = sorted((sorted(frame_calls, key=lambda call: call[0])[len(frame_calls) // 2]
                        for frame_calls in calls), key=lambda call: call[0])
    if blobs is not None:
        blobs.extend(blob for _, _, frame_blobs in per_frame for blob in frame_blobs)
    count = len(per_frame)
    middle = per_frame[2 * count // 5:max(2 * count // 5 + 1, 3 * count // 5)]

    def mean_ms(group, stage: str) -> float:
        return 1000 * sum(times.get(stage, 0.0) for _, times, _ in group) / len(group)

    return {stage: {"all": mean_ms(per_frame, stage), "middle": mean_ms(middle, stage)} for stage in stages}


def size_classes() -> list[tuple[str, str, int, float]]:
    """The blob size classes of ``blob_split``: (figure key, label, smallest, limit) for
    the longer side of a blob's box, smallest <= side < limit (px), from BLOB_SIZE_LIMITS."""
    edges = (0, *BLOB_SIZE_LIMITS, math.inf)
    classes = []
    for smallest, limit in zip(edges, edges[1:]):
        if smallest == 0:
            classes.append((f"under_{limit}", f"under {limit} px", smallest, limit))
        elif limit == math.inf:
            classes.append((f"{smallest}_up", f"{smallest} px and more", smallest, limit))
        else:
            classes.append((f"{smallest}_to_{limit - 1}", f"{smallest}-{limit - 1} px", smallest, limit))
    return classes


def blob_split(blobs: list[tuple[int, float]], frame_count: int) -> dict[str, dict[str, float]]:
    """Where the "blobs" stage's time goes, by blob size (``size_classes``): per class, blobs
    per frame, ms per frame and us per blob, of ``blobs`` (side, seconds; those of
    ``stage_breakdown``'s calls on ``frame_count`` frames)."""
    split = {}
    for key, _, smallest, limit in size_classes():
        seconds = [time for side, time in blobs if smallest <= side < limit]
        split[key] = {"per_frame": len(seconds) / frame_count,
                      "ms_per_frame": 1000 * sum(seconds) / frame_count,
                      "us_per_blob": 1e6 * sum(seconds) / len(seconds) if seconds else 0.0}
    return split


def blob_rows(splits: dict[str, dict[str, dict[str, float]]]) -> list[list[str]]:
    """Table rows (size class, then per set: blobs per frame, ms per frame, us per blob) of
    ``blob_split``s."""
    return [[label, *(text for split in splits.values()
                      for text in (f"{split[key]['per_frame']:.2f}", f"{split[key]['ms_per_frame']:.2f}",
                                   f"{split[key]['us_per_blob']:.0f}"))]
            for key, label, _, _ in size_classes()]


def breakdown_rows(breakdowns: dict[str, dict[str, dict[str, float]]],
                   stages: tuple[str, ...] = STAGES) -> list[list[str]]:
    """Table rows (stage, then per set: all frames, middle fifth) of ``stage_breakdown``s."""
    rows = []
    for stage in (*stages, "total"):
        row = [stage]
        for by_stage in breakdowns.values():
            for group in ("all", "middle"):
                value = (sum(times[group] for times in by_stage.values()) if stage == "total"
                         else by_stage[stage][group])
                row.append(f"{value:.2f}")
        rows.append(row)
    return rows


def recorded(result: "ExperimentResult", name: str, count: int, measured: dict[str, dict[str, float]],
             label: str | None = None) -> tuple[list, float]:
    """Record ``measured``'s figures under ``name`` (each detector's, and the ratio plain /
    balltrack of their wall p50s); returns its row of the report's table, and the ratio."""
    for detector_name, figures_of in measured.items():
        for metric, value in figures_of.items():
            result.figure(f"{name}/{detector_name}/{metric}", value)
    plain, ours = measured["plain"], measured["balltrack"]
    ratio = result.figure(f"{name}/ratio", plain["wall_p50_ms"] / ours["wall_p50_ms"])
    return [label or name, count, f"{plain['wall_p50_ms']:.2f} / {plain['wall_p90_ms']:.2f}",
            f"{ours['wall_p50_ms']:.2f} / {ours['wall_p90_ms']:.2f}", f"{ratio:.2f}"], ratio


def stage_table(result: "ExperimentResult", breakdowns: dict[str, dict[str, dict[str, float]]],
                stages: tuple[str, ...], caption: str) -> None:
    """The report's table of ``stage_breakdown``s per set (all frames, middle fifth)."""
    result.table(["stage", *(f"{name}: {group}" for name in breakdowns for group in ("all frames", "middle fifth"))],
                 breakdown_rows(breakdowns, stages), caption)


def method_row(result: "ExperimentResult", name: str, count: int, measured: dict[str, dict[str, float]],
               method: str, other: str, label: str | None = None) -> list:
    """Record the other method's ratio (plain / it, wall p50) under ``name``; returns the row of
    the methods' table: the plain pipeline, the configured method and the other one."""
    plain = measured["plain"]["wall_p50_ms"]
    ours, theirs = measured["balltrack"]["wall_p50_ms"], measured[other]["wall_p50_ms"]
    result.figure(f"{name}/{other}/ratio", plain / theirs)
    result.compare(f"speed against the plain pipeline: {label or name}", "1x (the paper's pipeline)",
                   f"{method} {plain / ours:.2f}x, {other} {plain / theirs:.2f}x (wall p50, one thread)")
    return [label or name, count, f"{plain:.2f}", f"{ours:.2f}", f"{plain / ours:.2f}", f"{theirs:.2f}",
            f"{plain / theirs:.2f}"]


def speed_result(config: DetectorConfig, render_count: int, photos: Path | None, repeats: int,
                 passes: int, threads: int = 1, quick: bool = False) -> "ExperimentResult":
    """Both detectors timed side by side on ``render_count`` simulator renders and the photos
    under ``photos`` (None: renders only), at least ``repeats`` calls each per set (whole passes
    over its frames, see ``measure``), then the balltrack detector's stage split over
    ``passes`` passes; OpenCV on ``threads`` threads. The figures, goals and tables of
    ``balltrack experiment detector_speed`` and of this module's main."""
    from balltrack.experiments.base import ExperimentResult, Stopwatch, record_machine_speed, shown_path

    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, mode="in-process", quick=quick)
    record_machine_speed(result)
    previous_threads = cv2.getNumThreads()
    cv2.setNumThreads(threads)
    try:
        other = next(method for method in Method if method != config.method)
        detectors = {"plain": PlainDetector(config), "balltrack": build_detector(config),
                     str(other): build_detector(dataclasses.replace(config, method=other))}
        compile_kernels()  # (as a service does before its first frame: no call waits for numba)
        sets = {"renders": simulator_frames(render_count)}
        groups = {"renders": None}
        if photos is not None and (named := named_photo_frames(photos)):
            sets["photos"] = [frame for _, frame in named]
            groups["photos"] = [photo_set_name(photos, path) for path, _ in named]
        rows, paced_rows, set_rows, breakdowns, plain_breakdowns, blob_splits = [], [], [], {}, {}, {}
        method_rows, learned_breakdowns = [], {}
        learned = detectors["balltrack"] if config.method == Method.learned else detectors[str(Method.learned)]
        rules = detectors["balltrack"] if config.method == Method.rules else detectors[str(Method.rules)]
        for name, frames in sets.items():
            measured = measure(detectors, frames, repeats, groups=groups[name])
            by_group = measured.pop("by_group", {})
            row, speedup = recorded(result, name, len(frames), measured)
            rows.append(row)
            method_rows.append(method_row(result, name, len(frames), measured, config.method, other))
            for group, group_measured in by_group.items():  # (photos: each set's share of the same calls)
                label = f"{name}: {group}"
                set_row, set_speedup = recorded(result, f"{name}/set/{group}", groups[name].count(group),
                                                group_measured, label)
                set_rows.append(set_row)
                method_rows.append(method_row(result, f"{name}/set/{group}", groups[name].count(group),
                                              group_measured, config.method, other, label))
                plain, ours = group_measured["plain"]["wall_p50_ms"], group_measured["balltrack"]["wall_p50_ms"]
                result.goal(f"{name}/{group}", f"{group} photos (640x480, one thread): the balltrack detector "
                                               f"at least {GOAL_SET_RATIO:g}x as fast as the plain pipeline (wall p50)",
                            f">= {GOAL_SET_RATIO:g}x", f"{set_speedup:.2f}x ({plain:.2f} vs {ours:.2f} ms)",
                            set_speedup >= GOAL_SET_RATIO)
            plain, ours = measured["plain"]["wall_p50_ms"], measured["balltrack"]["wall_p50_ms"]
            if name == "renders":
                result.goal(name, f"{name} (640x480, one thread): the balltrack detector at least "
                                  f"{GOAL_RATIO:g}x as fast as the plain pipeline (wall p50)",
                            f">= {GOAL_RATIO:g}x", f"{speedup:.2f}x ({plain:.2f} vs {ours:.2f} ms)",
                            speedup >= GOAL_RATIO)
            if name == "renders":
                paced = measure(detectors, frames, repeats, pause=PACED_PAUSE)
                paced_rows.append(recorded(result, "renders_paced", len(frames), paced,
                                           f"renders, one call per {1000 * PACED_PAUSE:.0f} ms")[0])
            blobs: list[tuple[int, float]] = []
            breakdowns[name] = stage_breakdown(rules, frames, passes, blobs=blobs)
            learned_breakdowns[name] = stage_breakdown(learned, frames, passes, LEARNED_STAGES)
            plain_breakdowns[name] = stage_breakdown(detectors["plain"], frames, passes, PLAIN_STAGES)
            blob_splits[name] = blob_split(blobs, len(frames))
            for size, figures_of in blob_splits[name].items():
                for metric, value in figures_of.items():
                    result.figure(f"{name}/blobs_by_size/{size}/{metric}", value)
            for kind, split in (("stage", breakdowns), ("plain_stage", plain_breakdowns),
                                ("learned_stage", learned_breakdowns)):
                for stage, times in split[name].items():
                    result.figure(f"{name}/{kind}/{stage}/all_ms", times["all"])
                    result.figure(f"{name}/{kind}/{stage}/middle_ms", times["middle"])
        shrunk_rows = []
        if "photos" in sets:
            shrunk = {"plain": detectors["plain"],
                      **{width: BallDetector(dataclasses.replace(config, work_width=width)) for width in SHRUNK_WIDTHS},
                      "own blobs": OwnBlobRegions(config, sets["photos"])}
            measured = measure(shrunk, sets["photos"], repeats)
            shrunk_rows = [recorded(result, f"photos_at_{width}", len(sets["photos"]),
                                    {"plain": measured["plain"], "balltrack": measured[width]},
                                    f"photos, the balltrack detector at work_width {width}")[0]
                           for width in SHRUNK_WIDTHS]
            shrunk_rows.append(recorded(result, "photos_own_blob_regions", len(sets["photos"]),
                                        {"plain": measured["plain"], "balltrack": measured["own blobs"]},
                                        "photos, the balltrack detector at 640 with its colour mask only "
                                        "in boxes around its own blobs, found beforehand")[0])
        result.table(SPEED_HEADERS, rows + paced_rows,
                     f"Calls alternating on the same frames, in whole passes over each set "
                     f"({', '.join(f'{calls_for(repeats, len(frames))} on the {name}' for name, frames in sets.items())}, "
                     f"per detector), "
                     f"OpenCV on {threads} thread{'s' if threads > 1 else ''}; the goals read the "
                     f"calls back to back. The last row: the renders again, the machine idle "
                     f"{1000 * PACED_PAUSE:.0f} ms before each call, as between a camera's frames "
                     f"(what a service's call costs; no goal):")
        result.table(["frames", "count", "plain p50 (ms)", f"{config.method} p50 (ms)", "plain / it",
                      f"{other} p50 (ms)", "plain / it"], method_rows,
                     "The same calls, both of balltrack's methods (rules: the hand-written checks; learned: "
                     "the network trained in the simulator) beside the plain pipeline:")
        stage_table(result, learned_breakdowns, LEARNED_STAGES,
                    "Where the learned detector's time goes, ms per frame (as below for the rules): colour "
                    "mask, proposals, patches, network (see services/detector/learned.py):")
        if shrunk_rows:
            result.table(SPEED_HEADERS, shrunk_rows,
                         "The photos again, the balltrack detector shrinking each to a smaller width "
                         "first (work_width; the plain pipeline at 640 x 480 in the same calls): what "
                         "processing fewer pixels buys, at a cost in recall that real_photos "
                         "--set work_width=W measures; and, last, with its colour mask computed only "
                         "around the blobs that mask has (as if its coarse colour search found them "
                         "exactly, the most a better search could save; see OwnBlobRegions). No goal:")
        if set_rows:
            result.table(SPEED_HEADERS, set_rows,
                         "The same calls on the photos, set by set (the goal reads all the photos "
                         "together; the sets differ: the plain pipeline's Hough is slow on "
                         "masks full of clutter and quick on clean ones):")
        stage_table(result, breakdowns, STAGES,
                    f"Where the balltrack detector's time goes, ms per frame (the detector alone, {passes} pass{'es' if passes > 1 else ''} "
                     "over the frames, each frame's median call; middle fifth = the frames "
                    "nearest its median, which the p50 reads). Stages: colour mask = steps 1-4, blobs = 5-6, "
                    "acceptance = 7, outline = 8-9, washed out = 10 (see services/detector/detector.py):")
        result.table(["blob size", *(f"{name}: {column}" for name in blob_splits
                                     for column in ("blobs per frame", "ms per frame", "us per blob"))],
                     blob_rows(blob_splits),
                     "The blobs stage by blob size (the longer side of its box; the same calls as "
                     "the stages above). From one class to the next a blob has about 4x the pixels; "
                     "its time grows less than that: much of it is the number of steps its search "
                     "takes (proposals, fits, measurements), not its pixels:")
        stage_table(result, plain_breakdowns, PLAIN_STAGES,
                    "The same for the plain pipeline: its colour mask (blur, HSV, CLAHE, inRange) "
                    "and its Hough transform. The goal leaves the balltrack detector half the "
                    "plain pipeline's time for all its stages:")
        result.settings = {"photos": (f"{shown_path(photos)}, each made a 640x480 frame of a landscape 4:3 camera "
                                      "(portrait turned, wider cut, nothing stretched)") if "photos" in sets else "none",
                           "plain pipeline": "blur 5, HSV, CLAHE on V, inRange, HoughCircles"}
    finally:
        cv2.setNumThreads(previous_threads)
    result.seconds = clock.seconds
    return result


def run(options) -> "ExperimentResult":
    """The ``balltrack experiment detector_speed`` entry point: simulator renders, and the
    photos of ``--photos`` (or the development photos, ``development_photos``) when there are any."""
    from balltrack.experiments.base import development_photos

    photos = options.photos or development_photos()
    return speed_result(options.detector_config(), options.budget(30, 60), photos if photos.is_dir() else None,
                        repeats=60 if options.quick else 300, passes=1 if options.quick else 3,
                        quick=options.quick)


def main(argv: list[str] | None = None) -> int:
    from balltrack.experiments.base import PHOTOS_DEFAULT_TEXT, SHARED_PHOTOS, development_photos

    parser = ArgumentParser(prog="python -m balltrack.experiments.detector_speed",
                            description=__doc__.splitlines()[0])
    parser.add_argument("--photos", type=Path, default=None,
                        help=f"folder of .jpg/.png photos, searched recursively (default {PHOTOS_DEFAULT_TEXT}, "
                             "when it exists)")
    parser.add_argument("--no-photos", action="store_true", help="simulator renders only")
    parser.add_argument("--frames", type=int, default=60, help="simulator renders (default 60)")
    parser.add_argument("--repeats", type=int, default=300, help="calls per detector and set, at least (whole passes over its frames)")
    parser.add_argument("--threads", type=int, default=1,
                        help="OpenCV threads (cv2.setNumThreads; default 1, the goal's single thread)")
    args = parser.parse_args(argv)
    if args.repeats < 10 or args.frames < 3 or args.threads < 1:
        print("detector_speed: --repeats must be at least 10, --frames at least 3 and --threads "
              "at least 1", file=sys.stderr)
        return 2
    photos = None if args.no_photos else development_photos(args.photos)
    if photos is not None and not photos.is_dir():
        # The folder beside the repository may well be absent; one given or named by the variable is a mistake.
        if photos == SHARED_PHOTOS and args.photos is None:
            photos = None
        else:
            print(f"detector_speed: {photos}: not a folder", file=sys.stderr)
            return 2
    if photos is not None and not photo_paths(photos):
        print(f"detector_speed: no .jpg/.png photos under {photos}", file=sys.stderr)
        photos = None
    result = speed_result(DetectorConfig(), args.frames, photos, args.repeats, passes=3, threads=args.threads)
    print("\n\n".join([*result.notes, *result.tables]))
    for goal in result.goals:
        print(f"goal {goal.name}: {goal.achieved} (target {goal.target}): {goal.status}")
    return 0


if __name__ == "__main__":
    exit_with(main)
