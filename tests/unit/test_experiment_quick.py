"""One experiment end to end through ``experiments.cli.main``: files, stable names, plausible numbers.

The illumination experiment runs in-process (simulator, detector and locator cores) with a
tiny frame budget, so this takes a few seconds.
"""

import json
import os
import platform
from pathlib import Path

import cv2
import numpy as np
import pytest

from balltrack.experiments import cli, detector_speed
from balltrack.services.detector.detector import STAGES
from balltrack.services.detector.regions import REGION_MARGIN


def test_illumination_writes_results_report_and_plots(tmp_path):
    status = cli.main(["illumination", "--frames", "2", "--out", str(tmp_path), "--no-progress"])
    assert status == 0

    results = json.loads((tmp_path / "results.json").read_text())
    entry = results["experiments"]["illumination"]
    assert entry["mode"] == "in-process"
    figures = results["figures"]
    for setup in ("ambient_0.4", "ambient_0"):
        for level in ("0.8", "0.5", "0.1", "0.05", "0.02", "0.01"):
            for metric in ("detection_rate", "frames", "false_detections",
                           "exact_median_error_rel", "faithful_median_error_rel"):
                assert f"illumination/{setup}/diffuse_{level}/{metric}" in figures
            assert figures[f"illumination/{setup}/diffuse_{level}/frames"] == 2
    # A tennis ball 1 m ahead under the brightest light with Gazebo's ambient: always found,
    # located within a few percent by the exact model; the faithful model is ~5-10 % off there.
    assert figures["illumination/ambient_0.4/diffuse_0.8/detection_rate"] == 1.0
    assert figures["illumination/ambient_0.4/diffuse_0.8/false_detections"] == 0
    assert 0.0 <= figures["illumination/ambient_0.4/diffuse_0.8/exact_median_error_rel"] < 0.05
    assert 0.01 < figures["illumination/ambient_0.4/diffuse_0.8/faithful_median_error_rel"] < 0.3
    for name, value in figures.items():
        if name.endswith("/detection_rate"):
            assert 0.0 <= value <= 1.0, name

    goals = {goal["name"]: goal for goal in results["goals"]}
    assert set(goals) == {"illumination/ambient_0.4/paper_levels", "illumination/ambient_0.4/lowest_level",
                          "illumination/ambient_0/paper_levels", "illumination/ambient_0/lowest_level"}
    for goal in goals.values():
        assert goal["status"] == ("PASS" if goal["passed"] else "MISS")

    report = (tmp_path / "report.md").read_text()
    assert "in-process" in report and "Table 1" in report and "~500 lx" in report
    # What it ran on, since its timings are the machine's and the libraries' too.
    from importlib import metadata
    assert entry["environment"]["numpy"] == metadata.version("numpy")
    assert entry["environment"]["cpus"].startswith(f"{os.cpu_count()} x ")
    assert f"**Environment:** python {platform.python_version()}, opencv-python-headless " in report
    for plot in entry["plots"]:
        assert (tmp_path / plot).stat().st_size > 1000
        assert f"]({plot})" in report


