"""Score the detector on sets of labelled real photos, beside the paper's plain pipeline.

A set is a folder of images with a ``labels.json`` mapping each file name to a list of boxes
``{x, y, w, h}`` (pixels, top-left corner), one per ball; a folder without one stands for every
subfolder that has one (e.g. ../shared/data: every development set). Scoring, as the sets'
READMEs say:

- a ball counts when its box is at least ``min_ball_px`` (20) pixels wide; as a ball cut by
  the frame edge keeps its full extent along the edge, its size (and radius) is taken from the
  box's longer side;
- a counted ball is found when some detection's centre lies within half the ball's radius of
  the box centre;
- a detection whose centre lies in no box at all (small balls included) is a false positive.

Each set is scored with the balltrack detector (default settings plus any changes), with each of
its two methods (``learned``, ``rules``: the configured one is "balltrack", whose figures the goal
reads), and with the paper's plain pipeline (``detector_speed.PlainDetector``: blur, HSV, CLAHE on V, ``inRange``,
``HoughCircles``, no checks) on the same images; each with recall, false positives per image
and average precision (the area under its precision-recall curve over the detections' scores). Goal of issue 9, per set: recall >= 90 % of
the counted balls and at most 0.20 false positives per image, with one set of settings. How
far a set's figures hold: on other draws of its photos (``resampled``) and on copies of them
nudged in ways no one would see (``nudged``).

Example::

    python -m balltrack.experiments.real_photos ../shared/data
    python -m balltrack.experiments.real_photos ../shared/data/real_tennis_dev --set param2=18
    python -m balltrack.experiments.real_photos ../shared/data --summary --misses
    python -m balltrack.experiments.real_photos ../shared/data --summary --nudged
    balltrack experiment real_photos --photos ../shared/data --out runs/photos

The photos are only read: nothing of them is copied into the output folder but file names and
numbers.
"""

import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from balltrack.common.arguments import ArgumentParser
from balltrack.common.config import ConfigError, load_config
from balltrack.common.images import UnreadableImage, read_image
from balltrack.common.terminal import exit_with
from balltrack.experiments.detector_speed import PlainDetector
from balltrack.experiments.photo_variants import NUDGES, VARIANTS, Variant
from balltrack.services.detector.config import DetectorConfig, Method
from balltrack.services.detector.detector import BallDetector, Detection, build_detector
from balltrack.services.detector.explain import explain_place, finds, summary

# Photo sets whose README allows training on them (../shared/data): the learned detector's
# training reads them (training/data.py), and a folder of sets stands for the others only.
TRAINABLE_SETS = ("train_orange_ball", "train_robocup_ball")
MIN_BALL_PX = 20
GOAL_RECALL = 0.90
GOAL_FALSE_POSITIVES = 0.20
NAME = "real_photos"
TITLE = "Detector on labelled real photos"

Detect = Callable[[np.ndarray], list]


def balltrack_detect(config: DetectorConfig) -> Detect:
    """The balltrack detector (``config.method``'s) as a function of a frame."""
    detector = build_detector(config)
    return lambda image: detector.detect(image).detections


def plain_detect(config: DetectorConfig) -> Detect:
    """The paper's plain pipeline (same HSV and Hough settings) as a function of a frame."""
    detector = PlainDetector(config)
    return lambda image: [Detection(u=x, v=y, radius_px=radius, score=1.0)
                          for x, y, radius in detector.detect(image)]


def photo_sets(folder) -> list[Path]:
    """The labelled sets a folder stands for: itself when it holds labels.json, else each of its
    subfolders that does (sorted) but the sets the learned detector is trained on
    (TRAINABLE_SETS: scoring a detector on its own training photos says nothing of how it does
    on others; name such a set itself to score it); [] when there is none."""
    folder = Path(folder)
    if (folder / "labels.json").is_file():
        return [folder]
    if not folder.is_dir():
        return []
    return sorted(child for child in folder.iterdir()
                  if (child / "labels.json").is_file() and child.name not in TRAINABLE_SETS)


class LabelsError(ValueError):
    """A set's labels.json that is not JSON text; the text names the file."""


