"""The sub-pixel outline (services/detector/outline.py) on drawn profiles and frames."""

import math

import numpy as np
import pytest

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, rim_directions
from balltrack.services.detector.mask import ColourMasker
from balltrack.services.detector import outline
from balltrack.services.detector.outline import (allowed_samples, crossings, edge_peaks, median,
                                                 narrow_fit, outline_edges, ray_bounds, ray_profiles,
                                                 silhouette)
from tests import harness
from tests.unit.detector.drawing import floor, scene, to_uint8


def step_profiles(rays, count, edge, inside=(40.0, 220.0, 190.0), outside=(100.0, 100.0, 100.0)):
    """Rays x samples x 3 profiles: ``inside`` colour up to sample ``edge``, ``outside`` after."""
    profiles = np.empty((rays, count, 3), np.float32)
    profiles[:, :edge] = inside
    profiles[:, edge:] = outside
    return profiles


def planes_and_mask_circle(image):
    planes = ColourMasker(DetectorConfig()).planes(image)
    ys, xs = np.nonzero(planes.mask == 255)
    # the colour mask's own circle: centred on the blob, its radius from its area
    return planes, Candidate(float(xs.mean()), float(ys.mean()), math.sqrt(xs.size / math.pi))


def test_ray_profiles_sample_along_rays_and_know_the_patch_bounds():
    patch = np.zeros((50, 80, 3), np.float32)
    patch[:, :, 0] = np.arange(80)[None, :]  # blue channel = column
    radii = np.arange(0.0, 10.0, 0.5, dtype=np.float32)
    profiles = ray_profiles(patch, 30.0, 20.0, radii, rim_directions(4))
    enter, leave = ray_bounds(patch.shape, 30.0, 20.0, rim_directions(4))
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
        enter, leave = ray_bounds(shape, x, y, directions)
        expected = ((radii[None, :] >= np.maximum(start, enter + margin)[:, None])
                    & (radii[None, :] <= np.minimum(stop, leave - margin)[:, None]))
        assert (allowed_samples(shape, x, y, radii, directions, start, stop, margin) == expected).all()


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
    position, defined, contrast = crossings(profiles, np.full(3, 20), half=5)
    assert position == pytest.approx(np.full(3, 20.0), abs=1e-6)
    assert defined.all()
    assert contrast == pytest.approx(np.full(3, np.linalg.norm(inside - outside)), rel=1e-6)
    # a flat profile has no crossing
    assert not crossings(np.full((2, 40, 3), 80.0, np.float32), np.full(2, 20), half=3)[1].any()


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
    x, y, found = narrow_fit(px, py, widths, directions, from_x, from_y, 9.4, 36, 0.7)
    assert math.hypot(x - centre_x, y - centre_y) < 1e-6
    # (the blur correction: the 50 % contour lies sigma^2 / 2r inside the edge)
    assert found == pytest.approx(radius + sigma ** 2 / (2 * radius), abs=1e-6)
    # the same edges on one side only prove nothing
    side = directions[0] > 0.5
    assert narrow_fit(px[side], py[side], widths[side], directions[:, side], from_x, from_y,
                      9.4, 36, 0.7) is None


@pytest.mark.parametrize("radius", [6.0, 9.5, 15.0, 24.0])
def test_narrow_fit_on_the_wide_rounds_edges_agrees_with_a_narrow_round(radius, monkeypatch):
    u, v = 160.35, 120.6
    image = harness.draw_ball(to_uint8(floor(320, 240)), u, v, radius)
    planes, mask_circle = planes_and_mask_circle(image)
    arguments = (planes.frame, planes.mask, planes.gain, planes.reference, mask_circle, [])
    calls = []
    real_narrow_fit = outline.narrow_fit
    monkeypatch.setattr(outline, "narrow_fit", lambda *given: calls.append(1) or real_narrow_fit(*given))
    reused = silhouette(*arguments)
    assert calls, "the wide round's edges were not reused"
    monkeypatch.setattr(outline, "narrow_fit", lambda *given: None)  # a narrow round of its own
    narrow = silhouette(*arguments)
    assert math.hypot(reused[0] - narrow[0], reused[1] - narrow[1]) < 0.1
    assert abs(reused[2] - narrow[2]) < 0.1
    assert math.hypot(reused[0] - u, reused[1] - v) < 0.2 and abs(reused[2] - radius) < 0.25


def test_median_is_numpys():
    generator = np.random.default_rng(3)
    for count in (1, 2, 3, 36, 37, 90):
        for dtype in (np.float32, np.float64):
            values = (generator.random(count) * 50).astype(dtype)
            assert median(values) == float(np.median(values))
