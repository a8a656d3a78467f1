"""Every output of the ball detector on a set of frames, recorded once and compared after a change.

A change that only makes the detector faster must change no output. ``record`` writes, for
each frame, every detection (u, v, radius, score), every candidate circle judged on the way
(``BallDetector.detect_judged``: u, v, radius, and its score or its rejection) and the colour
mask's pixel count, as JSON (its floats written exactly). ``compare`` runs the detector again
on the same frames and names each frame whose outputs differ, exiting 1 if any does: a speed-up
is then shown to be the same computation, to the bit.

Frames: the photos under ``--photos`` (at 640x480, as ``detector_speed`` reads them), every
``--every``-th camera frame of ``--recording`` (an .mcap, e.g. a demo's run.mcap) and
``--renders`` simulator renders (``detector_speed``'s). ``compare`` reads the same sources,
which the recording names.

Example::

    python -m balltrack.experiments.detector_outputs record before.json \\
        --photos ../shared/data --recording runs/demo-X/run.mcap --every 2 --renders 60
    # ... change the detector ...
    python -m balltrack.experiments.detector_outputs compare before.json
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from balltrack.common.arguments import ArgumentParser, integer
from balltrack.common.messages import MessageError
from balltrack.common.recording import RecordingError
from balltrack.common.terminal import exit_with, print_lines

FORMAT = "balltrack detector outputs 1"
# How many differing frames ``compare`` describes (it counts them all).
SHOWN_DIFFERENCES = 5


def frames_of(sources: dict) -> list[tuple[str, np.ndarray]]:
    """(name, BGR frame) of every frame the sources give, in a fixed order."""
    from balltrack.experiments.detector_speed import named_photo_frames, simulator_frames

    frames = []
    if sources.get("photos"):
        folder = Path(sources["photos"])
        if not folder.is_dir():
            raise OSError(f"{folder}: no such folder of photos")
        # (named by their own paths: an unreadable file is left out, not shifting the names)
        frames.extend((f"photo {path.relative_to(folder).as_posix()}", frame)
                      for path, frame in named_photo_frames(folder))
    if sources.get("recording"):
        frames.extend(recording_frames(Path(sources["recording"]), sources["every"]))
    if sources.get("renders"):
        frames.extend((f"render {index}", frame) for index, frame in enumerate(simulator_frames(sources["renders"])))
    return frames


def recording_frames(path: Path, every: int) -> list[tuple[str, np.ndarray]]:
    """Every ``every``-th camera frame (``image_raw``) of a recording, decoded to BGR."""
    from balltrack.common.images import image_to_bgr
    from balltrack.common.messages import decode
    from balltrack.common.recording import RecordingFile

    if not path.is_file():
        raise OSError(f"{path}: no such recording")
    frames = []
    images = (message for message in RecordingFile(path).messages()
              if message.message_type == "Image" and message.key.endswith("image_raw"))
    for index, message in enumerate(images):
        if index % every == 0:
            frames.append((f"{path.name} frame {index}", image_to_bgr(decode("Image", message.payload))))
    return frames


def outputs(frames: list[tuple[str, np.ndarray]]) -> list[dict]:
    """Per frame: its name, detections, judged candidates (sorted) and mask pixel count."""
    from balltrack.services.detector.detector import BallDetector

    detector = BallDetector()
    results = []
    for name, frame in frames:
        result, judged = detector.detect_judged(frame)
        results.append({
            "frame": name,
            "detections": [[found.u, found.v, found.radius_px, found.score] for found in result.detections],
            "candidates": sorted([[candidate.u, candidate.v, candidate.radius_px, candidate.score]
                                  for candidate in judged], key=lambda item: (item[:3], item[3] is None, item[3] or 0.0)),
            "mask_pixels": int(np.count_nonzero(result.mask == 255)),
        })
    return results


def differences(recorded: list[dict], now: list[dict]) -> list[str]:
    """One line per frame whose outputs differ (or that one side lacks)."""
    lines = []
    for index in range(max(len(recorded), len(now))):
        before = recorded[index] if index < len(recorded) else None
        after = now[index] if index < len(now) else None
        if before is None or after is None or before["frame"] != after["frame"]:
            lines.append(f"frame {index}: {before and before['frame']!r} recorded, {after and after['frame']!r} now")
            continue
        what = [part for part in ("detections", "candidates", "mask_pixels") if before[part] != after[part]]
        if what:
            line = f"{after['frame']}: {', '.join(what)} differ"
            if "detections" in what:
                line += f" (recorded {before['detections']}, now {after['detections']})"
            lines.append(line)
    return lines


def record_or_compare(args: argparse.Namespace) -> tuple[int, list[str]]:
    """``main``'s work: the exit status and the lines to print."""
    if args.action == "record":
        sources = {"photos": args.photos, "recording": args.recording, "every": args.every,
                   "renders": args.renders}
        results = outputs(frames_of(sources))
        args.file.write_text(json.dumps({"format": FORMAT, "sources": sources, "frames": results}))
        return 0, [f"detector_outputs: recorded {len(results)} frames in {args.file}"]
    try:
        recorded = json.loads(args.file.read_text())
    except ValueError:
        raise OSError(f"{args.file}: not a detector outputs file (not JSON)") from None
    if not isinstance(recorded, dict) or recorded.get("format") != FORMAT:
        raise OSError(f"{args.file}: not a detector outputs file")
    lines = differences(recorded["frames"], outputs(frames_of(recorded["sources"])))
    report = [f"detector_outputs: {len(recorded['frames'])} frames, {len(lines)} differ",
              *lines[:SHOWN_DIFFERENCES]]
    if len(lines) > SHOWN_DIFFERENCES:
        report.append(f"... and {len(lines) - SHOWN_DIFFERENCES} more")
    return (1 if lines else 0), report


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.detector_outputs", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("action", choices=("record", "compare"))
    parser.add_argument("file", type=Path, help="the JSON the outputs are recorded in")
    parser.add_argument("--photos", help="a folder of photos (searched recursively)")
    parser.add_argument("--recording", help="an .mcap recording with camera frames")
    parser.add_argument("--every", type=integer(minimum=1), default=1,
                        help="use every this many frames of the recording (default 1)")
    parser.add_argument("--renders", type=integer(minimum=0), default=0, help="simulator renders (default 0)")
    args = parser.parse_args(argv)
    if args.action == "record" and not (args.photos or args.recording or args.renders):
        parser.error("record needs frames: --photos, --recording and/or --renders")
    # (SIGTERM ends a run as Ctrl-C does, see exit_with: one line, status 1, nothing written)
    try:
        status, report = record_or_compare(args)
    except (OSError, RecordingError, MessageError) as error:
        print(f"detector_outputs: {error}", file=sys.stderr)
        return 2
    print_lines(report)  # (quietly, when the reader has gone: `| head`)
    return status


if __name__ == "__main__":
    exit_with(main)
