"""Keeping the target among several balls: prediction, size reference, merges (pure core)."""

import math

import pytest

from balltrack.services.follower.association import (CLEAN, COVERED, NEW, AssociationSettings,
                                                     TargetAssociation)
from balltrack.services.follower.config import FollowerConfig

FRAME = 1 / 30


def association(**changes) -> TargetAssociation:
    return TargetAssociation(AssociationSettings.from_config(FollowerConfig(**changes)))


def ball(x, z, y=0.1):
    return {"x": x, "y": y, "z": z}


def run_target(tracker: TargetAssociation, start_x: float, speed: float, size: float,
               frames: int) -> float:
    """Feed ``frames`` frames of a lone target moving at ``speed`` (normalised x per s); returns
    the time of the last frame."""
    now = 0.0
    for index in range(frames):
        now = index * FRAME
        assert tracker.choose([ball(start_x + speed * now, size)], now) == ball(start_x + speed * now, size)
    return now


def test_no_target_takes_the_largest_and_starts_a_track():
    tracker = association()
    assert tracker.choose([ball(-0.5, 0.05), ball(0.4, 0.08)], 0.0) == ball(0.4, 0.08)
    assert tracker.last_kind == NEW
    assert tracker.track.x == 0.4 and tracker.track.size == 0.08


def test_predicted_position_follows_the_targets_image_motion():
    tracker = association()
    now = run_target(tracker, -0.2, 0.6, 0.04, 30)
    # Missed for 0.2 s: it moved on by about 0.12. A ball of the same size left near where the
    # target was last seen is not it; the one at the predicted position is.
    later = now + 0.2
    expected = -0.2 + 0.6 * later
    assert tracker.predicted(later)[0] == pytest.approx(expected, abs=0.01)
    stayed, moved_on = ball(-0.2 + 0.6 * now, 0.04), ball(expected + 0.005, 0.04)
    assert tracker.choose([stayed, moved_on], later) == moved_on
    assert tracker.last_kind == CLEAN


def test_a_lone_target_may_grow_fast_but_a_crowded_one_not():
    tracker = association()
    now = run_target(tracker, 0.0, 0.0, 0.04, 10)
    # Alone, in the last metres of an approach: 2 % a frame (0.6 per s in log) is the target.
    size = 0.04
    for _ in range(30):
        now += FRAME
        size *= math.exp(0.6 * FRAME)
        assert tracker.choose([ball(0.0, size)], now) == ball(0.0, size)
        assert tracker.last_kind == CLEAN
    assert tracker.track.size == pytest.approx(size)
    # Another ball comes near: from then on the reference follows at most target_size_rate...
    for step in range(10):
        now += FRAME
        other = ball(0.25 - 0.01 * step, size)
        assert tracker.choose([ball(0.0, size), other], now) == ball(0.0, size)
    # ...so when the two merge into one detection growing 6 % a frame, within a few frames it
    # is no longer the target alone, though each frame differs from the last by less than the
    # size ratio.
    reference = tracker.track.size
    kinds = []
    for _ in range(6):
        now += FRAME
        size *= 1.06
        tracker.choose([ball(0.0, size)], now)
        kinds.append(tracker.last_kind)
    assert kinds[0] == CLEAN and kinds[-1] == COVERED
    assert tracker.track.size < reference * 1.1


def test_a_larger_detection_covering_the_target_holds_it_but_is_not_steered_by():
    tracker = association(target_hold_secs=0.3)
    now = run_target(tracker, 0.1, 0.0, 0.04, 10)
    other = ball(0.6, 0.08)  # a larger ball elsewhere, which the paper's rule would take
    for _ in range(30):  # 1 s behind a nearer ball whose disc contains the target's position
        now += FRAME
        assert tracker.choose([ball(0.12, 0.09), other], now) is None  # not steered by
        assert tracker.last_kind == COVERED
    # The nearer ball moves away: the target is there again, the other large ball is not taken.
    now += FRAME
    assert tracker.choose([ball(0.1, 0.04), ball(0.3, 0.09), other], now) == ball(0.1, 0.04)
    assert tracker.last_kind == CLEAN


def test_two_balls_crossing_in_the_image_the_target_is_kept_after_they_part():
    """As measured in the multiball experiment: the target drifts left slowly, another ball of
    the same size crosses it leftward faster; for 20 frames the detector sees one blob whose
    centre lies between them and which grows. When they part, the target is the one that
    continued the target's own motion, not the one nearer the blob's last centre."""
    tracker = association()
    target_speed, other_speed, size = -0.07, -0.25, 0.036
    now = run_target(tracker, 0.12, target_speed, size, 30)
    target_x = lambda t: 0.12 + target_speed * t  # noqa: E731
    other_x = lambda t: target_x(now) + 0.09 + other_speed * (t - now)  # noqa: E731
    for _ in range(40):
        now += FRAME
        target, other = target_x(now), other_x(now)
        if abs(target - other) < 2 * size:
            # merged: one detection spanning both
            merged = ball((target + other) / 2, size + abs(target - other) / 2)
            tracker.choose([merged, ball(-0.8, 0.055)], now)
            assert tracker.last_kind in (CLEAN, COVERED)
        else:
            chosen = tracker.choose([ball(other, size), ball(target, size), ball(-0.8, 0.055)], now)
            assert chosen == ball(target, size)


def test_a_partly_hidden_target_looks_smaller_and_is_still_the_target():
    tracker = association()
    now = run_target(tracker, 0.0, 0.0, 0.05, 10)
    assert tracker.choose([ball(0.01, 0.042), ball(0.5, 0.06)], now + FRAME) == ball(0.01, 0.042)
    # Much smaller than the target: a farther ball, not the target.
    assert tracker.choose([ball(0.02, 0.02)], now + 2 * FRAME) is None


def test_after_the_hold_the_largest_is_taken_again():
    tracker = association(target_hold_secs=0.3)
    now = run_target(tracker, 0.0, 0.0, 0.05, 10)
    assert tracker.choose([ball(0.7, 0.08)], now + 0.2) is None
    assert tracker.choose([ball(0.7, 0.08)], now + 0.31) == ball(0.7, 0.08)
    assert tracker.last_kind == NEW


def test_time_going_backwards_drops_the_track():
    tracker = association()
    run_target(tracker, 0.0, 0.0, 0.05, 10)
    assert not tracker.holding(0.0 - 1.0)
    assert tracker.choose([ball(0.7, 0.08)], -1.0) == ball(0.7, 0.08)


def test_unusable_detections_are_ignored():
    tracker = association()
    assert tracker.choose([ball(math.nan, 0.05), ball(0.1, 0.0), ball(0.2, -1.0)], 0.0) is None
    assert tracker.track is None


@pytest.mark.parametrize("field, value", [("target_size_ratio", 1.0), ("target_shrink_ratio", 0.9),
                                          ("target_size_rate", 0.0), ("target_velocity_memory", 1.0),
                                          ("target_crowd_secs", -1.0)])
def test_association_parameters_are_validated(field, value):
    from balltrack.common.config import ConfigError

    with pytest.raises(ConfigError, match=field):
        FollowerConfig(**{field: value})
