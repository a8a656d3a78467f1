"""Ball position in 3D from its apparent size: the paper's equations, and exact pinhole geometry.

Frames and units. Positions are in the camera optical frame (x right, y down, z forward),
metres. Pixels follow the contract: ``u`` right, ``v`` down; the principal point is
``(cx, cy)``. A ball of radius ``R`` whose centre is at distance ``D`` from the camera is seen
with angular radius ``alpha = asin(R / D)``.

Faithful model (:func:`locate_faithful`). The paper's equations 1-8, literally: angles are taken
as linear in normalised image coordinates (``theta_x = x * hfov / 2``), the ball's angular
diameter as ``z * hfov`` and the range as ``d = R / tan(theta_ball / 2)``. Against a pinhole
camera this is an approximation: with the paper's 1.089 rad field of view it puts a centred
ball about 11 % too far away (``(hfov/2) / tan(hfov/2) = 0.899``) and the error changes across
the image (``experiments/locator_table.py`` prints it).

Exact model (:func:`locate_exact`). The image of a sphere under a pinhole camera is the section
of its tangent cone (apex at the camera, half-angle ``alpha``) by the image plane: an ellipse,
elongated along the radial direction (from the principal point through the ball) as soon as the
ball is off axis. In normalised coordinates (``f = 1``), for a ball whose centre direction makes
the angle ``phi`` with the optical axis, the two radial edge points are at ``tan(phi - alpha)``
and ``tan(phi + alpha)``, so

* ellipse centre, radial distance ``c = sin(phi) cos(phi) / K`` (not ``tan(phi)``: the image of
  the sphere's centre is not the centre of its image),
* radial semi-axis ``a = sin(alpha) cos(alpha) / K``,
* tangential semi-axis ``b = sin(alpha) / sqrt(K)``,

with ``K = cos(phi)^2 - sin(alpha)^2``; ``K > 0`` (an ellipse) exactly when the sphere lies in
front of the camera plane, ``Z > R``.

What the detector reports. A Hough or contour detector reports one circle for that ellipse. The
model here: its centre is the ellipse's centre, and its radius is, by ``circle_model``,

* ``"mean"`` (default): ``(a + b) / 2``, the least-squares best-fit circle (the mean distance
  of the ellipse's points from its centre is ``(a + b) / 2`` to within 0.3 % at 25 %
  elongation, the worst corner of a 62 degree camera);
* ``"area"``: ``sqrt(a b)``, the circle of equal area (moment- or contour-area-based detectors);
* ``"enclosing"``: ``a``, the smallest enclosing circle (``cv2.minEnclosingCircle``). For this
  model the inversion is the closed form "back-project the two radial edge points of the
  reported circle; ``alpha`` is half the angle between the rays, the ball's direction their
  bisector".

With square pixels (``fx == fy``) the semi-axes are those above times ``f``. With
``fx != fy`` the pixel ellipse is the normalised one stretched by ``(fx, fy)``, whose semi-axes
:func:`silhouette_ellipse` computes exactly, and :func:`locate_exact` refines the square-pixel
solution by Newton's method on :func:`project_sphere` (for the ``area`` model no refinement is
needed: areas scale by ``fx fy``). So for every model :func:`locate_exact` inverts
:func:`project_sphere` to numerical precision.

OpenCV's HoughCircles run on drawn ellipses of 5-25 % elongation reports radii scattered around
``mean`` (its centre also wanders by pixels), which is why ``mean`` is the default. Assuming the
wrong model costs nothing on axis and grows with elongation: a detector reporting the enclosing
circle read as ``mean`` is 6 % short at x = 0.9 and 9 % short at x = y = 0.9.

Lens distortion. A CameraInfo with ``distortion_model`` ``plumb_bob`` and non-zero ``d`` (a
real camera's calibration) describes an image whose circle was measured through the lens: the
exact model first maps the detected circle to the ideal pinhole image (:func:`undistort_circle`:
points on its rim through ``cv2.undistortPoints``, then the circle of the same ``circle_model``
fitted to them) and solves that. Near the border of a wide lens this matters: a ball's centre
moves tens of pixels and its size changes by percents.
"""

