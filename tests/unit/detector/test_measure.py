"""Candidate measurements (services/detector/measure.py) on drawn masks and frames."""

import dataclasses

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from balltrack.services.detector.checks import CORNER_SPREAD, CandidateMetrics
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, disc, rim_directions
from balltrack.services.detector.mask import EXPLAINED, ColourMasker
from balltrack.services.detector.measure import (EDGE_STEPS, INSIDE, NO_COLOUR, RING, area_counts, colour_stats,
                                                 disc_colour_sums,
                                                 edge_spread, evenly_spaced, mean_hue, measure_mask, ray_edges,
                                                 rim_counts, rim_points, rim_samples)
from tests.unit.detector.drawing import TENNIS_BGR, scene
from tests.unit.detector.test_checks import GOOD_COLOUR

SHAPE = (240, 320)


def test_a_clean_disc_measures_as_a_ball():
    x, y, radius = 160.3, 120.6, 25.0
    metrics = measure_mask(Candidate(x, y, radius), disc(SHAPE, x, y, radius))
    assert metrics.visible == 1.0
    assert metrics.support == 1.0 and metrics.leak == 0.0
    assert metrics.fill == 1.0 and metrics.outside == 0.0
    assert metrics.spread < 0.03
    assert CandidateMetrics(metrics, GOOD_COLOUR, size=5.0).clean


def test_a_circle_inside_a_large_area_leaks_everywhere():
    mask = np.full(SHAPE, 255, np.uint8)
    metrics = measure_mask(Candidate(160.0, 120.0, 20.0), mask)
    assert metrics.fill == 1.0 and metrics.outside == 1.0
    assert metrics.leak == 1.0 and metrics.support == 0.0
    assert not CandidateMetrics(metrics, GOOD_COLOUR, size=4.0).clean


def test_a_disc_cut_by_the_frame_edge_shows_part_of_its_rim():
    x, y, radius = 10.0, 120.0, 30.0
    metrics = measure_mask(Candidate(x, y, radius), disc(SHAPE, x, y, radius))
    # the rim samples left of x = 0 (inner or outer point) are out of the frame
    assert 0.4 < metrics.visible < 0.7
    assert metrics.support == 1.0 and metrics.fill == 1.0


def test_explained_pixels_are_neither_mask_nor_not():
    x, y, radius = 120.0, 120.0, 20.0
    mask = disc(SHAPE, x, y, radius) | disc(SHAPE, x + 36.0, y, 16.0)  # a touching neighbour
    candidate = Candidate(x, y, radius)
    touching = measure_mask(candidate, mask)
    assert touching.leak > 0.05 and touching.outside > 0.05
    explained = mask.copy()
    cv2.circle(explained, (156, 120), 18, EXPLAINED, -1)
    cleared = measure_mask(candidate, explained)
    assert cleared.visible < 1.0 and cleared.leak < 0.02 and cleared.outside == 0.0
    everything = np.full(SHAPE, EXPLAINED, np.uint8)
    assert measure_mask(candidate, everything) is None


def test_a_square_has_corners():
    square = np.zeros(SHAPE, np.uint8)
    square[80:160, 120:200] = 255
    candidate = Candidate(159.5, 119.5, 45.0)  # about the square's own circle
    assert edge_spread(159.5, 119.5, 45.0, square, 96) > CORNER_SPREAD
    assert edge_spread(160.0, 120.0, 40.0, disc(SHAPE, 160.0, 120.0, 40.0), 96) < 0.03
    metrics = measure_mask(candidate, square)
    assert metrics.spread > CORNER_SPREAD
    # its four corners poke out of the circle in four places
    assert metrics.leak_runs == 4
    # a disc with a neighbour touching it leaks in one
    pair = disc(SHAPE, 160.0, 120.0, 40.0) | disc(SHAPE, 230.0, 120.0, 30.0)
    assert measure_mask(Candidate(160.0, 120.0, 40.0), pair).leak_runs == 1
    assert measure_mask(Candidate(160.0, 120.0, 40.0), disc(SHAPE, 160.0, 120.0, 40.0)).leak_runs == 0
    # too few rays with an edge: nothing to measure the spread on
    assert edge_spread(160.0, 120.0, 40.0, np.zeros(SHAPE, np.uint8), 96) == 0.0


