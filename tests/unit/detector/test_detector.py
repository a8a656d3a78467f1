"""The detector's pure core on synthetic frames drawn with cv2/numpy, and on the real dev photos.

Synthetic balls are shaded yellow-green discs drawn with sub-pixel accuracy (4x4 supersampled
coverage) on a textured grey floor; dark versions scale the whole frame down to a few pixel
units, as the simulator's dimmest lights do. The sub-pixel tests also use the integration
tests' ball (tests/harness.py, blurred), pre-blurred and JPEG frames, strongly shaded balls and
balls whose unlit side is black. Every found ball must be within 0.5 px (centre) and 3 % or
0.3 px (radius) of the truth unless a test says otherwise.
"""

import dataclasses
import importlib
import json
import math
import pkgutil
import time

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from balltrack.common.config import ConfigError, load_config
from balltrack.experiments.base import development_photos
from balltrack.experiments.real_photos import score_folder, score_image
from balltrack.services.detector.annotate import annotate
from balltrack.services.detector.checks import CandidateMetrics
from balltrack.services.detector.measure import NO_COLOUR, MaskMetrics
from balltrack.services.detector.config import DetectorConfig
from balltrack.services import detector as detector_package
from balltrack.services.detector.detector import (STAGES, BallDetector, Detection, DetectionResult,
                                                  acceptance_order, compile_kernels, without_contained)
from balltrack.services.detector.geometry import Candidate
from balltrack.services.detector.mask import EXPLAINED
from balltrack.services.detector.proposals import fill_holes, frame_search
from tests import harness
from tests.unit.detector.drawing import (TENNIS_BGR, coverage, draw_ball, draw_box, draw_lit_from_above,
                                         floor, pitch_dark_frame, scene, to_uint8)

SHARED_DATA = development_photos()
REAL_DEV_SET = SHARED_DATA / "real_tennis_dev"


@pytest.fixture(scope="module")
def detector():
    return BallDetector(DetectorConfig())


def assert_found(detections, u, v, radius, centre_tolerance=0.5, radius_tolerance=0.03):
    assert detections, f"no ball found, expected ({u:.1f}, {v:.1f}, r={radius:.1f})"
    best = min(detections, key=lambda d: math.hypot(d.u - u, d.v - v))
    error = math.hypot(best.u - u, best.v - v)
    assert error <= centre_tolerance, f"centre off by {error:.2f} px: {best} vs ({u}, {v})"
    assert abs(best.radius_px - radius) <= max(radius_tolerance * radius, 0.3), \
        f"radius {best.radius_px:.2f} vs {radius}"
    return best


# ------------------------------------------------------------------------ bright frames
@pytest.mark.parametrize("radius", [6.0, 9.5, 15.0, 24.0, 40.0])
@pytest.mark.parametrize("u, v", [(320.3, 250.6), (101.7, 372.2), (560.4, 95.5)])
def test_finds_one_ball_of_any_size_anywhere(detector, radius, u, v):
    result = detector.detect(scene([(u, v, radius)]))
    assert len(result.detections) == 1, result.detections
    found = assert_found(result.detections, u, v, radius)
    assert 0.5 <= found.score <= 1.0


def test_finds_a_ball_filling_much_of_the_frame(detector):
    assert_found(detector.detect(scene([(330.0, 260.0, 150.0)])).detections, 330.0, 260.0, 150.0)


def compiled_signatures() -> dict[str, set[str]]:
    """Every compiled function of the detector (see jit.py) and the argument types it has been
    compiled for."""
    modules = [importlib.import_module(f"{detector_package.__name__}.{module.name}")
               for module in pkgutil.iter_modules(detector_package.__path__)
               if module.name not in ("__main__", "service")]  # (the core's modules only)
    return {f"{module.__name__}.{name}": set(map(str, function.signatures))
            for module in modules for name, function in vars(module).items()
            if hasattr(function, "signatures") and function.__module__ == module.__name__}


