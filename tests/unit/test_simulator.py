"""The simulator core with real MuJoCo physics and rendering (EGL, software rasteriser)."""

import math
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402

from balltrack.common.config import ConfigError, load_config  # noqa: E402
from balltrack.services.simulator.config import SimulatorConfig  # noqa: E402
from balltrack.services.simulator.scenario import (  # noqa: E402
    TENNIS_RADIUS,
    available_scenarios,
    load_scenario,
)
from balltrack.services.simulator.sim import Simulation  # noqa: E402
from balltrack.services.simulator.world import build_mjcf  # noqa: E402


@pytest.fixture(scope="module")
def sim():
    simulation = Simulation(SimulatorConfig(scenario="chase"))
    yield simulation
    simulation.close()


@pytest.fixture(scope="module")
def multi_sim():
    simulation = Simulation(SimulatorConfig(scenario="multi"))
    yield simulation
    simulation.close()


def drive(simulation, linear, angular, seconds):
    """Command (linear, angular) every frame for ``seconds``; returns the poses, one per frame."""
    poses = []
    for _ in range(round(seconds * simulation.config.rate_hz)):
        simulation.set_command(linear, angular, simulation.time)
        simulation.step_frame()
        poses.append(simulation.robot_pose())
    return poses


def measured_velocity(poses, period):
    """Mean speed along the path and mean yaw rate over consecutive poses."""
    path = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(poses, poses[1:]))
    turned = sum(math.remainder(b[2] - a[2], 2 * math.pi) for a, b in zip(poses, poses[1:]))
    duration = (len(poses) - 1) * period
    return path / duration, turned / duration


# -- motion ------------------------------------------------------------------------------------

@pytest.mark.parametrize("linear, angular", [(0.3, 0.0), (0.25, 0.8), (0.0, 1.5), (-0.2, -0.5)])
def test_robot_follows_commanded_velocity_within_one_percent(sim, linear, angular):
    sim.reset()
    drive(sim, linear, angular, 1.0)  # accelerate (limits: 1 m/s^2, 4 rad/s^2)
    poses = drive(sim, linear, angular, 2.0)
    speed, yaw_rate = measured_velocity(poses, sim.period)
    assert speed == pytest.approx(abs(linear), rel=0.01, abs=1e-6)
    assert yaw_rate == pytest.approx(angular, rel=0.01, abs=1e-6)
    if angular == 0:
        (x0, y0, yaw0), (x1, y1, _) = poses[0], poses[-1]
        heading = math.atan2(y1 - y0, x1 - x0)
        expected = yaw0 if linear > 0 else yaw0 + math.pi
        assert abs(math.remainder(heading - expected, 2 * math.pi)) < 1e-6


def test_velocity_and_acceleration_limits_hold(sim):
    sim.reset()
    config = sim.config
    sim.set_command(5.0, 10.0)  # far beyond the limits: clamped
    assert sim.commanded_velocity() == (config.max_linear, config.max_angular)
    poses = [sim.robot_pose()] + drive(sim, 5.0, -10.0, 2.0)
    speeds = [math.hypot(b[0] - a[0], b[1] - a[1]) / sim.period for a, b in zip(poses, poses[1:])]
    rates = [abs(math.remainder(b[2] - a[2], 2 * math.pi)) / sim.period
             for a, b in zip(poses, poses[1:])]
    tolerance = 1e-3
    assert max(speeds) <= config.max_linear * (1 + tolerance)
    assert max(rates) <= config.max_angular * (1 + tolerance)
    assert max(speeds) > 0.95 * config.max_linear
    # Per-frame change in speed is bounded by the acceleration limit (plus chord-vs-arc slack).
    accelerations = [abs(b - a) / sim.period for a, b in zip(speeds, speeds[1:])]
    assert max(accelerations) <= config.max_linear_accel * 1.05
    # Reaching full speed takes max_linear / max_linear_accel = 0.5 s, not one frame.
    assert speeds[0] < 0.1 * config.max_linear
    assert speeds[round(0.25 * config.rate_hz)] < 0.6 * config.max_linear


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e6, "fast", None, True])
def test_bad_velocity_commands_are_rejected(sim, bad):
    sim.reset()
    sim.set_command(0.2, 0.1)
    with pytest.raises(ValueError):
        sim.set_command(bad, 0.0)
    with pytest.raises(ValueError):
        sim.set_command(0.0, bad)
    with pytest.raises(ValueError):
        sim.set_command(0.1, 0.1, sim_time=math.nan)
    assert sim.commanded_velocity() == (0.2, 0.1)  # the last good command still holds


