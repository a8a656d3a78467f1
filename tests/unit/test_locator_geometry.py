"""The locator's geometry: sphere projection, the exact inverse, and the paper's equations."""

import math

import numpy as np
import pytest

from balltrack.common.config import ConfigError, load_config, replace_config
from balltrack.services.locator.config import LocatorConfig
from balltrack.common.pinhole import Intrinsics
from balltrack.services.locator.geometry import faithful_v_fov, locate_exact, locate_faithful
from balltrack.services.locator.projection import CIRCLE_MODELS, circle_radius, project_sphere, silhouette_ellipse

WIDTH, HEIGHT, HFOV = 640, 480, 1.089
BALL_RADIUS = 0.033
CAMERA = Intrinsics.from_fov(WIDTH, HEIGHT, HFOV)
# A real calibration: non-square pixels and an off-centre principal point.
CALIBRATED = Intrinsics(fx=531.7, fy=519.2, cx=324.6, cy=236.1, width=WIDTH, height=HEIGHT)

DISTANCES = np.geomspace(0.1, 5.0, 12)
GRID = np.linspace(-1.0, 1.0, 9)  # normalised image coordinates, corners included


def on_ray(intrinsics, x, y, distance):
    """A ball centre at ``distance`` along the ray through normalised image point (x, y)."""
    u = WIDTH / 2 * (1 + x)
    v = HEIGHT / 2 * (1 + y)
    ray = np.array([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0])
    return distance * ray / np.linalg.norm(ray)


def field_of_view(intrinsics):
    for distance in DISTANCES:
        for x in GRID:
            for y in GRID:
                yield on_ray(intrinsics, x, y, distance)


def as_array(position):
    return np.array([position.x, position.y, position.z])


# --- intrinsics --------------------------------------------------------------------------------

def test_intrinsics_from_fov_matches_the_brief():
    assert CAMERA.fx == pytest.approx(320 / math.tan(HFOV / 2), rel=1e-15)
    assert CAMERA.fy == CAMERA.fx
    assert (CAMERA.cx, CAMERA.cy, CAMERA.width, CAMERA.height) == (320, 240, 640, 480)
    assert CAMERA.h_fov == pytest.approx(HFOV, rel=1e-12)
    assert CAMERA.v_fov == pytest.approx(2 * math.atan(math.tan(HFOV / 2) * 0.75), rel=1e-12)


def test_intrinsics_from_camera_info_and_validation():
    info = {"fx": 500.0, "fy": 501.0, "cx": 320.5, "cy": 239.5, "width": 640, "height": 480,
            "hfov": 1.0, "vfov": 0.8, "header": {}}
    assert Intrinsics.from_camera_info(info) == Intrinsics(500.0, 501.0, 320.5, 239.5, 640, 480)
    with pytest.raises(ValueError, match="fx"):
        Intrinsics(0.0, 500.0, 320, 240, 640, 480)
    with pytest.raises(ValueError, match="fy"):
        Intrinsics(500.0, math.nan, 320, 240, 640, 480)
    with pytest.raises(ValueError, match="width"):
        Intrinsics(500.0, 500.0, 320, 240, 0, 480)


# --- projection ----------------------------------------------------------------------------------

def test_projection_on_axis_is_a_circle_of_radius_f_tan_alpha():
    u, v, radius_px = project_sphere([0, 0, 1.0], BALL_RADIUS, CAMERA)
    alpha = math.asin(BALL_RADIUS / 1.0)
    assert (u, v) == pytest.approx((320, 240), abs=1e-9)
    assert radius_px == pytest.approx(CAMERA.fx * math.tan(alpha), rel=1e-12)
    ellipse = silhouette_ellipse([0, 0, 1.0], BALL_RADIUS, CAMERA)
    assert ellipse.semi_major == pytest.approx(ellipse.semi_minor, rel=1e-9)