import math
import sys
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

DISTORTION_MODELS = ("plumb_bob", "", "none")
# Points taken on a detected circle's rim to carry it through the lens model, and on a sphere's
# outline through a distorted lens (its area is then short by (2 pi / N)^2 / 6, 5e-5 of it).
_RIM_POINTS = 64
_OUTLINE_POINTS = 360
# cv2.undistortPoints' default 5 iterations leave pixels of error at a wide lens' corners.
_UNDISTORT_CRITERIA = (3, 100, 1e-10)  # cv2.TERM_CRITERIA_COUNT | EPS, without importing cv2 here

CIRCLE_MODELS = ("mean", "area", "enclosing")
DEFAULT_CIRCLE_MODEL = "mean"

# The search for alpha in (0, pi/2): at most this many steps (64 halvings reach the resolution
# of a double), and it stops once a step moves alpha by less than this share of it.
_BISECTION_STEPS = 64
_ALPHA_RESOLUTION = 4.0 * sys.float_info.epsilon
_NEWTON_STEPS = 20
_NEWTON_TOLERANCE_PX = 1e-10


@dataclass(frozen=True)
class Position3D:
    """A ball centre in the camera optical frame (metres) and its range ``distance``.

    ``distance`` is the paper's ``d``: in the exact model the straight-line distance from the
    camera to the ball's centre, ``sqrt(x^2 + y^2 + z^2)``; in the faithful model the value of
    equation 2, which is also the norm of the faithful ``(x, y, z)``.
    """

    x: float
    y: float
    z: float
    distance: float


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels, as carried by the contract's CameraInfo, and the lens'
    ``plumb_bob`` distortion coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])`` (empty or all
    zero: an ideal pinhole)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion: tuple[float, ...] = ()

    def __post_init__(self):
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name}: must be a positive focal length in pixels, got {value!r}")
        for name in ("cx", "cy"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name}: must be finite, got {getattr(self, name)!r}")
        for name in ("width", "height"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        if len(self.distortion) not in (0, 4, 5, 8) or not all(
                math.isfinite(value) for value in self.distortion):
            raise ValueError(f"distortion: expected 0, 4, 5 or 8 finite coefficients, "
                             f"got {self.distortion!r}")

    @property
    def distorted(self) -> bool:
        return any(value != 0.0 for value in self.distortion)

    @property
    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_fov(cls, width: int, height: int, h_fov: float) -> "Intrinsics":
        """Square pixels, principal point at ``(W/2, H/2)``, horizontal field of view ``h_fov``.

        The principal point matches the contract's normalisation ``x = (u - W/2) / (W/2)``.
        """
        if not 0.0 < h_fov < math.pi:
            raise ValueError(f"h_fov: must be in (0, pi), got {h_fov!r}")
        focal = (width / 2.0) / math.tan(h_fov / 2.0)
        return cls(focal, focal, width / 2.0, height / 2.0, int(width), int(height))

    @classmethod
    def from_camera_info(cls, info: Mapping) -> "Intrinsics":
        """From a decoded CameraInfo message (a dict with fx, fy, cx, cy, width, height, and
        optionally distortion_model and d)."""
        model = info.get("distortion_model", "")
        if model not in DISTORTION_MODELS:
            raise ValueError(f"distortion_model: {model!r} is not one of plumb_bob, none")
        distortion = tuple(float(value) for value in info.get("d", ())) if model == "plumb_bob" else ()
        return cls(float(info["fx"]), float(info["fy"]), float(info["cx"]), float(info["cy"]),
                   int(info["width"]), int(info["height"]), distortion)

    @property
    def h_fov(self) -> float:
        """Horizontal field of view (radians) from the left to the right image border."""
        return math.atan(self.cx / self.fx) + math.atan((self.width - self.cx) / self.fx)

    @property
    def v_fov(self) -> float:
        """Vertical field of view (radians) from the top to the bottom image border."""
        return math.atan(self.cy / self.fy) + math.atan((self.height - self.cy) / self.fy)


@dataclass(frozen=True)
class Ellipse:
    """A sphere's silhouette in pixels: centre, semi-axes, and the major axis' angle.

    ``angle`` is in radians from the +u axis towards +v, in (-pi/2, pi/2]; off axis (square
    pixels) the major axis points along the radial direction from the principal point.
    """

    u: float
    v: float
    semi_major: float
    semi_minor: float
    angle: float


# ---------------------------------------------------------------------------------------------
# Faithful model: the paper's equations 1-8.

def faithful_v_fov(h_fov: float, width: int, height: int) -> float:
    """The vertical field of view the faithful model uses when there is no CameraInfo.

    ``h_fov * H / W``: the faithful model treats angle as linear in pixels (equation 6 maps
    ``x in [-1, 1]`` to ``[-hfov/2, hfov/2]``), so one pixel is ``h_fov / W`` radians in both
    directions. (A pinhole camera would have ``2 atan(tan(h_fov/2) H / W)``, 4.6 % more for
    640x480 at 1.089 rad; with CameraInfo the caller passes its ``vfov`` instead.)
    """
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    return h_fov * height / width


def locate_faithful(x: float, y: float, z: float, h_fov: float, v_fov: float,
                    ball_radius: float) -> Position3D:
    """The paper's equations 1-8 for a Ball2D ``(x, y, z)``; camera optical frame.

    ``x``, ``y``: normalised image coordinates in [-1, 1] (positive right and down); ``z``:
    apparent diameter / image width.
    """
    for name, value in (("x", x), ("y", y), ("z", z), ("h_fov", h_fov), ("v_fov", v_fov),
                        ("ball_radius", ball_radius)):
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value!r}")
    theta_ball = z * h_fov                               # (1)
    if not 0.0 < theta_ball < math.pi:
        raise ValueError(f"z: apparent size z * h_fov must be in (0, pi), got {theta_ball!r}")
    if ball_radius <= 0.0:
        raise ValueError(f"ball_radius: must be > 0, got {ball_radius!r}")
    distance = ball_radius / math.tan(theta_ball / 2.0)  # (2)
    theta_y = y * v_fov / 2.0                            # (3)
    y_3d = distance * math.sin(theta_y)                  # (4)
    distance_xz = distance * math.cos(theta_y)           # (5)
    theta_x = x * h_fov / 2.0                            # (6)
    x_3d = distance_xz * math.sin(theta_x)               # (7)
    z_3d = distance_xz * math.cos(theta_x)               # (8)
    return Position3D(x_3d, y_3d, z_3d, distance)


