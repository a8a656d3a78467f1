"""The colour mask's regions of interest (services/detector/regions.py)."""

import cv2
import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from balltrack.services.detector.mask import ColourMasker
from balltrack.services.detector.regions import (HALF_VALUE_SIGMA, PartEqualiser, coarse_boxes,
                                                 coarse_hue_table, doubled_part, half_value, regions_apply,
                                                 source_span)
from tests.unit.detector.drawing import scene


def test_doubled_part_is_the_part_of_the_doubled_plane():
    rng = np.random.default_rng(1)
    small = rng.integers(0, 256, (60, 80), dtype=np.uint8)
    doubled = cv2.resize(small, (160, 120), interpolation=cv2.INTER_LINEAR)
    for _ in range(200):
        top, left = rng.integers(0, 119), rng.integers(0, 159)
        rows = slice(top, int(rng.integers(top + 1, 121)))
        columns = slice(left, int(rng.integers(left + 1, 161)))
        span = source_span(rows, columns, 60, 80)
        assert np.array_equal(doubled_part(small[span], span, rows, columns), doubled[rows, columns])


def test_half_value_of_a_part_is_the_whole_planes_part():
    rng = np.random.default_rng(2)
    frame = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    whole = half_value(frame)
    value = np.max(cv2.resize(frame, (80, 60), interpolation=cv2.INTER_AREA), axis=2)
    assert np.array_equal(whole, cv2.GaussianBlur(value, (3, 3), HALF_VALUE_SIGMA))
    for _ in range(100):
        top, left = int(rng.integers(0, 59)), int(rng.integers(0, 79))
        rows = slice(top, int(rng.integers(top + 1, 61)))
        columns = slice(left, int(rng.integers(left + 1, 81)))
        assert np.array_equal(half_value(frame, rows, columns), whole[rows, columns])


def test_part_equaliser_matches_the_whole_frame_route_within_rounding():
    image = scene([(200.0, 150.0, 20.0), (500.0, 380.0, 35.0)], brightness=0.6)
    masker = ColourMasker(DetectorConfig())  # clahe 2.0 on an 8x8 grid
    value = cv2.extractChannel(cv2.cvtColor(cv2.GaussianBlur(image, (5, 5), 0), cv2.COLOR_BGR2HSV), 2)
    whole = cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(half_value(image))
    assert np.array_equal(cv2.resize(whole, (640, 480), interpolation=cv2.INTER_LINEAR),
                          masker.equalise(value, image))
    equaliser = PartEqualiser(cv2.createCLAHE(clipLimit=2.0), 8, image)
    rows, columns = slice(60, 95), slice(85, 120)
    part = equaliser.part(rows, columns)
    # (OpenCV interpolates between tiles in float: a part's weights may round differently)
    assert np.abs(part.astype(int) - whole[rows, columns]).max() <= 1
    # most of the plane: equalised whole
    assert np.array_equal(equaliser.part(slice(0, 240), slice(0, 300)), whole[:, :300])


def test_coarse_boxes_hold_the_balls_and_nothing_else():
    config = DetectorConfig()
    image = scene([(200.0, 150.0, 4.0), (500.0, 380.0, 40.0)])
    boxes = coarse_boxes(image, coarse_hue_table(config), config)
    assert len(boxes) == 2
    for u, v, radius in ((200.0, 150.0, 4.0), (500.0, 380.0, 40.0)):
        assert any(left <= u - radius and right >= u + radius and top <= v - radius
                   and bottom >= v + radius for left, top, right, bottom in boxes)
    covered = sum((right - left) * (bottom - top) for left, top, right, bottom in boxes)
    assert covered < 0.1 * image.shape[0] * image.shape[1]


def test_a_frame_mostly_of_ball_colour_is_done_whole():
    config = DetectorConfig()
    image = scene([(320.0, 240.0, 290.0)])
    assert coarse_boxes(image, coarse_hue_table(config), config) is None


def test_regions_apply_to_wide_even_frames_only():
    assert regions_apply((480, 640, 3))
    assert not regions_apply((240, 320, 3)) and not regions_apply((480, 641, 3))


def test_mask_by_regions_is_the_whole_frames():
    masker = ColourMasker(DetectorConfig())
    # a ball cut by the frame's edge, one whose blob reaches past its first box, a small one
    image = scene([(8.0, 200.0, 30.0), (320.0, 240.0, 60.0), (500.0, 100.0, 5.0)])
    assert masker._mask_in_regions(image, 1.0) is not None
    planes = masker.planes(image)
    whole, _, _ = masker._colour_mask(image, 1.0, 5, DetectorConfig().min_chroma, opening=True)
    assert np.count_nonzero(whole) > 0
    assert np.count_nonzero(planes.mask != whole) <= 0.002 * np.count_nonzero(whole)


def test_detect_in_given_regions_computes_the_mask_only_there():
    detector = BallDetector(DetectorConfig())
    image = scene([(200.0, 150.0, 20.0), (500.0, 380.0, 35.0)])
    everywhere = detector.detect(image)
    assert sorted((round(d.u), round(d.v)) for d in everywhere.detections) == [(200, 150), (500, 380)]
    # a box around the first ball only: the second is not in the mask, so not found
    around_first = detector.detect(image, regions=[(160, 110, 240, 190)])
    assert [(round(d.u), round(d.v)) for d in around_first.detections] == [(200, 150)]
    assert np.count_nonzero(around_first.mask[300:, 400:]) == 0
    assert np.count_nonzero(around_first.mask[110:190, 160:240]) > 0
