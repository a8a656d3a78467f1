"""Accuracy of the 3D position: random ball positions in view, both locator models.

Each frame puts the robot somewhere in the world and a tennis ball at a random point of the
image (normalised x, y uniform in [-0.95, 0.95]) and a random distance from 0.3 to 3.5 m (the
paper's range), on the floor or above it (as on a table or in flight; a point that would be
under the floor is drawn again). Reported: detection rate, median and 95th-percentile 3D
error of the exact (pinhole) and faithful (paper's equations 1-8) locator, in metres and
relative to the distance, plus plots of the error against distance and image position.

Example::

    balltrack experiment accuracy --quick --out runs/accuracy
"""

import math

import numpy as np

from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, percent, progress, quantile
from balltrack.experiments.rig import (CAMERA_AHEAD, CAMERA_HEIGHT, TENNIS_RADIUS, TENNIS_RGB, Perception,
                             position_errors, scenario_data)

NAME = "accuracy"
TITLE = "3D position accuracy at random positions in view"
DISTANCE_RANGE = (0.3, 3.5)
BINS = ((0.3, 1.0), (1.0, 2.0), (2.0, 3.5))
MODELS = ("exact", "faithful")


def _random_point(rng, rig: Perception, robot) -> list[float]:
    """World position of a ball centre at a random image point and distance, above the floor."""
    robot_x, robot_y, yaw = robot
    info = rig.info
    while True:
        x, y = rng.uniform(-0.95, 0.95, size=2)
        distance = rng.uniform(*DISTANCE_RANGE)
        u = info["width"] / 2 * (1 + x)
        v = info["height"] / 2 * (1 + y)
        ray = np.array([(u - info["cx"]) / info["fx"], (v - info["cy"]) / info["fy"], 1.0])
        right, down, forward = distance * ray / np.linalg.norm(ray)
        camera_x = robot_x + CAMERA_AHEAD * math.cos(yaw)
        camera_y = robot_y + CAMERA_AHEAD * math.sin(yaw)
        world = [camera_x + forward * math.cos(yaw) + right * math.sin(yaw),
                 camera_y + forward * math.sin(yaw) - right * math.cos(yaw),
                 CAMERA_HEIGHT - down]
        if world[2] >= TENNIS_RADIUS and max(abs(world[0]), abs(world[1])) < 4.8:
            return world


