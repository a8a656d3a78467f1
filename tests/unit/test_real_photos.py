"""The real-photos experiment's sets, scoring beside the plain pipeline, and its summary, on
drawn photos (the real sets are not in the repository; see tests/unit/detector for them)."""

import json

import cv2

from balltrack.experiments import real_photos
from balltrack.services.detector.config import DetectorConfig
from tests.unit.detector.drawing import scene


def write_set(folder, balls_per_image):
    folder.mkdir(parents=True)
    labels = {}
    for index, balls in enumerate(balls_per_image):
        name = f"{index}.png"
        cv2.imwrite(str(folder / name), scene(balls, seed=index))
        labels[name] = [{"x": u - radius, "y": v - radius, "w": 2 * radius, "h": 2 * radius}
                        for u, v, radius in balls]
    (folder / "labels.json").write_text(json.dumps(labels))


def test_a_folder_of_sets_is_every_labelled_subfolder(tmp_path):
    write_set(tmp_path / "b_set", [[(300.0, 200.0, 30.0)]])
    write_set(tmp_path / "a_set", [[(200.0, 240.0, 25.0)], []])
    (tmp_path / "unlabelled").mkdir()
    assert real_photos.photo_sets(tmp_path) == [tmp_path / "a_set", tmp_path / "b_set"]
    assert real_photos.photo_sets(tmp_path / "a_set") == [tmp_path / "a_set"]
    assert real_photos.photo_sets(tmp_path / "unlabelled") == []
    assert real_photos.photo_sets(tmp_path / "missing") == []


def test_each_set_scored_by_both_detectors_with_the_goal(tmp_path):
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)], [(420.0, 150.0, 40.0)], []])
    scores = real_photos.score_sets(real_photos.photo_sets(tmp_path), DetectorConfig())
    ours, plain = scores["drawn"]["balltrack"], scores["drawn"]["plain"]
    assert (ours["images"], ours["labelled"], ours["found"], ours["false_positives"]) == (3, 2, 2, 0)
    assert plain["images"] == 3 and plain["labelled"] == 2
    [row] = real_photos.summary_rows(scores)
    assert row[0] == "drawn" and row[-1] == "PASS"
    assert real_photos.meets_goal({"recall": 0.9, "false_positives_per_image": 0.2})
    assert not real_photos.meets_goal({"recall": 0.89, "false_positives_per_image": 0.0})
    assert not real_photos.meets_goal({"recall": 1.0, "false_positives_per_image": 0.21})


def test_command_line_summary_and_bad_folder(tmp_path, capsys):
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)]])
    assert real_photos.main([str(tmp_path), "--summary", "--no-plain"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 2 and lines[1].startswith("drawn") and lines[1].endswith("PASS")
    assert real_photos.main([str(tmp_path / "missing")]) == 2


def test_experiment_reports_a_goal_per_set(tmp_path):
    from balltrack.experiments.base import Options

    write_set(tmp_path / "photos" / "one", [[(200.0, 240.0, 25.0)]])
    write_set(tmp_path / "photos" / "two", [[(330.0, 260.0, 35.0)]])
    options = Options(out=tmp_path / "out", photos=tmp_path / "photos", progress=False)
    result = real_photos.run(options)
    assert [goal.name for goal in result.goals] == ["real_photos/one", "real_photos/two"]
    assert all(goal.passed for goal in result.goals)
    assert result.figures["real_photos/one/balltrack/recall"] == 1.0
    assert "real_photos/two/plain/recall" in result.figures
