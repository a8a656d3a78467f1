"""Colour edges along rays (services/detector/edges.py) on synthetic profiles and patches."""

import numpy as np
import pytest

from balltrack.services.detector.edges import (allowed_samples, crossing_edges, edge_peaks, median,
                                               outline_edges, ray_bounds, ray_profiles)
from balltrack.services.detector.geometry import rim_directions


def step_profiles(rays, count, edge, inside=(40.0, 220.0, 190.0), outside=(100.0, 100.0, 100.0)):
    """Rays x samples x 3 profiles: ``inside`` colour up to sample ``edge``, ``outside`` after."""
    profiles = np.empty((rays, count, 3), np.float32)
    profiles[:, :edge] = inside
    profiles[:, edge:] = outside
    return profiles


def test_ray_profiles_sample_along_rays_and_know_the_patch_bounds():
    patch = np.zeros((50, 80, 3), np.float32)
    patch[:, :, 0] = np.arange(80)[None, :]  # blue channel = column
    radii = np.arange(0.0, 10.0, 0.5, dtype=np.float32)
    profiles = ray_profiles(patch, 30.0, 20.0, radii, rim_directions(4))
    enter, leave = ray_bounds(50, 80, 30.0, 20.0, rim_directions(4))
    assert profiles.shape == (4, radii.size, 3)
    # the ray along +x reads the column, the ray along +y a constant one
    assert profiles[0, :, 0] == pytest.approx(30.0 + radii, abs=1e-3)
    assert profiles[1, :, 0] == pytest.approx(np.full(radii.size, 30.0), abs=1e-3)
    # distances to the patch's last column / row (+x, +y) and first (-x, -y)
    assert leave[:2] == pytest.approx([49.0, 29.0]) and leave[2:] == pytest.approx([30.0, 20.0])
    assert (enter < 0).all()


def test_allowed_samples_far_from_the_sides_are_the_bounds_own():
    # (the shortcut for rays that stay inside the patch must give the general case's samples)
    random = np.random.default_rng(3)
    shape, directions = (60, 90), rim_directions(36)
    for _ in range(200):
        x, y = random.uniform(-5, 95), random.uniform(-5, 65)
        start, stop, margin = random.uniform(0, 20), random.uniform(10, 40), random.uniform(0.5, 3)
        radii = np.arange(max(0.0, start - margin), stop + margin, 0.5, dtype=np.float32)
        enter, leave = ray_bounds(*shape, x, y, directions)
        expected = ((radii[None, :] >= np.maximum(start, enter + margin)[:, None])
                    & (radii[None, :] <= np.minimum(stop, leave - margin)[:, None]))
        assert (allowed_samples(*shape, x, y, radii, directions, start, stop, margin) == expected).all()


def test_a_ray_along_an_axis_from_outside_the_patch_is_never_inside_it():
    # (a ball cut by the frame's edge, its centre past the edge: its rays along that edge run
    # outside the frame, where the samples would be the border's replicas)
    directions = rim_directions(4)  # +x, +y, -x, -y
    enter, leave = ray_bounds(50, 80, 85.0, 20.0, directions)
    assert not (enter[1] <= leave[1]) and not (enter[3] <= leave[3])  # along y, at x = 85
    assert enter[2] == pytest.approx(6.0) and leave[2] == pytest.approx(85.0)  # -x enters the patch
    radii = np.arange(0.0, 30.0, 0.5, dtype=np.float32)
    allowed = allowed_samples(50, 80, 85.0, 20.0, radii, directions, 0.0, 30.0, 1.0)
    assert not allowed[[0, 1, 3]].any() and allowed[2].any()


def test_edge_peaks_find_the_step_and_ignore_flat_rays():
    profiles = step_profiles(6, 40, 20)
    profiles[5] = 100.0  # no edge along this ray
    allowed = np.ones((6, 40), bool)
    peak, has_edge, gradient = edge_peaks(profiles, allowed)
    assert has_edge[:5].all() and not has_edge[5]
    # the central difference straddles the step: samples 19 and 20
    assert set(np.nonzero(peak[0])[0]) == {19, 20}
    assert gradient[0, 19] > 0 and gradient[0, 5] == 0.0
    # an edge outside the allowed part of the ray is not seen
    allowed[:, 15:25] = False
    assert not edge_peaks(profiles, allowed)[1][:5].any()


def test_crossings_at_half_way_on_a_linear_ramp():
    inside, outside = np.array([40.0, 220.0, 190.0]), np.array([100.0, 100.0, 100.0])
    ramp = np.linspace(0.0, 1.0, 9)  # samples 16..24 go from inside to outside
    profiles = step_profiles(3, 40, 20, inside, outside)
    profiles[:, 16:25] = inside[None, None, :] * (1 - ramp)[None, :, None] + outside * ramp[None, :, None]
    position, defined, contrast = crossing_edges(profiles, np.full(3, 20), 5, np.arange(3))
    assert position == pytest.approx(np.full(3, 20.0), abs=1e-6)
    assert defined.all()
    assert contrast == pytest.approx(np.full(3, np.linalg.norm(inside - outside)), rel=1e-6)
    # a flat profile has no crossing
    assert not crossing_edges(np.full((2, 40, 3), 80.0, np.float32), np.full(2, 20), 3, np.arange(2))[1].any()


def test_shading_is_a_darker_version_of_the_ball_or_black():
    # A ray's first edge that is not shading is its outline hypothesis; its outermost edge is
    # the other, whatever the edge is.
    colour = np.array([40.0, 220.0, 190.0], np.float32)
    darker = step_profiles(1, 20, 10, colour, 0.5 * colour)
    floor_grey = step_profiles(1, 20, 10, colour, (100.0, 100.0, 100.0))
    black = step_profiles(1, 20, 10, colour, (1.0, 2.0, 1.0))
    brighter = step_profiles(1, 20, 10, 0.5 * colour, colour)
    peak = np.zeros((1, 20), bool)
    peak[0, 10] = True
    for profiles, expected in ((darker, True), (floor_grey, False), (black, True), (brighter, False)):
        first, found, outermost = outline_edges(profiles, peak, colour, 3, 1.0, 8.0)
        assert found[0] == (not expected) and outermost[0] == 10
        if found[0]:
            assert first[0] == 10


def test_median_is_numpys():
    generator = np.random.default_rng(3)
    for count in (1, 2, 3, 36, 37, 90):
        for dtype in (np.float32, np.float64):
            values = (generator.random(count) * 50).astype(dtype)
            assert median(values) == float(np.median(values))