@pytest.mark.parametrize("bgr, hue", [((0, 0, 255), 0.0), ((0, 255, 255), 30.0), ((0, 255, 0), 60.0),
                                      ((255, 0, 0), 120.0), ((255, 0, 255), 150.0),
                                      ((40, 40, 40), -1.0)])
def test_mean_hue_is_opencvs_hue(bgr, hue):
    assert mean_hue(bgr) == pytest.approx(hue)
    if hue >= 0:
        pixel = cv2.cvtColor(np.array([[bgr]], np.uint8), cv2.COLOR_BGR2HSV)[0, 0, 0]
        assert abs(float(pixel) - hue) <= 0.5


def test_colour_stats_of_a_ball_and_of_no_colour():
    image = scene([(160.0, 120.0, 25.0)], width=320, height=240)
    planes = ColourMasker(DetectorConfig()).planes(image)
    colour = colour_stats(Candidate(160.0, 120.0, 25.0), planes)
    assert colour.colourfulness > DetectorConfig().min_colourfulness
    assert abs(colour.mean_hue - mean_hue(TENNIS_BGR)) < 3.0
    assert abs(colour.colour_hue - mean_hue(TENNIS_BGR)) < 3.0
    assert colour.mean_chroma > 100
    assert colour_stats(Candidate(40.0, 40.0, 15.0), planes) == NO_COLOUR  # no mask there
    assert colour_stats(Candidate(-100.0, -100.0, 10.0), planes) == NO_COLOUR  # off the frame


def test_lit_colourfulness_is_measured_next_to_the_balls_own_lit_side():
    image = scene([(160.0, 120.0, 25.0)], width=320, height=240)
    planes = ColourMasker(DetectorConfig()).planes(image)
    bright = colour_stats(Candidate(160.0, 120.0, 25.0), planes)
    # the ball is the frame's brightest thing: the reference level is its own lit side's
    assert bright.lit_colourfulness == pytest.approx(bright.colourfulness)
    # beside a white wall four times as bright: dull next to it, vivid next to its own lit side
    dim = colour_stats(Candidate(160.0, 120.0, 25.0), dataclasses.replace(planes, reference=4 * planes.reference))
    assert dim.colourfulness == pytest.approx(bright.colourfulness / 4)
    assert dim.colourfulness < DetectorConfig().min_colourfulness < dim.lit_colourfulness


def test_evenly_spaced_is_linspace_to_the_bit():
    # (edge_spread's samples must be np.linspace's exactly: detections depend on them)
    for radius in np.random.default_rng(5).uniform(1.0, 200.0, 500):
        assert np.array_equal(evenly_spaced(0.7 * radius, 1.5 * radius, EDGE_STEPS),
                              np.linspace(0.7 * radius, 1.5 * radius, EDGE_STEPS))


@settings(max_examples=60, deadline=None)
@given(patch=arrays(np.uint8, st.tuples(st.integers(1, 30), st.integers(1, 30)),
                    elements=st.sampled_from([0, 255, EXPLAINED])),
       seed=st.integers(0, 2**32 - 1))
def test_area_counts_are_the_usable_and_mask_pixels_of_each_area(patch, seed):
    areas = np.random.default_rng(seed).choice(np.array([0, RING, INSIDE], np.uint8), patch.shape)
    usable, on = patch != EXPLAINED, patch == 255
    expected = tuple(int(np.count_nonzero(selected)) for selected in (
        usable & (areas == INSIDE), on & (areas == INSIDE), usable & (areas == RING), on & (areas == RING)))
    assert area_counts(patch, areas) == expected


def blotchy_disc(x: float, y: float, radius: float, seed: int) -> np.ndarray:
    """A 80x60 mask: a disc about the circle (x, y, radius), off centre and of another size,
    with holes, specks and a few explained pixels."""
    rng = np.random.default_rng(seed)
    mask = disc((60, 80), x + rng.normal(0.0, 3.0), y + rng.normal(0.0, 3.0), radius * rng.uniform(0.7, 1.5))
    noise = rng.random((60, 80))
    mask[noise < 0.04] = 0
    mask[noise > 0.96] = 255
    mask[(noise > 0.5) & (noise < 0.51)] = EXPLAINED
    return mask