# ---------------------------------------------------------------------------------------------
# Exact model: projection of a sphere, and its inverse.

def circle_radius(semi_major: float, semi_minor: float, circle_model: str = DEFAULT_CIRCLE_MODEL) -> float:
    """The radius of the circle a detector reports for an ellipse, under ``circle_model``."""
    if circle_model == "mean":
        return 0.5 * (semi_major + semi_minor)
    if circle_model == "area":
        return math.sqrt(semi_major * semi_minor)
    if circle_model == "enclosing":
        return semi_major
    raise ValueError(f"circle_model: must be one of {', '.join(CIRCLE_MODELS)}, got {circle_model!r}")


def silhouette_ellipse(center_xyz: Sequence[float], radius: float, intrinsics: Intrinsics) -> Ellipse:
    """The exact image of a sphere (centre ``(X, Y, Z)`` in the optical frame) in pixels.

    In normalised coordinates (the plane ``z = 1``) the silhouette is the ellipse of the module
    docstring; written with the centre's coordinates (``K = (Z^2 - R^2) / D^2``) its centre is
    ``(X, Y) Z / (Z^2 - R^2)``, its radial semi-axis ``R sqrt(D^2 - R^2) / (Z^2 - R^2)`` and its
    tangential one ``R / sqrt(Z^2 - R^2)``. Pixels are that ellipse stretched by ``(fx, fy)``
    and shifted by ``(cx, cy)``; the stretched ellipse's semi-axes are the singular values of
    ``diag(fx, fy) [a e_radial, b e_tangential]`` (closed form for 2x2). The unit tests check it
    against the cone's conic ``K^-T (c c^T - cos(alpha)^2 I) K^-1`` and against projected
    tangent rays. Raises ValueError unless the sphere lies entirely in front of the camera
    (``Z > R``), which is exactly when its silhouette is an ellipse.
    """
    try:
        x, y, z = (float(value) for value in center_xyz)
    except (TypeError, ValueError):
        raise ValueError(f"center_xyz: must be three numbers, got {center_xyz!r}") from None
    if not all(math.isfinite(value) for value in (x, y, z)):
        raise ValueError(f"center_xyz: must be finite, got {center_xyz!r}")
    if not (math.isfinite(radius) and radius > 0.0):
        raise ValueError(f"radius: must be > 0, got {radius!r}")
    if z <= radius:
        raise ValueError(f"sphere not entirely in front of the camera (z={z!r} <= radius={radius!r})")
    lateral = math.hypot(x, y)
    depth_term = (z - radius) * (z + radius)  # Z^2 - R^2 without cancellation
    radial_x, radial_y = (x / lateral, y / lateral) if lateral > 0.0 else (1.0, 0.0)
    centre_scale = z / depth_term
    radial_axis = radius * math.sqrt((lateral * lateral + depth_term)) / depth_term  # sqrt(D^2 - R^2)
    tangential_axis = radius / math.sqrt(depth_term)
    fx, fy = intrinsics.fx, intrinsics.fy
    # Columns: the radial and the tangential semi-axis vectors, stretched into pixels.
    m11, m12 = fx * radial_axis * radial_x, -fx * tangential_axis * radial_y
    m21, m22 = fy * radial_axis * radial_y, fy * tangential_axis * radial_x
    frobenius = m11 * m11 + m12 * m12 + m21 * m21 + m22 * m22
    determinant = abs(m11 * m22 - m12 * m21)
    spread = math.sqrt(max(0.0, (frobenius - 2.0 * determinant) * (frobenius + 2.0 * determinant)))
    semi_major = math.sqrt(0.5 * (frobenius + spread))
    semi_minor = determinant / semi_major  # the product of the singular values is |det|
    # The major axis is the leading eigenvector of M M^T.
    angle = 0.5 * math.atan2(2.0 * (m11 * m21 + m12 * m22), (m11 * m11 + m12 * m12) - (m21 * m21 + m22 * m22))
    if angle <= -0.5 * math.pi:  # an axis, not a direction: keep it in (-pi/2, pi/2]
        angle += math.pi
    return Ellipse(fx * x * centre_scale + intrinsics.cx, fy * y * centre_scale + intrinsics.cy,
                   semi_major, semi_minor, angle)


