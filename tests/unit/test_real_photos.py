"""The real-photos experiment's sets, scoring beside the plain pipeline, and its summary, on
drawn photos (the real sets are not in the repository; see tests/unit/detector for them)."""

import json

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from balltrack.experiments import photo_variants, real_photos
from balltrack.services.detector.config import DetectorConfig
from tests.unit.detector.drawing import draw_ball, scene


def write_set(folder, balls_per_image):
    folder.mkdir(parents=True)
    labels = {}
    for index, balls in enumerate(balls_per_image):
        name = f"{index}.png"
        cv2.imwrite(str(folder / name), scene(balls, seed=index))
        labels[name] = [{"x": u - radius, "y": v - radius, "w": 2 * radius, "h": 2 * radius}
                        for u, v, radius in balls]
    (folder / "labels.json").write_text(json.dumps(labels))


def write_set_with_a_pale_ball(folder):
    """A set of one image: a ball at (200, 240) and, in the labels, a second one at (420, 240)
    drawn pale (its saturation far below s_min) and in shade (too dim for the washed-out pass,
    services/detector/pale.py), which the detector misses."""
    write_set(folder, [[(200.0, 240.0, 25.0)]])
    image = cv2.imread(str(folder / "0.png"))
    pale = draw_ball(image.astype(np.float32), 420.0, 240.0, 25.0, colour=(60, 70, 68))
    cv2.imwrite(str(folder / "0.png"), np.clip(np.rint(pale), 0, 255).astype(np.uint8))
    labels = json.loads((folder / "labels.json").read_text())
    labels["0.png"].append({"x": 395.0, "y": 215.0, "w": 50.0, "h": 50.0})
    (folder / "labels.json").write_text(json.dumps(labels))


def test_a_folder_of_sets_is_every_labelled_subfolder(tmp_path):
    write_set(tmp_path / "b_set", [[(300.0, 200.0, 30.0)]])
    write_set(tmp_path / "a_set", [[(200.0, 240.0, 25.0)], []])
    (tmp_path / "unlabelled").mkdir()
    assert real_photos.photo_sets(tmp_path) == [tmp_path / "a_set", tmp_path / "b_set"]
    assert real_photos.photo_sets(tmp_path / "a_set") == [tmp_path / "a_set"]
    assert real_photos.photo_sets(tmp_path / "unlabelled") == []
    assert real_photos.photo_sets(tmp_path / "missing") == []
    # the sets the learned detector trains on are scored only when named
    write_set(tmp_path / "train_orange_ball", [[(200.0, 240.0, 25.0)]])
    assert real_photos.photo_sets(tmp_path) == [tmp_path / "a_set", tmp_path / "b_set"]
    assert real_photos.photo_sets(tmp_path / "train_orange_ball") == [tmp_path / "train_orange_ball"]


def test_each_set_scored_by_both_detectors_with_the_goal(tmp_path):
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)], [(420.0, 150.0, 40.0)], []])
    scores = real_photos.score_sets(real_photos.photo_sets(tmp_path), DetectorConfig())
    ours, plain = scores["drawn"]["balltrack"], scores["drawn"]["plain"]
    assert (ours["images"], ours["labelled"], ours["found"], ours["false_positives"]) == (3, 2, 2, 0)
    assert plain["images"] == 3 and plain["labelled"] == 2
    [row] = real_photos.summary_rows(scores)
    assert row[0] == "drawn" and row[-1] == "PASS"
    # 2 of 2 balls found: a miss would leave 0.5 < 0.9; 0 false positives on 3 images: one
    # would make 0.33 > 0.2
    assert row[-2] == "+0 balls, +0 FP"
    assert real_photos.meets_goal({"recall": 0.9, "false_positives_per_image": 0.2})
    assert not real_photos.meets_goal({"recall": 0.89, "false_positives_per_image": 0.0})
    assert not real_photos.meets_goal({"recall": 1.0, "false_positives_per_image": 0.21})