def test_safety_stop_after_command_timeout(sim):
    sim.reset()
    timeout = sim.config.cmd_timeout
    start = sim.time
    assert sim.command_time is None
    sim.set_command(0.4, 0.0, start)
    assert sim.command_time == start
    # Still driving just before the timeout.
    while sim.time + sim.period < start + timeout - 1e-9:
        sim.step_frame()
    assert not sim.safety_stopped
    assert sim.commanded_velocity() == (0.4, 0.0)
    assert sim.robot_velocity()[0] == pytest.approx(0.4)
    # After the timeout the target is zero; the robot brakes at the acceleration limit.
    sim.step_frame()
    sim.step_frame()
    assert sim.safety_stopped
    assert sim.commanded_velocity() == (0.0, 0.0)
    braking = 0.4 / sim.config.max_linear_accel
    for _ in range(round((braking + 0.1) * sim.config.rate_hz)):
        sim.step_frame()
    assert sim.robot_velocity() == (0.0, 0.0)
    before = sim.robot_pose()
    for _ in range(15):
        sim.step_frame()
    assert np.allclose(sim.robot_pose(), before, atol=1e-6)
    # A new command wakes it up again.
    drive(sim, 0.2, 0.0, 0.5)
    assert not sim.safety_stopped
    assert sim.robot_velocity()[0] == pytest.approx(0.2)


def test_robot_never_leaves_the_world(sim):
    sim.reset()
    limit = sim.scenario.robot_limit
    assert sim.handle_command({"op": "place_robot", "x": limit - 0.2, "y": 0.0, "yaw": 0.0})["ok"]
    drive(sim, 0.5, 0.0, 2.0)
    x, y, _ = sim.robot_pose()
    assert x == pytest.approx(limit)
    assert abs(y) < 1e-9


def test_scripted_balls_move_along_their_paths():
    config = SimulatorConfig()
    for name, check in (("moving", "line"), ("orbit", "circle")):
        scenario = load_scenario(name)
        ball = scenario.balls[0]
        positions = np.array([ball.position_at(t) for t in np.linspace(0, 30, 301)])
        if check == "line":
            assert np.allclose(positions[:, 0], 2.0)
            assert positions[:, 1].min() == pytest.approx(-1.0, abs=0.02)
            assert positions[:, 1].max() == pytest.approx(1.0, abs=0.02)
            steps = np.linalg.norm(np.diff(positions[:, :2], axis=0), axis=1)
            assert steps.max() <= ball.motion.speed * 0.1 + 1e-9
        else:
            radii = np.linalg.norm(positions[:, :2] - ball.motion.center, axis=1)
            assert np.allclose(radii, ball.motion.radius)
        assert np.allclose(positions[:, 2], TENNIS_RADIUS)
    simulation = Simulation(config, load_scenario("moving"))
    try:
        first = simulation.ground_truth()["balls"][0]["position"]
        for _ in range(10):
            simulation.step_frame()
        moved = simulation.ground_truth()["balls"][0]["position"]
        assert moved[1] == pytest.approx(first[1] - 0.3 * 10 / 30)
    finally:
        simulation.close()


# -- camera ------------------------------------------------------------------------------------

def mask_centroid(mask):
    rows, columns = np.nonzero(mask)
    return columns.mean(), rows.mean()


