"""Camera models and chessboard calibration: ROS YAML in and out, and calibration recovering
known intrinsics from chessboard frames rendered through a known lens."""

import math

import cv2
import numpy as np
import pytest

from balltrack.cli import main as balltrack_main
from balltrack.services.camera.calibration import (CameraModel, calibrate, calibration_yaml, parse_board,
                                                   parse_calibration, pinhole, read_calibration)

WIDTH, HEIGHT = 640, 480
TRUE_MATRIX = np.array([[520.0, 0.0, 326.0], [0.0, 516.0, 233.0], [0.0, 0.0, 1.0]])
TRUE_DISTORTION = np.array([-0.24, 0.07, 0.0008, -0.0006, 0.0])
BOARD = (9, 6)
SQUARE = 0.025
PIXELS_PER_SQUARE = 48


def board_texture() -> np.ndarray:
    """The printed board: (9 + 1) x (6 + 1) squares and one square of white margin around."""
    columns, rows = BOARD[0] + 1, BOARD[1] + 1
    texture = np.full(((rows + 2) * PIXELS_PER_SQUARE, (columns + 2) * PIXELS_PER_SQUARE), 255, np.uint8)
    for row in range(rows):
        for column in range(columns):
            if (row + column) % 2 == 0:
                top, left = (row + 1) * PIXELS_PER_SQUARE, (column + 1) * PIXELS_PER_SQUARE
                texture[top:top + PIXELS_PER_SQUARE, left:left + PIXELS_PER_SQUARE] = 0
    return texture


