"""Outline arcs (services/detector/arcs.py): circles of the round pieces of drawn blobs."""

import math

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from balltrack.services.detector.arcs import arc_proposals, deepest_cut, outline_pieces
from balltrack.services.detector.geometry import disc

SHAPE = (240, 320)


def nearest(circles, x, y):
    return min(circles, key=lambda circle: math.hypot(circle.x - x, circle.y - y))


def test_a_ball_partly_behind_another_is_proposed_by_its_arc():
    # the back ball shows about half its disc beside the front one
    back, front = (120.0, 110.0, 26.0), (150.0, 130.0, 24.0)
    mask = disc(SHAPE, *back) | disc(SHAPE, *front)
    circles = arc_proposals(mask, 0, 0, 5.0, 120.0)
    for x, y, radius in (back, front):
        found = nearest(circles, x, y)
        assert math.hypot(found.x - x, found.y - y) < 2.0
        assert abs(found.radius - radius) < 1.5


def test_circles_are_given_in_frame_coordinates_and_within_the_radius_limits():
    mask = disc(SHAPE, 100.0, 100.0, 20.0) | disc(SHAPE, 135.0, 100.0, 20.0)
    [first, second] = sorted(arc_proposals(mask, 10, 30, 5.0, 120.0), key=lambda circle: circle.x)
    assert math.hypot(first.x - 110.0, first.y - 130.0) < 2.0
    assert math.hypot(second.x - 145.0, second.y - 130.0) < 2.0
    assert arc_proposals(mask, 0, 0, 25.0, 120.0) == []  # balls smaller than the limit
    assert arc_proposals(mask, 0, 0, 5.0, 15.0) == []    # or larger


def test_a_convex_blob_has_no_pieces():
    assert outline_pieces(disc(SHAPE, 160.0, 120.0, 30.0)) == []
    box = np.zeros(SHAPE, np.uint8)
    box[60:160, 100:220] = 255
    assert outline_pieces(box) == []


def test_straight_and_ragged_outlines_propose_no_circle():
    # an L of two bars: concave at its inner corner, but its pieces are straight
    shape_l = np.zeros(SHAPE, np.uint8)
    shape_l[40:200, 60:100] = 255
    shape_l[160:200, 60:260] = 255
    assert outline_pieces(shape_l)
    assert arc_proposals(shape_l, 0, 0, 5.0, 120.0) == []
    # a star: its points are lobes too sharp and short to be arcs of a circle
    angles = np.linspace(0, 2 * math.pi, 16, endpoint=False)
    lengths = np.where(np.arange(16) % 2 == 0, 80.0, 30.0)
    points = np.stack([160 + lengths * np.cos(angles), 120 + lengths * np.sin(angles)], axis=1)
    star = np.zeros(SHAPE, np.uint8)
    cv2.fillPoly(star, [np.rint(points).astype(np.int32)], 255)
    assert arc_proposals(star, 0, 0, 5.0, 120.0) == []


def test_balls_in_a_row_are_cut_apart_on_both_sides():
    # the convex hull's long edges each span two concave points: cuts within cuts
    centres = [(80.0, 120.0), (116.0, 120.0), (152.0, 120.0), (188.0, 120.0)]
    mask = np.zeros(SHAPE, np.uint8)
    for x, y in centres:
        mask |= disc(SHAPE, x, y, 20.0)
    circles = arc_proposals(mask, 0, 0, 5.0, 120.0)
    for x, y in centres:
        found = nearest(circles, x, y)
        assert math.hypot(found.x - x, found.y - y) < 2.0 and abs(found.radius - 20.0) < 1.5


def test_overlapping_balls_with_one_neck_filled_are_cut_across_their_waist():
    # one concave point is left where the balls meet (the other side filled, as the mask's
    # closing or a shadow does): the blob's waist parts the two rims
    mask = disc(SHAPE, 140.0, 120.0, 20.0) | disc(SHAPE, 170.0, 120.0, 20.0)
    cv2.fillPoly(mask, [np.array([[140, 120], [170, 120], [170, 140], [140, 140]], np.int32)], 255)
    assert len(outline_pieces(mask)) == 2
    circles = arc_proposals(mask, 0, 0, 5.0, 120.0)
    for x in (140.0, 170.0):
        found = nearest(circles, x, 120.0)
        assert math.hypot(found.x - x, found.y - 120.0) < 1.5 and abs(found.radius - 20.0) < 1.5


def test_elongated_blobs_without_a_waist_are_not_cut():
    ellipse = np.zeros(SHAPE, np.uint8)
    cv2.ellipse(ellipse, (160, 120), (50, 22), 30, 0, 360, 255, -1)
    assert outline_pieces(ellipse) == []
    # a wedge with one concave point: wider at one end only
    wedge = np.zeros(SHAPE, np.uint8)
    cv2.fillPoly(wedge, [np.array([[60, 100], [240, 70], [240, 170], [60, 140]], np.int32)], 255)
    cv2.circle(wedge, (150, 160), 12, 0, -1)
    assert len(outline_pieces(wedge)) <= 1


def opencv_deepest_cut(points, depth):
    """deepest_cut as OpenCV's convexHull and convexityDefects give it: the reference."""
    contour = np.rint(points).astype(np.int32).reshape(-1, 1, 2)
    hull = cv2.convexHull(contour, returnPoints=False)
    if hull is None or len(hull) < 4:
        return None
    defects = cv2.convexityDefects(contour, np.sort(hull.reshape(-1))[:, None].astype(np.int32))
    if defects is None:
        return None
    defects = defects.reshape(-1, 4)
    defects = defects[(defects[:, 2] > 0) & (defects[:, 2] < len(points) - 1)]
    if not len(defects) or defects[np.argmax(defects[:, 3]), 3] / 256.0 < depth:
        return None
    return int(defects[np.argmax(defects[:, 3]), 2])


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.5, 4.0))
def test_the_deepest_cut_is_opencvs_on_outlines_of_random_blobs(seed, depth):
    # Blobs of 1-5 discs, ragged or not; each outline whole and an open piece of it. (Outlines
    # that pass through a pixel twice, a one-pixel spur, are left out: where that pixel is a
    # hull vertex, which visit OpenCV takes is up to its unstable sort.)
    rng = np.random.default_rng(seed)
    mask = np.zeros((120, 120), np.uint8)
    for count in range(rng.integers(1, 6)):
        cv2.circle(mask, (int(rng.integers(20, 100)), int(rng.integers(20, 100))),
                   int(rng.integers(3 if count else 12, 30)), 255, -1)
    if rng.random() < 0.5:
        mask = cv2.morphologyEx(mask | ((rng.random(mask.shape) < 0.1) * 255).astype(np.uint8), cv2.MORPH_OPEN, None)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    for contour in contours:
        points = contour.reshape(-1, 2).astype(np.float64)
        if len(points) < 24:
            continue
        start = int(rng.integers(0, len(points) - 12))
        for piece in (points, points[start:start + int(rng.integers(12, len(points) - start + 1))]):
            if len(np.unique(piece, axis=0)) == len(piece):
                assert deepest_cut(piece, depth) == opencv_deepest_cut(piece, depth)