def read_labels(folder: Path) -> dict:
    """A labelled set's ``labels.json``: file name -> list of boxes."""
    path = folder / "labels.json"
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise LabelsError(f"{path}: not JSON ({error})") from None


def labelled_image(folder: Path, name: str) -> np.ndarray:
    """The image ``name`` of a labelled set; FileNotFoundError when it is missing or not an
    image (a set's labels name every file they score)."""
    try:
        return read_image(folder / name)
    except UnreadableImage as error:
        raise FileNotFoundError(f"{folder / name}: missing or not an image ({error})") from None


def _box_contains(box: dict, u: float, v: float) -> bool:
    return box["x"] <= u <= box["x"] + box["w"] and box["y"] <= v <= box["y"] + box["h"]


def counted_balls(boxes: list[dict], min_ball_px: int = MIN_BALL_PX) -> list[tuple[float, float, float]]:
    """The centre (u, v) and radius of each labelled ball that counts (see the module's scoring)."""
    return [(box["x"] + box["w"] / 2.0, box["y"] + box["h"] / 2.0, max(box["w"], box["h"]) / 2.0)
            for box in boxes if max(box["w"], box["h"]) >= min_ball_px]


def score_image(boxes: list[dict], detections: list, min_ball_px: int = MIN_BALL_PX) -> dict:
    """Score one image's detections (objects with ``u``, ``v``, ``score``) against its labelled
    boxes; ``outcomes``: per detection, best score first, [score, 1] when it is the first to
    find a counted ball, [score, 0] when it is a false positive (neither: not listed)."""
    counted = counted_balls(boxes, min_ball_px)
    found = 0
    for centre_u, centre_v, radius in counted:
        if any(finds(d.u, d.v, centre_u, centre_v, radius) for d in detections):
            found += 1
    false_positives = sum(1 for d in detections if not any(_box_contains(b, d.u, d.v) for b in boxes))
    outcomes, unmatched = [], list(counted)
    for d in sorted(detections, key=lambda detection: detection.score, reverse=True):
        ball = next((ball for ball in unmatched if finds(d.u, d.v, *ball)), None)
        if ball is not None:
            unmatched.remove(ball)
            outcomes.append([float(d.score), 1])
        elif not any(_box_contains(b, d.u, d.v) for b in boxes):
            outcomes.append([float(d.score), 0])
    return {"labelled": len(counted), "found": found, "false_positives": false_positives, "outcomes": outcomes}


def average_precision(outcomes: list[list], labelled: int) -> float:
    """The area under a set's precision-recall curve (every point, precision made falling):
    ``outcomes`` are all its images' (see ``score_image``), ranked by score together."""
    if labelled == 0:
        return 1.0
    ranked = sorted(outcomes, key=lambda outcome: outcome[0], reverse=True)
    hits = np.cumsum([outcome[1] for outcome in ranked]) if ranked else np.zeros(0)
    precision = hits / np.arange(1, len(ranked) + 1) if ranked else np.zeros(0)
    # (the precision at a recall is the best at that recall or any higher)
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    return float(sum(precision[index] for index, outcome in enumerate(ranked) if outcome[1]) / labelled)


