"""The learned detector's training data (training/scenes.py, augment.py, data.py) and the
export of its network (training/train.py); no training runs long here."""

import json
import math

import cv2
import mujoco
import numpy as np
import pytest

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.learned import PATCH, PLANES, BallNetwork, LearnedDetector, Proposal
from balltrack.training import data, scenes
from balltrack.training.augment import EFFECTS, augment
from tests.unit.detector.drawing import scene


@pytest.fixture(scope="module")
def world():
    built = scenes.World(np.random.default_rng(5))
    yield built
    built.close()


def test_ground_truth_matches_what_the_camera_sees(world):
    checked = 0
    for _ in range(30):
        picture = world.picture()
        assert picture.image.shape == (scenes.HEIGHT, scenes.WIDTH, 3) and picture.image.dtype == np.uint8
        segmentation = world.segmentation()
        by_position = {tuple(np.round(world.data.mocap_pos[body], 6)): geom
                       for body, geom in zip(world.ball_bodies, world.ball_geoms)}
        for ball in picture.balls:
            assert 0.0 <= ball.visible <= 1.0 and 0.0 < ball.in_frame <= 1.0
            if ball.visible < 0.98 or ball.in_frame < 1.0 or ball.radius < 8:
                continue
            # A whole ball in view: its pixels are the projected disc.
            pixels = [np.argwhere((segmentation[..., 0] == geom) & (segmentation[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)))
                      for geom in by_position.values()]
            rows_columns = min(pixels, key=lambda found: math.inf if len(found) == 0 else
                               np.hypot(*(found.mean(axis=0) - (ball.v, ball.u))))
            # (as a labeller boxes it: the centre and half the longer side of its pixels' box)
            low, high = rows_columns.min(axis=0), rows_columns.max(axis=0) + 1
            centre_v, centre_u = (low + high - 1) / 2
            assert math.hypot(centre_u - ball.u, centre_v - ball.v) <= 1.0
            assert (high - low).max() / 2 == pytest.approx(ball.radius, abs=1.0)
            checked += 1
    assert checked >= 3


def test_a_world_sets_a_colour_range_of_the_default_width(world):
    low, high = world.hue_range
    assert (high - low) % 180 == scenes.HUE_RANGE


def test_augment_keeps_the_picture_shape_and_changes_it():
    image = scene([(200.0, 240.0, 25.0)])
    changed = augment(image, np.random.default_rng(1))
    assert changed.shape == image.shape and changed.dtype == np.uint8
    for effect, _ in EFFECTS:
        assert effect(image, np.random.default_rng(2)).shape == image.shape


def test_labels_a_centred_proposal_a_ball_a_group_not_and_a_near_miss_left_out():
    ball = scenes.Ball(u=100.0, v=100.0, radius=20.0, in_frame=1.0, visible=1.0)
    hidden = scenes.Ball(u=300.0, v=100.0, radius=20.0, in_frame=1.0, visible=0.2)
    proposals = [Proposal(104.0, 98.0, 22.0), Proposal(110.0, 100.0, 60.0), Proposal(115.0, 100.0, 20.0),
                 Proposal(300.0, 100.0, 20.0), Proposal(500.0, 300.0, 20.0)]
    labels, corrections = data.label(proposals, [ball, hidden])
    assert labels.tolist() == [1, 0, -1, -1, 0]
    assert corrections[0] == pytest.approx([-4 / 22, 2 / 22, math.log(20 / 22)])


def test_samples_are_the_same_for_the_same_seed():
    first, second = data.render_samples(4, seed=3), data.render_samples(4, seed=3)
    assert first.inputs.shape[1:] == (PLANES, PATCH, PATCH) and len(first.labels) > 0
    assert np.array_equal(first.labels, second.labels)
    assert np.array_equal(first.inputs, second.inputs)


def test_the_colour_range_of_a_photo_is_its_balls_hue():
    image = scene([(200.0, 240.0, 25.0)])  # yellow-green felt, H ~36
    low, high = data.target_hue_range(image, [scenes.Ball(200.0, 240.0, 25.0, 1.0, 1.0)])
    assert low <= 36 <= high and high - low == 25
    grey = np.full((480, 640, 3), 128, np.uint8)
    assert data.target_hue_range(grey, [scenes.Ball(200.0, 240.0, 25.0, 1.0, 1.0)]) is None


def test_a_box_on_the_frame_edge_is_a_cut_ball_of_its_longer_side():
    [ball] = data.photo_balls([{"x": 0, "y": 100, "w": 10, "h": 40}], width=640, height=480)
    assert ball.radius == 20 and ball.u == pytest.approx(10 - 20 - 0.5)
    [whole] = data.photo_balls([{"x": 100, "y": 100, "w": 40, "h": 40}], width=640, height=480)
    assert (whole.u, whole.v, whole.radius, whole.in_frame) == pytest.approx((119.5, 119.5, 20, 1.0))


def test_development_sets_are_never_trained_on(tmp_path):
    folder = tmp_path / "tennis_floor_dev"
    folder.mkdir()
    (folder / "labels.json").write_text(json.dumps({}))
    with pytest.raises(ValueError, match="not a set that may be trained on"):
        data.photo_samples(folder, copies=1, seed=0)


def test_the_exported_network_runs_in_opencv_as_in_torch(tmp_path):
    torch = pytest.importorskip("torch", reason="the train extra (pip install -e '.[train]') is not installed")
    from balltrack.training import train

    torch.manual_seed(0)
    network = train.build_network().eval()
    train.export(network, tmp_path / "model.onnx", work_width=320)
    batch = np.random.default_rng(0).normal(size=(5, PLANES, PATCH, PATCH)).astype(np.float32)
    with torch.no_grad():
        expected = network(torch.from_numpy(batch)).numpy()
    expected[:, 0] = 1 / (1 + np.exp(-expected[:, 0]))
    for runtime in BallNetwork.RUNTIMES:
        exported = BallNetwork(tmp_path / "model.onnx", runtime=runtime)
        assert exported(batch) == pytest.approx(expected, abs=1e-4)
        assert exported.work_width == 320
    # frames are processed at the model's width when the configured one is wider
    detector = LearnedDetector(DetectorConfig(), BallNetwork(tmp_path / "model.onnx"))
    work, scale, _ = detector.work_frame(np.zeros((480, 640, 3), np.uint8))
    assert work.shape == (240, 320, 3) and scale == 0.5


@pytest.mark.slow  # (trains for several epochs: left to the whole suite, out of the quick tier)
def test_a_short_training_learns_balls_from_not_balls():
    pytest.importorskip("torch", reason="the train extra (pip install -e '.[train]') is not installed")
    from balltrack.training import train

    samples = data.render_samples(40, seed=11)
    untrained = train.figures(train.build_network(), samples)
    network = train.train(samples, epochs=8, seed=0, log=lambda line: None)
    figures = train.figures(network, samples)
    assert figures["balls"] > 20
    # (better than the untrained network on both, and than a coin on balls)
    assert figures["balls_accepted"] > 0.5 and figures["not_balls_rejected"] > 0.8
    assert (figures["balls_accepted"] + figures["not_balls_rejected"]
            > untrained["balls_accepted"] + untrained["not_balls_rejected"] + 0.2)