def test_compile_kernels_compiles_what_frames_need():
    # A service calls compile_kernels before its first frame so that no frame waits for the
    # compiler: frames of every kind must then need no new compilation.
    compile_kernels()
    compiled = compiled_signatures()
    detector = BallDetector(DetectorConfig())
    frames = [scene([(330.0, 260.0, 30.0), (100.0, 100.0, 12.0)]),
              scene([(300.0, 240.0, 40.0), (372.0, 240.0, 32.0)]),    # touching
              scene([(10.0, 200.0, 35.0)], seed=3),                   # cut by the frame's edge
              scene([(320.0, 240.0, 20.0)], brightness=0.05),         # dark
              # (its outline's search spans the frame's width: a contiguous slice of its mask)
              scene([(80.0, 240.0, 40.0)], width=160),
              pitch_dark_frame(balls=[(320.0, 300.0, 25.0)])]
    for frame in frames:
        detector.detect(frame)
    assert compiled_signatures() == compiled


def test_stage_times_split_a_call_among_the_stages_it_ran():
    profiled = BallDetector(DetectorConfig())
    frame = scene([(330.0, 260.0, 30.0)])
    profiled.stage_times = {}
    started = time.perf_counter()
    result = profiled.detect(frame)
    elapsed = time.perf_counter() - started
    assert len(result.detections) == 1
    assert set(profiled.stage_times) == set(STAGES)  # a ball found: every stage ran
    assert all(seconds > 0 for seconds in profiled.stage_times.values())
    assert sum(profiled.stage_times.values()) <= elapsed  # parts of the call, not more
    # A ball-free frame stops after the blobs; the times add up call after call.
    before = dict(profiled.stage_times)
    profiled.detect(scene([], seed=1))
    assert profiled.stage_times["colour mask"] > before["colour mask"]
    assert profiled.stage_times["outline"] == before["outline"]
    # Off by default: nothing is kept.
    assert BallDetector(DetectorConfig()).stage_times is None


def test_blob_times_list_each_blob_searched_with_its_size():
    profiled = BallDetector(DetectorConfig())
    profiled.blob_times = []
    profiled.stage_times = {}
    # (two balls apart: two blobs, each about its diameter across)
    profiled.detect(scene([(200.0, 240.0, 30.0), (460.0, 240.0, 12.0)]))
    sizes = sorted(side for side, _ in profiled.blob_times)
    assert len(sizes) == 2 and abs(sizes[0] - 25) <= 3 and abs(sizes[1] - 61) <= 3
    assert all(seconds > 0 for _, seconds in profiled.blob_times)
    assert sum(seconds for _, seconds in profiled.blob_times) <= profiled.stage_times["blobs"]
    # Off by default: nothing is kept.
    assert BallDetector(DetectorConfig()).blob_times is None


def test_no_detection_on_ball_free_frames(detector):
    for seed in range(3):
        assert detector.detect(scene([], seed=seed)).detections == []


# -------------------------------------------------------------------------- dark frames
@pytest.mark.parametrize("brightness", [0.5, 0.1, 0.05, 0.03])
@pytest.mark.parametrize("radius", [10.0, 30.0])
def test_finds_balls_in_dark_frames(detector, brightness, radius):
    # At 0.03 the floor is ~3 units and the ball's green channel ~7: hue survives only
    # because the detector normalises brightness before it thresholds.
    image = scene([(300.5, 260.5, radius)], brightness=brightness)
    assert image.max() <= max(8, 255 * brightness + 8)
    result = detector.detect(image)
    assert len(result.detections) == 1, result.detections
    assert_found(result.detections, 300.5, 260.5, radius)


@pytest.mark.parametrize("brightness", [0.05, 0.02, 0.01])
def test_dark_floor_alone_gives_nothing(detector, brightness):
    for seed in range(3):
        image = scene([], brightness=brightness, seed=seed)
        # sensor noise of a unit or two, which gives random hues at these levels
        noise = np.random.default_rng(seed).integers(-1, 2, image.shape)
        noisy = np.clip(image.astype(np.int16) + noise, 0, 255).astype(np.uint8)
        assert detector.detect(image).detections == []
        assert detector.detect(noisy).detections == []


def in_shade_beside_a_white_wall(shade, ball=None, box=None):
    """A frame whose top is a white wall, with a ball (u, v, radius) or a box (x0, y0, x1, y1)
    in even shade below it: felt colour at ``shade`` of its full brightness."""
    image = draw_box(floor(), 0, 0, 640, 200, (245, 245, 245))
    colour = tuple(shade * channel for channel in TENNIS_BGR)
    if ball is not None:
        image = draw_ball(image, *ball, colour=colour, shade_floor=0.8)
    if box is not None:
        image = draw_box(image, *box, colour)
    return to_uint8(image)


