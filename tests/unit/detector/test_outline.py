"""The sub-pixel outline (services/detector/outline.py) on drawn frames and edges."""

import math

import numpy as np
import pytest

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, rim_directions
from balltrack.services.detector.mask import ColourMasker
from balltrack.services.detector import outline
from balltrack.services.detector.outline import narrow_fit, silhouette
from tests import harness
from tests.unit.detector.drawing import floor, scene, to_uint8


def planes_and_mask_circle(image):
    planes = ColourMasker(DetectorConfig()).planes(image)
    ys, xs = np.nonzero(planes.mask == 255)
    # the colour mask's own circle: centred on the blob, its radius from its area
    return planes, Candidate(float(xs.mean()), float(ys.mean()), math.sqrt(xs.size / math.pi))


@pytest.mark.parametrize("radius", [6.0, 15.0, 40.0])
def test_silhouette_finds_the_outline_of_a_blurred_ball(radius):
    u, v = 160.35, 120.6
    image = harness.draw_ball(to_uint8(floor(320, 240)), u, v, radius)
    planes, mask_circle = planes_and_mask_circle(image)
    outline = silhouette(planes.frame, planes.mask, planes.gain, planes.reference, mask_circle, [])
    assert outline is not None
    x, y, found = outline
    # the colour mask's circle is 0.6-0.75 px too large (blur spreads the colour)
    assert mask_circle.radius - radius > 0.5
    assert math.hypot(x - u, y - v) < 0.2
    assert abs(found - radius) < 0.25


def test_silhouette_of_a_ball_cut_by_the_frame_edge():
    u, v, radius = 12.4, 120.2, 25.0
    planes, mask_circle = planes_and_mask_circle(scene([(u, v, radius)], width=320, height=240))
    # start from a poor circle: the blob's centre is well inside the frame
    outline = silhouette(planes.frame, planes.mask, planes.gain, planes.reference,
                         Candidate(mask_circle.x, v, radius + 1.5), [])
    x, y, found = outline
    assert math.hypot(x - u, y - v) < 0.75 and abs(found - radius) < 0.75


def test_no_outline_without_an_edge_in_the_frame():
    # a colour mask over a frame that shows nothing there
    planes = ColourMasker(DetectorConfig()).planes(scene([(160.0, 120.0, 20.0)], width=320, height=240))
    blank = np.full_like(planes.frame, 120)
    assert silhouette(blank, planes.mask, 1.0, 120.0, Candidate(160.0, 120.0, 20.0), []) is None
    # a circle with no colour under it
    assert silhouette(planes.frame, planes.mask, 1.0, 120.0, Candidate(40.0, 40.0, 10.0), []) is None


def test_the_outline_of_a_ball_touching_another():
    first, second = (130.3, 120.2, 30.0), (130.3 + 30.0 + 18.0, 124.2, 18.0)
    image = harness.draw_ball(harness.draw_ball(to_uint8(floor(320, 240)), *first), *second)
    planes = ColourMasker(DetectorConfig()).planes(image)
    ball, neighbour = Candidate(*first), Candidate(*second)
    x, y, radius = silhouette(planes.frame, planes.mask, planes.gain, planes.reference, ball,
                              [neighbour])
    assert math.hypot(x - first[0], y - first[1]) < 0.5 and abs(radius - first[2]) < 0.9


def test_narrow_fit_on_edges_seen_from_another_centre():
    # edges of a circle (12.3, 8.1, r 9) seen along 36 rays from (11.5, 8.6), blur sigma 0.8
    centre_x, centre_y, radius, sigma = 12.3, 8.1, 9.0, 0.8
    directions = rim_directions(36)[:2]
    from_x, from_y = 11.5, 8.6
    # where each ray from (from_x, from_y) meets the circle
    offset_x, offset_y = from_x - centre_x, from_y - centre_y
    along = directions[0] * offset_x + directions[1] * offset_y
    reach = -along + np.sqrt(along ** 2 - (offset_x ** 2 + offset_y ** 2 - radius ** 2))
    px, py = from_x + directions[0] * reach, from_y + directions[1] * reach
    widths = np.full(px.size, sigma)
    ok, x, y, found = narrow_fit(px, py, widths, directions, from_x, from_y, 9.4, 36, 0.7)
    assert ok and math.hypot(x - centre_x, y - centre_y) < 1e-6
    # (the blur correction: the 50 % contour lies sigma^2 / 2r inside the edge)
    assert found == pytest.approx(radius + sigma ** 2 / (2 * radius), abs=1e-6)
    # the same edges on one side only prove nothing
    side = directions[0] > 0.5
    assert not narrow_fit(px[side], py[side], widths[side], directions[:, side], from_x, from_y,
                          9.4, 36, 0.7)[0]


@pytest.mark.parametrize("radius", [6.0, 9.5, 15.0, 24.0])
def test_narrow_fit_on_the_wide_rounds_edges_agrees_with_a_narrow_round(radius):
    u, v = 160.35, 120.6
    image = harness.draw_ball(to_uint8(floor(320, 240)), u, v, radius)
    planes, mask_circle = planes_and_mask_circle(image)
    arguments = (planes.frame, planes.mask, planes.gain, planes.reference, mask_circle, [])
    reused_rounds, narrow_rounds = [], []
    reused = silhouette(*arguments, trace=reused_rounds)
    assert reused_rounds[-1] == outline.ROUND_OUTCOMES[outline.FOUND_REUSED], reused_rounds
    narrow = silhouette(*arguments, reuse_edges=False, trace=narrow_rounds)  # a narrow round of its own
    assert narrow_rounds[-1] == outline.ROUND_OUTCOMES[outline.FOUND], narrow_rounds
    assert math.hypot(reused[0] - narrow[0], reused[1] - narrow[1]) < 0.1
    assert abs(reused[2] - narrow[2]) < 0.1
    assert math.hypot(reused[0] - u, reused[1] - v) < 0.2 and abs(reused[2] - radius) < 0.25
