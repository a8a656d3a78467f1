"""Ball sizes (the abstract's "varying ball sizes"): detection and distance error per radius.

Balls of the tennis ball's colour with radius 0.02 to 0.12 m rest on the floor at 0.5, 1, 2
and 3 m from the camera (random bearing within +-20 degrees, small robot jitter); the locator
is told the right radius. Reported per radius and distance: detection rate, the ball's image
radius, and the median distance error of the exact and faithful locator.

Example::

    balltrack experiment sizes --quick --out runs/sizes
"""

import math

import numpy as np

from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, percent, progress, quantile
from balltrack.experiments.rig import TENNIS_RGB, Perception, position_errors, scenario_data

NAME = "sizes"
TITLE = "Ball sizes: detection and distance error per radius"
RADII = (0.02, 0.033, 0.05, 0.08, 0.12)
DISTANCES = (0.5, 1.0, 2.0, 3.0)


def run(options: Options) -> ExperimentResult:
    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, quick=options.quick)
    frames = options.budget(quick=4, full=20)
    detector_config = options.detector_config()
    result.settings = {"frames per radius and distance": frames, "ball": "on the floor",
                       "bearing": "+-20 deg", "detector min_radius": f"{detector_config.min_radius} px"}
    rng = np.random.default_rng(options.seed + 505)
    rows = {}
    with progress(total=len(RADII) * len(DISTANCES) * frames, desc=NAME, options=options) as bar:
        for radius in RADII:
            data = scenario_data(balls=[{"id": "ball", "radius": radius, "rgb": TENNIS_RGB,
                                         "position": [1.0, 0.0]}], name=f"sizes_{radius:g}")
            with Perception(data, detector=detector_config) as rig:
                for distance in DISTANCES:
                    found = 0
                    radii, exact, faithful = [], [], []
                    for _ in range(frames):
                        rig.place_robot(rng.uniform(-1.0, -0.5), rng.uniform(-0.3, 0.3),
                                        math.radians(rng.uniform(-10, 10)))
                        rig.place_ball_from_camera("ball", distance, math.radians(rng.uniform(-20, 20)))
                        detections = rig.detect()
                        ball = rig.truth()[0]
                        radii.append(ball["expected"][2])
                        matched = rig.match(detections, [ball])
                        bar.update()
                        if "ball" not in matched:
                            continue
                        found += 1
                        errors = position_errors(rig.locate(detections[matched["ball"]], radius),
                                                 ball["in_camera"])
                        exact.append(abs(errors["exact_distance_rel"]))
                        faithful.append(abs(errors["faithful_distance_rel"]))
                    entry = {"rate": found / frames, "radius_px": quantile(radii, 0.5),
                             "exact": quantile(exact, 0.5), "faithful": quantile(faithful, 0.5)}
                    rows[(radius, distance)] = entry
                    prefix = f"r_{radius:g}/d_{distance:g}"
                    result.figure(f"{prefix}/detection_rate", entry["rate"])
                    result.figure(f"{prefix}/radius_px", entry["radius_px"])
                    result.figure(f"{prefix}/exact_median_distance_error_rel", entry["exact"])
                    result.figure(f"{prefix}/faithful_median_distance_error_rel", entry["faithful"])

    table = []
    for radius in RADII:
        row = [f"{radius:g}"]
        for distance in DISTANCES:
            entry = rows[(radius, distance)]
            row.append(f"{percent(entry['rate'], 0)}, r {entry['radius_px']:.1f} px, "
                       f"exact {percent(entry['exact'])}, faithful {percent(entry['faithful'])}")
        table.append(row)
    result.table(["radius (m)"] + [f"{distance:g} m" for distance in DISTANCES], table,
                 "Detection rate, image radius and median |distance error| (exact, faithful) per "
                 "ball radius and distance (the paper reports no numbers for sizes):")
    small = [(radius, distance) for (radius, distance), entry in rows.items()
             if entry["radius_px"] < detector_config.min_radius]
    if small:
        result.notes.append("Image radius below the detector's min_radius "
                            f"({detector_config.min_radius} px), so not detectable by design: "
                            + ", ".join(f"r {radius:g} m at {distance:g} m"
                                        for radius, distance in small)
                            + ".")
    detected_all = [f"{radius:g}" for radius in RADII
                    if all(rows[(radius, distance)]["rate"] >= 0.95 for distance in DISTANCES)]
    worst = max((entry["exact"] for entry in rows.values() if entry["exact"] is not None),
                default=None)
    result.compare("varying ball sizes", "\"adapts\" (abstract; no figures)",
                   f"all distances 0.5-3 m at >= 95 % for r = {', '.join(detected_all) or 'none'} m; "
                   f"median exact distance error <= {percent(worst)}")
    _plot(result, rows, options)
    result.seconds = clock.seconds
    return result


def _plot(result: ExperimentResult, rows: dict, options: Options) -> None:
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(11, 4))
    for radius in RADII:
        axes[0].plot(DISTANCES, [100 * rows[(radius, d)]["rate"] for d in DISTANCES], "o-",
                     label=f"r = {radius:g} m")
        axes[1].plot(DISTANCES, [100 * rows[(radius, d)]["exact"] if rows[(radius, d)]["exact"]
                                 is not None else math.nan for d in DISTANCES], "o-",
                     label=f"r = {radius:g} m")
    axes[0].set_ylabel("detection rate (%)")
    axes[0].set_ylim(-5, 105)
    axes[1].set_ylabel("exact locator: median |distance error| (%)")
    for axis in axes:
        axis.set_xlabel("distance (m)")
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize=8)
    result.save_plot(figure, options.out, "sizes.png")


if __name__ == "__main__":
    import sys

    from balltrack.common.terminal import exit_with
    from balltrack.experiments.cli import main

    exit_with(lambda: main([NAME, *sys.argv[1:]]))