@pytest.mark.parametrize("shade", [0.25, 0.3, 0.45])
def test_finds_a_ball_in_shade_beside_a_white_wall(detector, shade):
    # dull next to the wall's brightness, but as vivid as ever next to its own lit side
    result = detector.detect(in_shade_beside_a_white_wall(shade, ball=(320.0, 330.0, 40.0)))
    assert len(result.detections) == 1, result.detections
    assert_found(result.detections, 320.0, 330.0, 40.0)


def test_shaded_things_of_ball_colour_that_are_no_plain_ball_give_nothing(detector):
    for box in ((200, 280, 440, 340), (280, 260, 360, 340)):  # a strip, a square
        assert detector.detect(in_shade_beside_a_white_wall(0.3, box=box)).detections == []


def test_dark_distractors_give_nothing(detector):
    distractors = [("ball", 150.0, 300.0, 25.0, (30, 30, 200)), ("ball", 450.0, 300.0, 30.0, (30, 120, 240)),
                   ("box", 250, 150, 350, 230, (20, 110, 235))]
    for brightness in (0.1, 0.03):
        assert detector.detect(scene([], brightness=brightness, distractors=distractors)).detections == []


# ------------------------------------------------------------------ edge, touching, sizes
@pytest.mark.parametrize("u, v, radius", [
    (12.4, 240.2, 25.0),    # centre inside, a quarter of the disc cut off on the left
    (-6.3, 200.7, 30.0),    # centre outside the frame on the left
    (620.6, 470.1, 22.0),   # bottom-right corner
    (330.2, -8.4, 28.0),    # centre above the top edge
])
def test_finds_balls_cut_by_the_frame_edge(detector, u, v, radius):
    result = detector.detect(scene([(u, v, radius)]))
    assert len(result.detections) == 1, result.detections
    # (only the arc in view locates the circle: the centre is a little less certain)
    assert_found(result.detections, u, v, radius, centre_tolerance=0.75)


def test_two_touching_balls_are_two_detections_largest_first(detector):
    first, second = (250.3, 260.2, 30.0), (250.3 + 30.0 + 18.0, 260.2 + 4.0, 18.0)
    gap = math.hypot(second[0] - first[0], second[1] - first[1]) - first[2] - second[2]
    assert gap < 0.5  # they touch (the distance is within half a pixel of the radius sum)
    result = detector.detect(scene([first, second]))
    assert len(result.detections) == 2, result.detections
    assert result.detections[0].radius_px > result.detections[1].radius_px
    assert_found(result.detections[:1], *first)
    assert_found(result.detections[1:], *second)


def test_a_row_of_three_touching_balls(detector):
    balls = [(200.0, 300.0, 20.0), (240.0, 300.0, 20.0), (280.0, 300.0, 20.0)]
    result = detector.detect(scene(balls))
    assert len(result.detections) == 3, result.detections
    for ball in balls:
        assert_found(result.detections, *ball)


def test_a_heap_of_touching_balls_of_flat_colour(detector):
    # No shading between them: one blob of colour, split into its balls.
    image = to_uint8(floor())
    balls = [(300.0, 240.0, 22.0), (343.0, 246.0, 22.0), (321.0, 283.0, 22.0), (366.0, 284.0, 21.0)]
    for u, v, radius in balls:
        cv2.circle(image, (int(u), int(v)), int(radius), TENNIS_BGR, -1, cv2.LINE_AA)
    result = detector.detect(image)
    assert len(result.detections) == len(balls), result.detections
    for u, v, radius in balls:
        assert_found(result.detections, u, v, radius, centre_tolerance=2.0, radius_tolerance=0.1)


def test_what_a_found_ball_leaves_of_a_heap_is_searched_as_a_blob(detector):
    # two touching balls left beside a found one: split as any blob is, not taken as one
    # circle round both
    found, pair = (300.0, 240.0, 30.0), [(342.0, 275.0, 22.0), (386.0, 275.0, 22.0)]
    planes = detector._masker.planes(scene([found, *pair]))
    _, shape_mask = fill_holes(planes.mask, planes.extent)
    search = frame_search(planes, detector.config, 1.0, shape_mask)
    explained = search.mask.copy()
    cv2.circle(explained, (300, 240), int(math.ceil(1.08 * 30.0 + 1)), EXPLAINED, -1)
    candidates = detector._leftover_candidates([Candidate(*found)], explained, search)
    for u, v, radius in pair:
        best = max((candidate for candidate, _ in candidates
                    if math.hypot(candidate.x - u, candidate.y - v) < 1.0
                    and abs(candidate.radius - radius) < 1.0), key=lambda candidate: candidate.score)
        assert best.score >= 0.9


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([(60, 80), (50, 70)]), st.integers(0, 80), st.integers(0, 60),
                          st.integers(0, 80), st.integers(0, 60), st.booleans(), st.integers(0, 2**32 - 1),
                          st.lists(st.tuples(st.floats(-10, 90), st.floats(-10, 70), st.floats(0.5, 20)),
                                   min_size=1, max_size=3)),
                min_size=1, max_size=6))
