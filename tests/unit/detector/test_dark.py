"""Dark sides (services/detector/dark.py): balls whose unlit side is black, in drawn frames."""

import math

import numpy as np

from balltrack.services.detector.checks import CandidateMetrics
from balltrack.services.detector.measure import ColourMetrics, MaskMetrics, measure_mask
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.dark import dark_around, dark_side, lit_rim_support, second_look
from balltrack.services.detector.geometry import Candidate
from balltrack.services.detector.mask import ColourMasker
from balltrack.services.detector.outline import DARK_WIDE_REACH, WIDE_REACH
from balltrack.services.detector.proposals import frame_search
from tests.unit.detector.drawing import TENNIS_BGR, coverage, draw_ball, draw_box, floor, to_uint8

U, V, RADIUS = 160.4, 120.7, 30.0
# what the candidate checks make of a lit cap: a ragged rim (they reject it)
CAP_METRICS = CandidateMetrics(
    MaskMetrics(visible=1.0, support=0.5, leak=0.1, fill=0.7, outside=0.05, spread=0.1),
    ColourMetrics(colourfulness=0.6, mean_hue=36.0, mean_chroma=100.0, colour_hue=36.0, lit_colourfulness=0.6),
    size=4.0)


def black_side_frame(terminator: float = 0.0):
    """A ball whose lower part is in black shadow (a light from above, no ambient) on a lit
    grey floor: its colour is a cap, above ``terminator`` radii over the centre (0: a half-disc;
    more as the light grazes)."""
    image = floor(320, 240)
    rows = np.mgrid[0:240, 0:320][0].astype(np.float32)
    colour = np.where((rows < V - terminator * RADIUS)[..., None], np.array(TENNIS_BGR, np.float32), 4.0)
    cover = coverage(image.shape, U, V, RADIUS)[..., None]
    return to_uint8(image * (1.0 - cover) + colour * cover)


def lit_cap(planes):
    """A circle on the colour mask's cap: centred on it, of the cap's area."""
    ys, xs = np.nonzero(planes.mask == 255)
    return Candidate(float(xs.mean()), float(ys.mean()), math.sqrt(xs.size / math.pi))


def test_the_colour_of_a_ball_with_a_black_side_is_a_cap():
    planes = ColourMasker(DetectorConfig()).planes(black_side_frame())
    cap = lit_cap(planes)
    assert cap.y < V - 8 and cap.radius < 0.8 * RADIUS
    assert not planes.mask[int(V) + 5:int(V + RADIUS), int(U)].any()


def test_dark_side_of_a_ball_lit_from_above():
    image = black_side_frame()
    planes = ColourMasker(DetectorConfig()).planes(image)
    assert dark_side(planes.frame, planes.mask, Candidate(U, V, RADIUS))


def test_no_dark_side_in_an_evenly_lit_ball_or_a_box():
    lit = to_uint8(draw_ball(floor(320, 240), U, V, RADIUS))
    planes = ColourMasker(DetectorConfig()).planes(lit)
    assert not dark_side(planes.frame, planes.mask, Candidate(U, V, RADIUS))
    # the circle around a box's face: its corners are out of the mask, but not dark ones
    box = to_uint8(draw_box(floor(320, 240), 130, 90, 190, 150, (40, 225, 190)))
    planes = ColourMasker(DetectorConfig()).planes(box)
    assert not dark_side(planes.frame, planes.mask, Candidate(160.0, 120.0, 38.0))
    # a circle with no colour in it
    assert not dark_side(planes.frame, planes.mask, Candidate(40.0, 40.0, 10.0))


def test_dark_around_a_cap_but_not_around_a_ball_on_a_lit_floor():
    image = black_side_frame()
    planes = ColourMasker(DetectorConfig()).planes(image)
    assert dark_around(planes.frame, planes.mask, lit_cap(planes))
    lit = to_uint8(draw_ball(floor(320, 240), U, V, RADIUS))
    planes = ColourMasker(DetectorConfig()).planes(lit)
    assert not dark_around(planes.frame, planes.mask, Candidate(U, V, RADIUS))