@settings(max_examples=80, deadline=None)
@given(x=st.floats(-5.0, 85.0), y=st.floats(-5.0, 65.0), radius=st.floats(1.0, 40.0),
       seed=st.integers(0, 2**32 - 1))
def test_ray_edges_are_where_each_ray_leaves_the_mask(x, y, radius, seed):
    # each ray checked step by step
    mask = blotchy_disc(x, y, radius, seed)
    samples = rim_samples(radius)
    directions = rim_directions(samples)
    steps = evenly_spaced(0.7 * radius, 1.5 * radius, EDGE_STEPS)
    in_frame, edges = ray_edges(x, y, radius, mask, directions[0], directions[1], steps)
    expected_in_frame, expected = 0, []
    for cos, sin in zip(directions[0], directions[1]):
        points = [(int(np.rint(y + sin * step)), int(np.rint(x + cos * step))) for step in steps]
        if not all(0 <= row < 60 and 0 <= column < 80 for row, column in points):
            continue
        expected_in_frame += 1
        values = [int(mask[point]) for point in points]
        off = [index for index, value in enumerate(values) if value != 255]
        if values[0] == 255 and off and EXPLAINED not in values and steps[off[0]] >= 0.85 * radius:
            expected.append(steps[off[0]])
    assert in_frame == expected_in_frame
    assert edges.tolist() == expected


@settings(max_examples=80, deadline=None)
@given(x=st.floats(-5.0, 85.0), y=st.floats(-5.0, 65.0), radius=st.floats(1.0, 40.0),
       seed=st.integers(0, 2**32 - 1))
def test_rim_counts_read_rim_points_pairs(x, y, radius, seed):
    mask = blotchy_disc(x, y, radius, seed)
    offset = max(1.5, 0.15 * radius)
    directions = rim_directions(rim_samples(radius))
    counts = rim_counts(mask, x, y, radius - offset, radius + offset, directions[0], directions[1])
    # the pairs as rim_points gives them, read one by one
    points = rim_points(x, y, radius, 80, 60)
    pairs = [(int(mask[inner_y, inner_x]), int(mask[outer_y, outer_x]))
             for inner_x, inner_y, outer_x, outer_y in points.T]
    known = [(inner == 255, outer == 255) for inner, outer in pairs if EXPLAINED not in (inner, outer)]
    leaking = [outer for _, outer in known]
    runs = sum(1 for index in range(len(leaking)) if leaking[index] and not leaking[index - 1])
    expected = (len(known), sum(1 for inner, outer in known if inner and not outer), sum(leaking),
                max(1, runs) if any(leaking) else 0)
    assert counts == expected


@settings(max_examples=60, deadline=None)
@given(patch=arrays(np.uint8, st.tuples(st.integers(1, 30), st.integers(1, 30), st.just(3))),
       seed=st.integers(0, 2**32 - 1))
def test_disc_colour_sums_make_cv2_means(patch, seed):
    rng = np.random.default_rng(seed)
    shape = patch.shape[:2]
    inside = np.where(rng.random(shape) < 0.7, 255, 0).astype(np.uint8)
    mask = rng.choice(np.array([0, 255, EXPLAINED], np.uint8), shape)
    chroma = rng.integers(0, 256, shape, dtype=np.uint8)
    inside_count, inside_sums, selected_count, selected_sums, chroma_sum = disc_colour_sums(
        patch, mask, chroma, inside)
    selected = np.bitwise_and(inside, np.where(mask == 255, 255, 0).astype(np.uint8))
    assert (inside_count, selected_count) == (cv2.countNonZero(inside), cv2.countNonZero(selected))
    # colour_stats' means: each sum times the count's reciprocal is cv2.mean to the bit
    if inside_count:
        assert [total * (1.0 / inside_count) for total in inside_sums] == list(cv2.mean(patch, inside)[:3])
    if selected_count:
        assert [total * (1.0 / selected_count) for total in selected_sums] == list(cv2.mean(patch, selected)[:3])
        assert chroma_sum * (1.0 / selected_count) == cv2.mean(chroma, selected)[0]