def test_the_explained_plane_is_the_mask_with_its_balls_whatever_came_before(frames):
    # The plane is reused from call to call (made anew when the frame size changes) and only
    # its box is copied and cleared: each use must still hold exactly the mask, zero outside
    # its box, with that use's balls drawn.
    detector = BallDetector(DetectorConfig())
    for shape, left, top, right, bottom, boxed, seed, balls in frames:
        mask = np.zeros(shape, np.uint8)
        part = mask[top:bottom, left:right]
        part[...] = np.random.default_rng(seed).choice([0, 255], size=part.shape)
        discs = [Candidate(x, y, radius) for x, y, radius in balls]
        plane, plane_box = detector._explained_plane(0, mask, (left, top, right, bottom) if boxed else None, discs)
        expected = mask.copy()
        for disc in discs:
            cv2.circle(expected, (int(round(disc.x)), int(round(disc.y))),
                       int(math.ceil(disc.radius * 1.08 + 1)), EXPLAINED, -1)
        np.testing.assert_array_equal(plane, expected)
        outside = plane.copy()
        outside[plane_box[1]:plane_box[3], plane_box[0]:plane_box[2]] = 0
        assert not outside.any(), plane_box


def test_detections_are_sorted_largest_first(detector):
    balls = [(100.0, 100.0, 8.0), (500.0, 120.0, 30.0), (300.0, 350.0, 16.0)]
    result = detector.detect(scene(balls))
    assert len(result.detections) == 3
    radii = [d.radius_px for d in result.detections]
    assert radii == sorted(radii, reverse=True)
    assert_found(result.detections[:1], 500.0, 120.0, 30.0)


# ------------------------------------------------------------------- sub-pixel outline
# The colour mask's edge lies where blur has spread the colour, 0.5-1 px outside the ball
# whatever its size, and a strongly shaded side pulls the mask's centre towards the lit side;
# the detector reports the outline found on the frame instead. Tolerances: the radius within
# 3 % or 0.3 px (the locator's distance error is the radius error), the centre within 0.5 px.
SIZES = [3.5, 5.0, 8.0, 13.0, 21.0, 34.0, 55.0, 90.0, 150.0]
POSITIONS = [(320.3, 240.6), (301.55, 262.35), (338.8, 228.15)]


def blurred_scene(u, v, radius, seed=0):
    """The integration tests' ball (tests/harness.py: anti-aliased, then 3x3 Gaussian blur)."""
    return harness.draw_ball(to_uint8(floor(seed=seed)), u, v, radius)


def jpeg(image, quality=80):
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return cv2.imdecode(data, cv2.IMREAD_COLOR)


@pytest.mark.parametrize("radius", SIZES)
def test_outline_of_blurred_balls_to_a_fraction_of_a_pixel(detector, radius):
    # Before the outline was located on the frame, radii came out +0.5-0.6 px here (+14 % at
    # 3.5 px, +6 % at 8 px, +2.8 % at 21 px).
    for index, (u, v) in enumerate(POSITIONS):
        result = detector.detect(blurred_scene(u, v, radius, seed=index))
        assert len(result.detections) == 1, result.detections
        assert_found(result.detections, u, v, radius)


@pytest.mark.parametrize("radius", [8.0, 13.0, 21.0, 34.0, 55.0, 90.0])
def test_outline_of_pre_blurred_balls(detector, radius):
    # A soft camera: the whole frame blurred again (5x5 Gaussian) on top of the ball's own edge.
    for index, (u, v) in enumerate(POSITIONS):
        image = cv2.GaussianBlur(scene([(u, v, radius)], seed=index), (5, 5), 0)
        assert_found(detector.detect(image).detections, u, v, radius)


