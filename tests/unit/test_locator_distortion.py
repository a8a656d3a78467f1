"""The locator's exact model through a distorted lens: balls projected with cv2.projectPoints
through known intrinsics and plumb_bob distortion, measured (circle fit, and the detector on
drawn frames), then located with and without the distortion."""

import math

import cv2
import numpy as np
import pytest

from balltrack.services.detector.detector import BallDetector
from balltrack.common.pinhole import Intrinsics
from balltrack.services.locator.geometry import locate_exact, undistort_circle
from balltrack.services.locator.projection import (distorted_silhouette, outline_ellipse, project_sphere,
                                                   silhouette_ellipse)

WIDTH, HEIGHT = 640, 480
FOCAL = 400.0  # a wide lens (77 degrees across), where distortion matters most
CAMERA = np.array([[FOCAL, 0.0, 319.5], [0.0, FOCAL, 239.5], [0.0, 0.0, 1.0]])
BARREL = (-0.30, 0.10, 0.001, -0.0005, -0.015)  # k1 k2 p1 p2 k3, a typical cheap webcam
BALL_RADIUS = 0.033
DISTORTED = Intrinsics(FOCAL, FOCAL, 319.5, 239.5, WIDTH, HEIGHT, BARREL)
IGNORED = Intrinsics(FOCAL, FOCAL, 319.5, 239.5, WIDTH, HEIGHT)

# Ball centres in the optical frame: on axis, half way out, and near the frame's edge.
CENTRE = (0.0, 0.0, 0.8)
MIDDLE = (0.25, 0.10, 0.9)
EDGE = (0.62, 0.05, 0.8)
CORNER = (0.55, 0.38, 0.85)


def silhouette(center, distortion=BARREL, points=720) -> np.ndarray:
    """The sphere's outline in the distorted image: its tangent circle (where the rays from the
    camera graze the sphere) through cv2.projectPoints."""
    center = np.asarray(center, float)
    distance = np.linalg.norm(center)
    axis = center / distance
    ring_centre = center * (1.0 - BALL_RADIUS ** 2 / distance ** 2)
    ring_radius = BALL_RADIUS * math.sqrt(distance ** 2 - BALL_RADIUS ** 2) / distance
    first = np.cross(axis, [0.0, 1.0, 0.0])
    first /= np.linalg.norm(first)
    second = np.cross(axis, first)
    angles = np.linspace(0.0, 2.0 * math.pi, points, endpoint=False)
    ring = ring_centre + ring_radius * (np.outer(np.cos(angles), first) + np.outer(np.sin(angles), second))
    projected, _ = cv2.projectPoints(ring, np.zeros(3), np.zeros(3), CAMERA, np.array(distortion))
    return projected.reshape(-1, 2)


def fitted_circle(outline: np.ndarray) -> tuple[float, float, float]:
    """Least-squares circle through the outline (what the default `mean` model assumes)."""
    design = np.column_stack([2 * outline[:, 0], 2 * outline[:, 1], np.ones(len(outline))])
    (u, v, c), *_ = np.linalg.lstsq(design, np.sum(outline ** 2, axis=1), rcond=None)
    return u, v, math.sqrt(c + u * u + v * v)


def error_of(circle, intrinsics, truth) -> float:
    position = locate_exact(*circle, intrinsics, BALL_RADIUS)
    return math.dist((position.x, position.y, position.z), truth) / math.dist(truth, (0, 0, 0))


def test_zero_distortion_changes_nothing():
    circle = fitted_circle(silhouette(MIDDLE, distortion=(0, 0, 0, 0, 0)))
    zeros = Intrinsics(FOCAL, FOCAL, 319.5, 239.5, WIDTH, HEIGHT, (0.0,) * 5)
    assert not zeros.distorted
    assert undistort_circle(*circle, zeros) == circle
    assert locate_exact(*circle, zeros, BALL_RADIUS) == locate_exact(*circle, IGNORED, BALL_RADIUS)


def test_intrinsics_read_distortion_from_camera_info():
    info = {"width": WIDTH, "height": HEIGHT, "fx": FOCAL, "fy": FOCAL, "cx": 319.5, "cy": 239.5}
    assert Intrinsics.from_camera_info(info).distortion == ()
    assert Intrinsics.from_camera_info({**info, "distortion_model": "none", "d": list(BARREL)}).distortion == ()
    assert Intrinsics.from_camera_info({**info, "distortion_model": "plumb_bob",
                                        "d": list(BARREL)}) == DISTORTED
    with pytest.raises(ValueError, match="distortion_model"):
        Intrinsics.from_camera_info({**info, "distortion_model": "fisheye", "d": [0.1] * 4})
    with pytest.raises(ValueError, match="distortion"):
        Intrinsics.from_camera_info({**info, "distortion_model": "plumb_bob", "d": [0.1, 0.2, 0.3]})