@pytest.mark.parametrize("center", [(0.8, 0.3, 1.0), (-0.5, 0.4, 0.9), (0.02, -0.6, 1.3)])
def test_projection_matches_the_closed_form_ellipse(center):
    # Square pixels: the radial edge points are at f tan(phi -+ alpha), the tangential
    # semi-axis is f sin(alpha) / sqrt(cos(phi)^2 - sin(alpha)^2).
    radius = 0.2
    center = np.array(center)
    distance = np.linalg.norm(center)
    phi = math.acos(center[2] / distance)
    alpha = math.asin(radius / distance)
    focal = CAMERA.fx
    ellipse = silhouette_ellipse(center, radius, CAMERA)
    inner, outer = focal * math.tan(phi - alpha), focal * math.tan(phi + alpha)
    radial = np.array([center[0], center[1]]) / math.hypot(center[0], center[1])
    assert (ellipse.u, ellipse.v) == pytest.approx(tuple(np.array([320, 240]) + radial * (inner + outer) / 2),
                                                   rel=1e-12)
    assert ellipse.semi_major == pytest.approx((outer - inner) / 2, rel=1e-12)
    k = math.cos(phi) ** 2 - math.sin(alpha) ** 2
    assert ellipse.semi_minor == pytest.approx(focal * math.sin(alpha) / math.sqrt(k), rel=1e-12)
    # The major axis is radial.
    assert abs(math.cos(ellipse.angle) * radial[1] - math.sin(ellipse.angle) * radial[0]) < 1e-9
    # And the image of the sphere's centre is not the centre of its image (it is nearer the axis).
    assert math.hypot(ellipse.u - 320, ellipse.v - 240) > focal * math.tan(phi)


@pytest.mark.parametrize("intrinsics", [CAMERA, CALIBRATED], ids=["square", "calibrated"])
def test_silhouette_matches_the_cone_conic(intrinsics):
    # Independent derivation: the tangent cone (p . c)^2 = cos(alpha)^2 |p|^2 pulled back to
    # pixels is the conic Q = K^-T (c c^T - cos(alpha)^2 I) K^-1; its centre and semi-axes
    # come from its 2x2 block.
    rng = np.random.default_rng(2)
    inverse_k = np.linalg.inv(np.array([[intrinsics.fx, 0, intrinsics.cx], [0, intrinsics.fy, intrinsics.cy],
                                        [0, 0, 1.0]]))
    for _ in range(50):
        center = on_ray(intrinsics, rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0.1, 5))
        distance = np.linalg.norm(center)
        direction = center / distance
        conic = inverse_k.T @ (np.outer(direction, direction)
                               - (1 - (BALL_RADIUS / distance) ** 2) * np.eye(3)) @ inverse_k
        quadratic, linear, constant = -conic[:2, :2], -conic[:2, 2], -conic[2, 2]
        centre = np.linalg.solve(quadratic, -linear)
        level = -linear @ centre - constant
        eigenvalues, eigenvectors = np.linalg.eigh(quadratic)
        ellipse = silhouette_ellipse(center, BALL_RADIUS, intrinsics)
        assert (ellipse.u, ellipse.v) == pytest.approx(tuple(centre), abs=1e-7)
        assert ellipse.semi_major == pytest.approx(math.sqrt(level / eigenvalues[0]), rel=1e-7)
        assert ellipse.semi_minor == pytest.approx(math.sqrt(level / eigenvalues[1]), rel=1e-7)
        if ellipse.semi_major > 1.0001 * ellipse.semi_minor:  # the axis is defined
            major = eigenvectors[:, 0]
            assert abs(math.cos(ellipse.angle) * major[1] - math.sin(ellipse.angle) * major[0]) < 1e-6


@pytest.mark.parametrize("intrinsics", [CAMERA, CALIBRATED], ids=["square", "calibrated"])
def test_silhouette_contains_the_projected_tangent_rays(intrinsics):
    # Independent of the conic algebra: rays tangent to the sphere, projected by the pinhole
    # model, must all lie on the ellipse.
    rng = np.random.default_rng(1)
    for _ in range(20):
        center = on_ray(intrinsics, rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0.15, 5))
        radius = BALL_RADIUS
        ellipse = silhouette_ellipse(center, radius, intrinsics)
        distance = np.linalg.norm(center)
        axis = center / distance
        alpha = math.asin(radius / distance)
        first = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
        first /= np.linalg.norm(first)
        second = np.cross(axis, first)
        major = np.array([math.cos(ellipse.angle), math.sin(ellipse.angle)])
        minor = np.array([-major[1], major[0]])
        for turn in np.linspace(0, 2 * math.pi, 36, endpoint=False):
            around = math.cos(turn) * first + math.sin(turn) * second
            ray = math.cos(alpha) * axis + math.sin(alpha) * around
            pixel = np.array([intrinsics.fx * ray[0] / ray[2] + intrinsics.cx,
                              intrinsics.fy * ray[1] / ray[2] + intrinsics.cy])
            offset = pixel - [ellipse.u, ellipse.v]
            level = (offset @ major / ellipse.semi_major) ** 2 + (offset @ minor / ellipse.semi_minor) ** 2
            assert level == pytest.approx(1.0, abs=1e-7)


