"""Colour is a setting: an orange ball with the HSV range set for orange is found as often as a
tennis ball is with the defaults, by both of the detector's methods.

The learned detector's network sees brightness, chroma and the colour mask, never a hue: which
colour counts is the mask's, set by ``h_min``/``h_max``. This experiment checks that in the
simulator: the same scene and the same random placements (distance 0.4-3 m, bearing within the
view, the robot's pose jittered, the light at the scenario's level), once with a tennis ball and
the default settings, once with an orange ball and the range set for orange.

Example::

    balltrack experiment colour_setting --quick --out runs/colour
    balltrack experiment colour_setting --detector method=learned --out runs/colour
"""

import dataclasses
import math

import numpy as np

from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, percent, progress
from balltrack.experiments.rig import TENNIS_RADIUS, TENNIS_RGB, Perception, scenario_data
from balltrack.services.detector.config import Method

NAME = "colour_setting"
TITLE = "Colour is a setting: an orange ball with an orange range, beside a tennis ball with the defaults"
# An orange ball (OpenCV hue ~12) and the range a user sets for it: as wide as the default
# tennis range (25-50), around its hue.
ORANGE_RGB = [0.95, 0.45, 0.08]
ORANGE_RANGE = {"h_min": 0, "h_max": 25}
BALLS = (("tennis", TENNIS_RGB, {}), ("orange", ORANGE_RGB, ORANGE_RANGE))
# The orange ball may be found this much less often than the tennis ball and still pass.
GOAL_GAP = 0.05


def run(options: Options) -> ExperimentResult:
    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, quick=options.quick)
    frames = options.budget(quick=20, full=120)
    base = options.detector_config()
    result.settings = {"frames per ball and method": frames, "distance": "0.4-3 m", "bearing": "+-20 deg",
                       "orange ball": f"rgb {ORANGE_RGB}, detector {ORANGE_RANGE}",
                       "tennis ball": f"rgb {TENNIS_RGB}, detector defaults"}
    rates: dict[tuple[str, str], float] = {}
    with progress(total=len(Method) * len(BALLS) * frames, desc=NAME, options=options) as bar:
        for method in Method:
            for name, rgb, colour_range in BALLS:
                config = dataclasses.replace(base, method=method, **colour_range)
                data = scenario_data(balls=[{"id": name, "radius": TENNIS_RADIUS, "rgb": rgb,
                                             "position": [1.0, 0.0]}], name=NAME)
                # (the same placements for every ball and method)
                rng = np.random.default_rng(options.seed + 211)
                found = false_detections = 0
                with Perception(data, detector=config) as rig:
                    for _ in range(frames):
                        rig.place_robot(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3),
                                        math.radians(rng.uniform(-10, 10)))
                        rig.place_ball_from_camera(name, rng.uniform(0.4, 3.0), math.radians(rng.uniform(-20, 20)))
                        detections = rig.detect()
                        matched = rig.match(detections, rig.truth())
                        found += name in matched
                        false_detections += len(detections) - len(matched)
                        bar.update()
                rates[(str(method), name)] = found / frames
                result.figure(f"{method}/{name}/detection_rate", found / frames)
                result.figure(f"{method}/{name}/false_detections", false_detections)
    result.table(["method", "tennis ball, default range", "orange ball, orange range"],
                 [[str(method), *(percent(rates[(str(method), name)], 0) for name, _, _ in BALLS)]
                  for method in Method],
                 f"Detection rate, {frames} placements each (the same for every row and column):")
    for method in Method:
        tennis, orange = rates[(str(method), "tennis")], rates[(str(method), "orange")]
        result.goal(str(method), f"{method}: the orange ball with its range found at least as often as the "
                                 f"tennis ball with the defaults, less {percent(GOAL_GAP, 0)}",
                    f">= tennis - {percent(GOAL_GAP, 0)}", f"{percent(orange, 0)} vs {percent(tennis, 0)}",
                    orange >= tennis - GOAL_GAP)
    result.seconds = clock.seconds
    return result
