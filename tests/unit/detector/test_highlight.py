"""Washed-out highlights (services/detector/highlight.py) on synthetic frames."""

import dataclasses

import cv2
import numpy as np

from balltrack.services.detector.checks import CandidateMetrics
from balltrack.services.detector.measure import ColourMetrics, MaskMetrics
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from balltrack.services.detector.geometry import disc
from balltrack.services.detector.highlight import crescent_circle, needs_highlight, pale_pixels
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


def washed_out(u, v, radius, shift, size, background):
    """A ball on ``background`` whose highlight covers all of it but a crescent on the right:
    the highlight a disc of ``size`` radii, ``shift`` radii left of the ball's centre."""
    image = draw_ball(background, u, v, radius)
    cover = coverage(image.shape, u, v, radius) * coverage(image.shape, u - shift * radius, v, size * radius)
    return to_uint8(image * (1.0 - cover[..., None]) + np.array(PALE, np.float32) * cover[..., None])


def crescent_contour(u, v, radius, shift, size):
    mask = disc((240, 320), u, v, radius) & ~disc((240, 320), u - shift * radius, v, size * radius)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return max(contours, key=cv2.contourArea)


def test_a_crescent_blob_proposes_the_circle_of_its_outer_arc():
    u, v, radius = 160.4, 120.6, 40.0
    circle = crescent_circle(crescent_contour(u, v, radius, 0.45, 1.2), small_radius=5.0, max_radius=120.0)
    assert circle is not None
    assert abs(circle.x - u) < 1.0 and abs(circle.y - v) < 1.0 and abs(circle.radius - radius) < 1.0
    # too small to be looked at with its highlight
    assert crescent_circle(crescent_contour(u, v, radius, 0.45, 1.2), small_radius=25.0, max_radius=120.0) is None
    # a disc with a notch, one with a bite out of it (their enclosing circles are proposed
    # already), a strip
    notched = crescent_contour(u, v, radius, 1.6, 0.8)
    strip = np.array([[[60, 100]], [[260, 100]], [[260, 130]], [[60, 130]]], np.int32)
    bitten = crescent_contour(u, v, radius, 1.4, 1.0)
    for contour in (notched, bitten, strip):
        assert crescent_circle(contour, small_radius=5.0, max_radius=120.0) is None


def test_a_ball_washed_out_but_for_a_crescent():
    # on a dark floor, its shaded side a crescent which no enclosing or Hough circle fits
    u, v, radius = 320.4, 240.6, 40.0
    frame = washed_out(u, v, radius, 0.45, 1.2, 0.5 * floor())
    [ball] = BallDetector(DetectorConfig()).detect(frame).detections
    assert abs(ball.u - u) < 1.0 and abs(ball.v - v) < 1.0 and abs(ball.radius_px - radius) < 1.0


def test_a_candidate_whose_leak_fails_it_is_not_measured_with_its_highlight():
    config = DetectorConfig()
    colour = ColourMetrics(0.6, 36.0, 120.0, 36.0, 0.6)
    ring = MaskMetrics(visible=1.0, support=0.5, leak=0.05, fill=0.3, outside=0.05, spread=0.02)
    assert needs_highlight(CandidateMetrics(ring, colour, size=4.0), config)
    assert not needs_highlight(CandidateMetrics(ring, colour, size=1.5), config)
    # a highlight only adds mask: past this leak, no rim support can pass judge
    leaking = dataclasses.replace(ring, leak=0.3)
    assert not needs_highlight(CandidateMetrics(leaking, colour, size=4.0), config)
    crowded = dataclasses.replace(ring, outside=0.35)
    assert not needs_highlight(CandidateMetrics(crowded, colour, size=4.0), config)