def test_circle_models():
    assert circle_radius(12.0, 10.0, "mean") == 11.0
    assert circle_radius(12.0, 10.0, "area") == pytest.approx(math.sqrt(120.0))
    assert circle_radius(12.0, 10.0, "enclosing") == 12.0
    with pytest.raises(ValueError, match="circle_model"):
        circle_radius(12.0, 10.0, "hough")


def test_projection_rejects_spheres_not_in_front_of_the_camera():
    with pytest.raises(ValueError, match="in front"):
        project_sphere([0, 0, 0.02], BALL_RADIUS, CAMERA)
    with pytest.raises(ValueError, match="in front"):
        project_sphere([1.0, 0, -1.0], BALL_RADIUS, CAMERA)
    with pytest.raises(ValueError, match="radius"):
        project_sphere([0, 0, 1.0], 0.0, CAMERA)


# --- exact mode ------------------------------------------------------------------------------

@pytest.mark.parametrize("circle_model", CIRCLE_MODELS)
@pytest.mark.parametrize("intrinsics", [CAMERA, CALIBRATED], ids=["square", "calibrated"])
def test_exact_mode_inverts_the_projection_everywhere(intrinsics, circle_model):
    # 0.1 to 5 m, the whole field of view including its corners. The brief asks for 0.5 % of
    # distance; the inverse is exact, so hold it to 1e-9.
    worst = 0.0
    for center in field_of_view(intrinsics):
        u, v, radius_px = project_sphere(center, BALL_RADIUS, intrinsics, circle_model)
        position = locate_exact(u, v, radius_px, intrinsics, BALL_RADIUS, circle_model)
        distance = np.linalg.norm(center)
        worst = max(worst, np.linalg.norm(as_array(position) - center) / distance,
                    abs(position.distance - distance) / distance)
    assert worst < 1e-9


def test_exact_mode_on_axis():
    position = locate_exact(320, 240, CAMERA.fx * math.tan(math.asin(0.033 / 2.0)), CAMERA, 0.033)
    assert (position.x, position.y) == pytest.approx((0, 0), abs=1e-12)
    assert position.z == pytest.approx(2.0, rel=1e-12)
    assert position.distance == pytest.approx(2.0, rel=1e-12)


def test_exact_enclosing_model_is_the_radial_edge_point_construction():
    # The brief's construction, done independently: back-project the two points where the
    # radial line through the circle's centre meets the circle; alpha is half the angle
    # between the rays, the ball lies along their bisector at R / sin(alpha).
    u, v, radius_px = 560.0, 410.0, 25.0
    radial = np.array([u - CAMERA.cx, v - CAMERA.cy])
    radial /= np.linalg.norm(radial)
    rays = []
    for sign in (-1, 1):
        edge = np.array([u, v]) + sign * radius_px * radial
        ray = np.array([(edge[0] - CAMERA.cx) / CAMERA.fx, (edge[1] - CAMERA.cy) / CAMERA.fy, 1.0])
        rays.append(ray / np.linalg.norm(ray))
    alpha = 0.5 * math.acos(float(rays[0] @ rays[1]))
    bisector = (rays[0] + rays[1]) / np.linalg.norm(rays[0] + rays[1])
    expected = BALL_RADIUS / math.sin(alpha) * bisector
    position = locate_exact(u, v, radius_px, CAMERA, BALL_RADIUS, "enclosing")
    assert as_array(position) == pytest.approx(expected, rel=1e-12)