def test_learned_becomes_the_default_only_when_not_worse_on_every_set():
    def scored(found, false_positives_per_image):
        return {"found": found, "false_positives_per_image": false_positives_per_image}

    better = {"learned": scored(10, 0.1), "rules": scored(9, 0.2)}
    equal = {"learned": scored(9, 0.2), "rules": scored(9, 0.2)}
    fewer_balls = {"learned": scored(8, 0.0), "rules": scored(9, 0.2)}
    more_false_positives = {"learned": scored(10, 0.21), "rules": scored(9, 0.2)}
    assert real_photos.learned_not_worse(better) and real_photos.learned_not_worse(equal)
    assert not real_photos.learned_not_worse(fewer_balls)
    assert not real_photos.learned_not_worse(more_false_positives)
    assert real_photos.default_choice({"a": better, "b": equal}) == "learned"
    assert real_photos.default_choice({"a": better, "b": fewer_balls}) == "rules"
    assert real_photos.default_choice({}) == "rules"


def test_command_line_summary_and_bad_folder(tmp_path, capsys):
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)]])
    assert real_photos.main([str(tmp_path), "--summary", "--no-plain"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 6 and lines[1].startswith("drawn") and lines[1].endswith("PASS")
    assert lines[2].startswith("default by issue 60's rule") and lines[2].split()[-1] in ("learned", "rules")
    # then how the figures hold up when the set's images are drawn again (one image: always it)
    assert lines[3] == "" and lines[4].startswith("set") and "resampled sets meeting the goal" in lines[4]
    assert lines[5].split() == ["drawn", "1.000-1.000", "0.00-0.00", "100", "%"]
    assert real_photos.main([str(tmp_path / "missing")]) == 2
    assert capsys.readouterr().err.strip() == f"{tmp_path / 'missing'}: no such file or folder"
    # A set's labels.json names its set; another file is refused as one.
    capsys.readouterr()
    assert real_photos.main([str(tmp_path / "drawn" / "labels.json"), "--summary", "--no-plain"]) == 0
    assert capsys.readouterr().out.strip().splitlines()[1].startswith("drawn")
    photo = next((tmp_path / "drawn").glob("*.png"))
    assert real_photos.main([str(photo), "--no-plain"]) == 2
    assert capsys.readouterr().err.strip() == f"{photo}: a file, not a folder of photos with a labels.json"


def test_a_set_whose_labels_name_no_image_or_are_not_json_is_one_line_and_status_2(tmp_path, capsys):
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)]])
    capsys.readouterr()
    labels = json.loads((tmp_path / "drawn" / "labels.json").read_text())
    (tmp_path / "drawn" / "labels.json").write_text(json.dumps({**labels, "gone.png": []}))
    assert real_photos.main([str(tmp_path / "drawn"), "--summary"]) == 2
    error = capsys.readouterr().err.strip()
    assert error == f"real_photos: {tmp_path / 'drawn' / 'gone.png'}: missing or not an image (No such file or directory)"
    (tmp_path / "drawn" / "labels.json").write_text("{not json")
    assert real_photos.main([str(tmp_path / "drawn"), "--summary"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith(f"real_photos: {tmp_path / 'drawn' / 'labels.json'}: not JSON (") and "\n" not in error


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
    assert result.figures["real_photos/one/balltrack/resampled/pass_share"] == 1.0
    assert result.figures["real_photos/two/balltrack/resampled/recall_low"] == 1.0
    assert result.figures["real_photos/one/balltrack/nudged/pass_share"] == 1.0
    assert result.figures["real_photos/two/balltrack/nudged/recall_min"] == 1.0


def test_variants_move_the_boxes_with_the_image():
    image = np.zeros((100, 200, 3), np.uint8)
    image[10:30, 20:50] = (40, 200, 180)
    box = {"x": 20.0, "y": 10.0, "w": 30.0, "h": 20.0}
    flipped, [flipped_box] = photo_variants.mirrored(image, [box])
    assert flipped_box == {"x": 150.0, "y": 10.0, "w": 30.0, "h": 20.0}
    assert flipped[10:30, 150:180].min() > 0 and not flipped[:, :150].any()
    smaller, [smaller_box] = photo_variants.scaled(0.5)(image, [box])
    assert smaller.shape == (50, 100, 3) and smaller_box == {"x": 10.0, "y": 5.0, "w": 15.0, "h": 10.0}
    grey = np.full((8, 8, 3), 100, np.uint8)
    warmer, _ = photo_variants.white_balanced(red=1.1, blue=0.9)(grey, [])
    assert tuple(warmer[0, 0]) == (90, 100, 110)  # BGR: blue down, red up
    assert photo_variants.exposed(1.4)(grey, [])[0][0, 0, 0] == 140
    noisy, _ = photo_variants.noisy(6.0)(grey, [])
    assert np.array_equal(noisy, photo_variants.noisy(6.0)(grey, [])[0]) and noisy.std() > 3


def test_each_variant_is_scored_per_set(tmp_path):
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)], [(420.0, 150.0, 40.0)]])
    rows = real_photos.variant_rows(real_photos.photo_sets(tmp_path), DetectorConfig())
    assert [row[0] for row in rows] == list(photo_variants.VARIANTS)
    mirrored = dict((row[0], row[1]) for row in rows)["mirrored"]
    assert mirrored.startswith("1.000 (2/2)") and mirrored.endswith("PASS")


