"""Washed-out highlights (services/detector/highlight.py) on synthetic frames."""

import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from balltrack.services.detector.highlight import pale_pixels
from tests.unit.detector.drawing import coverage, draw_ball, draw_box, floor, to_uint8

PALE = (215, 250, 240)  # felt in a highlight: H ~38 like the felt, S ~35, V 250


def with_highlight(image, u, v, radius, colour=PALE):
    """The ball at (u, v) turned pale over its lit upper left, up to its rim."""
    cover = coverage(image.shape, u - 0.35 * radius, v - 0.35 * radius, 0.95 * radius)
    cover *= coverage(image.shape, u, v, radius)
    return image * (1.0 - cover[..., None]) + np.array(colour, np.float32) * cover[..., None]


def test_pale_pixels_are_bright_unsaturated_and_near_white_or_of_the_targets_hue():
    patch = np.array([[PALE, (250, 250, 250), (250, 225, 215), (40, 225, 190), (110, 128, 125)]], np.uint8)
    pale = pale_pixels(patch, DetectorConfig(blur_kernel=1), brightness=200)
    # felt in a highlight, white; not pale blue, not saturated felt, not dark
    assert pale.tolist() == [[True, True, False, False, False]]


def test_a_ball_whose_highlight_reaches_its_rim():
    u, v, radius = 320.4, 240.6, 40.0
    frame = to_uint8(with_highlight(draw_ball(floor(), u, v, radius), u, v, radius))
    result = BallDetector(DetectorConfig()).detect(frame)
    # the colour mask holds a crescent only
    inside = coverage(frame.shape, u, v, 0.85 * radius) > 0.99
    assert np.count_nonzero(result.mask[inside]) < 0.4 * np.count_nonzero(inside)
    assert len(result.detections) == 1
    ball = result.detections[0]
    assert abs(ball.u - u) < 1.0 and abs(ball.v - v) < 1.0 and abs(ball.radius_px - radius) < 1.5


def test_a_crescent_on_white_paper_is_no_ball():
    # the same crescent of felt, but the white goes on past its circle
    u, v, radius = 320.4, 240.6, 40.0
    image = draw_ball(draw_box(floor(), 200, 120, 440, 360, PALE), u, v, radius)
    frame = to_uint8(with_highlight(image, u, v, radius))
    assert BallDetector(DetectorConfig()).detect(frame).detections == []