def run(options: Options) -> ExperimentResult:
    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, quick=options.quick)
    frames = options.budget(quick=60, full=500)
    result.settings = {"frames": frames, "distance": "0.3-3.5 m uniform",
                       "image position": "uniform over 95 % of the frame",
                       "light": "diffuse 0.8, ambient 0.4"}
    rng = np.random.default_rng(options.seed + 303)
    data = scenario_data(balls=[{"id": "tennis", "radius": TENNIS_RADIUS, "rgb": TENNIS_RGB,
                                 "position": [1.11, 0.0]}], name="accuracy")
    samples = []
    found = 0
    with Perception(data, detector=options.detector_config()) as rig, \
            progress(total=frames, desc=NAME, options=options) as bar:
        for _ in range(frames):
            robot = (rng.uniform(-1.5, 0.0), rng.uniform(-1.5, 1.5), rng.uniform(-0.5, 0.5))
            rig.place_robot(*robot)
            rig.sim.place_ball("tennis", _random_point(rng, rig, robot))
            detections = rig.detect()
            ball = rig.truth()[0]
            bar.update()
            matched = rig.match(detections, [ball])
            if "tennis" not in matched:
                samples.append({"distance": ball["distance"], "u": ball["expected"][0],
                                "v": ball["expected"][1], "detected": False})
                continue
            found += 1
            errors = position_errors(rig.locate(detections[matched["tennis"]]), ball["in_camera"])
            samples.append({"distance": ball["distance"], "u": ball["expected"][0],
                            "v": ball["expected"][1], "detected": True, **errors})

    detected = [sample for sample in samples if sample["detected"]]
    result.figure("frames", frames)
    result.figure("detection_rate", found / frames)
    rows = []
    for label in MODELS:
        for unit, key in (("m", f"{label}_error_m"), ("rel", f"{label}_error_rel")):
            values = [sample[key] for sample in detected]
            result.figure(f"{label}/median_error_{unit}", quantile(values, 0.5))
            result.figure(f"{label}/p95_error_{unit}", quantile(values, 0.95))
        distance_errors = [abs(sample[f"{label}_distance_rel"]) for sample in detected]
        result.figure(f"{label}/median_distance_error_rel", quantile(distance_errors, 0.5))
        result.figure(f"{label}/p95_distance_error_rel", quantile(distance_errors, 0.95))
        metres = [sample[f"{label}_error_m"] for sample in detected]
        relative = [sample[f"{label}_error_rel"] for sample in detected]
        rows.append([label, "all", len(detected),
                     _cm(quantile(metres, 0.5)), _cm(quantile(metres, 0.95)),
                     percent(quantile(relative, 0.5)), percent(quantile(relative, 0.95)),
                     percent(quantile(distance_errors, 0.5))])
        for low, high in BINS:
            subset = [sample for sample in detected if low <= sample["distance"] < high]
            metres = [sample[f"{label}_error_m"] for sample in subset]
            relative = [sample[f"{label}_error_rel"] for sample in subset]
            distance_errors = [abs(sample[f"{label}_distance_rel"]) for sample in subset]
            name = f"{label}/d_{low:g}-{high:g}"
            result.figure(f"{name}/samples", len(subset))
            result.figure(f"{name}/median_error_rel", quantile(relative, 0.5))
            result.figure(f"{name}/p95_error_rel", quantile(relative, 0.95))
            rows.append([label, f"{low:g}-{high:g} m", len(subset),
                         _cm(quantile(metres, 0.5)), _cm(quantile(metres, 0.95)),
                         percent(quantile(relative, 0.5)), percent(quantile(relative, 0.95)),
                         percent(quantile(distance_errors, 0.5))])
    result.table(["locator", "distance", "detections", "median 3D error", "p95 3D error",
                  "median 3D error / distance", "p95 3D error / distance",
                  "median distance error"], rows,
                 f"Detected {found}/{frames} ({percent(found / frames)}). 3D error of the "
                 "located centre against ground truth (the paper gives no accuracy figure; its "
                 "sample output, fig. 5, is one position without ground truth):")
    exact = [sample["exact_error_rel"] for sample in detected]
    faithful = [sample["faithful_error_rel"] for sample in detected]
    result.compare("3D position error, random positions 0.3-3.5 m",
                   "not given (fig. 5: one output, x 0.15, y -0.34, z 0.045 m)",
                   f"median {percent(quantile(exact, 0.5))} exact, "
                   f"{percent(quantile(faithful, 0.5))} faithful (of the distance)")
    _plots(result, detected, (rig.width, rig.height), options)
    result.seconds = clock.seconds
    return result


def _cm(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f} cm"


def _plots(result: ExperimentResult, detected: list[dict], size: tuple[int, int],
           options: Options) -> None:
    import matplotlib.pyplot as plt

    if not detected:
        return
    distance = [sample["distance"] for sample in detected]
    figure, axis = plt.subplots(figsize=(7, 4.5))
    for label, marker in (("exact", "o"), ("faithful", "x")):
        axis.scatter(distance, [100 * sample[f"{label}_error_rel"] for sample in detected], s=12,
                     marker=marker, label=label, alpha=0.7)
    axis.set_xlabel("distance (m)")
    axis.set_ylabel("3D error (% of distance)")
    axis.set_yscale("log")
    axis.grid(True, alpha=0.3, which="both")
    axis.legend()
    axis.set_title("3D error vs distance")
    result.save_plot(figure, options.out, "accuracy_vs_distance.png")

    figure, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    us = [sample["u"] for sample in detected]
    vs = [sample["v"] for sample in detected]
    for axis, label in zip(axes, ("exact", "faithful")):
        errors = [100 * sample[f"{label}_error_rel"] for sample in detected]
        scatter = axis.scatter(us, vs, c=errors, cmap="viridis", s=18,
                               vmin=0, vmax=max(1.0, float(np.percentile(errors, 95))))
        axis.set_xlim(0, size[0])
        axis.set_ylim(size[1], 0)
        axis.set_aspect("equal")
        axis.set_xlabel("u (px)")
        axis.set_ylabel("v (px)")
        axis.set_title(f"{label}: 3D error (% of distance) by image position")
        figure.colorbar(scatter, ax=axis, fraction=0.04)
    result.save_plot(figure, options.out, "accuracy_vs_image_position.png")


if __name__ == "__main__":
    import sys

    from balltrack.common.terminal import exit_with
    from balltrack.experiments.cli import main

    exit_with(lambda: main([NAME, *sys.argv[1:]]))
