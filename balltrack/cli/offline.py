"""The detector offline.

``balltrack detect IMAGE...``: one JSON line per image; with ``--explain U,V``, why a ball at
that place was or was not found (see services/detector/explain.py). SIGINT or SIGTERM stops it
after the image in hand (its line printed whole), with status 0.

``balltrack fit-colour``: the colour range of balls marked on frames, as a detector parameter
file (see services/detector/colour_fit.py). SIGINT or SIGTERM stops it after the image in hand
with one line on stderr and status 1: it prints nothing, so a script that saves its output as
a parameter file does not take an empty file for a fit.
"""

import json
import math
import sys
from pathlib import Path

from balltrack.common.config import ConfigError, load_config
from balltrack.common.shutdown import stop_on_signals


def command_detect(args) -> int:
    from balltrack.common.images import UnreadableImage, read_image
    from balltrack.services.detector.config import DetectorConfig
    from balltrack.services.detector.detector import BallDetector, build_detector
    from balltrack.services.detector.explain import explain_place, summary
    from balltrack.services.detector.mask import check_image

    try:
        config = load_config(DetectorConfig, args.config, args.overrides, section="detector")
        places = [parse_place(text) for text in args.explain]
    except (ConfigError, ValueError) as error:
        print(f"balltrack detect: {error}", file=sys.stderr)
        return 2
    if places and config.method != "rules":
        print("balltrack detect: --explain reads the rules' checks: use it with method=rules", file=sys.stderr)
        return 2
    detector = BallDetector(config) if places else build_detector(config)
    stop = stop_on_signals()
    status = 0
    for path in args.images:
        if stop.is_set():
            break
        try:
            image = read_image(path)
            check_image(image)
        except UnreadableImage as error:
            print(json.dumps({"file": path, "error": f"cannot read image ({error})"}), flush=True)
            status = 1
            continue
        except ValueError as error:  # (smaller than the detector takes: 8 px a side)
            print(json.dumps({"file": path, "error": f"cannot detect in it ({error})"}), flush=True)
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


def command_fit_colour(args) -> int:
    from balltrack.common.images import UnreadableImage, read_image
    from balltrack.experiments.real_photos import counted_balls
    from balltrack.services.detector.colour_fit import ColourSamples, colour_samples, fit_colour
    from balltrack.services.detector.config import DetectorConfig

    def fail(message: str) -> int:
        print(f"balltrack fit-colour: {message}", file=sys.stderr)
        return 2

    try:
        config = load_config(DetectorConfig, args.config, args.overrides, section="detector")
        boxes = [parse_box(text) for text in args.boxes]
        images = marked_images(args.images, boxes, args.labels)
    except (ConfigError, ValueError) as error:
        return fail(str(error))
    stop = stop_on_signals()
    samples = []
    for path, marked in images:
        if stop.is_set():
            print(f"balltrack fit-colour: stopped by a signal after {len(samples)} of {len(images)} "
                  "images; nothing fitted", file=sys.stderr)
            return 1
        try:
            image = read_image(path)
        except UnreadableImage as error:
            return fail(f"{path}: cannot read image ({error})")
        height, width = image.shape[:2]
        for box in marked:
            # (a ball's centre outside the image: a box of another image, or x and y swapped)
            if not (0 <= box["x"] + box["w"] / 2 < width and 0 <= box["y"] + box["h"] / 2 < height):
                return fail(f"{path}: the box {box['x']:g},{box['y']:g},{box['w']:g},{box['h']:g} has its "
                            f"centre outside the {width}x{height} image")
        samples.append(colour_samples(image, counted_balls(marked, min_ball_px=0), config))
    try:
        fit = fit_colour(ColourSamples.joined(samples), config)
    except ValueError as error:
        return fail(str(error))
    print(f"# balltrack fit-colour: {fit.balls} balls ({fit.ball_pixels:,} pixels) in {len(images)} images")
    print(f"# this range admits {100 * fit.ball_admitted:.1f} % of the balls' pixels and "
          f"{100 * fit.other_admitted:.1f} % of the frames' other pixels;")
    print(f"# the configured one (hue {config.h_min}-{config.h_max}, saturation >= {config.s_min}) "
          f"{100 * fit.ball_admitted_before:.1f} % and {100 * fit.other_admitted_before:.1f} %")
    print("[detector]")
    for name, value in fit.changes().items():
        print(f"{name} = {value}")
    return 0


def parse_box(text: str) -> dict:
    """``X,Y,W,H`` (pixels, top-left corner) as a box; ValueError with a one-line reason."""
    try:
        x, y, width, height = (float(part) for part in text.split(","))
    except ValueError:
        raise ValueError(f"--box: expected X,Y,W,H in pixels (e.g. 180,200,60,60), got {text!r}") from None
    if not all(map(math.isfinite, (x, y, width, height))) or width <= 0 or height <= 0:
        raise ValueError(f"--box: X and Y must be finite, W and H positive, got {text!r}")
    return {"x": x, "y": y, "w": width, "h": height}


def marked_images(images: list[str], boxes: list[dict], labels: str | None) -> list[tuple[Path, list[dict]]]:
    """(image, its boxes) pairs: every image given with the ``--box`` boxes, or, from a labels
    file (``{"file name": [{"x", "y", "w", "h"}, ...]}``, the photo sets' format), every image it
    lists beside it; ValueError with a one-line reason when neither or both are given."""
    if labels is None:
        if not images or not boxes:
            raise ValueError("give images and --box X,Y,W,H (the balls in them), or --labels FILE")
        return [(Path(image), boxes) for image in images]
    if images or boxes:
        raise ValueError("--labels lists the images and their boxes: give no images or --box with it")
    try:
        listed = json.loads(Path(labels).read_text())
        pairs = [(Path(labels).parent / name, [dict(box, x=float(box["x"]), y=float(box["y"]),
                                                    w=float(box["w"]), h=float(box["h"])) for box in marked])
                 for name, marked in listed.items()]
    except OSError as error:
        raise ValueError(f"{labels}: cannot read ({error.strerror or error})") from None
    except (ValueError, TypeError, KeyError, AttributeError):
        raise ValueError(f"{labels}: expected {{\"image\": [{{\"x\", \"y\", \"w\", \"h\"}}, ...]}}") from None
    if not pairs:
        raise ValueError(f"{labels}: lists no images")
    return pairs


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
    fit = commands.add_parser("fit-colour", help="the colour range of balls marked on frames, as detector parameters")
    fit.add_argument("images", nargs="*", metavar="IMAGE")
    fit.add_argument("--box", action="append", default=[], dest="boxes", metavar="X,Y,W,H",
                     help="a ball in each IMAGE: its box in pixels, top-left corner (repeatable)")
    fit.add_argument("--labels", metavar="FILE",
                     help="a labels.json of the photo sets' format: the images beside it and their boxes")
    fit.add_argument("--config", metavar="FILE", help="TOML parameter file (the range it is compared with)")
    fit.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE",
                     help="a detector parameter, repeatable")
    fit.set_defaults(handler=command_fit_colour)
