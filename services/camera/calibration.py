"""Camera models: the ROS ``camera_info`` YAML file, an ideal pinhole, and chessboard calibration.

The file format is the one ``camera_calibration`` (ROS) writes and ``camera_info_manager``
reads::

    image_width: 640
    image_height: 480
    camera_name: webcam
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
    rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
    projection_matrix: {rows: 3, cols: 4, data: [fx', 0, cx', 0, 0, fy', cy', 0, 0, 0, 1, 0]}

:func:`calibrate` is OpenCV's chessboard calibration (findChessboardCorners, cornerSubPix,
calibrateCamera). Nothing here touches the network; errors are one-line ValueErrors.
"""

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Sequence

import cv2
import numpy as np
import yaml

from balltrack.common.messages import shorten
from balltrack.common.pinhole import DISTORTION_MODELS, Intrinsics, check_intrinsics

_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics of one camera at one image size, with its plumb_bob distortion."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()
    camera_name: str = "camera"
    # Kept as read (ROS tools use them for stereo and rectified images); identity / K by default.
    rectification: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    projection: tuple[float, ...] | None = field(default=None)

    def __post_init__(self):
        check_intrinsics(self.fx, self.fy, self.cx, self.cy, self.width, self.height, self.distortion)

    @property
    def intrinsics(self) -> Intrinsics:
        """The pinhole model of these frames, as the locator reads it from CameraInfo."""
        return Intrinsics(self.fx, self.fy, self.cx, self.cy, self.width, self.height, self.distortion)

    @property
    def camera_matrix(self) -> np.ndarray:
        return self.intrinsics.camera_matrix

    @property
    def hfov(self) -> float:
        """From the left to the right image border (radians), ignoring distortion."""
        return self.intrinsics.h_fov

    @property
    def vfov(self) -> float:
        return self.intrinsics.v_fov

    def camera_info(self) -> dict:
        """The CameraInfo message's fields besides the header."""
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy, "hfov": self.hfov, "vfov": self.vfov,
                "distortion_model": "plumb_bob",
                "d": [float(value) for value in self.distortion] or [0.0] * 5}

    def scaled_to(self, width: int, height: int) -> "CameraModel":
        """The same camera delivering frames of another size (the sensor image resized, as a
        webcam does when asked for a lower resolution): focal lengths and principal point
        scale; distortion, in normalised coordinates, does not. A different aspect ratio means
        a cropped sensor, which a calibration cannot be carried to: ValueError."""
        if (width, height) == (self.width, self.height):
            return self
        if abs(width * self.height - height * self.width) > 0.01 * width * self.height:
            raise ValueError(f"calibration is for {self.width}x{self.height}, frames are {width}x{height} "
                             f"(another aspect ratio): calibrate at this size")
        scale_x, scale_y = width / self.width, height / self.height
        # Pixel centres at integer coordinates: a pixel edge (-0.5) maps to an edge.
        return replace(self, width=width, height=height, fx=self.fx * scale_x, fy=self.fy * scale_y,
                       cx=(self.cx + 0.5) * scale_x - 0.5, cy=(self.cy + 0.5) * scale_y - 0.5,
                       projection=None)


def pinhole(width: int, height: int, hfov: float) -> CameraModel:
    """An ideal camera as the simulator has: square pixels, horizontal field of view ``hfov``,
    principal point at the image centre ((W - 1) / 2, pixel centres at integer coordinates)."""
    if not 0.0 < hfov < math.pi:
        raise ValueError(f"hfov: must be in (0, pi) radians, got {hfov!r}")
    focal = (width / 2) / math.tan(hfov / 2)
    return CameraModel(width, height, focal, focal, (width - 1) / 2, (height - 1) / 2)


def _matrix(data: dict, name: str, rows: int, cols: int | Sequence[int]) -> list[float]:
    entry = data.get(name)
    if not isinstance(entry, dict) or not isinstance(entry.get("data"), list):
        raise ValueError(f"{name}: expected a map with rows, cols and data")
    values = entry["data"]
    allowed = (cols,) if isinstance(cols, int) else tuple(cols)
    if entry.get("rows") != rows or entry.get("cols") not in allowed or len(values) != rows * entry["cols"]:
        raise ValueError(f"{name}: expected {rows}x{'/'.join(map(str, allowed))} with as many data, "
                         f"got rows={entry.get('rows')!r} cols={entry.get('cols')!r} and {len(values)} values")
    numbers = []
    for value in values:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{name}: data must be numbers")
        try:
            number = float(value)
        except OverflowError:  # a YAML integer past a float's range
            number = math.inf
        if not math.isfinite(number):
            raise ValueError(f"{name}: data must be finite numbers, got {shorten(value, 40)}")
        numbers.append(number)
    return numbers