def test_misses_are_listed_with_why(tmp_path, capsys):
    folder = tmp_path / "drawn"
    write_set_with_a_pale_ball(folder)
    (missed,) = real_photos.missed_balls(folder, DetectorConfig())
    assert (missed["file"], missed["u"], missed["v"], missed["radius_px"]) == ("0.png", 420.0, 240.0, 25.0)
    assert "saturation" in missed["summary"] and missed["explanation"]["candidate"] is None
    assert real_photos.main([str(tmp_path), "--summary", "--no-plain", "--misses"]) == 0
    out = capsys.readouterr().out
    assert "== drawn: 1 balls of at least 20 px not found" in out
    assert "0.png ball at (420, 240), radius 25 px: no candidate" in out


def test_one_variant_is_scored_and_its_misses_listed_where_the_variant_moved_them(tmp_path, capsys):
    folder = tmp_path / "drawn"
    write_set_with_a_pale_ball(folder)
    capsys.readouterr()
    assert real_photos.main([str(folder), "--summary", "--no-plain", "--variant", "mirrored", "--misses"]) == 0
    out = capsys.readouterr().out
    # (the found ball and the pale one change sides: 640 - 200 and 640 - 420)
    assert "drawn" in out and "0.500 (1/2)" in out
    assert "0.png ball at (220, 240), radius 25 px: no candidate" in out
    (missed,) = real_photos.missed_balls(folder, DetectorConfig(), photo_variants.VARIANTS["mirrored"])
    assert (missed["u"], missed["v"]) == (220.0, 240.0)
    with pytest.raises(SystemExit) as exit:
        real_photos.main([str(folder), "--variant", "upside down"])
    assert exit.value.code == 2
    error = capsys.readouterr().err.strip()
    assert "--variant: invalid choice: 'upside down'" in error and "\n" not in error


@given(st.integers(min_value=0, max_value=3000))
def test_fewest_found_is_the_least_number_of_balls_that_meets_the_recall_goal(labelled):
    needed = real_photos.fewest_found(labelled)
    recall = needed / labelled if labelled else 1.0
    assert real_photos.meets_goal({"recall": recall, "false_positives_per_image": 0.0})
    if needed > 0:
        assert not real_photos.meets_goal({"recall": (needed - 1) / labelled, "false_positives_per_image": 0.0})


@given(st.integers(min_value=1, max_value=3000))
def test_most_false_positives_is_the_most_that_meets_the_goal(images):
    allowed = real_photos.most_false_positives(images)
    assert real_photos.meets_goal({"recall": 1.0, "false_positives_per_image": allowed / images})
    assert not real_photos.meets_goal({"recall": 1.0, "false_positives_per_image": (allowed + 1) / images})


def test_to_spare_counts_the_balls_and_false_positives_a_set_can_still_lose_or_add():
    # 78 of 86 balls (78 needed: 77 / 86 = 0.895), 15 false positives on 86 images (17 allowed)
    assert real_photos.to_spare({"found": 78, "labelled": 86, "false_positives": 15, "images": 86}) == (0, 2)
    # short of the goal: negative
    assert real_photos.to_spare({"found": 8, "labelled": 10, "false_positives": 3, "images": 10}) == (-1, -1)
    assert real_photos.spare_text({"found": 8, "labelled": 10, "false_positives": 3, "images": 10}) == "-1 balls, -1 FP"


