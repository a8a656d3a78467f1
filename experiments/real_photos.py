"""Score the detector on a folder of labelled real photos (e.g. the real tennis-ball dev set).

The folder holds images and a ``labels.json`` mapping each file name to a list of boxes
``{x, y, w, h}`` (pixels, top-left corner), one per ball. Scoring, as the data set's README says:

- a ball counts when its box is at least ``min_ball_px`` (20) pixels wide; as a ball cut by
  the frame edge keeps its full extent along the edge, its size (and radius) is taken from the
  box's longer side;
- a counted ball is found when some detection's centre lies within half the ball's radius of
  the box centre;
- a detection whose centre lies in no box at all (small balls included) is a false positive.

Example::

    python -m balltrack.experiments.real_photos /work/shared/data/real_tennis_dev
    python -m balltrack.experiments.real_photos /work/shared/data/real_tennis_dev --set param2=18
    balltrack experiment real_photos --photos /work/shared/data/real_tennis_dev --out runs/photos

As an experiment (``run``) it reports recall and false positives per image with the detector's
default settings (plus any ``--detector`` changes). The photos are only read: nothing of them
is copied into the output folder but file names and numbers.
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import cv2

from balltrack.common.config import ConfigError, load_config
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector

MIN_BALL_PX = 20
NAME = "real_photos"
TITLE = "Detector on labelled real photos"


def _box_contains(box: dict, u: float, v: float) -> bool:
    return box["x"] <= u <= box["x"] + box["w"] and box["y"] <= v <= box["y"] + box["h"]


def score_image(boxes: list[dict], detections: list, min_ball_px: int = MIN_BALL_PX) -> dict:
    """Score one image's detections (objects with ``u``, ``v``) against its labelled boxes."""
    counted = [box for box in boxes if max(box["w"], box["h"]) >= min_ball_px]
    found = 0
    for box in counted:
        centre_u, centre_v = box["x"] + box["w"] / 2.0, box["y"] + box["h"] / 2.0
        radius = max(box["w"], box["h"]) / 2.0
        if any(math.hypot(d.u - centre_u, d.v - centre_v) <= radius / 2.0 for d in detections):
            found += 1
    false_positives = sum(1 for d in detections if not any(_box_contains(b, d.u, d.v) for b in boxes))
    return {"labelled": len(counted), "found": found, "false_positives": false_positives}


def score_folder(folder, config: DetectorConfig | None = None) -> dict:
    """Run the detector over every labelled image in ``folder`` and score it.

    Returns ``recall`` (found / labelled), ``false_positives_per_image``, ``found``,
    ``labelled``, ``false_positives``, ``images``, ``median_ms`` (detector time per image) and
    ``files``: per file ``{labelled, found, false_positives, detections: [{u, v, radius_px,
    score}]}``.
    """
    folder = Path(folder)
    labels = json.loads((folder / "labels.json").read_text())
    detector = BallDetector(config or DetectorConfig())
    files: dict[str, dict] = {}
    timings: list[float] = []
    for name in sorted(labels):
        image = cv2.imread(str(folder / name), cv2.IMREAD_COLOR)
        if image is None:
            raise FileNotFoundError(f"{folder / name}: missing or not an image")
        started = time.perf_counter()
        detections = detector.detect(image).detections
        timings.append((time.perf_counter() - started) * 1000.0)
        entry = score_image(labels[name], detections)
        entry["detections"] = [{"u": round(d.u, 1), "v": round(d.v, 1),
                                "radius_px": round(d.radius_px, 1), "score": d.score}
                               for d in detections]
        files[name] = entry
    labelled = sum(entry["labelled"] for entry in files.values())
    found = sum(entry["found"] for entry in files.values())
    false_positives = sum(entry["false_positives"] for entry in files.values())
    timings.sort()
    return {
        "recall": found / labelled if labelled else 1.0,
        "false_positives_per_image": false_positives / len(files) if files else 0.0,
        "found": found,
        "labelled": labelled,
        "false_positives": false_positives,
        "images": len(files),
        "median_ms": timings[len(timings) // 2] if timings else 0.0,
        "files": files,
    }


def run(options) -> "ExperimentResult":
    """The ``balltrack experiment real_photos`` entry point (skipped without ``--photos``)."""
    from balltrack.experiments.base import ExperimentResult, Stopwatch, percent, progress

    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, mode="offline", quick=options.quick)
    if options.photos is None:
        result.mode = "skipped"
        result.mode_note = "No --photos folder was given."
        result.figure("skipped", True)
        return result
    with progress(total=1, desc=NAME, options=options, unit="folder") as bar:
        scored = score_folder(options.photos, options.detector_config())
        bar.update()
    result.settings = {"folder": str(options.photos), "images": scored["images"],
                       "counted balls": f"box >= {MIN_BALL_PX} px wide",
                       "found": "a detection centre within half the ball's radius of the box centre",
                       "false positive": "a detection centre in no box"}
    result.figure("skipped", False)
    for key in ("recall", "false_positives_per_image", "found", "labelled", "false_positives",
                "images", "median_ms"):
        result.figure(key, scored[key])
    result.table(["image", "balls counted", "found", "false positives", "detections (u, v, r)"],
                 [[name, entry["labelled"], entry["found"], entry["false_positives"],
                   " ".join(f"({d['u']:.0f}, {d['v']:.0f}, {d['radius_px']:.0f})"
                            for d in entry["detections"])]
                  for name, entry in scored["files"].items()],
                 f"Recall {percent(scored['recall'])} ({scored['found']}/{scored['labelled']}), "
                 f"false positives per image {scored['false_positives_per_image']:.2f} "
                 f"({scored['false_positives']} in {scored['images']} images), median "
                 f"{scored['median_ms']:.0f} ms per image. The paper has no real-photo figures "
                 "(its future work):")
    result.compare("real photos", "future work", f"recall {percent(scored['recall'])}, "
                   f"{scored['false_positives_per_image']:.2f} false positives per image "
                   f"({scored['images']} images)")
    result.seconds = clock.seconds
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m balltrack.experiments.real_photos",
                                     description="Score the ball detector on labelled photos.")
    parser.add_argument("folder", help="folder with images and labels.json")
    parser.add_argument("--config", help="detector TOML config file")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a detector parameter (repeatable)")
    parser.add_argument("--json", action="store_true", help="print the full result as JSON")
    args = parser.parse_args(argv)
    try:
        config = load_config(DetectorConfig, args.config, args.set, section="detector")
    except ConfigError as error:
        print(f"config error: {error}", file=sys.stderr)
        return 2
    if not (Path(args.folder) / "labels.json").is_file():
        print(f"{args.folder}: no labels.json there (not a labelled photo folder)", file=sys.stderr)
        return 2
    result = score_folder(args.folder, config)
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    print(f"{'file':<24}{'balls':>6}{'found':>6}{'FP':>4}  detections (u, v, r, score)")
    for name, entry in result["files"].items():
        shown = " ".join(f"({d['u']:.0f},{d['v']:.0f},{d['radius_px']:.0f},{d['score']:.2f})"
                         for d in entry["detections"])
        print(f"{name:<24}{entry['labelled']:>6}{entry['found']:>6}{entry['false_positives']:>4}  {shown}")
    print(f"recall {result['recall']:.3f} ({result['found']}/{result['labelled']}), "
          f"false positives per image {result['false_positives_per_image']:.2f} "
          f"({result['false_positives']}/{result['images']}), median {result['median_ms']:.1f} ms/image")
    return 0


if __name__ == "__main__":
    sys.exit(main())