@pytest.mark.parametrize("radius", [10.0, 13.0, 21.0, 34.0, 55.0, 90.0])
def test_outline_of_balls_in_jpeg_frames(detector, radius):
    for index, (u, v) in enumerate(POSITIONS):
        image = jpeg(blurred_scene(u, v, radius, seed=index))
        assert_found(detector.detect(image).detections, u, v, radius)


@pytest.mark.parametrize("radius", [44.0, 80.0, 130.0])
def test_centre_of_a_strongly_shaded_large_ball(detector, radius):
    # The shaded side (12 % of the lit colour) drops out of the colour mask's edge; the mask's
    # centre was 1.2-2.9 px towards the lit side at these sizes.
    for u, v in POSITIONS[:2]:
        image = to_uint8(draw_ball(floor(), u, v, radius, shade_floor=0.12))
        assert_found(detector.detect(image).detections, u, v, radius)


@pytest.mark.parametrize("radius", [6.0, 12.0, 30.0, 60.0])
def test_a_ball_with_a_black_side_is_found_whole(detector, radius):
    # No ambient light: the lower third of the ball is black, out of the colour mask, so the
    # colour alone gives a cap. The outline around the cap is the ball.
    u, v = 300.4, 250.7
    image = to_uint8(draw_lit_from_above(floor(), u, v, radius))
    result = detector.detect(image)
    disc = coverage(image.shape, u, v, radius) > 0.5
    assert np.count_nonzero(result.mask[disc]) < 0.85 * np.count_nonzero(disc)  # a cap, really
    assert len(result.detections) == 1, result.detections
    assert_found(result.detections, u, v, radius)


@pytest.mark.parametrize("radius", [3.5, 4.2])
def test_far_balls_of_a_few_pixels(detector, radius):
    # A tennis ball 4-5 m away: 3.5-4.5 px.
    for index, (u, v) in enumerate(POSITIONS):
        result = detector.detect(scene([(u, v, radius)], seed=index))
        assert len(result.detections) == 1, result.detections
        assert_found(result.detections, u, v, radius)


def test_nothing_smaller_than_min_radius(detector):
    assert detector.detect(scene([(320.3, 240.6, 2.4)])).detections == []
    small = BallDetector(DetectorConfig(min_radius=8))
    assert small.detect(scene([(320.3, 240.6, 6.0)])).detections == []
    assert_found(small.detect(scene([(320.3, 240.6, 9.0)])).detections, 320.3, 240.6, 9.0)


def test_touching_balls_keep_their_outlines(detector):
    # Rays towards the neighbour see its colour, not this ball's outline: they are left out.
    first, second = (250.3, 260.2, 30.0), (250.3 + 30.0 + 18.0, 260.2 + 4.0, 18.0)
    image = harness.draw_ball(harness.draw_ball(to_uint8(floor()), *first), *second)
    result = detector.detect(image)
    assert len(result.detections) == 2, result.detections
    assert_found(result.detections[:1], *first)
    assert_found(result.detections[1:], *second)


def test_a_ball_is_not_suppressed_by_a_piece_of_itself():
    ball = Candidate(200.0, 200.0, 60.0, score=0.7)
    patch = Candidate(215.0, 190.0, 6.0, score=0.9)      # between a logo's letters
    on_rim = Candidate(200.0, 257.0, 5.0, score=0.8)     # cut off the rim by a seam
    neighbour = Candidate(200.0, 200.0, 25.0, score=0.9)  # ball-sized: judged on its own
    outside = Candidate(320.0, 200.0, 6.0, score=0.9)
    kept = [candidate for candidate, _ in without_contained(
        [(ball, None), (patch, None), (on_rim, None), (neighbour, None), (outside, None)])]
    assert kept == [ball, neighbour, outside]
    # a circle that failed its checks suppresses nothing
    failed = dataclasses.replace(ball, score=0.0)
    assert len(without_contained([(failed, None), (patch, None)])) == 2


def test_a_speck_is_accepted_after_the_balls_it_may_overlap():
    def measured(x, y, radius, score, size):
        metrics = CandidateMetrics(MaskMetrics(visible=1.0, support=1.0, leak=0.0, fill=1.0, outside=0.0,
                                               spread=0.0), NO_COLOUR, size)
        return Candidate(x, y, radius, score=score), metrics

    ball = measured(200.0, 200.0, 60.0, 0.7, 12.0)
    speck = measured(242.0, 242.0, 3.0, 0.9, 0.6)  # astride the ball's rim, not inside it
    larger = measured(100.0, 100.0, 8.0, 0.8, 1.6)
    assert sorted([speck, ball, larger], key=acceptance_order, reverse=True) == [larger, ball, speck]