def scored_images(per_image: list[tuple[int, int, int]]) -> dict:
    """A scored set (as ``score_folder`` returns it) of images with these (counted balls, found,
    false positives)."""
    files = {f"{index}.png": {"labelled": labelled, "found": found, "false_positives": false_positives}
             for index, (labelled, found, false_positives) in enumerate(per_image)}
    labelled = sum(entry[0] for entry in per_image)
    found = sum(entry[1] for entry in per_image)
    false_positives = sum(entry[2] for entry in per_image)
    return {"files": files, "labelled": labelled, "found": found, "false_positives": false_positives,
            "images": len(per_image), **real_photos.rates(labelled, found, false_positives, len(per_image))}


def test_resampled_sets_of_alike_images_have_the_sets_own_figures():
    figures = real_photos.resampled(scored_images([(2, 2, 0)] * 20))
    assert figures == {"recall_low": 1.0, "recall_high": 1.0, "false_positives_low": 0.0,
                       "false_positives_high": 0.0, "pass_share": 1.0}
    figures = real_photos.resampled(scored_images([(3, 2, 1)] * 20))
    assert figures["recall_low"] == figures["recall_high"] == pytest.approx(2 / 3)
    assert figures["false_positives_low"] == figures["false_positives_high"] == 1.0
    assert figures["pass_share"] == 0.0
    assert real_photos.resampled(scored_images([]))["pass_share"] == 1.0  # (no ball, no image: meets it)


def test_resampled_figures_spread_around_a_set_at_the_goals_edge():
    # 90 balls, 9 missed, each in an image of its own: recall 0.9, just enough
    at_edge = scored_images([(1, 1, 0)] * 81 + [(1, 0, 0)] * 9)
    assert real_photos.meets_goal(at_edge)
    figures = real_photos.resampled(at_edge)
    assert figures["recall_low"] < 0.9 < figures["recall_high"] <= 1.0
    # a resampled set passes when it drew at most its share of the missed images: about half do
    assert 0.3 < figures["pass_share"] < 0.7
    assert real_photos.resampled(at_edge) == figures  # (seeded: the same on every run)
    assert real_photos.resampled(at_edge, seed=10) != figures
    # the same set with a ball to spare in every resample is surer
    assert real_photos.resampled(scored_images([(1, 1, 0)] * 88 + [(1, 0, 0)] * 2))["pass_share"] > 0.99


@given(st.lists(st.tuples(st.integers(0, 5), st.integers(0, 5), st.integers(0, 3)), min_size=1, max_size=40))
def test_resampled_figures_are_shares_and_ordered_intervals(per_image):
    per_image = [(labelled, min(found, labelled), false_positives) for labelled, found, false_positives in per_image]
    figures = real_photos.resampled(scored_images(per_image), resamples=200)
    assert 0.0 <= figures["recall_low"] <= figures["recall_high"] <= 1.0
    assert 0.0 <= figures["false_positives_low"] <= figures["false_positives_high"] <= 3.0
    assert 0.0 <= figures["pass_share"] <= 1.0


def test_a_moved_frame_loses_its_first_columns_and_rows_and_its_boxes_move_with_it():
    image = np.arange(5 * 6 * 3, dtype=np.uint8).reshape(5, 6, 3)
    moved, [box] = photo_variants.shifted(2, 1)(image, [{"x": 3.0, "y": 2.0, "w": 2.0, "h": 2.0}])
    assert moved.shape == (4, 4, 3) and moved.flags.c_contiguous
    assert np.array_equal(moved[0, 0], image[1, 2])
    assert box == {"x": 1.0, "y": 1.0, "w": 2.0, "h": 2.0}


