"""``balltrack detect IMAGE...``: the detector offline, one JSON line per image."""

import json
import sys

from balltrack.common.config import ConfigError, load_config


def command_detect(args) -> int:
    import cv2

    from balltrack.services.detector.config import DetectorConfig
    from balltrack.services.detector.detector import BallDetector

    try:
        config = load_config(DetectorConfig, args.config, args.overrides, section="detector")
    except ConfigError as error:
        print(f"balltrack detect: {error}", file=sys.stderr)
        return 2
    detector = BallDetector(config)
    status = 0
    for path in args.images:
        image = cv2.imread(path, cv2.IMREAD_COLOR)
        if image is None:
            print(json.dumps({"file": path, "error": "cannot read image"}), flush=True)
            status = 1
            continue
        detections = detector.detect(image).detections
        balls = [{"u": round(d.u, 2), "v": round(d.v, 2), "radius_px": round(d.radius_px, 2),
                  "score": round(d.score, 3)} for d in detections]
        print(json.dumps({"file": path, "balls": balls}), flush=True)
    return status



def register(commands) -> None:
    detect = commands.add_parser("detect", help="run the detector offline on image files")
    detect.add_argument("images", nargs="+", metavar="IMAGE")
    detect.add_argument("--config", metavar="FILE", help="TOML parameter file")
    detect.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE",
                        help="a detector parameter, repeatable")
    detect.set_defaults(handler=command_detect)