def test_a_ball_with_a_logo_and_a_highlight(detector):
    image = harness.draw_ball(to_uint8(floor()), 320.4, 240.6, 70.0)
    cv2.putText(image, "Penn 1", (265, 250), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (20, 20, 20), 3)
    cv2.circle(image, (300, 215), 14, (250, 250, 250), -1)
    result = detector.detect(image)
    assert len(result.detections) == 1, result.detections
    assert_found(result.detections, 320.4, 240.6, 70.0, centre_tolerance=2.0, radius_tolerance=0.05)


# ------------------------------------------------------------------------ distractors
DISTRACTORS = [
    ("ball", 120.0, 300.0, 28.0, (30, 30, 210)),     # red ball
    ("ball", 260.0, 330.0, 32.0, (210, 60, 25)),     # blue ball
    ("ball", 420.0, 320.0, 26.0, (235, 235, 235)),   # white ball
    ("ball", 540.0, 360.0, 30.0, (20, 120, 240)),    # orange ball
    ("box", 60, 60, 160, 150, (15, 115, 240)),       # orange box
    ("box", 250, 60, 290, 200, (40, 115, 25)),       # green cylinder, side view
    ("box", 400, 80, 520, 140, (150, 30, 150)),      # purple box
]


def test_other_coloured_objects_are_not_detected(detector):
    for brightness in (1.0, 0.5):
        assert detector.detect(scene([], brightness=brightness, distractors=DISTRACTORS)).detections == []


def test_only_the_tennis_ball_among_distractors(detector):
    result = detector.detect(scene([(380.0, 420.0, 20.0)], distractors=DISTRACTORS))
    assert len(result.detections) == 1, result.detections
    assert_found(result.detections, 380.0, 420.0, 20.0)


def test_a_yellow_green_box_is_not_a_ball(detector):
    assert detector.detect(scene([], distractors=[("box", 200, 200, 262, 262, TENNIS_BGR)])).detections == []


def test_other_targets_by_configuration():
    red = BallDetector(DetectorConfig(h_min=170, h_max=8))  # a hue range that wraps through 0
    image = scene([], distractors=[("ball", 320.0, 240.0, 25.0, (30, 30, 210))])
    assert_found(red.detect(image).detections, 320.0, 240.0, 25.0)


# ----------------------------------------------------------------------- frame formats
@pytest.mark.parametrize("width, height", [(160, 120), (333, 211), (641, 479), (1920, 1080)])
def test_any_frame_size(detector, width, height):
    scale = width / 640
    u, v, radius = width * 0.43 + 0.3, height * 0.61 + 0.2, max(6.0, 20.0 * scale)
    result = detector.detect(scene([(u, v, radius)], width=width, height=height))
    assert result.mask.shape == (height, width)
    assert len(result.detections) == 1, result.detections
    assert_found(result.detections, u, v, radius, centre_tolerance=0.5 * max(1.0, scale))


@pytest.mark.parametrize("width, height", [(1280, 960), (1920, 1080), (1000, 563)])
def test_frames_wider_than_work_width_keep_their_centres(detector, width, height):
    # Such frames are shrunk to work_width; a shrunk pixel's centre is not its index over the
    # scale. Before that was taken into account centres came out 0.5 px (1280) to 1 px (1920)
    # up and left of the ball's.
    shrink = width / 640
    for index, (across, down, size) in enumerate([(0.47, 0.42, 0.063), (0.78, 0.69, 0.086)]):
        u, v, radius = across * width + 0.3, down * height + 0.7, size * width
        result = detector.detect(scene([(u, v, radius)], width=width, height=height, seed=index))
        assert len(result.detections) == 1, result.detections
        assert_found(result.detections, u, v, radius, centre_tolerance=0.1 * shrink)


def test_mono_frames_give_no_ball_and_grey_arrays_are_accepted(detector):
    grey = cv2.cvtColor(scene([(320.0, 240.0, 30.0)]), cv2.COLOR_BGR2GRAY)
    assert detector.detect(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)).detections == []
    result = detector.detect(grey)
    assert result.detections == [] and result.mask.shape == grey.shape