def test_second_look_finds_the_whole_ball_around_its_cap():
    config = DetectorConfig()
    planes = ColourMasker(config).planes(black_side_frame())
    search = frame_search(planes, config, 1.0)
    judged = []
    kept = second_look([(lit_cap(planes), CAP_METRICS)], [], planes.mask, search, config,
                       WIDE_REACH, judged)
    assert len(kept) == 1
    ball = kept[0]
    assert math.hypot(ball.x - U, ball.y - V) < 1.0 and abs(ball.radius - RADIUS) < 1.0
    # scored on fill and rim support, which the dark side lowers
    assert 0.0 < ball.score < 1.0
    [(entry, metrics, score)] = judged
    assert entry is ball and metrics.dark_side and score == ball.score
    assert metrics.colour == CAP_METRICS.colour


def pitch_dark(image):
    """The frame as a camera sees it with next to no light: colour a grey level or two."""
    return np.round(image.astype(np.float32) / 80).astype(np.uint8)


def test_under_a_grazing_light_only_the_lit_part_of_the_rim_is_a_colour_edge():
    # Pitch dark, the lit cap the top 30 % of the disc: on the whole rim the colour edge is
    # under min_edge_support, on its lit part it is complete.
    config = DetectorConfig()
    planes = ColourMasker(config).planes(pitch_dark(black_side_frame(terminator=0.4)))
    assert planes.dark
    ball = Candidate(U, V, RADIUS)
    assert measure_mask(ball, planes.mask).support < config.min_edge_support
    assert lit_rim_support(planes.frame, planes.mask, ball) > 0.9


def test_second_look_finds_the_ball_around_its_cap_in_a_pitch_dark_frame():
    config = DetectorConfig()
    planes = ColourMasker(config).planes(pitch_dark(black_side_frame()))
    kept = second_look([(lit_cap(planes), CAP_METRICS)], [], planes.mask,
                       frame_search(planes, config, 1.0), config, DARK_WIDE_REACH)
    assert len(kept) == 1
    assert math.hypot(kept[0].x - U, kept[0].y - V) < 1.0 and abs(kept[0].radius - RADIUS) < 1.0


def test_colour_that_does_not_reach_the_outline_is_no_lit_rim():
    # a colour spot inside a black disc: the disc's rim is all dark inside, nothing to judge
    image = floor(320, 240)
    dark_disc = coverage(image.shape, U, V, RADIUS)[..., None]
    image = image * (1.0 - dark_disc) + 4.0 * dark_disc
    spot = coverage(image.shape, U, V - 12, 10.0)[..., None]
    image = to_uint8(image * (1.0 - spot) + np.array(TENNIS_BGR, np.float32) * spot)
    planes = ColourMasker(DetectorConfig()).planes(image)
    assert lit_rim_support(planes.frame, planes.mask, Candidate(U, V, RADIUS)) == 0.0


def test_second_look_passes_over_dull_orange_overlapping_and_surplus_candidates():
    config = DetectorConfig()
    planes = ColourMasker(config).planes(black_side_frame())
    search = frame_search(planes, config, 1.0)
    cap = lit_cap(planes)
    dull = CandidateMetrics(CAP_METRICS.mask, ColourMetrics(0.1, 36.0, 100.0, 36.0, 0.1), size=4.0)
    assert second_look([(cap, dull)], [], planes.mask, search, config, WIDE_REACH) == []
    # its colour at the range's orange end (a yellow box with a black stripe, wood, a lamp)
    orange = CandidateMetrics(CAP_METRICS.mask, ColourMetrics(0.6, 25.5, 100.0, 25.5, 0.6), size=4.0)
    assert second_look([(cap, orange)], [], planes.mask, search, config, WIDE_REACH) == []
    already = Candidate(U, V, RADIUS, score=0.9)
    assert second_look([(cap, CAP_METRICS)], [already], planes.mask, search, config,
                       WIDE_REACH) == [already]
    full = DetectorConfig(max_detections=1)
    other = Candidate(20.0, 20.0, 5.0)
    assert second_look([(cap, CAP_METRICS)], [other], planes.mask, search, full,
                       WIDE_REACH) == [other]


def test_second_look_finds_nothing_on_a_lit_floor():
    # a ragged yellow-green patch on a lit floor has no dark side to grow into
    config = DetectorConfig()
    image = to_uint8(draw_ball(floor(320, 240), U, V, RADIUS))
    planes = ColourMasker(config).planes(image)
    search = frame_search(planes, config, 1.0)
    assert second_look([(Candidate(U, V - 10, 18.0), CAP_METRICS)], [], planes.mask, search,
                       config, WIDE_REACH) == []
