"""Candidate judgement (services/detector/checks.py) of measured circles."""

import dataclasses

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from balltrack.services.detector.checks import CandidateMetrics, failed_checks, hue_in_range, judge
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.measure import ColourMetrics, MaskMetrics

GOOD_MASK = MaskMetrics(visible=1.0, support=0.95, leak=0.02, fill=0.97, outside=0.01, spread=0.02)
GOOD_COLOUR = ColourMetrics(colourfulness=0.6, mean_hue=36.0, mean_chroma=120.0, colour_hue=36.0,
                            lit_colourfulness=0.6)


def test_hue_in_range_with_and_without_wrapping():
    config = DetectorConfig()  # 25-50
    assert hue_in_range(36.0, config) and hue_in_range(24.6, config) and hue_in_range(50.5, config)
    assert not hue_in_range(24.0, config) and not hue_in_range(-1.0, config)
    red = DetectorConfig(h_min=170, h_max=8)
    assert hue_in_range(175.0, red) and hue_in_range(3.0, red) and not hue_in_range(30.0, red)


def test_judge_scores_a_ball():
    config = DetectorConfig()
    metrics = CandidateMetrics(GOOD_MASK, GOOD_COLOUR, size=3.0)
    clutter = GOOD_MASK.leak + GOOD_MASK.outside
    assert judge(metrics, config) == pytest.approx((GOOD_MASK.fill + GOOD_MASK.support - clutter) / 2)


@pytest.mark.parametrize("mask_changes, colour_changes, size", [
    ({"visible": 0.2}, {}, 3.0),                       # too little rim in view
    ({"visible": 0.9}, {}, 0.8),                       # a small ball must be whole
    ({"fill": 0.5}, {}, 3.0),                          # a ring, not a disc
    ({"support": 0.45, "leak": 0.1}, {}, 3.0),        # clutter asks for more rim support
    ({"outside": 0.35}, {}, 3.0),                      # in a large area of colour
    ({}, {"colourfulness": 0.2, "lit_colourfulness": 0.2}, 3.0),  # dull
    ({}, {"mean_chroma": 3.0, "mean_hue": 15.0}, 3.0),  # dim, and the mean colour is orange
    ({"spread": 0.06}, {"colour_hue": 26.0}, 3.0),     # its colour at the orange end (wood, skin)
    ({"spread": 0.06}, {"colour_hue": 48.5}, 3.0),     # or at the green end (leaves)
    ({"spread": 0.1, "leak": 0.1, "support": 0.99, "leak_runs": 4}, {}, 3.0),  # corners
    ({"fill": 0.56, "support": 0.46}, {}, 3.0),        # each check passed, but below min_score
])
def test_judge_rejects(mask_changes, colour_changes, size):
    metrics = CandidateMetrics(dataclasses.replace(GOOD_MASK, **mask_changes),
                               dataclasses.replace(GOOD_COLOUR, **colour_changes), size=size)
    assert judge(metrics, DetectorConfig()) is None
    assert failed_checks(metrics, DetectorConfig())


def test_failed_checks_name_the_value_and_the_bound():
    config = DetectorConfig()
    assert failed_checks(CandidateMetrics(GOOD_MASK, GOOD_COLOUR, size=3.0), config) == []
    ring = CandidateMetrics(dataclasses.replace(GOOD_MASK, fill=0.5), GOOD_COLOUR, size=3.0)
    assert failed_checks(ring, config) == ["fill 0.50 < min_fill_ratio 0.55"]
    # every failed check is listed, not only the first judge meets
    green = dataclasses.replace(GOOD_COLOUR, colour_hue=48.5, colourfulness=0.1, lit_colourfulness=0.1)
    cluttered = dataclasses.replace(GOOD_MASK, spread=0.06, fill=0.5, outside=0.6)
    reasons = failed_checks(CandidateMetrics(cluttered, green, size=3.0), config)
    assert [reason.split()[0] for reason in reasons] == ["fill", "edge", "mask", "colourfulness", "hue", "score"]
    assert "48.5" in reasons[4] and "25-50" in reasons[4]


def good_or(value, strategy):
    """The good candidate's value, or any: most examples then fail one or two checks, and many
    pass, so both sides of judge are exercised."""
    return st.one_of(st.just(value), strategy)


unit = st.floats(0.0, 1.0)