@pytest.mark.parametrize("center", [CENTRE, MIDDLE, EDGE, CORNER])
def test_correcting_is_as_good_as_an_ideal_lens(center):
    """The same circle fit on the same ball, through the lens and through an ideal one: no
    worse with the lens corrected. (The ideal camera's own error, up to 0.7 % at the edge, is
    the least-squares circle against the `mean` model on a 60 %-elongated ellipse.)"""
    ideal = error_of(fitted_circle(silhouette(center, distortion=(0, 0, 0, 0, 0))), IGNORED, center)
    corrected = error_of(fitted_circle(silhouette(center)), DISTORTED, center)
    assert ideal < 0.01, ideal
    assert corrected < ideal + 0.002, (center, corrected, ideal)


@pytest.mark.parametrize("circle_model", ["mean", "area", "enclosing"])
@pytest.mark.parametrize("center", [CENTRE, MIDDLE, EDGE, CORNER])
def test_exact_mode_inverts_the_distorted_projection(center, circle_model):
    circle = project_sphere(center, BALL_RADIUS, DISTORTED, circle_model)
    position = locate_exact(*circle, DISTORTED, BALL_RADIUS, circle_model)
    assert math.dist((position.x, position.y, position.z), center) < 1e-6


def test_outline_ellipse_of_an_ideal_lens_is_the_silhouette_ellipse():
    """The moment ellipse of the projected outline, through a lens with zero distortion, is
    the closed-form silhouette (so the distorted model tends to the pinhole one)."""
    barely = Intrinsics(FOCAL, FOCAL, 319.5, 239.5, WIDTH, HEIGHT, (1e-300, 0, 0, 0))
    expected = silhouette_ellipse(CORNER, BALL_RADIUS, IGNORED)
    found = outline_ellipse(distorted_silhouette(CORNER, BALL_RADIUS, barely, points=2000))
    assert found.u == pytest.approx(expected.u, abs=1e-6)
    assert found.v == pytest.approx(expected.v, abs=1e-6)
    assert found.semi_major == pytest.approx(expected.semi_major, rel=1e-5)
    assert found.semi_minor == pytest.approx(expected.semi_minor, rel=1e-5)
    assert found.angle == pytest.approx(expected.angle, abs=1e-6)


@pytest.mark.parametrize("center", [EDGE, CORNER])
def test_ignoring_the_distortion_is_measurably_worse_at_the_edge(center):
    circle = fitted_circle(silhouette(center))
    corrected = error_of(circle, DISTORTED, center)
    ignored = error_of(circle, IGNORED, center)
    assert ignored > 0.02, ignored  # several centimetres at under a metre
    assert ignored > 2 * corrected, (ignored, corrected)


@pytest.mark.parametrize("circle_model", ["mean", "area", "enclosing"])
def test_undistorted_circle_matches_each_circle_model(circle_model):
    """A circle mapped back to the ideal image keeps the model's meaning: the undistorted
    image of the distorted circle's rim is fitted with the same model."""
    u, v, radius = 560.0, 300.0, 20.0
    ideal_u, ideal_v, ideal_radius = undistort_circle(u, v, radius, DISTORTED, circle_model)
    # Barrel distortion pulls the border in: the ideal ball is further out and larger.
    assert ideal_u > u + 10 and ideal_radius > radius
    assert math.isfinite(ideal_v)


def frame_with_ball(outline: np.ndarray, scale: int = 4) -> np.ndarray:
    """A grey floor with a yellow-green ball filling ``outline`` (anti-aliased)."""
    generator = np.random.default_rng(1)
    image = np.full((HEIGHT, WIDTH, 3), (100, 104, 98), np.float32)
    image += generator.normal(0, 3, image.shape)
    mask = np.zeros((HEIGHT * scale, WIDTH * scale), np.uint8)
    vertices = np.round((outline + 0.5) * scale * 16 - 0.5 * 16).astype(np.int32)  # 4 fractional bits
    cv2.fillPoly(mask, [vertices.reshape(-1, 1, 2)], 255, cv2.LINE_AA, shift=4)
    coverage = cv2.resize(mask.astype(np.float32) / 255, (WIDTH, HEIGHT), interpolation=cv2.INTER_AREA)
    ball = np.array((40, 225, 190), np.float32)
    image = image * (1 - coverage[..., None]) + ball * coverage[..., None]
    return np.clip(image, 0, 255).astype(np.uint8)


def detected_circle(image: np.ndarray) -> tuple[float, float, float]:
    result = BallDetector().detect(image)
    assert len(result.detections) == 1, result.detections
    detection = result.detections[0]
    return detection.u, detection.v, detection.radius_px


@pytest.mark.parametrize("center", [CENTRE, EDGE, CORNER])
def test_detector_on_a_distorted_frame(center):
    """Through the real detector: correcting keeps the error near the undistorted camera's;
    ignoring the lens is more than twice as wrong at the frame edge."""
    ideal = error_of(detected_circle(frame_with_ball(silhouette(center, distortion=(0,) * 5))),
                     IGNORED, center)
    circle = detected_circle(frame_with_ball(silhouette(center)))
    corrected = error_of(circle, DISTORTED, center)
    ignored = error_of(circle, IGNORED, center)
    assert corrected < max(2 * ideal, 0.01), (corrected, ideal)
    if center != CENTRE:
        assert ignored > 2 * corrected, (ignored, corrected)
