"""Washed-out balls (services/detector/pale.py) on synthetic frames."""

import cv2
import numpy as np
import pytest

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from balltrack.services.detector.mask import ColourMasker
from balltrack.services.detector.regions import coarse_hue_table, pale_in_sample
from tests.unit.detector.drawing import draw_ball, draw_box, floor, to_uint8

# Felt in direct sun: H ~37 like the felt, but S ~65 (s_min is 80), V 235.
WASHED_OUT = (175, 235, 220)
U, V, RADIUS = 300.3, 220.6, 30.0


def found(frame, config=None):
    return BallDetector(config or DetectorConfig()).detect(frame).detections


def hsv_of(colour):
    return cv2.cvtColor(np.array([[colour]], np.uint8), cv2.COLOR_BGR2HSV)[0, 0]


def test_the_washed_out_colour_is_of_the_balls_hue_below_the_masks_saturation():
    hue, saturation, _ = hsv_of(WASHED_OUT)
    config = DetectorConfig()
    assert config.h_min <= hue <= config.h_max and config.pale_s_min <= saturation < config.s_min


def test_a_washed_out_ball_on_grey_ground_is_found():
    frame = to_uint8(draw_ball(floor(), U, V, RADIUS, WASHED_OUT))
    assert BallDetector(DetectorConfig()).detect(frame).mask[round(V), round(U)] == 0  # not in the colour mask
    balls = found(frame)
    assert len(balls) == 1
    ball = balls[0]
    assert abs(ball.u - U) < 1.5 and abs(ball.v - V) < 1.5 and abs(ball.radius_px - RADIUS) < 2.0
    assert found(frame, DetectorConfig(pale_s_min=0)) == []  # the pale pass is what finds it


def test_a_washed_out_ball_beside_a_vivid_one_is_found_too():
    image = draw_ball(floor(), U, V, RADIUS, WASHED_OUT)
    frame = to_uint8(draw_ball(image, 470.2, 300.7, 25.0))
    balls = sorted(found(frame), key=lambda ball: ball.u)
    assert len(balls) == 2
    for ball, (u, v) in zip(balls, ((U, V), (470.2, 300.7))):
        assert abs(ball.u - u) < 1.5 and abs(ball.v - v) < 1.5


@pytest.mark.parametrize("what, frame", [
    # a patch of a pale surface of the same colour: not alone
    ("on a surface of its colour", lambda: to_uint8(draw_ball(
        draw_box(floor(), 150, 100, 450, 380, (190, 232, 222)), U, V, RADIUS, WASHED_OUT))),
    # the same colour on a square: not round
    ("square", lambda: to_uint8(draw_box(floor(), 270, 190, 330, 250, WASHED_OUT))),
    # in shadow, far darker than the frame's bright level: not washed out but dim
    ("in shadow", lambda: to_uint8(draw_box(draw_ball(floor() * 0.5, U, V, RADIUS, np.array(WASHED_OUT) * 0.3),
                                            20, 20, 120, 120, (230, 230, 230)))),
    # pale blue, a hue out of range
    ("pale blue", lambda: to_uint8(draw_ball(floor(), U, V, RADIUS, (235, 205, 175)))),
    # too small for its shape to tell
    ("small", lambda: to_uint8(draw_ball(floor(), U, V, 6.0, WASHED_OUT))),
])
def test_pale_blobs_that_are_no_washed_out_ball(what, frame):
    assert found(frame()) == [], what


def test_frames_that_may_hold_a_washed_out_ball_are_done_whole():
    config = DetectorConfig()
    hue_table = coarse_hue_table(config)
    with_ball = to_uint8(draw_ball(floor(), U, V, RADIUS, WASHED_OUT))
    for frame, expected in ((with_ball, True), (to_uint8(floor()), False)):
        sample = cv2.cvtColor(np.ascontiguousarray(frame[::4, ::4]), cv2.COLOR_BGR2HSV)
        assert pale_in_sample(sample, hue_table, config, bright=120) is expected
    # too dim to be washed out
    sample = cv2.cvtColor(np.ascontiguousarray(with_ball[::4, ::4]), cv2.COLOR_BGR2HSV)
    assert pale_in_sample(sample, hue_table, config, bright=250) is False
    assert pale_in_sample(sample, hue_table, DetectorConfig(pale_s_min=0), bright=120) is False
    # so its colour mask is made whole (no extent), with the pale plane beside it
    planes = ColourMasker(config).planes(with_ball)
    assert planes.extent is None and planes.pale is not None and planes.pale[round(V), round(U)] == 255


def test_the_pale_pass_is_off_at_s_min_and_above():
    frame = to_uint8(draw_ball(floor(), U, V, RADIUS, WASHED_OUT))
    # (a colour range fitted with a low saturation floor keeps working: the pass is off)
    config = DetectorConfig(pale_s_min=20, s_min=20)
    assert ColourMasker(config).planes(frame).pale is None
    assert len(found(frame, config)) == 1  # (its saturation ~65 passes that range's mask)
