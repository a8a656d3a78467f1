"""Hidden parts (services/detector/occlusion.py): balls partly behind something straight, in
drawn masks and frames."""

import math

import numpy as np
import pytest

from balltrack.services.detector.checks import CandidateMetrics, judge
from balltrack.services.detector.measure import ColourMetrics, MaskMetrics
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from balltrack.services.detector.geometry import Candidate, disc
from balltrack.services.detector.occlusion import (hidden_side_metrics, measured_in_view,
                                                   straightest_line)
from tests.unit.detector.drawing import draw_ball, draw_box, floor, to_uint8

SHAPE = (240, 320)
X, Y, RADIUS = 160.4, 120.6, 40.0
COLOUR = ColourMetrics(colourfulness=0.6, mean_hue=36.0, mean_chroma=120.0, colour_hue=36.0,
                       lit_colourfulness=0.6)


def behind_a_wall(edge_x):
    """A ball's mask cut off right of a vertical wall edge at ``edge_x``."""
    mask = disc(SHAPE, X, Y, RADIUS)
    mask[:, int(edge_x):] = 0
    return mask


def test_straightest_line_among_other_points():
    generator = np.random.default_rng(0)
    line = np.stack([np.full(60, 50.0), np.arange(60.0)], axis=1)  # x = 50
    clutter = generator.uniform(0, 100, (40, 2))
    normal_x, normal_y, offset = straightest_line(np.concatenate([line, clutter]).astype(np.float32), 1.5)
    assert abs(normal_y) < 0.01 and offset / normal_x == pytest.approx(50.0, abs=0.2)
    assert straightest_line(np.zeros((1, 2), np.float32), 1.5) is None


@pytest.mark.parametrize("edge_x", [X + 3.0, X + 15.0])
def test_a_ball_behind_a_wall_edge_is_measured_on_its_part_in_view(edge_x):
    mask = behind_a_wall(edge_x)
    candidate = Candidate(X, Y, RADIUS)
    in_view = hidden_side_metrics(candidate, mask)
    assert in_view is not None
    assert 0.5 <= in_view.visible < 0.75
    assert in_view.fill > 0.95 and in_view.support > 0.9 and in_view.leak == 0.0
    assert in_view.spread < 0.03
    # as the colour mask alone measures it, it fails (half its disc empty); in view, it passes
    config = DetectorConfig()
    plain = CandidateMetrics(MaskMetrics(visible=1.0, support=0.55, leak=0.0, fill=0.5, outside=0.0,
                                         spread=0.0), COLOUR, size=8.0)
    assert judge(plain, config) is None
    measured = measured_in_view(candidate, plain, mask, config)
    assert measured.partly_hidden and judge(measured, config) is not None


def test_no_hidden_part_without_a_straight_edge_across_the_disc():
    candidate = Candidate(X, Y, RADIUS)
    # a whole ball; a ball with a round bite out of it (another ball in front); a ball whose
    # edge across the disc is a row of bumps
    bitten = disc(SHAPE, X, Y, RADIUS) & ~disc(SHAPE, X + 45.0, Y, 30.0)
    bumpy = disc(SHAPE, X, Y, RADIUS)
    bumpy[int(Y):, :] = 0
    for step in range(int(X - RADIUS), int(X + RADIUS), 16):
        bumpy |= disc(SHAPE, step + 8.0, Y, 8.0) & disc(SHAPE, X, Y, RADIUS)
    for mask in (disc(SHAPE, X, Y, RADIUS), bitten, bumpy):
        assert hidden_side_metrics(candidate, mask) is None
    # colour past the line: an edge within the object (a seam), not where it leaves the view
    seam = behind_a_wall(X + 5.0)
    seam[:, int(X + 9):] = disc(SHAPE, X, Y, RADIUS)[:, int(X + 9):]
    assert hidden_side_metrics(candidate, seam) is None
    # too little in view: a small segment of a disc is any shape with one round side
    assert hidden_side_metrics(candidate, behind_a_wall(X - 25.0)) is None


def test_measured_in_view_leaves_alone_what_it_cannot_help():
    config = DetectorConfig()
    mask = behind_a_wall(X + 5.0)
    candidate = Candidate(X, Y, RADIUS)
    failing = MaskMetrics(visible=1.0, support=0.55, leak=0.0, fill=0.5, outside=0.0, spread=0.0)
    dull = ColourMetrics(colourfulness=0.1, mean_hue=36.0, mean_chroma=40.0, colour_hue=36.0,
                         lit_colourfulness=0.1)
    for metrics in (CandidateMetrics(failing, dull, size=8.0),       # its colour fails: no help
                    CandidateMetrics(failing, COLOUR, size=1.5),     # too small
                    CandidateMetrics(MaskMetrics(1.0, 0.95, 0.02, 0.97, 0.01, spread=0.02), COLOUR,
                                     size=8.0)):                     # a ball already
        assert measured_in_view(candidate, metrics, mask, config) is metrics


def test_detector_finds_a_ball_half_behind_a_wall_at_its_true_circle():
    # a ball beside a grey wall's vertical edge, its right part behind the wall
    u, v, radius, edge = 300.4, 260.7, 45.0, 310
    image = draw_ball(floor(), u, v, radius)
    image = draw_box(image, edge, 0, 640, 480, (70, 80, 85))
    detections = BallDetector().detect(to_uint8(image)).detections
    assert len(detections) == 1, detections
    [ball] = detections
    assert math.hypot(ball.u - u, ball.v - v) < 1.5 and abs(ball.radius_px - radius) < 1.5
    # boxes of the ball's colour behind the same edge: their other straight sides are in view
    for box in ((150, 220, 300, 280), (180, 150, 300, 350)):
        boxed = draw_box(draw_box(floor(), *box, (40, 225, 190)), 280, 0, 640, 480, (70, 80, 85))
        assert BallDetector().detect(to_uint8(boxed)).detections == []