def test_bad_images_are_rejected(detector):
    with pytest.raises(ValueError):
        detector.detect(np.zeros((480, 640, 3), np.float32))
    with pytest.raises(ValueError):
        detector.detect(np.zeros((480, 640, 4), np.uint8))
    with pytest.raises(ValueError):
        detector.detect(np.zeros((4, 4, 3), np.uint8))


def test_result_types_and_mask(detector):
    image = scene([(300.0, 200.0, 25.0)])
    before = image.copy()
    result = detector.detect(image)
    assert np.array_equal(image, before)  # the input is not modified
    assert isinstance(result, DetectionResult)
    assert result.mask.dtype == np.uint8 and result.mask.shape == image.shape[:2]
    assert set(np.unique(result.mask)) <= {0, 255}
    assert result.mask[200, 300] == 255 and result.mask[20, 20] == 0
    detection = result.detections[0]
    assert isinstance(detection, Detection)
    assert all(isinstance(getattr(detection, name), float) for name in ("u", "v", "radius_px", "score"))
    with pytest.raises(dataclasses.FrozenInstanceError):
        detection.u = 0.0


def test_annotate_draws_on_a_copy(detector):
    image = scene([(300.0, 200.0, 25.0)])
    result = detector.detect(image)
    drawn = annotate(image, result.detections)
    assert drawn.shape == image.shape and drawn.dtype == np.uint8
    assert not np.array_equal(drawn, image)
    assert np.array_equal(annotate(image, []), image)
    assert annotate(image[:, :, 0], result.detections).shape == image.shape


# ---------------------------------------------------------------------- configuration
@pytest.mark.parametrize("changes, field", [
    ({"h_min": 180}, "h_min"), ({"h_max": -1}, "h_max"), ({"s_min": 300}, "s_min"),
    ({"s_min": 200, "s_max": 100}, "s_max"), ({"v_min": 100, "v_max": 50}, "v_max"),
    ({"dp": 0.5}, "dp"), ({"min_dist": 0.0}, "min_dist"), ({"param1": -1.0}, "param1"),
    ({"param2": float("nan")}, "param2"), ({"min_radius": 0}, "min_radius"),
    ({"min_radius": 10, "max_radius": 8}, "max_radius"), ({"max_radius": -5}, "max_radius"),
    ({"small_radius": 0}, "small_radius"), ({"min_visible_fraction": 1.2}, "min_visible_fraction"),
    ({"blur_kernel": 4}, "blur_kernel"), ({"blur_kernel": 5.0}, "blur_kernel"),
    ({"clahe_clip_limit": -1.0}, "clahe_clip_limit"), ({"clahe_tile_grid": 0}, "clahe_tile_grid"),
    ({"max_gain": 0.5}, "max_gain"), ({"gain_target": 0.0}, "gain_target"),
    ({"min_chroma": -1.0}, "min_chroma"), ({"open_kernel": -1}, "open_kernel"),
    ({"min_fill_ratio": 1.5}, "min_fill_ratio"), ({"min_edge_support": -0.1}, "min_edge_support"),
    ({"min_colourfulness": 2.0}, "min_colourfulness"), ({"max_detections": 0}, "max_detections"),
    ({"work_width": 10}, "work_width"), ({"min_score": True}, "min_score"),
])
def test_config_validation_names_the_field(changes, field):
    with pytest.raises(ConfigError) as error:
        DetectorConfig(**changes)
    assert str(error.value).startswith(f"{field}:")


def test_config_through_load_config(tmp_path):
    path = tmp_path / "detector.toml"
    path.write_text("[detector]\nh_min = 22\nparam2 = 25.0\n")
    config = load_config(DetectorConfig, path, ["min_radius=7"], section="detector")
    assert (config.h_min, config.param2, config.min_radius) == (22, 25.0, 7)
    with pytest.raises(ConfigError, match="^max_radius:"):
        load_config(DetectorConfig, None, ["min_radius=7", "max_radius=3"])
    with pytest.raises(ConfigError, match="^colour:"):
        load_config(DetectorConfig, None, ["colour=1"])