def test_exact_mode_scales_with_ball_radius():
    u, v, radius_px = project_sphere(on_ray(CAMERA, 0.5, -0.3, 1.5), BALL_RADIUS, CAMERA)
    small = locate_exact(u, v, radius_px, CAMERA, BALL_RADIUS)
    large = locate_exact(u, v, radius_px, CAMERA, 2 * BALL_RADIUS)
    assert as_array(large) == pytest.approx(2 * as_array(small), rel=1e-12)


@pytest.mark.parametrize("arguments, field", [
    ((320, 240, 0.0, CAMERA, BALL_RADIUS), "radius_px"),
    ((320, 240, -3.0, CAMERA, BALL_RADIUS), "radius_px"),
    ((math.nan, 240, 10.0, CAMERA, BALL_RADIUS), "u"),
    ((320, math.inf, 10.0, CAMERA, BALL_RADIUS), "v"),
    ((320, 240, 10.0, CAMERA, 0.0), "ball_radius"),
])
def test_exact_mode_rejects_bad_input(arguments, field):
    with pytest.raises(ValueError, match=field):
        locate_exact(*arguments)
    with pytest.raises(ValueError, match="circle_model"):
        locate_exact(320, 240, 10.0, CAMERA, BALL_RADIUS, "hough")


def test_exact_mode_survives_huge_circles():
    # A circle far bigger than the image (a corrupt detection) still gives a finite, close ball.
    position = locate_exact(600, 50, 5000.0, CAMERA, BALL_RADIUS)
    assert all(math.isfinite(value) for value in as_array(position))
    assert BALL_RADIUS < position.distance < 0.05


# --- faithful mode ---------------------------------------------------------------------------

def test_faithful_v_fov_is_linear_in_pixels():
    assert faithful_v_fov(HFOV, WIDTH, HEIGHT) == pytest.approx(0.81675, rel=1e-12)
    with pytest.raises(ValueError):
        faithful_v_fov(HFOV, 0, HEIGHT)


def test_faithful_mode_is_the_papers_equations_literally():
    # x = 0.5, y = -0.25, z = 0.05, hfov = 1.089, vfov = 1.089 * 480 / 640 = 0.81675, r = 0.033
    # (1) theta_ball = 0.05 * 1.089                    = 0.05445
    # (2) d   = 0.033 / tan(0.027225)                   = 1.211822
    # (3) theta_y = -0.25 * 0.81675 / 2                 = -0.10209375
    # (4) y3d = 1.211822 * sin(-0.10209375)             = -0.123505
    # (5) d'  = 1.211822 * cos(-0.10209375)             = 1.205512
    # (6) theta_x = 0.5 * 1.089 / 2                     = 0.27225
    # (7) x3d = 1.205512 * sin(0.27225)                 = 0.324161
    # (8) z3d = 1.205512 * cos(0.27225)                 = 1.161111
    position = locate_faithful(0.5, -0.25, 0.05, 1.089, 0.81675, 0.033)
    assert position.distance == pytest.approx(1.211822, abs=1e-6)
    assert position.y == pytest.approx(-0.123505, abs=1e-6)
    assert position.x == pytest.approx(0.324161, abs=1e-6)
    assert position.z == pytest.approx(1.161111, abs=1e-6)
    # d is the norm of (x, y, z) in this model.
    assert np.linalg.norm(as_array(position)) == pytest.approx(position.distance, rel=1e-12)


def test_faithful_mode_signs_follow_the_optical_frame():
    right_down = locate_faithful(0.4, 0.3, 0.05, HFOV, 0.8, BALL_RADIUS)
    left_up = locate_faithful(-0.4, -0.3, 0.05, HFOV, 0.8, BALL_RADIUS)
    assert right_down.x > 0 and right_down.y > 0 and right_down.z > 0
    assert (left_up.x, left_up.y, left_up.z) == pytest.approx((-right_down.x, -right_down.y, right_down.z))


@pytest.mark.parametrize("z", [0.0, -0.1, math.nan, 3.0])
def test_faithful_mode_rejects_impossible_sizes(z):
    with pytest.raises(ValueError, match="z"):
        locate_faithful(0.0, 0.0, z, HFOV, 0.8, BALL_RADIUS)


