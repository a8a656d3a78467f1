"""Detector cost per 640x480 frame: simulator renders (chase, multi, distractors scenarios) and,
if a folder is given, real photos resized to 640x480. Wall and CPU time per call, median and
90th percentile, one thread, the detector core called directly (no transport).

Example::

    python -m balltrack.experiments.detector_speed --photos ../shared/data/real_tennis_dev
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from balltrack.services.detector.detector import BallDetector


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


def photo_frames(folder: Path) -> list[np.ndarray]:
    images = [cv2.imread(str(path)) for path in sorted(folder.glob("*.jpg"))]
    return [cv2.resize(image, (640, 480)) for image in images if image is not None]


def measure(detector: BallDetector, frames: list[np.ndarray], repeats: int) -> dict[str, float]:
    wall, cpu = [], []
    for index in range(repeats):
        frame = frames[index % len(frames)]
        started_wall, started_cpu = time.perf_counter(), time.process_time()
        detector.detect(frame)
        wall.append((time.perf_counter() - started_wall) * 1000)
        cpu.append((time.process_time() - started_cpu) * 1000)
    deciles = lambda values: statistics.quantiles(values, n=10)  # noqa: E731
    return {"wall_p50_ms": statistics.median(wall), "wall_p90_ms": deciles(wall)[-1],
            "cpu_p50_ms": statistics.median(cpu), "cpu_p90_ms": deciles(cpu)[-1]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photos", type=Path, help="folder of .jpg photos (optional)")
    parser.add_argument("--repeats", type=int, default=300)
    args = parser.parse_args(argv)
    detector = BallDetector()
    sets = {"simulator renders": simulator_frames(60)}
    if args.photos:
        if not args.photos.is_dir():
            print(f"detector_speed: {args.photos}: not a folder", file=sys.stderr)
            return 2
        sets["real photos (resized)"] = photo_frames(args.photos)
    print(f"{'frames (640x480)':<24} {'wall p50':>9} {'wall p90':>9} {'cpu p50':>8} {'cpu p90':>8}  (ms)")
    for name, frames in sets.items():
        figures = measure(detector, frames, args.repeats)
        print(f"{name:<24} {figures['wall_p50_ms']:>9.2f} {figures['wall_p90_ms']:>9.2f} "
              f"{figures['cpu_p50_ms']:>8.2f} {figures['cpu_p90_ms']:>8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
