"""The exact image of a sphere, the forward model that ``geometry.locate_exact`` inverts.

A sphere seen by a pinhole camera images as an ellipse (``geometry``'s docstring derives its
centre and semi-axes); a detector reports one circle for it, whose radius depends on the
detector (``CIRCLE_MODELS``). Through a distorted lens the outline is projected point by point
and stands in for the ellipse by its area moments.
"""

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from balltrack.common.pinhole import Intrinsics

CIRCLE_MODELS = ("mean", "area", "enclosing")
DEFAULT_CIRCLE_MODEL = "mean"
# Points taken on a sphere's outline through a distorted lens (its area is then short by
# (2 pi / N)^2 / 6, 5e-5 of it).
_OUTLINE_POINTS = 360


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
    the same area moments (:func:`outline_ellipse`). ``geometry.locate_exact`` is the inverse of
    this function.
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