def faithful_range_errors(region, distances, circle_model="mean"):
    """Signed range errors (fraction) of the faithful model on an analytic projection."""
    v_fov = faithful_v_fov(HFOV, WIDTH, HEIGHT)
    errors = []
    for distance in distances:
        for x in np.linspace(-region, region, 7):
            for y in np.linspace(-region, region, 7):
                center = on_ray(CAMERA, x, y, distance)
                u, v, radius_px = project_sphere(center, BALL_RADIUS, CAMERA, circle_model)
                position = locate_faithful((u - 320) / 320, (v - 240) / 240, radius_px / 320,
                                           HFOV, v_fov, BALL_RADIUS)
                errors.append((position.distance - distance) / distance)
    return np.array(errors)


def test_faithful_mode_error_characterised():
    # On axis, far away, the faithful model's angle per pixel is hfov / W against the pinhole's
    # 2 tan(hfov / 2) / W, so it puts the ball (hfov/2) / tan(hfov/2) - 1 = +11.2 % too far.
    far_bias = math.tan(HFOV / 2) / (HFOV / 2) - 1
    on_axis = faithful_range_errors(0.0, [5.0])
    assert on_axis[0] == pytest.approx(far_bias, abs=2e-4)
    # Near the centre (|x|, |y| <= 0.1) over the paper's range 0.3-3.5 m: +9.5 % to +11.3 %.
    near_centre = faithful_range_errors(0.1, np.geomspace(0.3, 3.5, 8))
    assert near_centre.min() > 0.095 and near_centre.max() < 0.113
    # Close up (0.1 m) tan and sin part ways and the bias falls to about +1.5 %.
    assert faithful_range_errors(0.0, [0.1])[0] == pytest.approx(0.015, abs=0.001)
    # Off axis the silhouette grows and the ball comes out too close: -9 % at x = 0.9, 1 m.
    v_fov = faithful_v_fov(HFOV, WIDTH, HEIGHT)
    u, v, radius_px = project_sphere(on_ray(CAMERA, 0.9, 0.0, 1.0), BALL_RADIUS, CAMERA)
    at_edge = locate_faithful((u - 320) / 320, (v - 240) / 240, radius_px / 320, HFOV, v_fov, BALL_RADIUS)
    assert -0.10 < at_edge.distance - 1.0 < -0.08
    # Over the whole image (corners included), 0.1-5 m: within -36 % .. +11.3 %.
    whole = faithful_range_errors(1.0, np.geomspace(0.1, 5.0, 8))
    assert whole.min() > -0.36 and whole.max() < 0.113


# --- config ----------------------------------------------------------------------------------

def test_config_defaults():
    config = LocatorConfig()
    assert (config.h_fov, config.ball_radius, config.mode, config.circle_model) == \
        (1.089, 0.033, "auto", "mean")


@pytest.mark.parametrize("changes, field", [
    ({"h_fov": 0.0}, "h_fov"),
    ({"h_fov": 3.2}, "h_fov"),
    ({"h_fov": math.nan}, "h_fov"),
    ({"h_fov": "wide"}, "h_fov"),
    ({"ball_radius": 0.0}, "ball_radius"),
    ({"ball_radius": -0.033}, "ball_radius"),
    ({"ball_radius": True}, "ball_radius"),
    ({"mode": "approximate"}, "mode"),
    ({"circle_model": "hough"}, "circle_model"),
])
def test_config_rejects_bad_values(changes, field):
    with pytest.raises(ConfigError, match=f"^{field}:"):
        LocatorConfig(**changes)


def test_config_through_load_and_replace():
    config = load_config(LocatorConfig, overrides=["ball_radius=0.05", "mode=exact", "h_fov=1.2"])
    assert (config.ball_radius, config.mode, config.h_fov) == (0.05, "exact", 1.2)
    with pytest.raises(ConfigError, match="^mode:"):
        replace_config(config, {"mode": "magic"})
    with pytest.raises(ConfigError, match="^ball_radius:"):
        load_config(LocatorConfig, overrides=["ball_radius=-1"])


def test_resolved_mode():
    assert LocatorConfig().resolved_mode(have_intrinsics=False) == "faithful"
    assert LocatorConfig().resolved_mode(have_intrinsics=True) == "exact"
    assert LocatorConfig(mode="faithful").resolved_mode(have_intrinsics=True) == "faithful"
    assert LocatorConfig(mode="exact").resolved_mode(have_intrinsics=False) == "exact"