@settings(max_examples=500, deadline=None)
@given(mask=st.builds(MaskMetrics, visible=good_or(1.0, unit), support=good_or(0.95, unit),
                      leak=good_or(0.02, unit), fill=good_or(0.97, unit), outside=good_or(0.01, unit),
                      spread=good_or(0.02, st.floats(0.0, 0.2)), leak_runs=good_or(1, st.integers(0, 6))),
       colour=st.builds(ColourMetrics, colourfulness=good_or(0.6, st.floats(0.0, 1.5)),
                        mean_hue=good_or(36.0, st.floats(-1.0, 180.0)),
                        mean_chroma=good_or(120.0, st.floats(0.0, 20.0)),
                        colour_hue=good_or(36.0, st.floats(-1.0, 180.0)),
                        lit_colourfulness=good_or(0.6, st.floats(0.0, 1.5))),
       size=good_or(3.0, st.floats(0.3, 8.0)), highlighted=st.booleans(),
       front_edges=st.sampled_from([0.0, 0.3, 0.9]), hue_margin=st.sampled_from([0.0, 3.0]),
       wrapping=st.booleans())
def test_failed_checks_agree_with_judge(mask, colour, size, highlighted, front_edges, hue_margin, wrapping):
    config = DetectorConfig(hue_margin=hue_margin, **({"h_min": 20, "h_max": 10} if wrapping else {}))
    metrics = CandidateMetrics(mask, colour, size=size, highlighted=highlighted, front_edges=front_edges)
    assert (judge(metrics, config) is None) == bool(failed_checks(metrics, config))


def test_judge_accepts_what_the_rejections_border_on():
    config = DetectorConfig()
    # a dim ball whose mean colour has the target's hue
    dim = CandidateMetrics(GOOD_MASK, dataclasses.replace(GOOD_COLOUR, mean_chroma=3.0), size=3.0)
    assert judge(dim, config) is not None
    # an uneven edge without leaks (a touching neighbour) is not a corner
    uneven = CandidateMetrics(dataclasses.replace(GOOD_MASK, spread=0.1), GOOD_COLOUR, size=3.0)
    assert judge(uneven, config) is not None
    # nor is an uneven edge leaking in one or two places (a neighbour, a shadow, motion blur)
    smeared = dataclasses.replace(GOOD_MASK, spread=0.1, leak=0.1, support=0.99, leak_runs=2)
    assert judge(CandidateMetrics(smeared, GOOD_COLOUR, size=3.0), config) is not None
    # a two-colour ball: the mean of the whole disc is orange, its colour part is the target's
    two_colour = CandidateMetrics(GOOD_MASK, dataclasses.replace(GOOD_COLOUR, mean_hue=22.0), size=3.0)
    assert judge(two_colour, config) is not None
    # the colour's hue just inside the margin
    edge = dataclasses.replace(GOOD_COLOUR, colour_hue=config.h_min + config.hue_margin)
    assert judge(CandidateMetrics(GOOD_MASK, edge, size=3.0), config) is not None
    # plainly a ball by shape (clean, even edge, large): its colour need only be in the range
    warm = dataclasses.replace(GOOD_COLOUR, colour_hue=26.0)
    assert judge(CandidateMetrics(GOOD_MASK, warm, size=3.0), config) is not None
    assert judge(CandidateMetrics(dataclasses.replace(GOOD_MASK, spread=0.07), warm, size=3.0), config) is None
    assert judge(CandidateMetrics(GOOD_MASK, warm, size=1.5), config) is None
    # and its colour may be duller next to the frame's bright level (a lamp, a lit screen)
    dull = dataclasses.replace(GOOD_COLOUR, colourfulness=0.8 * config.min_colourfulness)
    assert judge(CandidateMetrics(GOOD_MASK, dull, size=3.0), config) is not None
    assert judge(CandidateMetrics(dataclasses.replace(GOOD_MASK, spread=0.07), dull, size=3.0), config) is None
    duller = dataclasses.replace(dull, colourfulness=0.2, lit_colourfulness=0.2)
    assert judge(CandidateMetrics(GOOD_MASK, duller, size=3.0), config) is None
    # a whole small ball
    assert judge(CandidateMetrics(GOOD_MASK, GOOD_COLOUR, size=0.8), config) is not None


def test_a_ball_plainly_round_may_be_vivid_next_to_its_own_lit_side():
    config = DetectorConfig()
    # in shade beside a white wall: dull next to the frame's bright level, not next to its own
    shaded = dataclasses.replace(GOOD_COLOUR, colourfulness=0.15, lit_colourfulness=0.4)
    assert judge(CandidateMetrics(GOOD_MASK, shaded, size=3.0), config) is not None
    # leaves in shade are as vivid next to their own light: a ragged edge or a small blob is no
    # plain ball
    assert judge(CandidateMetrics(dataclasses.replace(GOOD_MASK, spread=0.07), shaded, size=3.0),
                 config) is None
    assert judge(CandidateMetrics(GOOD_MASK, shaded, size=1.5), config) is None
    # pale (dull next to its own lit side too)
    pale = dataclasses.replace(shaded, lit_colourfulness=0.2)
    assert judge(CandidateMetrics(GOOD_MASK, pale, size=3.0), config) is None