def analytic_sphere_centroid(info, in_camera, radius):
    """Centroid of the exact image of a sphere: the pixels whose ray falls inside its cone."""
    columns, rows = np.meshgrid(np.arange(info["width"]), np.arange(info["height"]))
    rays = np.stack([(columns - info["cx"]) / info["fx"], (rows - info["cy"]) / info["fy"],
                     np.ones(columns.shape)], axis=-1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    centre = np.asarray(in_camera) / np.linalg.norm(in_camera)
    half_angle = math.asin(radius / np.linalg.norm(in_camera))
    return mask_centroid(rays @ centre > math.cos(half_angle))


# Ball positions in the world with the robot at the origin facing +x (camera at x = 0.11,
# height 0.10): centre of the image, left, right, near, far.
PROJECTION_CASES = {
    "centre": (2.11, 0.0, 0.10),
    "left": (2.0, 0.8, 0.033),
    "right": (1.6, -0.7, 0.033),
    "near": (0.5, 0.02, 0.06),
    "far": (3.6, 0.3, 0.033),
    "high_left": (1.2, 0.45, 0.35),
}


@pytest.mark.parametrize("case", sorted(PROJECTION_CASES))
def test_rendered_ball_centre_matches_pinhole_projection(multi_sim, case):
    simulation = multi_sim
    simulation.reset()
    for ball_id, parked in (("middle", (-4.0, -4.0)), ("far", (-4.0, 4.0))):
        request = {"op": "place_ball", "id": ball_id, "position": parked}
        assert simulation.handle_command(request)["ok"]
    reply = simulation.handle_command(
        {"op": "place_ball", "id": "near", "position": list(PROJECTION_CASES[case])})
    assert reply == {"ok": True}
    truth = next(ball for ball in simulation.ground_truth()["balls"] if ball["id"] == "near")
    assert truth["visible"]
    info = simulation.camera_info()
    u, v = simulation.project(truth["in_camera"])
    mask = simulation.ball_masks()["near"]
    assert mask.sum() > 50
    centroid = mask_centroid(mask)
    assert math.hypot(centroid[0] - u, centroid[1] - v) < 1.0, (centroid, (u, v))
    # Tighter: the rendered silhouette's centroid is that of the exact sphere image.
    exact = analytic_sphere_centroid(info, truth["in_camera"], truth["radius"])
    assert math.hypot(centroid[0] - exact[0], centroid[1] - exact[1]) < 0.25


def test_projection_with_a_turned_robot_and_other_intrinsics():
    config = SimulatorConfig(scenario="chase", width=320, height=240, hfov=1.3)
    simulation = Simulation(config)
    try:
        request = {"op": "place_robot", "x": 1.0, "y": -1.0, "yaw": 2.4}
        assert simulation.handle_command(request)["ok"]
        # 1.5 m ahead of the robot and 0.2 m to its left.
        yaw = 2.4
        target = (1.0 + 1.5 * math.cos(yaw) - 0.2 * math.sin(yaw),
                  -1.0 + 1.5 * math.sin(yaw) + 0.2 * math.cos(yaw), 0.033)
        request = {"op": "place_ball", "id": "tennis", "position": list(target)}
        assert simulation.handle_command(request)["ok"]
        truth = simulation.ground_truth()["balls"][0]
        assert truth["in_camera"] == pytest.approx([-0.2, 0.067, 1.5 - 0.11], abs=1e-9)
        info = simulation.camera_info()
        assert info["fx"] == pytest.approx(160 / math.tan(0.65))
        assert info["fy"] == info["fx"]
        assert (info["cx"], info["cy"]) == (159.5, 119.5)
        assert info["vfov"] == pytest.approx(2 * math.atan(math.tan(0.65) * 240 / 320))
        u, v = simulation.project(truth["in_camera"])
        centroid = mask_centroid(simulation.ball_masks()["tennis"])
        assert math.hypot(centroid[0] - u, centroid[1] - v) < 1.0
        image = simulation.render()
        assert image.shape == (240, 320, 3) and image.dtype == np.uint8
    finally:
        simulation.close()


def test_visibility_flag(sim):
    sim.reset()
    assert sim.ground_truth()["balls"][0]["visible"]  # chase: in view at the left edge
    assert sim.handle_command({"op": "place_ball", "id": "tennis", "position": [-2.0, 0.0]})["ok"]
    behind = sim.ground_truth()["balls"][0]
    assert behind["in_camera"][2] < 0 and not behind["visible"]
    assert sim.handle_command({"op": "place_ball", "id": "tennis", "position": [1.0, 1.5]})["ok"]
    aside = sim.ground_truth()["balls"][0]
    assert aside["in_camera"][2] > 0 and not aside["visible"]
    assert not sim.ball_masks()["tennis"].any()


def test_lower_light_gives_a_darker_image_monotonically(sim):
    sim.reset()
    levels = [0.8, 0.5, 0.1, 0.05, 0.02, 0.01]
    image_means, ball_means = [], []
    ball_mask = sim.ball_masks()["tennis"]
    assert ball_mask.sum() > 50
    for level in levels:
        assert sim.handle_command({"op": "set_light", "diffuse": level}) == {"ok": True}
        image = sim.render().astype(float)
        image_means.append(image.mean())
        ball_means.append(image[ball_mask].mean())
    assert all(a > b for a, b in zip(image_means, image_means[1:])), image_means
    assert all(a > b for a, b in zip(ball_means, ball_means[1:])), ball_means
    # Without ambient light, unlit surfaces go black and the dim scene is darker still.
    assert sim.handle_command({"op": "set_light", "diffuse": 0.01, "ambient": 0.0})["ok"]
    assert sim.render()[ball_mask].mean() < 0.2 * ball_means[-1]
    assert sim.light() == {"diffuse": [pytest.approx(0.01)] * 3, "ambient": [0.0] * 3}
    sim.reset()
    assert sim.light()["diffuse"] == [pytest.approx(0.8)] * 3


def test_config_light_override_and_dark_scenario():
    scenario = load_scenario("dark")
    assert scenario.light.diffuse == (0.05, 0.05, 0.05)
    xml = build_mjcf(scenario, SimulatorConfig(light_diffuse=0.3, ambient=0.1))
    model = mujoco.MjModel.from_xml_string(xml)
    assert np.allclose(model.light_diffuse[0], 0.3) and np.allclose(model.light_ambient[0], 0.1)


# -- determinism and commands ------------------------------------------------------------------

def run_sequence(config, scenario="moving"):
    simulation = Simulation(config, load_scenario(scenario))
    try:
        truths, images = [], []
        for frame in range(40):
            if frame % 3 == 0:  # like a 10 Hz cmd_vel at 30 fps
                simulation.set_command(0.3, 0.6 * math.sin(frame / 7), simulation.time)
            simulation.step_frame()
            truths.append(simulation.ground_truth())
            if frame % 10 == 0:
                images.append(simulation.render())
        return truths, images
    finally:
        simulation.close()


def test_same_seed_same_commands_identical_ground_truth():
    config = SimulatorConfig(seed=7, image_noise=3.0)
    truths_a, images_a = run_sequence(config)
    truths_b, images_b = run_sequence(config)
    assert truths_a == truths_b
    assert all(np.array_equal(a, b) for a, b in zip(images_a, images_b))
    _, images_c = run_sequence(SimulatorConfig(seed=8, image_noise=3.0))
    assert not np.array_equal(images_a[0], images_c[0])


def test_a_simulation_started_on_a_recorded_clock_goes_on_after_it():
    # (a simulator restarted with its clock_file: the scenario starts afresh, the clock does not)
    config = SimulatorConfig(width=160, height=120)
    fresh = Simulation(config, load_scenario("moving"))
    later = Simulation(config, load_scenario("moving"), start_time=12.5, start_frame=400)
    try:
        assert (later.stamp_ns, later.frame_index) == (12_500_000_000, 400)
        for _ in range(10):
            fresh.step_frame()
            later.step_frame()
        assert later.frame_index == 410 and later.time == pytest.approx(12.5 + fresh.time, abs=1e-9)
        # Scripted motion counts from the start, wherever the clock began.
        for moved, reference in zip(later.ground_truth()["balls"], fresh.ground_truth()["balls"]):
            assert moved["position"] == pytest.approx(reference["position"], abs=1e-9)
    finally:
        fresh.close()
        later.close()


def snapshot(simulation):
    return (simulation.ground_truth(), simulation.light(), simulation.robot_velocity(),
            simulation.commanded_velocity(), simulation.time, simulation.scenario.name)


BAD_REQUESTS = [
    "reset",
    {"scenario": "chase"},
    {"op": "explode"},
    {"op": "reset", "scenario": "no_such_scenario"},
    {"op": "reset", "scenario": 5},
    {"op": "reset", "world": "chase"},
    {"op": "set_light"},
    {"op": "set_light", "diffuse": 1.5},
    {"op": "set_light", "diffuse": [0.1, 0.2]},
    {"op": "set_light", "diffuse": 0.2, "ambient": -0.1},
    {"op": "set_light", "diffuse": "bright"},
    {"op": "set_light", "diffuse": math.nan},
    {"op": "set_light", "diffuse": 0.2, "specular": 0.1},
    {"op": "place_ball", "id": "nope", "position": [1.0, 0.0]},
    {"op": "place_ball", "position": [1.0, 0.0]},
    {"op": "place_ball", "id": "tennis", "position": [1.0]},
    {"op": "place_ball", "id": "tennis", "position": [1.0, math.nan]},
    {"op": "place_ball", "id": "tennis", "position": [50.0, 0.0]},
    {"op": "place_ball", "id": "tennis", "position": [1.0, 0.0, -1.0]},
    {"op": "place_ball", "id": "tennis", "position": "here"},
    {"op": "place_robot", "x": 1.0},
    {"op": "place_robot", "x": 1.0, "y": 99.0},
    {"op": "place_robot", "x": 1.0, "y": 0.0, "yaw": "north"},
    {"op": "place_robot", "x": math.inf, "y": 0.0},
    {"op": "place_robot", "x": 1.0, "y": 0.0, "z": 1.0},
]


def test_bad_commands_change_nothing(sim):
    sim.reset()
    drive(sim, 0.2, 0.3, 0.3)
    assert sim.handle_command({"op": "set_light", "diffuse": 0.3})["ok"]
    before = snapshot(sim)
    for request in BAD_REQUESTS:
        reply = sim.handle_command(request)
        assert reply["ok"] is False, request
        assert isinstance(reply["error"], str) and reply["error"], request
        assert snapshot(sim) == before, request


def test_good_commands_apply_and_reset_restores(sim):
    sim.reset()
    start = sim.ground_truth()
    assert sim.handle_command({"op": "place_robot", "x": 1.0, "y": 2.0, "yaw": 0.5}) == {"ok": True}
    assert sim.robot_pose() == pytest.approx((1.0, 2.0, 0.5))
    request = {"op": "place_ball", "id": "tennis", "position": [3.0, 2.0, 0.2]}
    assert sim.handle_command(request) == {"ok": True}
    assert sim.ground_truth()["balls"][0]["position"] == [3.0, 2.0, 0.2]
    assert sim.handle_command({"op": "place_robot", "x": 0.5, "y": 0.5}) == {"ok": True}
    assert sim.robot_pose() == pytest.approx((0.5, 0.5, 0.5))  # yaw kept
    assert sim.handle_command({"op": "set_light", "diffuse": [0.2, 0.3, 0.4], "ambient": 0.1})["ok"]
    assert sim.light()["diffuse"] == pytest.approx([0.2, 0.3, 0.4])
    time_before = sim.time
    assert sim.handle_command({"op": "reset"}) == {"ok": True}
    assert sim.ground_truth() == start
    assert sim.time == time_before  # the clock never goes back
    assert sim.handle_command({"op": "reset", "scenario": "multi"}) == {"ok": True}
    assert [ball["id"] for ball in sim.ground_truth()["balls"]] == ["near", "middle", "far"]
    assert sim.render().shape == (480, 640, 3)
    assert sim.handle_command({"op": "reset", "scenario": "chase"}) == {"ok": True}
    assert sim.ground_truth() == start


# -- scenarios and config ----------------------------------------------------------------------

def test_shipped_scenarios_load_and_build():
    names = available_scenarios()
    for required in ("chase", "search", "multi", "dark", "distractors"):
        assert required in names
    for name in names:
        scenario = load_scenario(name)
        mujoco.MjModel.from_xml_string(build_mjcf(scenario, SimulatorConfig()))
    assert len(load_scenario("multi").balls) == 3
    assert load_scenario("distractors").balls == []
    assert len(load_scenario("distractors").distractors) >= 3
    search = load_scenario("search").balls[0]
    assert search.position[0] < 0  # behind the robot


GOOD_BALL = '[[balls]]\nid = "a"\nposition = [1.0, 0.0]\n'


@pytest.mark.parametrize("text, expected", [
    ("colour = 1\n" + GOOD_BALL, "colour: unknown key"),
    ('[[balls]]\nid = "a"\nposition = [1.0, 0.0]\nspeed = 2\n', "balls[0].speed: unknown key"),
    ('[[balls]]\nid = "a"\nposition = "far"\n', "balls[0].position: expected a list"),
    ('[[balls]]\nid = "a"\nposition = [1.0, 0.0]\nradius = -0.1\n', "balls[0].radius: must be > 0"),
    ('[[balls]]\nid = "a"\nposition = [1.0, 0.0]\nradius = "big"\n',
     "balls[0].radius: expected a number"),
    ('[[balls]]\nid = "a"\nposition = [1.0, 0.0]\nrgb = [1.2, 0.5, 0.0]\n',
     "balls[0].rgb: colour values"),
    ('[[balls]]\nposition = [1.0, 0.0]\n[balls.motion]\ntype = "zigzag"\nspeed = 1.0\n',
     "balls[0].motion.type: must be one of line, circle"),
    ('[[balls]]\nposition = [1.0, 0.0]\n[balls.motion]\ntype = "line"\nspeed = 1.0\n',
     "balls[0].motion.end: missing"),
    ('[[balls]]\nposition = [1.0]\n', "balls[0].position: expected 2 or 3 numbers"),
    ('[[balls]]\nposition = [20.0, 0.0]\n', "balls[0].position: (20, 0) is outside the world"),
    (GOOD_BALL + GOOD_BALL, "balls[1].id: duplicate id 'a'"),
    ("[light]\ndiffuse = 2.0\n", "light.diffuse: colour values must be between 0 and 1"),
    ("[light]\nambient = true\n", "light.ambient: expected a number"),
    ('[floor]\ntexture = "marble"\n', "floor.texture: must be one of"),
    ('[[distractors]]\nshape = "cone"\nsize = [1.0]\nposition = [1.0, 1.0]\n',
     "distractors[0].shape: must be one of box, cylinder, sphere"),
    ('[[distractors]]\nshape = "box"\nsize = [1.0]\nposition = [1.0, 1.0]\n',
     "distractors[0].size: expected 3 numbers"),
    ("[robot]\nx = 100.0\n", "robot.x:"),
    ("balls = 3\n", "balls: expected an array of tables"),
    ("[world\n", "not valid TOML"),
])
def test_bad_scenario_files_raise_config_error_naming_the_problem(tmp_path, text, expected):
    path = tmp_path / "broken.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_scenario(str(path))
    message = str(caught.value)
    assert "broken.toml" in message
    assert expected in message


def test_missing_scenario_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="no_such_world.*no such scenario file"):
        load_scenario("no_such_world")
    with pytest.raises(ConfigError, match="missing.toml"):
        load_scenario(str(tmp_path / "missing.toml"))
    with pytest.raises(ConfigError, match="no such scenario file"):
        Simulation(SimulatorConfig(scenario="no_such_world"))


