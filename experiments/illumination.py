"""Illumination (paper Table 1): detection rate and position error as the main light dims.

A tennis ball about 1 m in front of the camera (small random jitter of distance, bearing and
the robot's pose per frame), the main light's diffuse level at 0.8, 0.5, 0.1, 0.05 (the
paper's four levels) and further down to 0.02 and 0.01, in two set-ups: a Gazebo-like scene
ambient of 0.4, and no ambient light at all (0), where only the diffuse light shows anything.
Approximate lux as in the paper's equation 9: diffuse x 10 000 lx.

Example::

    balltrack experiment illumination --quick --out runs/illumination
"""

import math

import numpy as np

from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, percent, progress, quantile
from balltrack.experiments.rig import TENNIS_RADIUS, TENNIS_RGB, Perception, position_errors, scenario_data

NAME = "illumination"
TITLE = "Detection under varying illumination (paper Table 1)"
LEVELS = (0.8, 0.5, 0.1, 0.05, 0.02, 0.01)
PAPER_LEVELS = (0.8, 0.5, 0.1, 0.05)
SETUPS = (("ambient_0.4", 0.4, "Gazebo-like ambient 0.4"), ("ambient_0", 0.0, "no ambient (0)"))
DISTANCE = 1.0
L_REF = 10000.0


def run(options: Options) -> ExperimentResult:
    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, quick=options.quick)
    frames = options.budget(quick=8, full=40)
    result.settings = {"frames per level": frames, "ball distance": f"{DISTANCE} m +- 5 cm",
                       "bearing jitter": "+-15 deg", "robot yaw jitter": "+-10 deg"}
    rng = np.random.default_rng(options.seed + 101)
    data = scenario_data(balls=[{"id": "tennis", "radius": TENNIS_RADIUS, "rgb": TENNIS_RGB,
                                 "position": [DISTANCE + 0.11, 0.0]}], name="illumination")
    rows: dict[tuple[str, float], dict] = {}
    montage: dict[tuple[str, float], np.ndarray] = {}
    total = len(SETUPS) * len(LEVELS) * frames
    with Perception(data, detector=options.detector_config()) as rig, \
            progress(total=total, desc=NAME, options=options) as bar:
        for setup, ambient, _label in SETUPS:
            for level in LEVELS:
                rig.sim.set_light(diffuse=level, ambient=ambient)
                found = 0
                false_detections = 0
                exact_errors, faithful_errors = [], []
                for _ in range(frames):
                    rig.place_robot(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3),
                                    math.radians(rng.uniform(-10, 10)))
                    rig.place_ball_from_camera("tennis", DISTANCE + rng.uniform(-0.05, 0.05),
                                               math.radians(rng.uniform(-15, 15)))
                    detections = rig.detect()
                    truth = rig.truth()
                    matched = rig.match(detections, truth)
                    false_detections += len(detections) - len(matched)
                    if "tennis" in matched:
                        found += 1
                        located = rig.locate(detections[matched["tennis"]])
                        errors = position_errors(located, truth[0]["in_camera"])
                        exact_errors.append(errors["exact_error_rel"])
                        faithful_errors.append(errors["faithful_error_rel"])
                    bar.update()
                if (setup, level) not in montage:
                    expected = truth[0]["expected"]
                    montage[(setup, level)] = _crop(rig.last_image, expected)
                rows[(setup, level)] = {
                    "rate": found / frames,
                    "exact": quantile(exact_errors, 0.5),
                    "faithful": quantile(faithful_errors, 0.5),
                    "false": false_detections,
                }
                prefix = f"{setup}/diffuse_{level:g}"
                result.figure(f"{prefix}/detection_rate", found / frames)
                result.figure(f"{prefix}/frames", frames)
                result.figure(f"{prefix}/false_detections", false_detections)
                result.figure(f"{prefix}/exact_median_error_rel", rows[(setup, level)]["exact"])
                result.figure(f"{prefix}/faithful_median_error_rel", rows[(setup, level)]["faithful"])

    table_rows = []
    for level in LEVELS:
        row = [f"{level:g}", f"~{level * L_REF:.0f} lx",
               "True" if level in PAPER_LEVELS else "(not tested)"]
        for setup, _ambient, _label in SETUPS:
            entry = rows[(setup, level)]
            row += [percent(entry["rate"], 0), percent(entry["exact"]), percent(entry["faithful"])]
        table_rows.append(row)
    result.table(["diffuse", "approx. lux (eq. 9)", "paper: detected",
                  "ambient 0.4: detected", "exact error", "faithful error",
                  "ambient 0: detected", "exact error", "faithful error"], table_rows,
                 "Detection rate per level and median 3D position error relative to the distance "
                 "(exact and faithful locator):")

    for setup, _ambient, label in SETUPS:
        paper_rates = [rows[(setup, level)]["rate"] for level in PAPER_LEVELS]
        result.goal(f"{setup}/paper_levels", f"100 % detection at the paper's levels "
                    f"(0.8, 0.5, 0.1, 0.05), {label}", "100 % at each",
                    f"lowest {percent(min(paper_rates), 0)}", min(paper_rates) >= 1.0)
        lowest = LEVELS[-1]
        rate = rows[(setup, lowest)]["rate"]
        result.goal(f"{setup}/lowest_level", f">= 95 % detection at the lowest level tested "
                    f"(diffuse {lowest:g}, ~{lowest * L_REF:.0f} lx), {label}", ">= 95 %",
                    percent(rate, 0), rate >= 0.95)
        reached = [level for level in LEVELS if rows[(setup, level)]["rate"] >= 0.95]
        lowest_reached = min(reached) if reached else None
        result.figure(f"{setup}/lowest_level_95", lowest_reached)
        result.notes.append(f"{label}: lowest diffuse level with >= 95 % detection: "
                            f"{lowest_reached if lowest_reached is not None else 'none'}.")

    for level in LEVELS:
        rates = " / ".join(percent(rows[(setup, level)]["rate"], 0) for setup, _a, _l in SETUPS)
        result.compare(f"detected at diffuse {level:g} (~{level * L_REF:.0f} lx)",
                       "True" if level in PAPER_LEVELS else "not tested",
                       f"{rates} (ambient 0.4 / no ambient)")
    _plots(result, rows, montage, options)
    result.seconds = clock.seconds
    return result


