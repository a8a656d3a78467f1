"""The learned detector's stages (services/detector/learned.py) and the committed model."""

import math

import cv2
import numpy as np
import pytest

from balltrack.services.detector.config import DetectorConfig, Method
from balltrack.services.detector.detector import BallDetector, build_detector
from balltrack.services.detector.learned import (CONTEXT, MODEL_PATH, PATCH, PLANES, BallNetwork, LearnedBall,
                                                 LearnedDetector, Proposal, patches, propose, refine, suppress)
from tests.unit.detector.drawing import scene


def disc_mask(circles, width=320, height=240):
    mask = np.zeros((height, width), np.uint8)
    for u, v, radius in circles:
        cv2.circle(mask, (u, v), radius, 255, -1)
    return mask


def near(proposals, u, v, radius, offset=0.25, ratio=0.25):
    return any(math.hypot(p.x - u, p.y - v) <= offset * radius and abs(math.log(p.radius / radius)) <= ratio
               for p in proposals)


def test_a_lone_disc_is_proposed_once_at_its_circle():
    proposals = propose(disc_mask([(100, 120, 30)]), min_radius=3, max_radius=120)
    assert near(proposals, 100, 120, 30)
    assert len(proposals) == 1


def test_touching_discs_are_each_proposed_besides_their_blob():
    proposals = propose(disc_mask([(100, 120, 30), (160, 120, 30), (130, 68, 30)]), min_radius=3, max_radius=120)
    for u, v in ((100, 120), (160, 120), (130, 68)):
        assert near(proposals, u, v, 30), (u, v, proposals)


def test_specks_below_the_smallest_radius_are_not_proposed():
    assert propose(disc_mask([(50, 50, 1), (200, 100, 1)]), min_radius=3, max_radius=120) == []
    assert propose(np.zeros((240, 320), np.uint8), min_radius=3, max_radius=120) == []


def test_patches_centre_the_proposal_and_carry_no_hue():
    features = np.zeros((240, 320, PLANES), np.uint8)
    cv2.circle(features, (100, 120), 20, (200, 150, 255), -1)
    [patch] = patches(features, [Proposal(100.0, 120.0, 20.0)])
    assert patch.shape == (PLANES, PATCH, PATCH) and patch.dtype == np.float32
    middle, corner = PATCH // 2, 1
    # brightness normalised per patch: bright disc above, dark surround below the patch's mean
    assert patch[0, middle, middle] > 0 > patch[0, corner, corner]
    assert patch[2, middle, middle] == pytest.approx(1.0) and patch[2, corner, corner] == 0.0
    # the disc spans 1 / CONTEXT of the patch's half-side
    row = patch[2, middle]
    assert np.count_nonzero(row > 0.5) == pytest.approx(PATCH / CONTEXT, abs=2)


def test_a_patch_beyond_the_frame_edge_is_zero_there():
    features = np.full((240, 320, PLANES), 255, np.uint8)
    [patch] = patches(features, [Proposal(5.0, 120.0, 20.0)])
    assert patch[2, PATCH // 2, 0] == 0.0 and patch[2, PATCH // 2, -1] == pytest.approx(1.0)


def test_refine_moves_and_resizes_by_the_network_outputs():
    [ball] = refine([Proposal(100.0, 50.0, 10.0)], np.array([[0.9, 0.5, -0.2, math.log(1.5)]], np.float32))
    assert (ball.x, ball.y, ball.radius, ball.score) == pytest.approx((105.0, 48.0, 15.0, 0.9))


def test_suppress_keeps_the_best_of_one_ball_and_both_of_two_touching():
    balls = [LearnedBall(100, 100, 20, 0.7), LearnedBall(104, 100, 21, 0.9), LearnedBall(140, 100, 20, 0.8),
             LearnedBall(300, 100, 20, 0.3)]
    kept = suppress(balls, min_score=0.5, limit=10)
    assert [(b.x, b.score) for b in kept] == [(104, 0.9), (140, 0.8)]
    assert len(suppress(balls, min_score=0.5, limit=1)) == 1


def test_the_method_chooses_the_detector():
    assert isinstance(build_detector(DetectorConfig()), BallDetector)
    assert isinstance(build_detector(DetectorConfig(method=Method.learned)), LearnedDetector)


def test_a_missing_model_is_named():
    with pytest.raises(FileNotFoundError, match="no model"):
        BallNetwork("/nonexistent/ball_network.onnx")


def test_the_committed_model_finds_drawn_balls_and_not_an_empty_floor():
    detector = LearnedDetector(DetectorConfig())
    balls = [(200.0, 240.0, 25.0), (420.0, 150.0, 40.0)]
    result = detector.detect(scene(balls))
    for u, v, radius in balls:
        assert any(math.hypot(d.u - u, d.v - v) <= 0.5 * radius and abs(d.radius_px / radius - 1) < 0.3
                   for d in result.detections), (u, v, result.detections)
    assert len(result.detections) == 2
    assert result.mask.shape == (480, 640)
    assert detector.detect(scene([])).detections == []


def test_the_committed_model_is_small():
    assert MODEL_PATH.stat().st_size <= 5 * 1024 * 1024


def test_both_runtimes_give_the_same_outputs():
    batch = np.random.default_rng(3).normal(size=(7, PLANES, PATCH, PATCH)).astype(np.float32)
    fast, opencv = BallNetwork(runtime="onnxruntime")(batch), BallNetwork(runtime="opencv")(batch)
    assert fast.shape == (7, 4) and fast == pytest.approx(opencv, abs=1e-4)
    assert BallNetwork()(batch[:0]).shape == (0, 4)
    with pytest.raises(ValueError, match="runtime"):
        BallNetwork(runtime="tensorflow")