def ideal_points_of_pixels(offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """For every pixel of the distorted image (shifted by ``offset`` px), its ray's normalised
    coordinates ``x/z, y/z`` in the ideal pinhole camera (H x W x 2)."""
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    pixels = np.stack([xs.ravel() + offset[0], ys.ravel() + offset[1]], axis=1).reshape(-1, 1, 2)
    ideal = cv2.undistortPoints(pixels, TRUE_MATRIX, TRUE_DISTORTION, None, None, None,
                                (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9))
    return ideal.reshape(HEIGHT, WIDTH, 2)


# 3 x 3 samples per pixel: the board is drawn anti-aliased, as a real sensor integrates light.
SUBPIXEL = [(dx, dy) for dx in (-1 / 3, 0.0, 1 / 3) for dy in (-1 / 3, 0.0, 1 / 3)]


def render_board(rotation: tuple[float, float, float], translation: tuple[float, float, float],
                 rays: list[np.ndarray], texture: np.ndarray, seed: int = 0) -> np.ndarray:
    """The board seen by the distorted camera: each sample's ray meets the board's plane and
    takes the texture there (inverse mapping, so the lens is applied exactly)."""
    matrix, _ = cv2.Rodrigues(np.array(rotation, float))
    # Board plane point (X, Y, 0) -> camera: X r1 + Y r2 + t, so the ray through (x, y, 1) meets
    # the plane at [r1 r2 t]^-1 (x, y, 1): a homography.
    to_plane = np.linalg.inv(np.column_stack([matrix[:, 0], matrix[:, 1], np.array(translation, float)]))
    # Board metres -> texture pixel centres (the first inner corner is 2 squares in), joined to it
    # as one homography, which OpenCV applies to every pixel's ray.
    scale, offset = PIXELS_PER_SQUARE / SQUARE, 2 * PIXELS_PER_SQUARE - 0.5
    to_texture = np.array([[scale, 0.0, offset], [0.0, scale, offset], [0.0, 0.0, 1.0]]) @ to_plane
    total = np.zeros((HEIGHT, WIDTH), np.float32)
    for normalised in rays:
        texture_points = cv2.perspectiveTransform(normalised.reshape(-1, 1, 2), to_texture)
        total += cv2.remap(texture, texture_points.reshape(HEIGHT, WIDTH, 2).astype(np.float32), None,
                           cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=128).astype(np.float32)
    image = total / len(rays) + np.random.default_rng(seed).normal(0, 2, total.shape)
    return cv2.cvtColor(np.clip(image, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)


# Board centre roughly (0.1, 0.07) m from its first corner: translations place it across the frame.
POSES = [
    ((0.0, 0.0, 0.0), (-0.10, -0.07, 0.55)),
    ((0.35, 0.0, 0.0), (-0.10, -0.07, 0.60)),
    ((-0.35, 0.1, 0.0), (-0.10, -0.07, 0.60)),
    ((0.0, 0.4, 0.1), (-0.12, -0.07, 0.60)),
    ((0.0, -0.4, -0.1), (-0.08, -0.07, 0.60)),
    ((0.2, 0.3, 0.05), (-0.25, -0.16, 0.62)),
    ((-0.2, 0.3, -0.05), (0.05, -0.16, 0.62)),
    ((0.2, -0.3, 0.05), (-0.25, 0.02, 0.62)),
    ((-0.2, -0.3, 0.0), (0.05, 0.02, 0.62)),
    ((0.1, 0.1, 0.3), (-0.30, -0.07, 0.65)),
    ((0.1, -0.1, -0.3), (0.10, -0.07, 0.65)),
    ((0.3, 0.2, 0.0), (-0.10, -0.20, 0.65)),
    ((-0.3, -0.2, 0.0), (-0.10, 0.06, 0.65)),
    ((0.45, 0.1, 0.2), (-0.10, -0.07, 0.75)),
    ((0.1, 0.45, -0.2), (-0.10, -0.07, 0.75)),
]


@pytest.fixture(scope="module")
def board_frames() -> list[tuple[str, np.ndarray]]:
    rays, texture = [ideal_points_of_pixels(offset) for offset in SUBPIXEL], board_texture()
    return [(f"pose{index}.png", render_board(rotation, translation, rays, texture, index))
            for index, (rotation, translation) in enumerate(POSES)]


def test_calibration_recovers_known_intrinsics(board_frames):
    result = calibrate(board_frames, BOARD, SQUARE, "synthetic")
    assert len(result.used) >= 12, result.skipped
    model = result.model
    assert (model.width, model.height) == (WIDTH, HEIGHT)
    for found, true in ((model.fx, 520.0), (model.fy, 516.0), (model.cx, 326.0), (model.cy, 233.0)):
        assert abs(found - true) < 0.01 * true, (found, true)
    assert abs(model.distortion[0] - TRUE_DISTORTION[0]) < 0.03, model.distortion
    assert result.rms_px < 0.5
    # The recovered camera images rays as the true one does (within 2 px, the principal point's
    # own uncertainty), out to the boards' widest views.
    rays = np.array([[0.0, 0.0, 1.0], [0.45, 0.3, 1.0], [-0.5, -0.35, 1.0], [0.5, -0.3, 1.0]])
    true_pixels, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), TRUE_MATRIX, TRUE_DISTORTION)
    found_pixels, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), model.camera_matrix,
                                        np.array(model.distortion))
    assert np.max(np.linalg.norm(true_pixels - found_pixels, axis=2)) < 2.0


def test_calibration_needs_three_boards(board_frames):
    blank = np.full((HEIGHT, WIDTH, 3), 200, np.uint8)
    with pytest.raises(ValueError, match="found in 2 of 4 images"):
        calibrate(board_frames[:2] + [("blank.png", blank), ("unreadable.png", None)], BOARD, SQUARE)
    with pytest.raises(ValueError, match="square"):
        calibrate(board_frames, BOARD, 0.0)


def test_calibrate_command_writes_ros_yaml(board_frames, tmp_path, capsys):
    for name, image in board_frames[:10]:
        cv2.imwrite(str(tmp_path / name), image)
    output = tmp_path / "camera.yaml"
    status = balltrack_main(["calibrate", str(tmp_path / "pose*.png"), "--board", "9x6", "--square", "0.025",
                             "-o", str(output), "--name", "bench"])
    printed = capsys.readouterr().out
    assert status == 0, printed
    assert "reprojection error" in printed
    model = read_calibration(output)
    assert model.camera_name == "bench"
    assert abs(model.fx - 520.0) < 0.01 * 520.0
    assert len(model.distortion) == 5