def score_folder(folder, config: DetectorConfig | None = None, detect: Detect | None = None,
                 variant: "Variant | None" = None) -> dict:
    """Run a detector (default: balltrack's with ``config``) over every labelled image in
    ``folder`` and score it; ``variant``: each image and its boxes altered first (see
    ``photo_variants.py``).

    Returns ``recall`` (found / labelled), ``false_positives_per_image``, ``average_precision``, ``found``,
    ``labelled``, ``false_positives``, ``images``, ``median_ms`` (detector time per image) and
    ``files``: per file ``{labelled, found, false_positives, detections: [{u, v, radius_px,
    score}]}``.
    """
    folder = Path(folder)
    labels = read_labels(folder)
    detect = detect or balltrack_detect(config or DetectorConfig())
    files: dict[str, dict] = {}
    timings: list[float] = []
    for name in sorted(labels):
        image = labelled_image(folder, name)
        boxes = labels[name]
        if variant is not None:
            image, boxes = variant(image, boxes)
        started = time.perf_counter()
        detections = detect(image)
        timings.append((time.perf_counter() - started) * 1000.0)
        entry = score_image(boxes, detections)
        entry["detections"] = [{"u": round(d.u, 1), "v": round(d.v, 1),
                                "radius_px": round(d.radius_px, 1), "score": d.score}
                               for d in detections]
        files[name] = entry
    labelled = sum(entry["labelled"] for entry in files.values())
    found = sum(entry["found"] for entry in files.values())
    false_positives = sum(entry["false_positives"] for entry in files.values())
    timings.sort()
    return {
        **rates(labelled, found, false_positives, len(files)),
        "average_precision": average_precision([outcome for entry in files.values() for outcome in entry["outcomes"]],
                                               labelled),
        "found": found,
        "labelled": labelled,
        "false_positives": false_positives,
        "images": len(files),
        "median_ms": timings[len(timings) // 2] if timings else 0.0,
        "files": files,
    }


def rates(labelled: int, found: int, false_positives: int, images: int) -> dict[str, float]:
    """A set's ``recall`` (1 with no counted ball) and ``false_positives_per_image`` (0 with no
    image), from its counts."""
    return {"recall": found / labelled if labelled else 1.0,
            "false_positives_per_image": false_positives / images if images else 0.0}


def meets_goal(scored: dict) -> bool:
    """Issue 9's goal for one set: recall >= GOAL_RECALL, <= GOAL_FALSE_POSITIVES per image."""
    return scored["recall"] >= GOAL_RECALL and scored["false_positives_per_image"] <= GOAL_FALSE_POSITIVES


def learned_not_worse(both: dict) -> bool:
    """Issue 60's rule for making the learned method the default, for one set: it finds at least
    as many of the counted balls as the rules and makes no more false positives per image."""
    learned, rules = both["learned"], both["rules"]
    return (learned["found"] >= rules["found"]
            and learned["false_positives_per_image"] <= rules["false_positives_per_image"])


def default_choice(scores: dict[str, dict]) -> str:
    """The method the rule picks over every set: learned only when it is not worse on each."""
    return "learned" if scores and all(learned_not_worse(both) for both in scores.values()) else "rules"


def fewest_found(labelled: int) -> int:
    """The fewest found balls of ``labelled`` that ``meets_goal`` passes (its recall check;
    started from the goal's share, then moved past float rounding by asking it)."""
    def passes(found: int) -> bool:
        return meets_goal({"recall": found / labelled if labelled else 1.0, "false_positives_per_image": 0.0})

    needed = math.ceil(GOAL_RECALL * labelled)
    while needed > 0 and passes(needed - 1):
        needed -= 1
    while not passes(needed):
        needed += 1
    return needed


def most_false_positives(images: int) -> int:
    """The most false positives on ``images`` images that ``meets_goal`` passes (its false
    positives check; found as ``fewest_found`` is)."""
    if not images:
        return 0

    def passes(false_positives: int) -> bool:
        return meets_goal({"recall": 1.0, "false_positives_per_image": false_positives / images})

    allowed = math.floor(GOAL_FALSE_POSITIVES * images)
    while allowed > 0 and not passes(allowed):
        allowed -= 1
    while passes(allowed + 1):
        allowed += 1
    return allowed


def to_spare(scored: dict) -> tuple[int, int]:
    """How far a set's figures are from the goal: the balls it could miss more, and the false
    positives it could make more, and still meet it (negative: how many it is short). A change
    to the detector that is not exact moved one to seven balls of a development set either way
    in six trials (see the README's real_photos paragraph): what such a change has to clear."""
    return (scored["found"] - fewest_found(scored["labelled"]),
            most_false_positives(scored["images"]) - scored["false_positives"])


# Resampling a set's images (``resampled``): how many same-size sets are drawn, and the seed
# that draws them (the same figures on every run).
RESAMPLES = 2000
RESAMPLE_SEED = 9
# The share of the resampled figures an interval leaves out, half below it and half above.
INTERVAL_OUTSIDE = 0.05


def resampled(scored: dict, resamples: int = RESAMPLES, seed: int = RESAMPLE_SEED) -> dict:
    """How much a set's figures owe to which photos it happens to hold: ``resamples`` sets of
    as many images, drawn with replacement from its scored images (balls, found balls and
    false positives of an image stay together: the balls of one photo share its light and its
    floor), each scored as the set is.

    Returns the 95 % intervals of the recall and of the false positives per image
    (``recall_low``, ``recall_high``, ``false_positives_low``, ``false_positives_high``) and
    ``pass_share``, the share of the drawn sets that ``meets_goal`` passes: about how often a
    larger set of photos like these would pass, were the detector as good on it as on these
    (it was tuned on these, so if anything less often). A set of no image gives its own figures
    and a pass share of 0 or 1."""
    entries = list(scored["files"].values())
    if not entries:
        share = 1.0 if meets_goal(scored) else 0.0
        return {"recall_low": scored["recall"], "recall_high": scored["recall"],
                "false_positives_low": scored["false_positives_per_image"],
                "false_positives_high": scored["false_positives_per_image"], "pass_share": share}
    counts = np.array([[entry["labelled"], entry["found"], entry["false_positives"]] for entry in entries],
                      np.int64)
    drawn = np.random.default_rng(seed).integers(0, len(entries), size=(resamples, len(entries)))
    sums = counts[drawn].sum(axis=1)  # (per drawn set: its counted balls, found balls, false positives)
    drawn_sets = [rates(int(labelled), int(found), int(false_positives), len(entries))
                  for labelled, found, false_positives in sums]
    passed = sum(meets_goal(figures) for figures in drawn_sets)
    tails = (INTERVAL_OUTSIDE / 2, 1 - INTERVAL_OUTSIDE / 2)
    recall_low, recall_high = np.quantile([figures["recall"] for figures in drawn_sets], tails)
    false_positives_low, false_positives_high = np.quantile(
        [figures["false_positives_per_image"] for figures in drawn_sets], tails)
    return {"recall_low": float(recall_low), "recall_high": float(recall_high),
            "false_positives_low": float(false_positives_low),
            "false_positives_high": float(false_positives_high), "pass_share": passed / resamples}


def resampled_text(figures: dict) -> tuple[str, str, str]:
    """``resampled``'s figures as the summary prints them: the recall interval, the false
    positives' interval and the pass share."""
    return (f"{figures['recall_low']:.3f}-{figures['recall_high']:.3f}",
            f"{figures['false_positives_low']:.2f}-{figures['false_positives_high']:.2f}",
            f"{100 * figures['pass_share']:.0f} %")


def nudged(folder, config: DetectorConfig, nudges: dict[str, Variant] | None = None) -> dict:
    """How far a set's balltrack figures hold when its photos are nudged: each scored again
    under each of ``nudges`` (default ``photo_variants.NUDGES``: exposure times 0.97-1.03, the
    frame moved by 1-2 px), changes no one would see. A detector whose decisions keep a margin
    from its thresholds gives about the same figures on every copy; one that passes on the
    photos' exact pixels gives figures that move by balls and false positives, and the photos'
    own figures are then one draw of that spread.

    Returns ``copies`` (per nudge: its ``recall`` and ``false_positives_per_image``), the
    lowest, median and highest of each across the copies (``recall_min``, ``recall_median``,
    ``recall_max``, ``false_positives_min``, ``false_positives_median``,
    ``false_positives_max``) and ``pass_share``: the share of the copies that meet the goal."""
    nudges = NUDGES if nudges is None else nudges
    copies = {name: score_folder(folder, config=config, variant=nudge) for name, nudge in nudges.items()}
    figures: dict = {"copies": {name: {key: scored[key] for key in ("recall", "false_positives_per_image")}
                                for name, scored in copies.items()}}
    for name, key in (("recall", "recall"), ("false_positives", "false_positives_per_image")):
        values = [scored[key] for scored in copies.values()]
        figures.update({f"{name}_min": float(min(values)), f"{name}_median": float(np.median(values)),
                        f"{name}_max": float(max(values))})
    figures["pass_share"] = sum(meets_goal(scored) for scored in copies.values()) / len(copies)
    return figures


def nudged_text(figures: dict) -> tuple[str, str, str]:
    """``nudged``'s figures as tables show them: the recall's lowest, median and highest, the
    same of the false positives per image, and how many copies meet the goal."""
    copies = len(figures["copies"])
    return (f"{figures['recall_min']:.3f} / {figures['recall_median']:.3f} / {figures['recall_max']:.3f}",
            f"{figures['false_positives_min']:.2f} / {figures['false_positives_median']:.2f} / "
            f"{figures['false_positives_max']:.2f}",
            f"{round(figures['pass_share'] * copies)} of {copies}")


NUDGED_HEADERS = ["set", "balltrack: recall, lowest / median / highest",
                  "false positives per image, lowest / median / highest",
                  "nudged copies meeting the goal"]
NUDGED_CAPTION = (f"How far the balltrack figures hold when each set's photos are nudged, {len(NUDGES)} copies "
                  f"({', '.join(NUDGES)}; see nudged):")


def spare_text(scored: dict) -> str:
    balls, false_positives = to_spare(scored)
    return f"{balls:+d} balls, {false_positives:+d} FP"


def score_sets(folders: list[Path], config: DetectorConfig, plain: bool = True,
               variant: Variant | None = None) -> dict[str, dict]:
    """Per set (folder name): ``{"balltrack": score_folder(...), "learned": ..., "rules": ...,
    "plain": ... or None}``: balltrack is the detector ``config`` makes, learned and rules the
    same settings with each method (one of them is balltrack's figures again);
    ``variant``: of altered copies of the photos (see ``score_folder``)."""
    scores = {}
    for folder in folders:
        ours = score_folder(folder, detect=balltrack_detect(config), variant=variant)
        scores[folder.name] = {"balltrack": ours, **{
            str(method): ours if method == config.method else score_folder(
                folder, detect=balltrack_detect(dataclasses.replace(config, method=method)), variant=variant)
            for method in Method},
            "plain": score_folder(folder, detect=plain_detect(config), variant=variant) if plain else None}
    return scores


def _figures(scored: dict | None) -> str:
    if scored is None:
        return "-"
    return (f"{scored['recall']:.3f} ({scored['found']}/{scored['labelled']}), "
            f"FP {scored['false_positives_per_image']:.2f}/image, AP {scored['average_precision']:.2f}")


def summary_rows(scores: dict[str, dict]) -> list[list]:
    """Per set: name, images, counted balls, the learned detector's, the rules' and the plain
    pipeline's figures, balltrack's (the configured method's) distance from the goal
    (``to_spare``) and the goal's verdict."""
    return [[name, both["balltrack"]["images"], both["balltrack"]["labelled"],
             *(_figures(both.get(detector)) for detector in COMPARED), spare_text(both["balltrack"]),
             "PASS" if meets_goal(both["balltrack"]) else "MISS"]
            for name, both in scores.items()]


def resampled_rows(resampled_sets: dict[str, dict]) -> list[list[str]]:
    """Per set: name and the ``resampled_text`` of its ``resampled`` figures."""
    return [[name, *resampled_text(figures)] for name, figures in resampled_sets.items()]


def resampled_balltrack(scores: dict[str, dict]) -> dict[str, dict]:
    """Per set: ``resampled`` of its balltrack figures."""
    return {name: resampled(both["balltrack"]) for name, both in scores.items()}


RESAMPLED_HEADERS = ["set", "balltrack: recall, 95 % interval", "false positives per image, 95 % interval",
                     f"resampled sets meeting the goal (of {RESAMPLES})"]

# The detectors side by side in the summary: balltrack's two methods and the paper's pipeline.
COMPARED = ("learned", "rules", "plain")
SUMMARY_HEADERS = ["set", "images", "balls >= 20 px", "learned: recall, false positives, AP",
                   "rules: recall, false positives, AP", "plain pipeline: recall, false positives, AP",
                   "balltrack: to spare", "goal"]


def run(options) -> "ExperimentResult":
    """The ``balltrack experiment real_photos`` entry point (skipped without ``--photos``)."""
    from balltrack.experiments.base import ExperimentResult, Stopwatch, percent, progress, shown_path

    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, mode="offline", quick=options.quick)
    folders = photo_sets(options.photos) if options.photos is not None else []
    if not folders:
        result.mode = "skipped"
        result.mode_note = "No --photos folder with labelled sets was given."
        result.figure("skipped", True)
        return result
    config = options.detector_config()
    scores = {}
    with progress(total=len(folders), desc=NAME, options=options, unit="set") as bar:
        for folder in folders:
            scores.update(score_sets([folder], config))
            bar.update()
    result.settings = {"photos": shown_path(options.photos), "sets": ", ".join(scores),
                       "counted balls": f"box >= {MIN_BALL_PX} px wide",
                       "found": "a detection centre within half the ball's radius of the box centre",
                       "false positive": "a detection centre in no box",
                       "plain pipeline": "blur 5, HSV, CLAHE on V, inRange, HoughCircles (same settings)"}
    result.figure("skipped", False)
    resampled_sets = resampled_balltrack(scores)
    result.settings["balltrack"] = f"method {config.method}"
    for name, both in scores.items():
        for detector, scored in both.items():
            for key in ("recall", "false_positives_per_image", "average_precision", "found", "labelled",
                        "false_positives", "images", "median_ms"):
                result.figure(f"{name}/{detector}/{key}", scored[key])
        ours = both["balltrack"]
        balls, false_positives = to_spare(ours)
        result.figure(f"{name}/balltrack/balls_to_spare", balls)
        result.figure(f"{name}/balltrack/false_positives_to_spare", false_positives)
        for key, value in resampled_sets[name].items():
            result.figure(f"{name}/balltrack/resampled/{key}", value)
        result.goal(name, f"{name}: recall >= {percent(GOAL_RECALL, 0)} of balls >= {MIN_BALL_PX} px, "
                          f"<= {GOAL_FALSE_POSITIVES:.2f} false positives per image (default settings)",
                    f">= {percent(GOAL_RECALL, 0)}, <= {GOAL_FALSE_POSITIVES:.2f}",
                    f"{percent(ours['recall'])}, {ours['false_positives_per_image']:.2f}", meets_goal(ours))
        result.figure(f"{name}/learned_not_worse", learned_not_worse(both))
        result.compare(f"real photos: {name} ({ours['images']} images)", "future work",
                       "; ".join(f"{method} recall {percent(both[method]['recall'])}, "
                                 f"{both[method]['false_positives_per_image']:.2f} false positives per image, "
                                 f"AP {both[method]['average_precision']:.2f}"
                                 for method in COMPARED if both.get(method) is not None))
    choice = default_choice(scores)
    result.figure("default_choice", choice)
    result.table(["set", "learned at least as good as rules (balls found, false positives per image)"],
                 [[name, "yes" if learned_not_worse(both) else "no"] for name, both in scores.items()],
                 f"Choice of default (issue 60: learned only when it is at least as good on every set): "
                 f"{choice}; configured in this run: {config.method}.")
    result.table(SUMMARY_HEADERS, summary_rows(scores),
                 f"Per set, balltrack's learned detector and its rules beside the paper's plain pipeline on the "
                 f"same photos (AP: average precision over the detections' scores); the goal is the "
                 f"configured method's ({config.method}):")
    result.table(RESAMPLED_HEADERS, resampled_rows(resampled_sets),
                 f"How much the balltrack figures owe to which photos a set holds: {RESAMPLES} sets "
                 f"of as many images drawn with replacement from each (an image's balls stay "
                 f"together), scored alike. The intervals hold the middle 95 % of their figures; "
                 f"the last column, about how often a larger set of such photos would pass, were "
                 f"the detector as good on it as on these, which it was tuned on (see resampled):")
    if not options.quick:
        nudged_sets = {folder.name: nudged(folder, config) for folder in folders}
        for name, figures in nudged_sets.items():
            for key, value in figures.items():
                if key != "copies":
                    result.figure(f"{name}/balltrack/nudged/{key}", value)
        result.table(NUDGED_HEADERS, [[name, *nudged_text(figures)] for name, figures in nudged_sets.items()],
                     NUDGED_CAPTION)
        result.table(["variant"] + list(scores), variant_rows(folders, config),
                     "How the balltrack figures hold up on altered copies of the photos (see "
                     "photo_variants.py; reported only, nothing is tuned on them):")
    for name, both in scores.items():
        result.table(["image", "balls counted", "found", "false positives", "detections (u, v, r)"],
                     [[image, entry["labelled"], entry["found"], entry["false_positives"],
                       " ".join(f"({d['u']:.0f}, {d['v']:.0f}, {d['radius_px']:.0f})"
                                for d in entry["detections"])]
                      for image, entry in both["balltrack"]["files"].items()],
                     f"{name}, balltrack detector per image (median "
                     f"{both['balltrack']['median_ms']:.0f} ms per image):")
    result.seconds = clock.seconds
    return result