# ------------------------------------------------------------------------ real photos
def test_scoring_rules():
    boxes = [{"x": 100, "y": 100, "w": 40, "h": 40}, {"x": 300, "y": 100, "w": 8, "h": 8},
             {"x": 0, "y": 200, "w": 15, "h": 50}]
    near = Detection(u=125.0, v=118.0, radius_px=20.0, score=1.0)   # within r/2 = 10 of (120, 120)
    tiny = Detection(u=304.0, v=104.0, radius_px=4.0, score=1.0)    # a small ball: not counted, not FP
    stray = Detection(u=500.0, v=400.0, radius_px=9.0, score=1.0)   # in no box: a false positive
    assert score_image(boxes, [near, tiny, stray]) == {"labelled": 2, "found": 1, "false_positives": 1,
                                                       "outcomes": [[1.0, 1], [1.0, 0]]}
    far = Detection(u=138.0, v=138.0, radius_px=20.0, score=1.0)    # in the box, too far from its centre
    assert score_image(boxes, [far]) == {"labelled": 2, "found": 0, "false_positives": 0, "outcomes": []}
    cut = Detection(u=5.0, v=228.0, radius_px=25.0, score=1.0)      # cut ball: radius from the long side
    assert score_image(boxes, [cut])["found"] == 1


@pytest.mark.skipif(not (REAL_DEV_SET / "labels.json").is_file(),
                    reason=f"real dev photos not present at {REAL_DEV_SET}")
def test_real_tennis_dev_set():
    # Measured with the defaults: recall 11/11 = 1.0, 1 false positive in 10 images (0.1).
    result = score_folder(REAL_DEV_SET)
    labels = json.loads((REAL_DEV_SET / "labels.json").read_text())
    assert result["images"] == len(labels) == 10
    assert result["labelled"] == 11
    assert result["recall"] == 1.0, result
    assert result["false_positives_per_image"] <= 0.1, result
    assert set(result["files"]) == set(labels)


# ----------------------------------------------------------- extremely dark, no ambient
@pytest.mark.parametrize("u, v, radius", [(300.4, 280.7, 17.0), (320.5, 260.2, 18.3),
                                          (450.2, 330.6, 11.5), (200.6, 300.3, 30.0)])
def test_a_pitch_dark_ball_is_found_whole(detector, u, v, radius):
    # The lit cap is 1-2 units above black, its pixels' hues rounding noise: the colour is
    # judged on averages (dark_gain), and the outline found around the black side.
    image = pitch_dark_frame(balls=[(u, v, radius)])
    lit = image[int(v - radius):int(v), int(u - radius):int(u + radius)]
    assert lit.max() <= 2
    result = detector.detect(image)
    assert len(result.detections) == 1, result.detections
    assert_found(result.detections, u, v, radius, centre_tolerance=1.0, radius_tolerance=0.06)


def test_pitch_dark_distractors_give_nothing(detector):
    # Orange as the simulator renders it at this level: (1, 1, 0) RGB, a yellow hue of chroma
    # 1, or (2, 1, 0); a dim green cylinder (0, 1, 0); red and blue balls.
    image = pitch_dark_frame(
        boxes=[(100, 250, 220, 340, (0.2, 1.2, 1.4)), (400, 240, 470, 300, (0.1, 1.0, 1.8)),
               (520, 200, 560, 330, (0.2, 1.1, 0.3))],
        distractor_balls=[(300.0, 300.0, 25.0, (0.3, 1.4, 2.6)), (250.0, 400.0, 20.0, (0.3, 0.3, 2.4)),
                          (450.0, 400.0, 22.0, (2.5, 0.6, 0.3))])
    assert image[120:].max() <= 3
    assert detector.detect(image).detections == []


# Figures with the defaults when they were last changed (recall, false positives per image):
# tennis_floor_dev 0.905, 0.12; tennis_indoor_dev 0.907, 0.17 (real_tennis_dev: see above).
# (Two of the indoor set's 15 false positives are unlabelled balls in shade, in 55.jpg and 108.jpg.)
# A floor a little below them: no change may quietly lose what these photos measure.
DEV_SET_FLOORS = {"tennis_floor_dev": (0.89, 0.14), "tennis_indoor_dev": (0.90, 0.18)}


@pytest.mark.parametrize("name", sorted(DEV_SET_FLOORS))
def test_development_photo_sets_do_not_regress(name):
    folder = SHARED_DATA / name
    if not (folder / "labels.json").is_file():
        pytest.skip(f"development photos not present at {folder}")
    recall, false_positives = DEV_SET_FLOORS[name]
    result = score_folder(folder)
    assert result["recall"] >= recall, result["recall"]
    assert result["false_positives_per_image"] <= false_positives, result["false_positives_per_image"]