def test_a_scenario_file_path_works(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('[light]\ndiffuse = [0.2, 0.3, 0.4]\n[[balls]]\nposition = [1.0, 0.0]\n'
                    '[balls.motion]\ntype = "circle"\ncenter = [0.0, 0.0]\nradius = 1.0\n'
                    'speed = 0.5\n')
    scenario = load_scenario(str(path))
    assert scenario.name == "mine"
    assert scenario.balls[0].id == "ball0"
    assert scenario.balls[0].position == (1.0, 0.0, TENNIS_RADIUS)
    assert scenario.light.diffuse == (0.2, 0.3, 0.4)


@pytest.mark.parametrize("override, field", [
    ("pacing=warp", "pacing"), ("width=0", "width"), ("hfov=4", "hfov"), ("rate_hz=0", "rate_hz"),
    ("cmd_timeout=-1", "cmd_timeout"), ("max_linear=0", "max_linear"),
    ("light_diffuse=2", "light_diffuse"),
    ("encoding=png", "encoding"), ("timestep=0.5", "timestep"), ("seed=-1", "seed"),
    ("no_such_field=1", "no_such_field"),
])
def test_bad_config_values_raise_config_error_naming_the_field(override, field):
    with pytest.raises(ConfigError, match=f"^{field}:"):
        load_config(SimulatorConfig, overrides=[override])


def test_config_defaults_and_overrides():
    config = load_config(SimulatorConfig,
                         overrides=["scenario=dark", "pacing=lockstep", "shadows=true"])
    assert (config.scenario, config.pacing, config.shadows) == ("dark", "lockstep", True)
    default = SimulatorConfig()
    assert (default.width, default.height, default.rate_hz) == (640, 480, 30.0)
    assert default.vfov == pytest.approx(2 * math.atan(math.tan(1.089 / 2) * 0.75))


def test_frame_loop_in_another_thread_with_commands_from_this_one():
    import threading

    simulation = Simulation(SimulatorConfig(scenario="chase", width=160, height=120))
    frames, errors = [], []

    def loop():
        try:
            for _ in range(20):
                simulation.step_frame()
                frames.append(simulation.render())
        except Exception as error:  # reported below
            errors.append(error)

    try:
        worker = threading.Thread(target=loop)
        worker.start()
        for level in (0.5, 0.2, 0.8):
            assert simulation.handle_command({"op": "set_light", "diffuse": level})["ok"]
        assert simulation.handle_command({"op": "reset", "scenario": "multi"})["ok"]
        worker.join(timeout=60)
        assert not errors and len(frames) == 20
        assert simulation.render_view("follow").shape == (120, 160, 3)
        assert simulation.render_view("top").shape == (120, 160, 3)
        with pytest.raises(ValueError):
            simulation.render_view("sky")
    finally:
        simulation.close()
    simulation.close()  # twice is fine
    with pytest.raises(RuntimeError):
        simulation.render()


def test_recorder_writes_video_and_ground_truth(tmp_path):
    import json

    from balltrack.services.simulator.output_files import OutputFiles

    config = SimulatorConfig(width=160, height=120, video_path=str(tmp_path / "run.avi"),
                             ground_truth_path=str(tmp_path / "truth.jsonl"))
    simulation = Simulation(config)
    recorder = OutputFiles.from_config(config)
    try:
        for _ in range(5):
            simulation.set_command(0.2, 0.0)
            simulation.step_frame(now_wall=123.0)
            recorder.write(simulation, simulation.render())
    finally:
        recorder.close()
        simulation.close()
    lines = [json.loads(line) for line in (tmp_path / "truth.jsonl").read_text().splitlines()]
    assert [line["seq"] for line in lines] == [1, 2, 3, 4, 5]
    assert lines[-1]["stamp"] == round(5 / 30 * 1e9)
    assert lines[-1]["wall_time"] == 123.0 and lines[-1]["balls"][0]["id"] == "tennis"
    assert (tmp_path / "run.avi").stat().st_size > 1000
    assert OutputFiles.from_config(SimulatorConfig()) is None


@pytest.mark.parametrize("arguments, reason", [(["--frames", "0"], "--frames: must be at least 1"),
                                               (["--set", "nonsense=1"], "nonsense: unknown parameter"),
                                               (["--robots", "1", "65"], "--robots: must be at most 64"),
                                               (["--robots", "16"], "robots: 16 in scenario 'chase': robot 1 "
                                                                    "would start at")])
def test_benchmark_rejects_bad_arguments_with_one_line(arguments, reason, capsys):
    from balltrack.services.simulator.benchmark import main

    with pytest.raises(SystemExit) as exit_info:
        main(arguments)
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert reason in error.strip().splitlines()[-1] and "Traceback" not in error
