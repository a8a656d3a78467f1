"""Distractors: scenes with no tennis ball; every detection is a false one.

Layouts: the shipped ``distractors`` scenario, then random ones (seeded) of 6-10 objects,
spheres, boxes and cylinders in colours other than the tennis ball's (red, orange, amber,
brown, green, cyan, blue, purple, pink, white, grey; their OpenCV hues are listed in the
report), placed 0.5-4 m around the robot. The robot turns (0.8 rad/s, creeping forward at
0.05 m/s) so that every object passes through the view at many angles and image positions.
Reported: false detections per 1000 frames (goal < 1), per layout; the first frames with a
false detection are saved as PNG with the detections drawn, for diagnosis.

Example::

    balltrack experiment distractors --quick --out runs/distractors
"""

import colorsys
import math

import numpy as np

from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, progress
from balltrack.experiments.rig import Perception, draw_detections, scenario_data
from balltrack.services.simulator.scenario import load_scenario

NAME = "distractors"
TITLE = "False detections in scenes without a tennis ball"
PALETTE = {
    "red": (0.85, 0.1, 0.1), "orange": (0.95, 0.45, 0.05), "amber": (1.0, 0.6, 0.0),
    "brown": (0.45, 0.3, 0.15), "green": (0.2, 0.75, 0.2), "dark green": (0.1, 0.45, 0.15),
    "cyan": (0.1, 0.7, 0.8), "blue": (0.1, 0.2, 0.85), "purple": (0.6, 0.1, 0.6),
    "pink": (0.9, 0.4, 0.6), "white": (0.95, 0.95, 0.95), "grey": (0.5, 0.5, 0.5),
}
TURN_RATE = 0.8
CREEP = 0.05
SAVED_FRAMES = 3


def opencv_hue(rgb) -> int:
    hue, _lightness, _saturation = colorsys.rgb_to_hls(*rgb)
    return round(hue * 180) % 180


def random_layout(rng, index: int) -> dict:
    names = list(PALETTE)
    objects = []
    for _ in range(int(rng.integers(6, 11))):
        angle = rng.uniform(-math.pi, math.pi)
        distance = rng.uniform(0.5, 4.0)
        position = [round(distance * math.cos(angle), 3), round(distance * math.sin(angle), 3)]
        colour = list(PALETTE[names[int(rng.integers(len(names)))]])
        shape = ["sphere", "box", "cylinder"][int(rng.integers(3))]
        if shape == "sphere":
            size = [round(rng.uniform(0.025, 0.12), 3)]
        elif shape == "box":
            size = [round(value, 3) for value in rng.uniform(0.08, 0.4, size=3)]
        else:
            size = [round(rng.uniform(0.03, 0.1), 3), round(rng.uniform(0.1, 0.5), 3)]
        objects.append({"shape": shape, "rgb": colour, "size": size, "position": position,
                        "yaw": round(rng.uniform(0, math.pi), 3)})
    return scenario_data(distractors=objects, name=f"distractors_random_{index}")


def run(options: Options) -> ExperimentResult:
    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, quick=options.quick)
    layouts_count = 3 if options.quick else 6
    frames = options.budget(quick=150, full=1000)
    result.settings = {"layouts": layouts_count, "frames per layout": frames,
                       "robot": f"turning {TURN_RATE} rad/s, {CREEP} m/s forward"}
    rng = np.random.default_rng(options.seed + 707)
    layouts = [("shipped 'distractors' scenario", load_scenario("distractors"))]
    layouts += [(f"random layout {index}", random_layout(rng, index))
                for index in range(1, layouts_count)]
    total_false = 0
    total_frames = 0
    saved = []
    rows = []
    detector_config = options.detector_config()
    with progress(total=layouts_count * frames, desc=NAME, options=options) as bar:
        for index, (label, layout) in enumerate(layouts):
            false_here = 0
            frames_with_false = 0
            with Perception(layout, detector=detector_config) as rig:
                sim = rig.sim
                for _ in range(frames):
                    sim.set_command(CREEP, TURN_RATE, sim.time)
                    detections = rig.detect()
                    if detections:
                        false_here += len(detections)
                        frames_with_false += 1
                        if len(saved) < SAVED_FRAMES:
                            filename = f"distractors_false_{len(saved) + 1}.png"
                            draw_detections(rig.last_image, detections, options.out / filename)
                            saved.append(f"{filename} ({label}, t = {sim.time:.1f} s: "
                                         + ", ".join(f"r {d.radius_px:.0f} px at ({d.u:.0f}, "
                                                     f"{d.v:.0f}) score {d.score:.2f}"
                                                     for d in detections) + ")")
                    sim.step_frame()
                    bar.update()
                scene = sim.scenario
            total_false += false_here
            total_frames += frames
            colours = sorted({_colour_name(item.rgb) for item in scene.distractors})
            rows.append([label, len(scene.distractors), ", ".join(colours), frames, false_here,
                         f"{1000 * false_here / frames:.2f}"])
            result.figure(f"layout_{index}/frames", frames)
            result.figure(f"layout_{index}/false_detections", false_here)
            result.figure(f"layout_{index}/frames_with_false_detections", frames_with_false)
    per_1000 = 1000 * total_false / total_frames
    result.figure("frames", total_frames)
    result.figure("false_detections", total_false)
    result.figure("false_per_1000_frames", per_1000)
    result.table(["layout", "objects", "colours", "frames", "false detections", "per 1000 frames"],
                 rows, "No tennis ball in any scene, so every detection is false:")
    result.notes.append("Distractor colours and their OpenCV hues (the tennis ball is "
                        f"{opencv_hue((0.7, 0.85, 0.15))}; the detector's range is "
                        f"{detector_config.h_min}-{detector_config.h_max}): "
                        + ", ".join(f"{name} {opencv_hue(rgb)}" for name, rgb in PALETTE.items())
                        + ". The floor, walls and sky are grey.")
    if saved:
        result.notes.append("Frames with false detections (circles drawn in magenta): "
                            + "; ".join(saved) + ".")
    resolution = 1000 / total_frames
    # With no false detection in n frames, the rate's one-sided 95 % upper bound is ~3/n.
    bound = 1000 * max(3.0, total_false + 2 * math.sqrt(total_false) + 1) / total_frames
    result.figure("false_per_1000_upper_95", bound)
    result.goal("false_per_1000", "false detections per 1000 frames without a tennis ball",
                "< 1", f"{per_1000:.2f} ({total_false} in {total_frames} frames; one false "
                f"detection = {resolution:.2f}; 95 % upper bound ~{bound:.1f})", per_1000 < 1.0)
    result.compare("false detections without a tennis ball", "not tested",
                   f"{per_1000:.2f} per 1000 frames ({total_frames} frames)")
    result.seconds = clock.seconds
    return result


def _colour_name(rgb) -> str:
    for name, value in PALETTE.items():
        if all(abs(a - b) < 1e-6 for a, b in zip(value, rgb)):
            return name
    return "rgb(" + ", ".join(f"{channel:g}" for channel in rgb) + ")"


if __name__ == "__main__":
    import sys

    from balltrack.common.terminal import exit_with
    from balltrack.experiments.cli import main

    exit_with(lambda: main([NAME, *sys.argv[1:]]))