def test_specks_turn_a_share_of_the_pixels_black_or_white():
    grey = np.full((200, 300, 3), 100, np.uint8)
    speckled, boxes = photo_variants.speckled(0.02)(grey, [{"x": 1.0, "y": 2.0, "w": 3.0, "h": 4.0}])
    assert boxes == [{"x": 1.0, "y": 2.0, "w": 3.0, "h": 4.0}]
    black, white = (speckled == 0).all(axis=2).mean(), (speckled == 255).all(axis=2).mean()
    assert 0.008 < black < 0.012 and 0.008 < white < 0.012
    assert (speckled == 100).all(axis=2).mean() == pytest.approx(1 - black - white)
    assert np.array_equal(speckled, photo_variants.speckled(0.02)(grey, [])[0])


def test_nudged_copies_of_a_plain_set_all_pass(tmp_path, capsys):
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)], [(420.0, 150.0, 40.0)]])
    figures = real_photos.nudged(tmp_path / "drawn", DetectorConfig())
    assert list(figures["copies"]) == list(photo_variants.NUDGES)
    assert all(copy == {"recall": 1.0, "false_positives_per_image": 0.0} for copy in figures["copies"].values())
    assert (figures["recall_min"], figures["recall_max"], figures["false_positives_max"]) == (1.0, 1.0, 0.0)
    assert figures["pass_share"] == 1.0
    assert real_photos.nudged_text(figures) == ("1.000 / 1.000 / 1.000", "0.00 / 0.00 / 0.00", "12 of 12")
    assert real_photos.main([str(tmp_path), "--summary", "--no-plain", "--nudged"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-3].startswith("How far the balltrack figures hold") and lines[-2].startswith("set")
    assert lines[-1].split() == ["drawn", "1.000", "/", "1.000", "/", "1.000", "0.00", "/", "0.00", "/", "0.00",
                                 "12", "of", "12"]


def test_nudged_figures_spread_over_the_copies(tmp_path):
    # (times 8 the drawn frame is white, the ball with it: that copy finds nothing)
    write_set(tmp_path / "drawn", [[(200.0, 240.0, 25.0)], [(420.0, 150.0, 40.0)]])
    nudges = {"as it is": photo_variants.exposed(1.0), "white": photo_variants.exposed(8.0)}
    figures = real_photos.nudged(tmp_path / "drawn", DetectorConfig(), nudges)
    assert figures["copies"]["white"]["recall"] == 0.0
    assert (figures["recall_min"], figures["recall_median"], figures["recall_max"]) == (0.0, 0.5, 1.0)
    assert figures["pass_share"] == 0.5
    assert real_photos.nudged_text(figures)[2] == "1 of 2"


def test_average_precision_ranks_every_image_s_outcomes_together():
    # two balls found, one false positive: AP 1 when the false one ranks last, less above them
    assert real_photos.average_precision([[0.9, 1], [0.8, 1], [0.1, 0]], labelled=2) == pytest.approx(1.0)
    # (precisions 1/2 and 2/3 at the two balls; the first takes the better one after it)
    assert real_photos.average_precision([[0.9, 0], [0.8, 1], [0.7, 1]], labelled=2) == pytest.approx(2 / 3)
    assert real_photos.average_precision([[0.9, 1], [0.8, 0], [0.7, 0], [0.6, 1]], labelled=2) == pytest.approx(
        (1 + 2 / 4) / 2)
    # a ball never found caps it at the share found
    assert real_photos.average_precision([[0.9, 1]], labelled=2) == pytest.approx(0.5)
    assert real_photos.average_precision([], labelled=0) == 1.0


def test_score_image_lists_each_detection_once_best_first():
    boxes = [{"x": 80, "y": 80, "w": 40, "h": 40}]
    Detection = real_photos.Detection
    detections = [Detection(100.0, 100.0, 20.0, 0.6), Detection(101.0, 100.0, 20.0, 0.9),
                  Detection(300.0, 300.0, 20.0, 0.7), Detection(85.0, 85.0, 5.0, 0.8)]
    scored = real_photos.score_image(boxes, detections)
    # the best of the two on the ball finds it; the other is neither found nor false; the one in
    # the box's corner is not a false positive
    assert scored["outcomes"] == [[0.9, 1], [0.7, 0]]
    assert (scored["found"], scored["false_positives"]) == (1, 1)