def _crop(image, expected, half: int = 48) -> np.ndarray:
    height, width = image.shape[:2]
    u, v = (width / 2, height / 2) if expected is None else expected[:2]
    left = int(min(max(0, u - half), width - 2 * half))
    top = int(min(max(0, v - half), height - 2 * half))
    return image[top:top + 2 * half, left:left + 2 * half, ::-1]  # BGR -> RGB for matplotlib


def _plots(result: ExperimentResult, rows: dict, montage: dict, options: Options) -> None:
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(10, 4))
    for setup, _ambient, label in SETUPS:
        axes[0].plot(LEVELS, [100 * rows[(setup, level)]["rate"] for level in LEVELS], "o-",
                     label=label)
        axes[1].plot(LEVELS, [100 * (rows[(setup, level)]["exact"] or math.nan) for level in LEVELS],
                     "o-", label=f"{label}, exact")
        axes[1].plot(LEVELS, [100 * (rows[(setup, level)]["faithful"] or math.nan)
                              for level in LEVELS], "s--", label=f"{label}, faithful")
    for axis in axes:
        axis.set_xscale("log")
        axis.set_xlabel("main light diffuse level (x 10 000 lx)")
        axis.grid(True, alpha=0.3)
    axes[0].axvline(0.05, color="grey", linestyle=":", label="paper's lowest level")
    axes[0].set_ylabel("detection rate (%)")
    axes[0].set_ylim(-5, 105)
    axes[0].legend()
    axes[1].set_ylabel("median 3D error (% of distance)")
    axes[1].legend(fontsize=7)
    result.save_plot(figure, options.out, "illumination_rate.png")

    figure, axes = plt.subplots(len(SETUPS), len(LEVELS), figsize=(1.6 * len(LEVELS), 3.6))
    for row, (setup, _ambient, label) in enumerate(SETUPS):
        for column, level in enumerate(LEVELS):
            axis = axes[row][column]
            axis.imshow(montage[(setup, level)])
            axis.set_xticks([])
            axis.set_yticks([])
            axis.set_title(f"{level:g}", fontsize=8)
            if column == 0:
                axis.set_ylabel(label, fontsize=7)
    result.save_plot(figure, options.out, "illumination_frames.png")


if __name__ == "__main__":
    import sys

    from balltrack.common.terminal import exit_with
    from balltrack.experiments.cli import main

    exit_with(lambda: main([NAME, *sys.argv[1:]]))
