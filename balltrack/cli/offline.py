"""``balltrack detect IMAGE...``: the detector offline, one JSON line per image; with ``--explain
U,V``, why a ball at that place was or was not found (see services/detector/explain.py).

SIGINT or SIGTERM stops it after the image in hand (its line printed whole), with status 0.
"""

import json
import math
import sys

from balltrack.common.config import ConfigError, load_config
from balltrack.common.shutdown import stop_on_signals


def command_detect(args) -> int:
    import cv2

    from balltrack.services.detector.config import DetectorConfig
    from balltrack.services.detector.detector import BallDetector
    from balltrack.services.detector.explain import explain_place, summary

    try:
        config = load_config(DetectorConfig, args.config, args.overrides, section="detector")
        places = [parse_place(text) for text in args.explain]
    except (ConfigError, ValueError) as error:
        print(f"balltrack detect: {error}", file=sys.stderr)
        return 2
    detector = BallDetector(config)
    stop = stop_on_signals()
    status = 0
    for path in args.images:
        if stop.is_set():
            break
        image = cv2.imread(path, cv2.IMREAD_COLOR)
        if image is None:
            print(json.dumps({"file": path, "error": "cannot read image"}), flush=True)
            status = 1
            continue
        result, judged = detector.detect_judged(image) if places else (detector.detect(image), [])
        balls = [{"u": round(d.u, 2), "v": round(d.v, 2), "radius_px": round(d.radius_px, 2),
                  "score": round(d.score, 3)} for d in result.detections]
        line = {"file": path, "balls": balls}
        if places:
            explained = [explain_place(image, result, judged, config, u, v) for u, v in places]
            line["explain"] = [{**explanation, "summary": summary(explanation)} for explanation in explained]
        print(json.dumps(line), flush=True)
    return status


def parse_place(text: str) -> tuple[float, float]:
    """``U,V`` (pixels) as two numbers; ValueError with a one-line reason otherwise."""
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        u, v = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"--explain: expected U,V in pixels (e.g. 412,230), got {text!r}") from None
    if not (math.isfinite(u) and math.isfinite(v)):
        raise ValueError(f"--explain: U and V must be finite numbers, got {text!r}")
    return u, v


def register(commands) -> None:
    detect = commands.add_parser("detect", help="run the detector offline on image files")
    detect.add_argument("images", nargs="+", metavar="IMAGE")
    detect.add_argument("--config", metavar="FILE", help="TOML parameter file")
    detect.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE",
                        help="a detector parameter, repeatable")
    detect.add_argument("--explain", action="append", default=[], metavar="U,V",
                        help="say why a ball at pixel (U, V) was or was not found: the colour there "
                             "against the colour tests, and the checks the candidate circle there "
                             "failed (repeatable)")
    detect.set_defaults(handler=command_detect)
