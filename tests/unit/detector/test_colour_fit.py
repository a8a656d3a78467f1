"""Fitting the colour mask's range to marked balls (services/detector/colour_fit.py), on drawn
frames: balls of a colour the default range (tennis yellow-green) does not admit."""

import dataclasses

import numpy as np
import pytest

from balltrack.common.config import replace_config
from balltrack.services.detector.checks import hue_in_range
from balltrack.services.detector.colour_fit import admitted, colour_samples, fit_colour
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from tests.unit.detector.drawing import draw_ball, draw_box, floor, to_uint8

ORANGE_BGR = (30, 110, 235)  # OpenCV hue ~12
YELLOWER_BGR = (30, 150, 235)  # hue ~18: an orange ball under a yellower light
RED_BGR = (40, 30, 220)      # hue ~178: a range for it wraps through 0
GREY_BGR = (150, 150, 150)
BALLS = [(160.0, 240.0, 30.0), (420.0, 300.0, 22.0)]


def frame(colour, balls=BALLS, boxes=()):
    image = floor()
    for box in boxes:
        image = draw_box(image, *box)
    for u, v, radius in balls:
        image = draw_ball(image, u, v, radius, colour=colour)
    return to_uint8(image)


def fitted(image, config=None, balls=BALLS):
    config = config or DetectorConfig()
    return fit_colour(colour_samples(image, balls, config), config)


def found(image, config):
    detections = BallDetector(config).detect(image).detections
    return sorted((round(d.u), round(d.v)) for d in detections)


@pytest.mark.parametrize("colour, hue", [(ORANGE_BGR, 12), (RED_BGR, 178)])
def test_the_fitted_range_finds_balls_the_default_one_does_not(colour, hue):
    image = frame(colour)
    fit = fitted(image)
    if fit.h_min <= fit.h_max:
        assert fit.h_min <= hue <= fit.h_max
    else:  # wraps through 0
        assert hue >= fit.h_min or hue <= fit.h_max
    assert fit.ball_admitted > 0.9 and fit.ball_admitted_before < 0.05
    assert fit.other_admitted < 0.01  # the grey floor
    assert found(image, DetectorConfig()) == []
    assert found(image, replace_config(DetectorConfig(), fit.changes())) == [(160, 240), (420, 300)]


def test_every_balls_mean_colour_lies_hue_margin_inside_the_range():
    # A small ball with a cast holds a tenth of the pixels: the pixels' hue range ends at its
    # colour, and a candidate's mean colour must lie hue_margin inside the range (checks.judge).
    small = (560.0, 120.0, 12.0)
    image = floor()
    for u, v, radius in BALLS:
        image = draw_ball(image, u, v, radius, colour=ORANGE_BGR)
    image = to_uint8(draw_ball(image, *small, colour=YELLOWER_BGR))
    config = DetectorConfig()
    samples = colour_samples(image, BALLS + [small], config)
    assert len(samples.ball_hues) == 3 and max(samples.ball_hues) > 16
    fitted_config = replace_config(config, fit_colour(samples, config).changes())
    assert all(hue_in_range(hue, fitted_config, config.hue_margin) for hue in samples.ball_hues)


def test_the_red_range_wraps_through_zero():
    fit = fitted(frame(RED_BGR))
    assert fit.h_min > fit.h_max


def test_background_of_the_balls_colour_is_counted():
    # an orange box beside the balls: the fitted range admits it, and says so
    image = frame(ORANGE_BGR, boxes=[(520, 40, 620, 140, ORANGE_BGR)])
    fit = fitted(image)
    assert fit.other_admitted > 0.02
    assert fitted(frame(ORANGE_BGR)).other_admitted < fit.other_admitted


def test_grey_balls_are_no_basis_for_a_range():
    with pytest.raises(ValueError, match="coloured"):
        fitted(frame(GREY_BGR))


def test_frames_with_no_ball_large_enough_are_no_basis_for_a_range():
    with pytest.raises(ValueError, match="no marked ball"):
        fitted(frame(ORANGE_BGR), balls=[])
    with pytest.raises(ValueError, match="no marked ball"):
        fitted(frame(ORANGE_BGR), balls=[(160.0, 240.0, 3.0)])


def test_frames_wider_than_the_work_size_are_sampled_as_the_detector_sees_them():
    image = frame(ORANGE_BGR)
    config = DetectorConfig()
    small = dataclasses.replace(config, work_width=320)
    # (half the work size: the same pixels, a quarter as many)
    whole, shrunk = colour_samples(image, BALLS, config).ball, colour_samples(image, BALLS, small).ball
    assert 0.2 < len(shrunk) / len(whole) < 0.3
    assert abs(float(np.median(whole[:, 0])) - float(np.median(shrunk[:, 0]))) <= 1


def test_admitted_applies_hue_saturation_and_chroma():
    # (chroma as the mask rounds it: S 100 x V 1 / 255 is 0 units, under min_chroma 1.5 -> 1)
    pixels = np.array([[30, 200, 200], [30, 50, 200], [60, 200, 200], [30, 100, 1], [175, 200, 200]], np.uint8)
    assert admitted(pixels, 25, 50, 80, 255, 1.5).tolist() == [True, False, False, False, False]
    assert admitted(pixels, 170, 40, 80, 255, 1.5).tolist() == [True, False, False, False, True]