def print_images(name: str, scored: dict) -> None:
    print(f"== {name}")
    print(f"{'file':<24}{'balls':>6}{'found':>6}{'FP':>4}  detections (u, v, r, score)")
    for image, entry in scored["files"].items():
        shown = " ".join(f"({d['u']:.0f},{d['v']:.0f},{d['radius_px']:.0f},{d['score']:.2f})"
                         for d in entry["detections"])
        print(f"{image:<24}{entry['labelled']:>6}{entry['found']:>6}{entry['false_positives']:>4}  {shown}")
    print(f"recall {scored['recall']:.3f} ({scored['found']}/{scored['labelled']}), "
          f"false positives per image {scored['false_positives_per_image']:.2f} "
          f"({scored['false_positives']}/{scored['images']}), median {scored['median_ms']:.1f} ms/image")


def missed_balls(folder, config: DetectorConfig, variant: Variant | None = None) -> list[dict]:
    """Every counted ball of a labelled set that the balltrack detector does not find, with why
    (``services/detector/explain.py``): ``{file, u, v, radius_px, summary, explanation}``, in
    file order; ``variant``: in altered copies of the photos (see ``score_folder``)."""
    folder = Path(folder)
    labels = read_labels(folder)
    detector = BallDetector(config)
    missed = []
    for name in sorted(labels):
        image, boxes = labelled_image(folder, name), labels[name]
        if variant is not None:
            image, boxes = variant(image, boxes)
        result, judged = detector.detect_judged(image)
        for centre_u, centre_v, radius in counted_balls(boxes):
            explanation = explain_place(image, result, judged, config, centre_u, centre_v, radius)
            if explanation["found"] is None:
                missed.append({"file": name, "u": explanation["u"], "v": explanation["v"],
                               "radius_px": radius, "summary": summary(explanation),
                               "explanation": explanation})
    return missed


