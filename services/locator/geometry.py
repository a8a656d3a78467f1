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
``projection.silhouette_ellipse`` computes exactly, and :func:`locate_exact` refines the
square-pixel solution by Newton's method on ``projection.project_sphere`` (for the ``area``
model no refinement is needed: areas scale by ``fx fy``). So for every model
:func:`locate_exact` inverts ``project_sphere`` to numerical precision.

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

import numpy as np

from balltrack.common.pinhole import Intrinsics
from balltrack.services.locator.projection import (CIRCLE_MODELS, DEFAULT_CIRCLE_MODEL, circle_radius,
                                                   outline_ellipse, project_sphere)

# Points taken on a detected circle's rim to carry it through the lens model.
_RIM_POINTS = 64
# cv2.undistortPoints' default 5 iterations leave pixels of error at a wide lens' corners.
_UNDISTORT_CRITERIA = (3, 100, 1e-10)  # cv2.TERM_CRITERIA_COUNT | EPS, without importing cv2 here

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
# Exact model: the inverse of projection.project_sphere.

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