def test_calibrate_command_errors_are_one_line(tmp_path, capsys):
    assert balltrack_main(["calibrate", str(tmp_path / "none.png"), "--square", "0.025",
                           "-o", str(tmp_path / "c.yaml")]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert error[-1].startswith("balltrack calibrate: a 9x6 board was found in 0 of 1"), error
    assert balltrack_main(["calibrate", "x.png", "--board", "9", "--square", "0.025"]) == 2
    assert "COLUMNSxROWS" in capsys.readouterr().err
    assert not (tmp_path / "c.yaml").exists()


ROS_YAML = """\
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [430.2, 0, 306.7, 0, 429.8, 246.1, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.33, 0.11, 0.0002, -0.0004, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [350.1, 0, 301.2, 0, 0, 380.4, 247.3, 0, 0, 0, 1, 0]
"""


def test_ros_yaml_is_read_and_written_back():
    model = parse_calibration(ROS_YAML)
    assert (model.width, model.height, model.camera_name) == (640, 480, "narrow_stereo")
    assert (model.fx, model.fy, model.cx, model.cy) == (430.2, 429.8, 306.7, 246.1)
    assert model.distortion == (-0.33, 0.11, 0.0002, -0.0004, 0.0)
    assert parse_calibration(calibration_yaml(model)) == model
    info = model.camera_info()
    assert info["distortion_model"] == "plumb_bob" and info["d"] == list(model.distortion)
    assert info["hfov"] == pytest.approx(math.atan(306.7 / 430.2) + math.atan(333.3 / 430.2))


@pytest.mark.parametrize("edit, field", [
    (("image_width: 640", "image_width: wide"), "image_width"),
    (("rows: 3\n  cols: 3\n  data: [430.2", "rows: 3\n  cols: 2\n  data: [430.2"), "camera_matrix"),
    (("distortion_model: plumb_bob", "distortion_model: fisheye"), "distortion_model"),
    (("data: [-0.33, 0.11, 0.0002, -0.0004, 0]", "data: [-0.33, 0.11, 0.0002, -0.0004, .nan]"),
     "distortion_coefficients"),
    (("data: [430.2, 0, 306.7", "data: [-430.2, 0, 306.7"), "fx"),
    (("camera_matrix:", "camera_matrix: [1, 2]\nx:"), "camera_matrix"),
    (("image_width: 640", "image_width: 99999999999"), "image size"),
    (("data: [430.2, 0, 306.7", "data: [" + "4" * 400 + ", 0, 306.7"), "camera_matrix: data must be finite"),
    (("data: [430.2, 0, 306.7", "data: [" + "4" * 5000 + ", 0, 306.7"), "not valid YAML"),
])
def test_bad_calibration_files_name_the_field(edit, field):
    with pytest.raises(ValueError, match=field) as raised:
        parse_calibration(ROS_YAML.replace(*edit), "camera.yaml")
    assert str(raised.value).startswith("camera.yaml: ") and "\n" not in str(raised.value)
    with pytest.raises(ValueError, match="not valid YAML"):
        parse_calibration("image_width: [", "camera.yaml")
    with pytest.raises(ValueError, match="expected a camera_info YAML map"):
        parse_calibration("- 1\n- 2\n", "camera.yaml")


def test_pinhole_matches_the_simulator():
    from balltrack.services.simulator.config import SimulatorConfig
    from balltrack.services.simulator.sim import Simulation

    model = pinhole(640, 480, 1.089)
    with Simulation(SimulatorConfig()) as simulation:
        simulated = simulation.camera_info()
    for name in ("width", "height", "fx", "fy", "cx", "cy", "hfov"):
        assert model.camera_info()[name] == pytest.approx(simulated[name]), name


def test_scaling_a_calibration_to_another_frame_size():
    model = parse_calibration(ROS_YAML)
    half = model.scaled_to(320, 240)
    assert (half.fx, half.fy) == pytest.approx((215.1, 214.9))
    assert (half.cx, half.cy) == pytest.approx((153.1, 122.8))
    assert half.distortion == model.distortion
    with pytest.raises(ValueError, match="aspect ratio"):
        model.scaled_to(640, 360)
    with pytest.raises(ValueError, match="size"):
        CameraModel(0, 480, 1.0, 1.0, 0.0, 0.0)


def test_board_sizes():
    assert parse_board("9x6") == (9, 6)
    assert parse_board("7X5") == (7, 5)
    for bad in ("9", "1x6", "ax6", ""):
        with pytest.raises(ValueError, match="COLUMNSxROWS"):
            parse_board(bad)