def parse_calibration(text: str, source: str = "calibration") -> CameraModel:
    """A CameraModel from ROS camera_info YAML text; ValueError naming the bad field."""
    try:
        data = yaml.safe_load(text)
    except (yaml.YAMLError, ValueError) as error:  # (ValueError: an integer of over 4300 digits)
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise ValueError(f"{source}: not valid YAML ({reason})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a camera_info YAML map")
    try:
        width, height = data.get("image_width"), data.get("image_height")
        if not (isinstance(width, int) and isinstance(height, int)) or isinstance(width, bool):
            raise ValueError("image_width/image_height: expected integers")
        matrix = _matrix(data, "camera_matrix", 3, 3)
        model = data.get("distortion_model", "plumb_bob") or "none"
        if model not in DISTORTION_MODELS:
            raise ValueError(f"distortion_model: {model!r} is not supported (plumb_bob or none)")
        distortion: list[float] = []
        if model == "plumb_bob" and "distortion_coefficients" in data:
            distortion = _matrix(data, "distortion_coefficients", 1, (0, 4, 5, 8))
        rectification = (_matrix(data, "rectification_matrix", 3, 3) if "rectification_matrix" in data
                         else None)
        projection = _matrix(data, "projection_matrix", 3, 4) if "projection_matrix" in data else None
        if matrix[1] != 0.0 or matrix[3] != 0.0 or matrix[6:] != [0.0, 0.0, 1.0]:
            raise ValueError("camera_matrix: expected [fx 0 cx; 0 fy cy; 0 0 1] (no skew)")
        name = str(data.get("camera_name") or "camera")
        extra = {"rectification": tuple(rectification)} if rectification else {}
        return CameraModel(width, height, matrix[0], matrix[4], matrix[2], matrix[5], tuple(distortion), name,
                           projection=tuple(projection) if projection else None, **extra)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None


def read_calibration(path: str | Path) -> CameraModel:
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: cannot read ({getattr(error, 'strerror', None) or error})") from None
    return parse_calibration(text, str(path))


def calibration_yaml(model: CameraModel) -> str:
    """The ROS camera_info YAML of ``model`` (projection = K with a zero last column unless
    one was read)."""
    projection = model.projection or (model.fx, 0.0, model.cx, 0.0, 0.0, model.fy, model.cy, 0.0,
                                      0.0, 0.0, 1.0, 0.0)

    def block(rows: int, values: Iterable[float]) -> dict:
        values = [float(value) for value in values]
        return {"rows": rows, "cols": len(values) // rows if rows else 0, "data": values}

    document = {
        "image_width": model.width, "image_height": model.height, "camera_name": model.camera_name,
        "camera_matrix": block(3, model.camera_matrix.ravel()),
        "distortion_model": "plumb_bob",
        "distortion_coefficients": block(1, model.distortion or (0.0,) * 5),
        "rectification_matrix": block(3, model.rectification),
        "projection_matrix": block(3, projection),
    }
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None)


def write_calibration(path: str | Path, model: CameraModel) -> None:
    Path(path).write_text(calibration_yaml(model))


# ---------------------------------------------------------------------------------------------
# Chessboard calibration.

# Inner corners a side of a board can have (a printed board has a few dozen at most; OpenCV
# takes only 32-bit sizes).
MAX_BOARD_SIDE = 100


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` -> (9, 6): inner corners per row and per column, as OpenCV counts them."""
    columns, separator, rows = text.lower().partition("x")
    try:
        size = (int(columns), int(rows))
    except ValueError:
        size = (0, 0)
    if not separator or min(size) < 2:
        raise ValueError(f"board: expected inner corners as COLUMNSxROWS, e.g. 9x6, got {text!r}")
    if max(size) > MAX_BOARD_SIDE:
        raise ValueError(f"board: at most {MAX_BOARD_SIDE} inner corners a side, got {text!r}")
    return size


def board_points(board: tuple[int, int], square: float) -> np.ndarray:
    """The board's inner corners in its own plane (metres), in OpenCV's detection order."""
    columns, rows = board
    grid = np.zeros((rows * columns, 3), np.float32)
    grid[:, :2] = np.mgrid[0:columns, 0:rows].T.reshape(-1, 2) * square
    return grid


def find_corners(image: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """The board's inner corners to sub-pixel accuracy (N x 1 x 2), or None if not all found."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    found, corners = cv2.findChessboardCorners(
        gray, board, flags=cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        return None
    return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), _SUBPIX_CRITERIA)


@dataclass
class CalibrationResult:
    model: CameraModel
    rms_px: float              # reprojection error over every corner used (pixels)
    used: list[str]            # the images whose board was found
    skipped: list[str]         # the images without a whole board (or unreadable)


def calibrate(images: Sequence[tuple[str, np.ndarray | None]], board: tuple[int, int], square: float,
              camera_name: str = "camera") -> CalibrationResult:
    """Calibrate from ``(name, image)`` pairs (None for an unreadable image) of a chessboard
    with ``board`` inner corners and squares of ``square`` metres. Needs 3 views at least."""
    if not (math.isfinite(square) and square > 0):
        raise ValueError(f"square: must be a positive size in metres, got {square!r}")
    object_points, image_points, used, skipped = [], [], [], []
    size = None
    for name, image in images:
        if image is None:
            skipped.append(name)
            continue
        image_size = (image.shape[1], image.shape[0])
        if size is not None and image_size != size:
            raise ValueError(f"{name}: {image_size[0]}x{image_size[1]}, but the first image was "
                             f"{size[0]}x{size[1]}: calibrate one size at a time")
        size = image_size
        corners = find_corners(image, board)
        if corners is None:
            skipped.append(name)
            continue
        object_points.append(board_points(board, square))
        image_points.append(corners)
        used.append(name)
    if len(used) < 3:
        raise ValueError(f"a {board[0]}x{board[1]} board was found in {len(used)} of "
                         f"{len(used) + len(skipped)} images; calibration needs at least 3 (10-20 is better)")
    rms, matrix, distortion, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    model = CameraModel(size[0], size[1], float(matrix[0, 0]), float(matrix[1, 1]), float(matrix[0, 2]),
                        float(matrix[1, 2]), tuple(float(value) for value in distortion.ravel()[:5]),
                        camera_name)
    return CalibrationResult(model, float(rms), used, skipped)