def test_rerun_of_another_experiment_merges(tmp_path):
    (tmp_path / "results.json").write_text(json.dumps({"experiments": {"range": {
        "title": "t", "mode": "in-process", "figures": {"range/x": 1}, "goals": []}}}))
    assert cli.main(["illumination", "--frames", "1", "--out", str(tmp_path), "--no-progress"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    assert list(results["experiments"]) == ["illumination", "range"]
    assert results["figures"]["range/x"] == 1


@pytest.mark.parametrize("arguments", [
    ["nonsense", "--out", "OUT"],
    ["illumination"],                                   # no --out
    ["illumination", "--out", "OUT", "--frames", "0"],
    ["real_photos", "--out", "OUT"],                    # no --photos
    ["illumination", "--out", "OUT", "--detector", "no_such_parameter=1"],
])
def test_bad_arguments_exit_2_with_one_line(arguments, tmp_path, capsys):
    arguments = [str(tmp_path / "out") if item == "OUT" else item for item in arguments]
    with pytest.raises(SystemExit) as exit_info:
        cli.main(arguments)
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("balltrack experiment:") and "\n" not in error


def test_own_blob_boxes_hold_each_blob_with_the_coarse_searchs_margin():
    mask = np.zeros((480, 640), np.uint8)
    cv2.circle(mask, (100, 100), 10, 255, -1)
    cv2.circle(mask, (500, 400), 20, 255, -1)
    boxes = sorted(detector_speed.own_blob_boxes(mask))
    assert boxes == [(90 - REGION_MARGIN, 90 - REGION_MARGIN, 111 + REGION_MARGIN, 111 + REGION_MARGIN),
                     (480 - REGION_MARGIN, 380 - REGION_MARGIN, 521 + REGION_MARGIN, 421 + REGION_MARGIN)]
    # two blobs close together cost less as one box, as the coarse search merges them
    cv2.circle(mask, (130, 100), 10, 255, -1)
    assert len(detector_speed.own_blob_boxes(mask)) == 2
    assert detector_speed.own_blob_boxes(np.zeros((480, 640), np.uint8)) == []


@pytest.mark.slow  # (times both detectors on every photo set: left to the whole suite, out of the quick tier)
def test_detector_speed_measures_both_detectors_side_by_side(tmp_path):
    status = cli.main(["detector_speed", "--frames", "3", "--quick", "--out", str(tmp_path), "--no-progress"])
    assert status == 0
    results = json.loads((tmp_path / "results.json").read_text())
    figures = results["figures"]
    sets = ["renders"] + (["photos"] if "detector_speed/photos/ratio" in figures else [])
    for name in sets:
        plain = figures[f"detector_speed/{name}/plain/wall_p50_ms"]
        ours = figures[f"detector_speed/{name}/balltrack/wall_p50_ms"]
        assert plain > 0 and ours > 0
        assert figures[f"detector_speed/{name}/ratio"] == pytest.approx(plain / ours, rel=1e-5)
    # The photos again, the balltrack detector on shrunk frames: figures only, no goal.
    # And with its colour mask only in boxes around its own blobs (the bound of a better coarse search).
    for name in ([f"photos_at_{width}" for width in detector_speed.SHRUNK_WIDTHS] + ["photos_own_blob_regions"]
                 if "photos" in sets else ()):
        shrunk = figures[f"detector_speed/{name}/balltrack/wall_p50_ms"]
        assert figures[f"detector_speed/{name}/ratio"] == pytest.approx(
            figures[f"detector_speed/{name}/plain/wall_p50_ms"] / shrunk, rel=1e-5)
    # The renders once more, paced as a camera's frames arrive: figures only, no goal.
    paced_plain = figures["detector_speed/renders_paced/plain/wall_p50_ms"]
    paced_ours = figures["detector_speed/renders_paced/balltrack/wall_p50_ms"]
    assert paced_plain > 0 and paced_ours > 0
    assert figures["detector_speed/renders_paced/ratio"] == pytest.approx(paced_plain / paced_ours, rel=1e-5)
    # (the machine's own speed in the same run: a ratio moves with it)
    assert figures["detector_speed/machine/python_loop_ms"] > 0
    assert figures["detector_speed/machine/opencv_blur_ms"] > 0
    assert 0 < figures["detector_speed/machine/encode_us"]
    assert 0 < figures["detector_speed/machine/encode_after_idle_us"]
    report = (tmp_path / "report.md").read_text()
    assert "Machine speed in this run" in report
    # Where the balltrack detector's time goes, per stage: the renders have a ball, so every
    # stage has run, and the middle fifth of the frames is some of them.
    for stage in STAGES:
        assert figures[f"detector_speed/renders/stage/{stage}/all_ms"] > 0
        assert figures[f"detector_speed/renders/stage/{stage}/middle_ms"] >= 0
    # The blobs stage by blob size: each class's time is its blobs times their mean time, and
    # the renders' ball is a blob of some class; together they are at most the blobs stage.
    by_size = {key: {metric: figures[f"detector_speed/renders/blobs_by_size/{key}/{metric}"]
                     for metric in ("per_frame", "ms_per_frame", "us_per_blob")}
               for key, *_ in detector_speed.size_classes()}
    assert len(by_size) == len(detector_speed.BLOB_SIZE_LIMITS) + 1
    assert sum(split["per_frame"] for split in by_size.values()) >= 1
    for split in by_size.values():
        assert split["ms_per_frame"] == pytest.approx(split["per_frame"] * split["us_per_blob"] / 1000, rel=1e-3, abs=1e-5)
    # (the same calls as the stage split: the blobs' own time is part of that stage's)
    assert (sum(split["ms_per_frame"] for split in by_size.values())
            <= figures["detector_speed/renders/stage/blobs/all_ms"] + 1e-3)
    assert "The blobs stage by blob size" in report
    assert "Where the balltrack detector's time goes" in report
    # and the plain pipeline's: its colour mask and its Hough transform
    from balltrack.experiments.detector_speed import PLAIN_STAGES
    for stage in PLAIN_STAGES:
        assert figures[f"detector_speed/renders/plain_stage/{stage}/all_ms"] > 0
    assert "The same for the plain pipeline" in report
    # The other method (learned) in the same calls, and where its time goes.
    for name in sets:
        learned = figures[f"detector_speed/{name}/learned/wall_p50_ms"]
        assert figures[f"detector_speed/{name}/learned/ratio"] == pytest.approx(
            figures[f"detector_speed/{name}/plain/wall_p50_ms"] / learned, rel=1e-5)
    from balltrack.services.detector.learned import STAGES as LEARNED_STAGES
    for stage in LEARNED_STAGES:
        assert figures[f"detector_speed/renders/learned_stage/{stage}/all_ms"] > 0
    assert "Where the learned detector's time goes" in report
    # Goals: 2x on the renders, 1.5x on each photo set.
    goals = {goal["name"]: goal for goal in results["goals"]}
    assert goals["detector_speed/renders"]["passed"] == (figures["detector_speed/renders/ratio"] >= 2.0)
    photo_goals = {name for name in goals if name.startswith("detector_speed/photos/")}
    assert set(goals) == {"detector_speed/renders"} | photo_goals
    assert bool(photo_goals) == ("photos" in sets)
    for name in photo_goals:
        group = name.rsplit("/", 1)[1]
        assert goals[name]["passed"] == (figures[f"detector_speed/photos/set/{group}/ratio"] >= 1.5)


def test_plain_pipeline_splits_its_calls_into_mask_and_hough():
    from balltrack.experiments.detector_speed import PLAIN_STAGES, PlainDetector
    from balltrack.services.detector.config import DetectorConfig

    frame = np.full((240, 320, 3), (70, 80, 90), np.uint8)
    cv2.circle(frame, (160, 120), 30, (40, 200, 180), -1)
    plain = PlainDetector(DetectorConfig())
    plain.detect(frame)
    assert plain.stage_times is None  # (not profiling: nothing recorded)
    plain.stage_times = {}
    for _ in range(2):
        plain.detect(frame)
    assert set(plain.stage_times) == set(PLAIN_STAGES)
    assert all(seconds > 0 for seconds in plain.stage_times.values())


def test_detector_speed_times_every_frame_as_often():
    # 100 calls on 145 photos once timed the first 100 only: the calls make whole passes.
    from balltrack.experiments.detector_speed import calls_for, measure

    class Counting:
        def __init__(self):
            self.seen = []

        def detect(self, frame):
            self.seen.append(int(frame[0, 0]))

    frames = [np.full((2, 2), index, np.uint8) for index in range(7)]
    detectors = {"plain": Counting(), "balltrack": Counting()}
    measure(detectors, frames, repeats=10)
    for detector in detectors.values():
        assert sorted(detector.seen) == sorted(list(range(7)) * 2)
    assert (calls_for(100, 145), calls_for(300, 145), calls_for(300, 60)) == (145, 435, 300)


def test_detector_speed_splits_the_same_calls_by_photo_set(monkeypatch):
    # Each set's figures come from its own frames' calls: a clock that each call moves on by
    # its frame's value (ms) makes every call's time known.
    from balltrack.experiments import detector_speed

    class Clock:
        now = 0.0

        def perf_counter(self):
            return self.now

        process_time = perf_counter

    clock = Clock()
    monkeypatch.setattr(detector_speed, "time", clock)

    class Moving:
        def __init__(self, factor):
            self.factor = factor

        def detect(self, frame):
            clock.now += self.factor * int(frame[0, 0]) / 1000

    frames = [np.full((2, 2), value, np.uint8) for value in (1, 2, 3, 10, 20, 30, 40)]
    groups = ["a", "a", "a", "b", "b", "b", "b"]
    measured = detector_speed.measure({"plain": Moving(2), "balltrack": Moving(1)}, frames,
                                      repeats=14, groups=groups)
    assert measured["balltrack"]["wall_p50_ms"] == pytest.approx(10)  # all 14 calls
    assert set(measured["by_group"]) == {"a", "b"}
    assert measured["by_group"]["a"]["balltrack"]["wall_p50_ms"] == pytest.approx(2)
    assert measured["by_group"]["b"]["balltrack"]["wall_p50_ms"] == pytest.approx(25)
    assert measured["by_group"]["b"]["plain"]["cpu_p50_ms"] == pytest.approx(50)
    # a set of one photo timed once has its one call as its p90
    single = detector_speed.measure({"plain": Moving(2), "balltrack": Moving(1)}, frames, repeats=7,
                                    groups=["a"] * 6 + ["c"])
    assert single["by_group"]["c"]["balltrack"] == {"wall_p50_ms": pytest.approx(40), "wall_p90_ms": pytest.approx(40),
                                                     "cpu_p50_ms": pytest.approx(40), "cpu_p90_ms": pytest.approx(40)}
    assert detector_speed.photo_set_name(Path("/d"), Path("/d/set1/x/a.jpg")) == "set1"
    assert detector_speed.photo_set_name(Path("/d/set1"), Path("/d/set1/a.jpg")) == "set1"


@pytest.mark.parametrize("height, width", [(1280, 960), (960, 1280), (360, 640), (1080, 1920), (480, 640), (600, 600)])
def test_photos_become_camera_frames_with_nothing_stretched(height, width):
    # A disc in the photo's middle, drawn as a ball: it must stay round in the 640x480 frame,
    # whatever the photo's shape (portrait photos are turned, wider ones cut, not squeezed).
    from balltrack.experiments.detector_speed import camera_frame

    photo = np.zeros((height, width, 3), np.uint8)
    radius = min(height, width) // 8
    cv2.circle(photo, (width // 2, height // 2), radius, (40, 200, 180), -1)
    frame = camera_frame(photo)
    assert frame.shape == (480, 640, 3)
    _, _, disc_width, disc_height = cv2.boundingRect(cv2.inRange(frame, (20, 100, 90), (60, 255, 255)))
    assert disc_width > 20
    assert abs(disc_width - disc_height) <= 2


def test_colour_setting_scores_both_balls_with_both_methods(tmp_path):
    assert cli.main(["colour_setting", "--frames", "4", "--out", str(tmp_path), "--no-progress"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    figures = results["figures"]
    for method in ("rules", "learned"):
        for ball in ("tennis", "orange"):
            assert 0.0 <= figures[f"colour_setting/{method}/{ball}/detection_rate"] <= 1.0
        # a ball 0.4-3 m ahead in good light: both methods find the tennis ball with the defaults
        assert figures[f"colour_setting/{method}/tennis/detection_rate"] >= 0.75
    goals = {goal["name"]: goal["passed"] for goal in results["goals"]}
    assert set(goals) == {"colour_setting/rules", "colour_setting/learned"}
    for method in ("rules", "learned"):
        assert goals[f"colour_setting/{method}"] == (
            figures[f"colour_setting/{method}/orange/detection_rate"]
            >= figures[f"colour_setting/{method}/tennis/detection_rate"] - 0.05)
