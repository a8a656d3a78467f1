"""Balls in front of other balls (services/detector/front.py): circles on the frame's
brightness inside a blob with no waist."""

import math

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from balltrack.services.detector.geometry import Candidate, rim_directions
from balltrack.services.detector.front import front_balls, may_overlap, rim_edge_share
from balltrack.services.detector.proposals import fill_holes, frame_search
from tests.unit.detector.drawing import TENNIS_BGR, coverage, draw_ball, floor, to_uint8

BACK, FRONT = (300.0, 222.0, 24.0), (306.0, 244.0, 24.0)


def blob_search(frame):
    """The frame's search and its one blob's contour."""
    config = DetectorConfig()
    planes = BallDetector(config)._masker.planes(frame)
    contours, mask = fill_holes(planes.mask, planes.extent)
    [contour] = [contour for contour in contours if cv2.contourArea(contour) > 500]
    return frame_search(planes, config, 1.0, mask), mask, contour


def felt_ball(image, u, v, radius, colour=TENNIS_BGR, shading=0.2):
    """A ball whose felt scatters the light: mostly even colour, ``shading`` of draw_ball's."""
    shaded = draw_ball(np.zeros_like(image), u, v, radius, colour)
    cover = coverage(image.shape, u, v, radius)[..., None]
    even = np.array(colour, np.float32) * 0.85 * cover
    return image * (1.0 - cover) + shading * shaded + (1.0 - shading) * even


def in_shadow(colour, light=0.7):
    return tuple(light * channel for channel in colour)


def test_the_ball_in_front_of_another_is_found_by_its_rim_on_the_frame():
    # the pair is one capsule of colour (centres 23 px apart, radius 24): no waist in the mask;
    # the front ball's rim shows against the ball behind it, which lies in its shadow
    frame = to_uint8(felt_ball(felt_ball(floor(), *BACK, colour=in_shadow(TENNIS_BGR)), *FRONT))
    search, mask, contour = blob_search(frame)
    found = front_balls(contour, search, mask, 7.5)
    assert found
    ball, metrics = max(found, key=lambda item: item[1].front_edges)
    assert math.hypot(ball.x - FRONT[0], ball.y - FRONT[1]) < 3.0
    assert abs(ball.radius - FRONT[2]) < 3.0
    assert metrics.front_edges >= 0.8


def test_a_blob_of_even_colour_holds_no_ball_in_front():
    frame = to_uint8(felt_ball(felt_ball(floor(), *BACK, shading=0.0), *FRONT, shading=0.0))
    search, mask, contour = blob_search(frame)
    assert front_balls(contour, search, mask, 7.5) == []


def test_a_rim_is_an_edge_only_across_it():
    size = 101
    levels = np.zeros((size, size), np.float32)
    cv2.circle(levels, (50, 50), 30, 100.0, -1)
    levels = cv2.GaussianBlur(levels, (5, 5), 0)
    gradient_x = cv2.Sobel(levels, cv2.CV_32F, 1, 0) / 8.0
    gradient_y = cv2.Sobel(levels, cv2.CV_32F, 0, 1) / 8.0
    assert rim_edge_share(gradient_x, gradient_y, 50.0, 50.0, 30.0, 5.0) > 0.95
    # a circle of the same size beside it crosses the edge only where they meet
    assert rim_edge_share(gradient_x, gradient_y, 50.0, 20.0, 30.0, 5.0) < 0.4


def test_the_detector_reports_the_front_ball_not_one_circle_round_the_pair():
    frame = to_uint8(felt_ball(felt_ball(floor(), *BACK, colour=in_shadow(TENNIS_BGR)), *FRONT))
    detections = BallDetector().detect(frame).detections
    front = min(detections, key=lambda ball: math.hypot(ball.u - FRONT[0], ball.v - FRONT[1]))
    assert math.hypot(front.u - FRONT[0], front.v - FRONT[1]) < 2.0
    assert abs(front.radius_px - FRONT[2]) < 2.0


def test_the_ball_behind_is_found_beside_the_front_one():
    # it overlaps the front ball's circle by more than two separate balls may (0.3), as far
    # as it is hidden behind it
    frame = to_uint8(felt_ball(felt_ball(floor(), *BACK, colour=in_shadow(TENNIS_BGR)), *FRONT))
    detections = BallDetector().detect(frame).detections
    assert len(detections) == 2
    for u, v, radius in (BACK, FRONT):
        ball = min(detections, key=lambda found: math.hypot(found.u - u, found.v - v))
        assert math.hypot(ball.u - u, ball.v - v) < 2.0
        assert abs(ball.radius_px - radius) < 2.0


def test_only_a_ball_in_front_may_hide_much_of_another():
    first, second = Candidate(100.0, 100.0, 20.0), Candidate(100.0, 118.0, 20.0)  # overlap ~0.43
    assert not may_overlap(first, second)
    assert may_overlap(first, Candidate(100.0, 118.0, 20.0, in_front=True))
    assert may_overlap(first, Candidate(100.0, 110.0, 20.0, in_front=True))  # ~0.68: mostly hidden
    assert not may_overlap(first, Candidate(100.0, 105.0, 20.0, in_front=True))  # one ball twice


def numpy_rim_edge_share(gradient_x, gradient_y, x, y, radius, step):
    """rim_edge_share in numpy array operations: the reference."""
    samples = int(min(96, max(24, 2 * math.pi * radius)))
    cos, sin = rim_directions(samples)[:2]
    height, width = gradient_x.shape
    strongest = np.zeros(samples, np.float32)
    seen = np.zeros(samples, bool)
    for offset in (-1.0, 0.0, 1.0):
        columns = np.rint(x + (radius + offset) * cos).astype(np.intp)
        rows = np.rint(y + (radius + offset) * sin).astype(np.intp)
        inside = (columns >= 0) & (columns < width) & (rows >= 0) & (rows < height)
        columns, rows = np.clip(columns, 0, width - 1), np.clip(rows, 0, height - 1)
        across = np.abs(gradient_x[rows, columns] * cos + gradient_y[rows, columns] * sin)
        strongest = np.maximum(strongest, np.where(inside, across, 0.0))
        seen |= inside
    if not seen.any():
        return 0.0
    return float(np.count_nonzero(strongest[seen] >= step)) / samples


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(-20, 80), st.floats(-20, 60), st.floats(2, 60),
       st.one_of(st.floats(0, 3), st.integers(0, 3).map(float)))
def test_the_rim_edge_share_is_the_array_operations_one(seed, x, y, radius, step):
    # (circles inside the planes, across their edges and outside them; whole gradients and
    # steps, so that some changes across the rim are exactly the step)
    rng = np.random.default_rng(seed)
    gradient_x, gradient_y = (rng.integers(-3, 4, (48, 64)).astype(np.float32) for _ in range(2))
    assert rim_edge_share(gradient_x, gradient_y, x, y, radius, step) == \
        numpy_rim_edge_share(gradient_x, gradient_y, x, y, radius, step)
