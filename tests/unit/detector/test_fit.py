"""Circle fitting (services/detector/fit.py) on synthetic points and drawn discs."""

import math

import numpy as np
import pytest

from hypothesis import given, settings
from hypothesis import strategies as st

from balltrack.services.detector.fit import geometric_steps, kasa, refine_on_boundary, robust_circle
from balltrack.services.detector.geometry import Candidate, disc
from balltrack.services.detector.proposals import boundary_points


def circle_points(x, y, radius, count=60, start=0.0, stop=2 * math.pi):
    angles = np.linspace(start, stop, count, endpoint=False)
    return x + radius * np.cos(angles), y + radius * np.sin(angles)


def fit_circle(px, py):
    """The Kasa circle through every point: (x, y, radius), or None."""
    px, py = np.asarray(px, np.float64), np.asarray(py, np.float64)
    ok, centre_x, centre_y, radius = kasa(px, py, np.ones(px.size, np.bool_))
    return (centre_x, centre_y, radius) if ok else None


def test_fit_circle_is_exact_on_exact_points():
    px, py = circle_points(3.25, -1.5, 7.75)
    centre_x, centre_y, radius = fit_circle(px, py)
    assert (centre_x, centre_y, radius) == pytest.approx((3.25, -1.5, 7.75), abs=1e-9)


def test_fit_circle_on_an_arc_and_with_noise():
    generator = np.random.default_rng(1)
    px, py = circle_points(0.4, 0.2, 20.0, count=200, start=0.3, stop=2.0)  # a quarter or so
    px, py = px + generator.normal(0, 0.05, px.size), py + generator.normal(0, 0.05, py.size)
    centre_x, centre_y, radius = fit_circle(px, py)
    assert math.hypot(centre_x - 0.4, centre_y - 0.2) < 0.3 and abs(radius - 20.0) < 0.3


def test_fit_circle_of_degenerate_points_is_none():
    line = np.linspace(-5, 5, 20)
    assert fit_circle(line, 2 * line) is None          # collinear
    assert fit_circle(np.zeros(10), np.zeros(10)) is None  # one point


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(-30, 30), st.floats(-30, 30))
def test_a_kasa_circle_is_the_same_from_any_origin(seed, origin_x, origin_y):
    # robust_circle and refine_on_boundary fit every round's points from the first round's
    # origin (a round selects points, it does not move them): the circle must not depend on
    # the origin.
    generator = np.random.default_rng(seed)
    count = int(generator.integers(8, 80))
    angles = generator.uniform(0, 2 * math.pi, count)
    radius = generator.uniform(2, 200)
    px = 5.0 + radius * np.cos(angles) + generator.normal(0, 0.5, count)
    py = -3.0 + radius * np.sin(angles) + generator.normal(0, 0.5, count)
    keep = generator.random(count) < 0.8
    keep[:8] = True
    direct = fit_circle(px[keep], py[keep])
    ok, *moved = kasa(px - origin_x, py - origin_y, keep)
    assert (direct is None) == (not ok)
    if direct is not None:
        tolerance = 1e-9 * (radius + 50)
        assert moved[0] + origin_x == pytest.approx(direct[0], abs=tolerance)
        assert moved[1] + origin_y == pytest.approx(direct[1], abs=tolerance)
        assert moved[2] == pytest.approx(direct[2], abs=tolerance)


def test_geometric_steps_converge_from_a_rough_start():
    px, py = circle_points(10.0, 20.0, 15.0, count=90)
    x, y, radius = geometric_steps(px, py, np.ones(px.size, bool), 11.0, 19.0, 13.5, 10)
    assert (x, y, radius) == pytest.approx((10.0, 20.0, 15.0), abs=1e-4)


def test_robust_circle_leaves_other_edges_out():
    px, py = circle_points(50.0, 60.0, 12.0, count=80)
    # a straight edge of another object crossing near the circle
    other_x, other_y = np.full(30, 66.0), np.linspace(40.0, 80.0, 30)
    all_x, all_y = np.concatenate([px, other_x]), np.concatenate([py, other_y])
    rounds = ((0.3, 2.0), (0.1, 1.0))
    x, y, radius, on_circle = robust_circle(all_x, all_y, 50.8, 59.5, 12.6, rounds, geometric=True)
    assert (x, y, radius) == pytest.approx((50.0, 60.0, 12.0), abs=1e-3)
    assert on_circle[:80].all()
    assert np.count_nonzero(on_circle[80:]) <= 4  # only where the edge meets the circle


def test_robust_circle_needs_eight_points():
    px, py = circle_points(0.0, 0.0, 10.0, count=7)
    assert robust_circle(px, py, 0.0, 0.0, 10.0, ((0.3, 2.0),), geometric=False) is None
    # points all far from the starting circle are not on it
    px, py = circle_points(0.0, 0.0, 10.0, count=40)
    assert robust_circle(px, py, 0.0, 0.0, 30.0, ((0.05, 0.5),), geometric=False) is None


@pytest.mark.parametrize("radius", [5.0, 12.5, 40.0])
def test_refine_on_boundary_finds_the_drawn_disc(radius):
    x, y = 100.3, 90.7
    mask = disc((200, 200), x, y, radius)
    boundary_x, boundary_y = boundary_points(mask)
    proposal = Candidate(x + 0.1 * radius, y - 0.08 * radius, 1.15 * radius)
    refined = refine_on_boundary(proposal, boundary_x, boundary_y)
    assert refined is not None
    assert math.hypot(refined.x - x, refined.y - y) < 0.3
    assert abs(refined.radius - radius) < 0.5


def test_refine_on_boundary_keeps_the_frame_edge_out():
    # a disc cut by the left edge: the border is not boundary, so the centre stays outside
    x, y, radius = -5.0, 100.0, 30.0
    mask = disc((200, 200), x, y, radius)
    boundary_x, boundary_y = boundary_points(mask)
    refined = refine_on_boundary(Candidate(6.0, 100.0, 24.0), boundary_x, boundary_y)
    assert math.hypot(refined.x - x, refined.y - y) < 0.5 and abs(refined.radius - radius) < 0.6


def test_refine_on_boundary_without_a_circle_is_none():
    empty = np.zeros(0, np.float64)
    assert refine_on_boundary(Candidate(50.0, 50.0, 10.0), empty, empty) is None
    mask = disc((200, 200), 100.0, 100.0, 10.0)
    boundary_x, boundary_y = boundary_points(mask)
    # a proposal far from every boundary pixel
    assert refine_on_boundary(Candidate(170.0, 170.0, 8.0), boundary_x, boundary_y) is None
    # a proposal three times too large: no boundary pixel lies near its rim
    assert refine_on_boundary(Candidate(100.0, 100.0, 30.0), boundary_x, boundary_y) is None