def project_sphere(center_xyz: Sequence[float], radius: float, intrinsics: Intrinsics,
                   circle_model: str = DEFAULT_CIRCLE_MODEL) -> tuple[float, float, float]:
    """The circle ``(u, v, radius_px)`` a detector reports for a sphere, under ``circle_model``.

    The centre is the silhouette ellipse's centre and the radius :func:`circle_radius` of its
    semi-axes. Through a distorted lens the silhouette is no longer an ellipse: its outline (the
    sphere's tangent circle, projected with the lens model) stands in for it by the ellipse of
    the same area moments (:func:`outline_ellipse`). :func:`locate_exact` is the inverse of this
    function.
    """
    if intrinsics.distorted:
        ellipse = outline_ellipse(distorted_silhouette(center_xyz, radius, intrinsics))
    else:
        ellipse = silhouette_ellipse(center_xyz, radius, intrinsics)
    return ellipse.u, ellipse.v, circle_radius(ellipse.semi_major, ellipse.semi_minor, circle_model)


def distort(normalised: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Pixels of ideal normalised image points (N x 2, ``X/Z, Y/Z``) through the plumb_bob lens
    (the OpenCV/ROS model, as cv2.projectPoints: radial k1 k2 k3 over k4 k5 k6, tangential
    p1 p2)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = (list(intrinsics.distortion) + [0.0] * 8)[:8]
    x, y = normalised[:, 0], normalised[:, 1]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    distorted_x = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    distorted_y = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([intrinsics.fx * distorted_x + intrinsics.cx,
                            intrinsics.fy * distorted_y + intrinsics.cy])


def distorted_silhouette(center_xyz: Sequence[float], radius: float, intrinsics: Intrinsics,
                         points: int = _OUTLINE_POINTS) -> np.ndarray:
    """The sphere's outline in the image (``points`` x 2 pixels, in order): the circle where
    rays from the camera graze the sphere, projected through the lens."""
    center = np.asarray(center_xyz, float)
    distance = float(np.linalg.norm(center))
    if not (center[2] > radius > 0.0):
        raise ValueError(f"sphere not entirely in front of the camera (z={center[2]!r} <= radius={radius!r})")
    axis = center / distance
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    first = np.cross(axis, helper)
    first /= np.linalg.norm(first)
    second = np.cross(axis, first)
    ring_centre = center * (1.0 - (radius / distance) ** 2)
    ring_radius = radius * math.sqrt((distance - radius) * (distance + radius)) / distance
    angles = np.linspace(0.0, 2.0 * math.pi, points, endpoint=False)
    ring = ring_centre + ring_radius * (np.outer(np.cos(angles), first) + np.outer(np.sin(angles), second))
    return distort(ring[:, :2] / ring[:, 2:], intrinsics)


def outline_ellipse(outline: np.ndarray) -> Ellipse:
    """The ellipse with the same area, centroid and second moments as the closed polygon
    ``outline`` (N x 2, in order): for an ellipse's own outline, that ellipse (up to the
    polygon's O(1/N^2) shortfall), however its points are spaced."""
    x, y = outline[:, 0] - outline[:, 0].mean(), outline[:, 1] - outline[:, 1].mean()
    next_x, next_y = np.roll(x, -1), np.roll(y, -1)
    cross = x * next_y - next_x * y
    area = 0.5 * float(np.sum(cross))
    if not abs(area) > 0.0:
        raise ValueError("degenerate outline (no area)")
    centre_x = float(np.sum((x + next_x) * cross)) / (6.0 * area)
    centre_y = float(np.sum((y + next_y) * cross)) / (6.0 * area)
    xx = float(np.sum((x * x + x * next_x + next_x * next_x) * cross)) / (12.0 * area) - centre_x ** 2
    yy = float(np.sum((y * y + y * next_y + next_y * next_y) * cross)) / (12.0 * area) - centre_y ** 2
    xy = float(np.sum((x * next_y + 2 * x * y + 2 * next_x * next_y + next_x * y) * cross)) / (24.0 * area) \
        - centre_x * centre_y
    # A filled ellipse's second central moments are a^2/4 and b^2/4 along its axes.
    spread = math.hypot(0.5 * (xx - yy), xy)
    major, minor = 0.5 * (xx + yy) + spread, max(0.0, 0.5 * (xx + yy) - spread)
    angle = 0.5 * math.atan2(2.0 * xy, xx - yy)
    if angle <= -0.5 * math.pi:
        angle += math.pi
    return Ellipse(centre_x + float(outline[:, 0].mean()), centre_y + float(outline[:, 1].mean()),
                   2.0 * math.sqrt(major), 2.0 * math.sqrt(minor), angle)


def _cone_angles(centre_offset: float, radius: float, circle_model: str) -> tuple[float, float]:
    """``(phi, alpha)`` of a ball whose circle, in normalised units (f = 1), has its centre at
    radial distance ``centre_offset`` from the principal point and radius ``radius``."""
    if circle_model == "enclosing":
        # The radial edge points of the circle are the images of the two tangent rays in the
        # plane of the optical axis and the ball: alpha is half the angle between them and the
        # ball's direction their bisector.
        inner = math.atan(centre_offset - radius)
        outer = math.atan(centre_offset + radius)
        return 0.5 * (outer + inner), 0.5 * (outer - inner)
    if circle_model not in CIRCLE_MODELS:
        raise ValueError(f"circle_model: must be one of {', '.join(CIRCLE_MODELS)}, got {circle_model!r}")

    hypotenuse = math.hypot(1.0, centre_offset)
    offset_angle = math.atan(centre_offset)

    def cone_for(alpha: float) -> tuple[float, float]:
        # For a given alpha, the ellipse centre c = sin(2 phi) / (cos(2 phi) + cos(2 alpha))
        # fixes phi: sin(2 phi - atan c) = c cos(2 alpha) / sqrt(1 + c^2).
        phi = 0.5 * (offset_angle + math.asin(centre_offset * math.cos(2.0 * alpha) / hypotenuse))
        sin_alpha = math.sin(alpha)
        k = math.cos(phi) ** 2 - sin_alpha ** 2
        if k <= 0.0:  # only reachable by rounding as alpha -> pi/2: an unbounded silhouette
            return phi, math.inf
        semi_major = sin_alpha * math.cos(alpha) / k
        semi_minor = sin_alpha / math.sqrt(k)
        return phi, circle_radius(semi_major, semi_minor, circle_model)

    # The reported radius grows monotonically from 0 (alpha -> 0) to infinity (alpha -> pi/2):
    # Newton's method from the enclosing model's alpha, kept inside the bracket that each
    # evaluation narrows (a bisection step whenever Newton's would leave it). It converges
    # in a handful of evaluations where a bisection needs ~60 (0.2 ms a ball in the locator).
    low, high = 0.0, 0.5 * math.pi
    alpha = 0.5 * (math.atan(centre_offset + radius) - math.atan(centre_offset - radius))
    for _ in range(_BISECTION_STEPS):
        reported = cone_for(alpha)[1]
        if reported < radius:
            low = alpha
        else:
            high = alpha
        if reported == radius or high - low <= _ALPHA_RESOLUTION * high:
            break
        step = _ALPHA_RESOLUTION ** 0.5 * alpha
        slope = (cone_for(alpha + step)[1] - reported) / step
        guess = alpha - (reported - radius) / slope if slope > 0.0 and math.isfinite(slope) else math.nan
        if not low < guess < high:
            guess = 0.5 * (low + high)
        if abs(guess - alpha) <= _ALPHA_RESOLUTION * alpha:
            alpha = guess
            break
        alpha = guess
    return cone_for(alpha)[0], alpha


def _locate_square_pixels(normal_x: float, normal_y: float, normal_radius: float,
                          ball_radius: float, circle_model: str) -> np.ndarray:
    """Sphere centre from a circle in normalised coordinates (f = 1)."""
    offset = math.hypot(normal_x, normal_y)
    phi, alpha = _cone_angles(offset, normal_radius, circle_model)
    if offset > 0.0:
        radial_x, radial_y = normal_x / offset, normal_y / offset
    else:
        radial_x, radial_y = 1.0, 0.0  # on axis phi == 0, any radial direction will do
    distance = ball_radius / math.sin(alpha)
    return distance * np.array([math.sin(phi) * radial_x, math.sin(phi) * radial_y, math.cos(phi)])


def undistort_circle(u: float, v: float, radius_px: float, intrinsics: Intrinsics,
                     circle_model: str = DEFAULT_CIRCLE_MODEL) -> tuple[float, float, float]:
    """The circle ``(u, v, radius_px)`` seen through the lens, roughly as the ideal pinhole camera
    with the same ``fx fy cx cy`` would have reported it: its rim's points are undistorted and
    the ``circle_model`` circle of their outline taken. Unchanged without distortion.
    (:func:`locate_exact` starts from this and then inverts the lens model exactly.)"""
    if not intrinsics.distorted:
        return u, v, radius_px
    import cv2

    angles = np.linspace(0.0, 2.0 * math.pi, _RIM_POINTS, endpoint=False)
    rim = np.column_stack([u + radius_px * np.cos(angles), v + radius_px * np.sin(angles)])
    matrix = intrinsics.camera_matrix
    points, coefficients = rim.reshape(-1, 1, 2), np.array(intrinsics.distortion)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4 takes the criteria in a separate function
        ideal = cv2.undistortPointsIter(points, matrix, coefficients, None, matrix, _UNDISTORT_CRITERIA)
    else:
        ideal = cv2.undistortPoints(points, matrix, coefficients, None, None, matrix, _UNDISTORT_CRITERIA)
    ideal = ideal.reshape(-1, 2)
    if not np.all(np.isfinite(ideal)):
        raise ValueError("the circle lies outside the lens model's valid range")
    ellipse = outline_ellipse(ideal)
    return ellipse.u, ellipse.v, circle_radius(ellipse.semi_major, ellipse.semi_minor, circle_model)


def locate_exact(u: float, v: float, radius_px: float, intrinsics: Intrinsics, ball_radius: float,
                 circle_model: str = DEFAULT_CIRCLE_MODEL) -> Position3D:
    """The sphere centre whose detected circle is ``(u, v, radius_px)``; the inverse of
    :func:`project_sphere` (exact for the circle model, to numerical precision). With lens
    distortion the circle is first carried to the ideal image by :func:`undistort_circle`, and
    the answer refined by Newton's method on the distorted :func:`project_sphere`."""
    for name, value in (("u", u), ("v", v), ("radius_px", radius_px), ("ball_radius", ball_radius)):
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value!r}")
    if radius_px <= 0.0:
        raise ValueError(f"radius_px: must be > 0, got {radius_px!r}")
    if ball_radius <= 0.0:
        raise ValueError(f"ball_radius: must be > 0, got {ball_radius!r}")
    if circle_model not in CIRCLE_MODELS:
        raise ValueError(f"circle_model: must be one of {', '.join(CIRCLE_MODELS)}, got {circle_model!r}")

    ideal_u, ideal_v, ideal_radius = undistort_circle(u, v, radius_px, intrinsics, circle_model)
    fx, fy = intrinsics.fx, intrinsics.fy
    mean_focal = math.sqrt(fx * fy)
    center = _locate_square_pixels((ideal_u - intrinsics.cx) / fx, (ideal_v - intrinsics.cy) / fy,
                                   ideal_radius / mean_focal, ball_radius, circle_model)
    if abs(fx - fy) > 1e-12 * mean_focal or intrinsics.distorted:
        center = _refine(center, np.array([u, v, radius_px]), intrinsics, ball_radius, circle_model)
    x, y, z = (float(value) for value in center)
    return Position3D(x, y, z, math.sqrt(x * x + y * y + z * z))