def print_misses(folders: list[Path], config: DetectorConfig, variant: Variant | None = None) -> None:
    for folder in folders:
        missed = missed_balls(folder, config, variant)
        print(f"== {folder.name}: {len(missed)} balls of at least {MIN_BALL_PX} px not found")
        for ball in missed:
            print(f"{ball['file']} ball at ({ball['u']:.0f}, {ball['v']:.0f}), radius {ball['radius_px']:.0f} px: "
                  f"{ball['summary']}")


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.real_photos",
                            description="Score the ball detector on labelled photo sets.")
    parser.add_argument("folders", nargs="+",
                        help="folders with images and labels.json, or folders of such folders")
    parser.add_argument("--config", help="detector TOML config file")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a detector parameter (repeatable)")
    parser.add_argument("--no-plain", action="store_true", help="leave out the plain pipeline")
    parser.add_argument("--summary", action="store_true", help="only the per-set table")
    parser.add_argument("--json", action="store_true", help="print the full result as JSON")
    parser.add_argument("--variants", action="store_true",
                        help="also score altered copies of the photos (mirrored, smaller, exposure, "
                             "white balance, JPEG, noise, specks: see photo_variants.py), balltrack only")
    parser.add_argument("--nudged", action="store_true",
                        help="also score each set's photos nudged (exposure by 1-3 %% either way, moved by 1-2 "
                             "px: how far its figures hold; see nudged), balltrack only")
    parser.add_argument("--misses", action="store_true",
                        help="also list each counted ball the balltrack detector misses, with why "
                             "(the colour there, or the checks its candidate failed)")
    parser.add_argument("--variant", choices=list(VARIANTS), metavar="NAME",
                        help="score (and, with --misses, list the misses of) one altered copy of "
                             "the photos instead of the photos themselves: "
                             + ", ".join(VARIANTS).replace("%", "%%"))  # (argparse formats help with %)
    args = parser.parse_args(argv)
    try:
        config = load_config(DetectorConfig, args.config, args.set, section="detector")
    except ConfigError as error:
        print(f"config error: {error}", file=sys.stderr)
        return 2
    folders = []
    for folder in args.folders:
        if not os.path.exists(folder):
            print(f"{folder}: no such file or folder", file=sys.stderr)
            return 2
        if os.path.isfile(folder):
            # (a set is named by its folder; its labels.json given instead is its folder)
            if os.path.basename(folder) != "labels.json":
                print(f"{folder}: a file, not a folder of photos with a labels.json", file=sys.stderr)
                return 2
            folder = os.path.dirname(folder) or "."
        sets = photo_sets(folder)
        if not sets:
            print(f"{folder}: no labels.json there or in its subfolders (not a labelled photo set)",
                  file=sys.stderr)
            return 2
        folders.extend(sets)
    try:
        variant = VARIANTS[args.variant] if args.variant else None
        scores = score_sets(folders, config, plain=not args.no_plain, variant=variant)
    except (FileNotFoundError, LabelsError) as error:  # (a set whose labels name no image, or are not JSON)
        print(f"real_photos: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(scores, indent=1))
        return 0
    if not args.summary:
        for name, both in scores.items():
            print_images(name, both["balltrack"])
    print(f"{SUMMARY_HEADERS[0]:<20} {SUMMARY_HEADERS[1]:>6} {'balls':>6}  {'learned':<45} {'rules':<45} "
          f"{'plain pipeline':<45} {'to spare':<18} "
          f"goal of {config.method} (recall >= {GOAL_RECALL:.2f}, FP <= {GOAL_FALSE_POSITIVES:.2f}/image)")
    for name, images, balls, learned, rules, plain, spare, goal in summary_rows(scores):
        print(f"{name:<20} {images:>6} {balls:>6}  {learned:<45} {rules:<45} {plain:<45} {spare:<18} {goal}")
    print(f"default by issue 60's rule (learned at least as good as rules on every set): {default_choice(scores)}")
    print(f"\n{'set':<20} {'balltrack: recall, 95 % interval':<34} {'FP per image, 95 % interval':<29} "
          f"resampled sets meeting the goal ({RESAMPLES}, images drawn with replacement)")
    for name, recall, false_positives, share in resampled_rows(resampled_balltrack(scores)):
        print(f"{name:<20} {recall:<34} {false_positives:<29} {share}")
    if args.nudged:
        print_nudged(folders, config)
    if args.variants:
        print_variants(folders, config)
    if args.misses:
        print_misses(folders, config, variant)
    return 0


def variant_rows(folders: list[Path], config: DetectorConfig) -> list[list[str]]:
    """Per variant of the photos (photo_variants.VARIANTS): its name, then each set's balltrack
    figures and the goal's verdict."""
    rows = []
    for variant_name, variant in VARIANTS.items():
        row = [variant_name]
        for folder in folders:
            scored = score_folder(folder, detect=balltrack_detect(config), variant=variant)
            row.append(f"{_figures(scored)} {'PASS' if meets_goal(scored) else 'MISS'}")
        rows.append(row)
    return rows


def print_nudged(folders: list[Path], config: DetectorConfig) -> None:
    print(f"\n{NUDGED_CAPTION}")
    print(f"{'set':<20} {'recall: lowest / median / highest':<36} {'FP per image: lowest / median / highest':<42} "
          f"copies meeting the goal")
    for folder in folders:
        recall, false_positives, passing = nudged_text(nudged(folder, config))
        print(f"{folder.name:<20} {recall:<36} {false_positives:<42} {passing}", flush=True)


def print_variants(folders: list[Path], config: DetectorConfig) -> None:
    print(f"\n{'variant':<14} " + " ".join(f"{folder.name:<36}" for folder in folders))
    for row in variant_rows(folders, config):
        print(f"{row[0]:<14} " + " ".join(f"{cell:<36}" for cell in row[1:]), flush=True)


if __name__ == "__main__":
    exit_with(main)
