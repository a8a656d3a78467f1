"""Explaining a place of a frame (services/detector/explain.py), on drawn frames."""

import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector, Detection, DetectionResult
from balltrack.services.detector.explain import explain_place, summary
from tests.unit.detector.drawing import draw_ball, draw_box, floor, to_uint8

PALE_BGR = (170, 200, 195)  # the felt's hue, washed out: saturation ~38, far below s_min 80


def explained(image, places, config=None):
    config = config or DetectorConfig()
    result, judged = BallDetector(config).detect_judged(image)
    return [explain_place(image, result, judged, config, *place) for place in places]


def test_a_found_ball_a_washed_out_one_and_a_square():
    image = floor()
    image = draw_ball(image, 160.0, 240.0, 30.0)
    image = draw_ball(image, 330.0, 240.0, 30.0, colour=PALE_BGR)
    image = draw_box(image, 460, 200, 540, 280, (40, 225, 190))  # felt-coloured, square
    places = [(160.0, 240.0, 30.0), (330.0, 240.0, 30.0), (500.0, 240.0, 40.0)]
    # (by default the washed-out pass finds the pale ball, round and alone on grey: services/detector/pale.py)
    assert explained(to_uint8(image), places)[1]["found"] is not None
    found, pale, square = explained(to_uint8(image), places, DetectorConfig(pale_s_min=0))
    assert found["found"] is not None and abs(found["found"]["radius_px"] - 30.0) < 2.0
    assert summary(found).startswith("found at (160, 240)")
    # no colour mask on the pale ball: its saturation is what fails
    assert pale["found"] is None and pale["candidate"] is None and pale["colour"]["mask_share"] == 0.0
    assert pale["colour"]["saturation"] < 60 and 30 < pale["colour"]["hue"] < 45
    assert [reason.split()[0] for reason in pale["colour"]["failed"]] == ["saturation"]
    assert "saturation" in summary(pale) and summary(pale).startswith("no candidate")
    # the square is colour all over, and its candidate circle fails on shape
    assert square["found"] is None and square["colour"]["failed"] == []
    assert square["colour"]["mask_share"] == 1.0
    assert square["candidate"] is not None and square["candidate"]["score"] is None
    assert square["candidate"]["failed"] and summary(square).startswith("candidate (")


def test_without_a_radius_the_place_is_inside_a_ball_or_not():
    image = to_uint8(draw_ball(floor(), 200.0, 200.0, 25.0))
    inside, outside = explained(image, [(215.0, 190.0), (300.0, 300.0)])
    assert inside["found"] is not None
    assert outside["found"] is None and outside["candidate"] is None
    assert outside["colour"]["failed"]  # grey floor: neither the hue nor the saturation of felt


def test_a_place_outside_the_frame_and_a_grey_frame():
    image = np.full((120, 160), 90, np.uint8)
    (far,) = explained(image, [(500.0, 500.0)])
    assert far["found"] is None and far["candidate"] is None
    assert far["colour"]["failed"] == ["the place is outside the frame"]
    assert summary(far) == "no candidate; the place is outside the frame"


def test_a_detection_off_centre_around_the_place_is_named():
    config = DetectorConfig()
    image = to_uint8(floor(200, 160))
    result = DetectionResult(detections=[Detection(u=100.0, v=80.0, radius_px=30.0, score=0.9)],
                             mask=np.zeros((160, 200), np.uint8))
    # a labelled ball of radius 12 px centred 18 px from the detection's centre: not found
    # (found means within 6 px), but inside the detection's disc
    explanation = explain_place(image, result, [], config, 118.0, 80.0, 12.0)
    assert explanation["found"] is None
    assert explanation["covered_by"] == {"u": 100.0, "v": 80.0, "radius_px": 30.0, "score": 0.9,
                                         "offset_px": 18.0}
    assert summary(explanation).startswith("inside the detection at (100, 80), radius 30.0 px, "
                                           "whose centre is 18 px away")
    near = explain_place(image, result, [], config, 103.0, 80.0, 12.0)
    assert near["found"] is not None and near["covered_by"] is None
    assert explain_place(image, result, [], config, 160.0, 80.0, 12.0)["covered_by"] is None


def test_a_place_with_no_candidate_of_its_own_names_the_off_centre_circle_judged_around_it():
    config = DetectorConfig()
    image = draw_ball(floor(), 160.0, 240.0, 30.0)
    image = to_uint8(draw_box(image, 460, 200, 540, 280, (40, 225, 190)))  # felt-coloured, square
    result, judged = BallDetector(config).detect_judged(image)
    # a small ball labelled 15 px off the square's centre: its colour passes, and the circle
    # judged there is the square's, too far off to be this ball's, and failing on shape
    square = explain_place(image, result, judged, config, 515.0, 240.0, 10.0)
    assert square["candidate"] is None and square["colour"]["failed"] == []
    around = square["around"]
    assert around is not None and around["score"] is None and around["failed"]
    assert abs(around["u"] - 500.0) < 4 and 10.0 < around["offset_px"] <= around["radius_px"]
    assert summary(square).startswith("no candidate; the colour here")
    assert f"the circle judged around it is off centre: ({around['u']:.0f}, {around['v']:.0f})" in summary(square)
    assert summary(square).endswith(around["failed"][-1])
    # one that passed (the ball's, with the detection itself left out of the result)
    undetected = DetectionResult(detections=[], mask=result.mask)
    ball = explain_place(image, undetected, judged, config, 178.0, 240.0, 8.0)
    assert ball["around"] is not None and ball["around"]["score"] is not None
    assert summary(ball).endswith("px away: passed, not kept")
    # a place no judged circle holds has none
    assert explain_place(image, result, judged, config, 300.0, 100.0, 10.0)["around"] is None