def _refine(center: np.ndarray, observed: np.ndarray, intrinsics: Intrinsics, ball_radius: float,
            circle_model: str) -> np.ndarray:
    """Newton's method on project_sphere for non-square pixels or a distorted lens, from the
    square-pixel, undistorted answer.

    Unknowns: the centre's normalised image coordinates X/Z, Y/Z and log of its distance, which
    keeps every iterate in front of the camera.
    """

    def center_of(parameters: np.ndarray) -> np.ndarray:
        ray = np.array([parameters[0], parameters[1], 1.0])
        return math.exp(parameters[2]) * ray / np.linalg.norm(ray)

    def residual(parameters: np.ndarray) -> np.ndarray:
        circle = project_sphere(center_of(parameters), ball_radius, intrinsics, circle_model)
        return np.array(circle) - observed

    parameters = np.array([center[0] / center[2], center[1] / center[2], math.log(np.linalg.norm(center))])
    best, best_error = parameters, float(np.max(np.abs(residual(parameters))))
    for _ in range(_NEWTON_STEPS):
        if best_error < _NEWTON_TOLERANCE_PX:
            break
        try:
            jacobian = np.empty((3, 3))
            for column in range(3):
                step = np.zeros(3)
                step[column] = 1e-7
                jacobian[:, column] = (residual(best + step) - residual(best - step)) / 2e-7
            candidate = best - np.linalg.solve(jacobian, residual(best))
            error = float(np.max(np.abs(residual(candidate))))
        except (np.linalg.LinAlgError, ValueError):
            break
        if not error < best_error:
            break
        best, best_error = candidate, error
    return center_of(best)
