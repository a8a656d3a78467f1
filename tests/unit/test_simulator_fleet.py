"""Several robots in one simulated world (services/simulator/fleet.py), with real MuJoCo physics
and rendering: the model's robots, their start rows, independent control, each camera's own
view, and the ``fleet`` scenario's balls, reached by every robot under its own referee."""

import math
import os
import threading
import time

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402

from balltrack.common.config import ConfigError, load_config  # noqa: E402
from balltrack.common.geometry import wrap_angle  # noqa: E402
from balltrack.services.simulator.config import SimulatorConfig  # noqa: E402
from balltrack.services.simulator.fleet import (  # noqa: E402
    fleet_layout,
    own_ball_id,
    own_ball_referees,
    robot_key,
    robot_names,
)
from balltrack.services.simulator.pacing import LockstepGate, wait_together  # noqa: E402
from balltrack.services.simulator.scenario import load_scenario, parse_scenario  # noqa: E402
from balltrack.services.simulator.sim import Simulation  # noqa: E402
from balltrack.services.simulator.world import build_mjcf  # noqa: E402

SMALL = {"width": 160, "height": 120}


@pytest.fixture(scope="module")
def fleet():
    simulation = Simulation(SimulatorConfig(scenario="fleet", robots=3, **SMALL))
    yield simulation
    simulation.close()


def model_names(model: mujoco.MjModel, kind: str, count: int) -> set[str]:
    return {getattr(model, kind)(index).name for index in range(count)}


# -- the model ---------------------------------------------------------------------------------

def test_the_model_holds_each_robot_with_its_camera_joints_and_drives():
    model = mujoco.MjModel.from_xml_string(build_mjcf(load_scenario("chase"),
                                                      SimulatorConfig(robots=3, **SMALL)))
    bodies = model_names(model, "body", model.nbody)
    cameras = model_names(model, "camera", model.ncam)
    for robot in ("robot1", "robot2", "robot3"):
        assert robot in bodies
        assert {f"{robot}_front", f"{robot}_follow"} <= cameras
        assert {f"{robot}_base_x", f"{robot}_base_y", f"{robot}_base_yaw"} <= model_names(
            model, "joint", model.njnt)
    assert "robot" not in bodies and "front" not in cameras and "robot4" not in bodies
    assert model.nu == 9 and model.njnt == 9
    # The single robot keeps the names it always had.
    single = mujoco.MjModel.from_xml_string(build_mjcf(load_scenario("chase"), SimulatorConfig(**SMALL)))
    assert "robot" in model_names(single, "body", single.nbody)
    assert "front" in model_names(single, "camera", single.ncam) and single.nu == 3


def test_robots_stand_in_rows_centred_on_the_scenario_start_and_apart():
    scenario = load_scenario("fleet")
    layout = fleet_layout(scenario, 16)
    starts = [(start.x, start.y) for start in layout.starts]
    assert len(set(starts)) == 16
    # Two rows of 8, 3 m apart, 1.5 m between neighbours, robot 1 on the left (+y) of the front row.
    assert sorted({round(x, 6) for x, _ in starts}) == [-1.5, 1.5]
    assert starts[0] == pytest.approx((1.5, 5.25)) and starts[7] == pytest.approx((1.5, -5.25))
    assert starts[8] == pytest.approx((-1.5, 5.25))
    assert min(math.dist(a, b) for index, a in enumerate(starts) for b in starts[index + 1:]) == pytest.approx(1.5)
    assert all(start.yaw == scenario.robot.yaw for start in layout.starts)
    # Each robot's own ball 1.2 m ahead, 0.3 m to the left; the scenario's balls come first.
    assert [ball.id for ball in layout.balls] == [own_ball_id(index) for index in range(1, 17)]
    for start, ball in zip(layout.starts, layout.balls):
        assert ball.position[:2] == pytest.approx((start.x + 1.2, start.y + 0.3))
    # A robot start turned by the scenario's yaw turns the rows with it.
    turned = parse_scenario({"robot": {"x": 1.0, "y": -1.0, "yaw": math.pi / 2}}, "test", "turned")
    (first, second) = fleet_layout(turned, 2).starts
    assert (first.x, first.y) == pytest.approx((1.0 - 0.75, -1.0))
    assert (second.x, second.y) == pytest.approx((1.0 + 0.75, -1.0))
    # One robot (robots = 0, or 1) stands where the scenario says.
    assert [(start.x, start.y) for start in fleet_layout(scenario, 0).starts] == [(0.0, 0.0)]
    assert [(start.x, start.y) for start in fleet_layout(scenario, 1).starts] == [(0.0, 0.0)]


def test_names_and_keys_of_the_robots():
    assert robot_names(0) == [""]
    assert robot_names(3) == ["robot1", "robot2", "robot3"]
    assert robot_key("", "cmd_vel") == "cmd_vel"
    assert robot_key("robot2", "camera/image_raw") == "robot2/camera/image_raw"
    referees = own_ball_referees(2)
    assert list(referees) == ["robot1", "robot2"]
    assert [referee.target for referee in referees.values()] == ["tennis1", "tennis2"]


def test_a_simulator_holding_part_of_a_fleet_numbers_its_robots_from_first_robot():
    assert robot_names(3, first=5) == ["robot5", "robot6", "robot7"]
    assert list(own_ball_referees(2, first=5)) == ["robot5", "robot6"]
    scenario = load_scenario("fleet")
    numbered, plain = fleet_layout(scenario, 4, first=5), fleet_layout(scenario, 4)
    assert [ball.id for ball in numbered.balls] == [own_ball_id(robot) for robot in range(5, 9)]
    # (the same rows as robots 1-4: each simulator is a world of its own)
    assert numbered.starts == plain.starts
    config = SimulatorConfig(scenario="fleet", robots=2, first_robot=5, **SMALL)
    model = mujoco.MjModel.from_xml_string(build_mjcf(scenario, config))
    assert {"robot5", "robot6"} <= model_names(model, "body", model.nbody)
    assert "robot1" not in model_names(model, "body", model.nbody)
    with Simulation(config) as simulation:
        assert [ball["id"] for ball in simulation.ground_truth(1)["balls"] if ball["visible"]] == ["tennis6"]


@pytest.mark.parametrize("setting, expected", [
    (["first_robot=0", "robots=2"], "first_robot: must be"),
    (["first_robot=5"], "first_robot: numbers the robots of robots >= 1"),
])
def test_bad_first_robot_setting_is_refused(setting, expected):
    with pytest.raises(ConfigError, match=expected):
        load_config(SimulatorConfig, None, setting, section="simulator")


@pytest.mark.parametrize("scenario, robots, expected", [
    ("chase", 64, "robots: 64 in scenario 'chase': robot 1 would start at"),
    ("fleet", 24, "robots: 24 in scenario 'fleet': robot 1 would start at"),
])
def test_robots_that_do_not_fit_are_refused_with_one_line(scenario, robots, expected, tmp_path):
    if scenario == "fleet":  # a fleet world too small for three rows with their balls
        path = tmp_path / "small_fleet.toml"
        path.write_text("[world]\nsize = 6.0\n[fleet]\nball_distance = 1.2\n")
        scenario = str(path)
        expected = expected.replace("'fleet'", "'small_fleet'")
    config = load_config(SimulatorConfig, None, [f"scenario={scenario}", f"robots={robots}"],
                         section="simulator")
    with pytest.raises(ConfigError, match="^" + expected) as raised:
        config.preflight()
    assert "\n" not in str(raised.value)
    with pytest.raises(ConfigError, match="^" + expected):
        Simulation(config)


@pytest.mark.parametrize("setting, expected", [
    ("robots=65", "robots: must be"),
    ("robots=-1", "robots: must be"),
    ("robots=two", "robots: expected an integer"),
])
def test_bad_robots_setting_is_refused(setting, expected):
    with pytest.raises(ConfigError, match=expected):
        load_config(SimulatorConfig, None, [setting], section="simulator")


@pytest.mark.parametrize("text, expected", [
    ("[fleet]\ncolumns = 2.5\n", "fleet.columns: must be a whole number"),
    ("[fleet]\ncolumns = 0\n", "fleet.columns: must be >= 1"),
    ("[fleet]\nspacing = 0\n", "fleet.spacing: must be > 0"),
    ("[fleet]\nrows = 2\n", "fleet.rows: unknown key"),
    ('[fleet]\nball_distance = 1.0\n[[balls]]\nid = "tennis1"\nposition = [3.0, 0.0]\n',
     "already has a ball 'tennis1'"),
])
def test_bad_fleet_tables_are_refused(text, expected, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=expected):
        fleet_layout(load_scenario(str(path)), 2)


# -- one world, several robots -----------------------------------------------------------------

def test_commanding_one_robot_moves_only_that_robot(fleet):
    fleet.reset()
    starts = [fleet.robot_pose(robot) for robot in range(3)]
    for _ in range(30):
        fleet.set_command(0.3, 0.5, fleet.time, robot=1)
        fleet.step_frame()
    assert fleet.robot_pose(0) == starts[0] and fleet.robot_pose(2) == starts[2]
    moved = fleet.robot_pose(1)
    assert math.dist(moved[:2], starts[1][:2]) > 0.2 and moved[2] > 0.3
    assert fleet.robot_velocity(1)[0] > 0.25 and fleet.robot_velocity(0) == (0.0, 0.0)
    # Each robot has its own safety stop: robot 3's command times out, robot 2's goes on.
    fleet.set_command(0.2, 0.0, fleet.time, robot=2)
    for _ in range(30):
        fleet.set_command(0.3, 0.0, fleet.time, robot=1)
        fleet.step_frame()
    assert fleet.commanded_velocity(2) == (0.0, 0.0) and fleet.commanded_velocity(1) == (0.3, 0.0)
    assert fleet.command_count == 61
    # A bad command to one robot leaves its command as it was.
    with pytest.raises(ValueError, match="linear"):
        fleet.set_command(float("nan"), 0.0, robot=1)
    assert fleet.commanded_velocity(1) == (0.3, 0.0)


def test_place_robot_moves_the_robot_of_the_request_and_reset_puts_all_back(fleet):
    fleet.reset()
    starts = [fleet.robot_pose(robot) for robot in range(3)]
    assert fleet.handle_command({"op": "place_robot", "x": -2.0, "y": 1.0, "yaw": 1.0}, robot=2) == {"ok": True}
    assert fleet.robot_pose(2) == pytest.approx((-2.0, 1.0, 1.0))
    assert [fleet.robot_pose(robot) for robot in (0, 1)] == starts[:2]
    assert fleet.ground_truth(2)["robot"] == pytest.approx({"x": -2.0, "y": 1.0, "yaw": 1.0})
    assert fleet.handle_command({"op": "reset"}) == {"ok": True}
    assert [fleet.robot_pose(robot) for robot in range(3)] == starts


def test_each_camera_renders_its_own_view_with_its_own_ball_nearest(fleet):
    fleet.reset()
    images = [fleet.render(robot) for robot in range(3)]
    assert all(image.shape == (120, 160, 3) for image in images)
    assert not np.array_equal(images[0], images[1]) and not np.array_equal(images[1], images[2])
    for robot in range(3):
        masks = fleet.ball_masks(robot)
        seen = {ball: int(mask.sum()) for ball, mask in masks.items() if mask.any()}
        assert list(seen) == [own_ball_id(robot + 1)], f"robot {robot + 1} sees {seen}"
        truth = fleet.ground_truth(robot)
        assert [ball["id"] for ball in truth["balls"] if ball["visible"]] == [own_ball_id(robot + 1)]
        own = truth["balls"][robot]
        # 1.2 m ahead of the robot's centre is 1.09 m ahead of its camera, 0.3 m to its left.
        assert own["in_camera"] == pytest.approx([-0.3, 0.1 - 0.033, 1.09], abs=1e-6)
    # Moving robot 2 changes robot 2's picture only.
    fleet.place_robot(x=0.5, y=0.0, yaw=0.3, robot=1)
    after = [fleet.render(robot) for robot in range(3)]
    assert np.array_equal(after[0], images[0]) and np.array_equal(after[2], images[2])
    assert not np.array_equal(after[1], images[1])
    assert fleet.render_view("follow", robot=1).shape == (120, 160, 3)


def test_leaving_out_what_a_camera_cannot_see_changes_no_pixel():
    """A robot's camera draws only the robots and balls in its view (sim_camera's culling); its
    picture is the same as the one drawn with every geom (the ``front`` view for people)."""
    with Simulation(SimulatorConfig(scenario="fleet", robots=12, **SMALL)) as simulation:
        for robot in range(12):  # turning on the spot and driving: each sees others' parts
            simulation.set_command(0.3 * (robot % 2), 1.5 if robot < 6 else -1.5, robot=robot)
        balls_seen = 0
        for frame in range(45):
            simulation.step_frame()
            if frame % 15 == 14:
                for robot in range(12):
                    assert np.array_equal(simulation.render(robot), simulation.render_view("front", robot)), robot
                    balls_seen = max(balls_seen, sum(mask.any() for mask in simulation.ball_masks(robot).values()))
        assert balls_seen >= 2, "no camera saw another robot's ball: the pictures tested little"


def test_in_the_fleet_scenario_every_robot_reaches_its_own_ball():
    """Each robot steered towards its own ball by its ground truth (as a perfect follower
    would) reaches it under its own referee, and only its own: the layout leaves each robot a
    free way to its ball."""
    robots = 4
    with Simulation(SimulatorConfig(scenario="fleet", robots=robots, **SMALL)) as simulation:
        referees = own_ball_referees(robots)
        others = {name: own_ball_referees(robots)[neighbour]
                  for name, neighbour in zip(referees, list(referees)[1:] + list(referees)[:1])}
        names = list(referees)
        while simulation.time < 15 and not all(referee.reached for referee in referees.values()):
            for robot, name in enumerate(names):
                truth = simulation.ground_truth(robot)
                referees[name].update(simulation.time, truth)
                others[name].update(simulation.time, truth)
                pose = truth["robot"]
                ball = truth["balls"][robot]["position"]
                turn = wrap_angle(math.atan2(ball[1] - pose["y"], ball[0] - pose["x"]) - pose["yaw"])
                distance = math.hypot(ball[0] - pose["x"], ball[1] - pose["y"])
                linear = 0.0 if distance < 0.25 or abs(turn) > 0.5 else 0.3
                simulation.set_command(linear, 2.0 * turn, simulation.time, robot=robot)
            simulation.step_frame()
        assert all(referee.reached for referee in referees.values()), {
            name: (referee.closest, referee.heading) for name, referee in referees.items()}
        assert not any(referee.reached for referee in others.values())


def test_one_robot_in_the_fleet_scenario_gets_one_ball_on_its_own_keys():
    with Simulation(SimulatorConfig(scenario="fleet", **SMALL)) as simulation:
        assert simulation.robot_count == 1
        truth = simulation.ground_truth()
        assert [ball["id"] for ball in truth["balls"]] == ["tennis1"]
        assert truth["balls"][0]["visible"]


# -- lockstep with several robots --------------------------------------------------------------

def test_a_frames_waits_for_several_robots_share_one_deadline():
    stop = threading.Event()
    answering, silent, gone = LockstepGate(stop), LockstepGate(stop), LockstepGate(stop)
    for gate in (answering, silent, gone):
        gate.set_alive("detector", True)
    gone.set_alive("detector", False)
    answering.answered(7)
    started = time.monotonic()
    missed = wait_together([lambda limit, gate=gate: gate.wait_answer(7, limit)
                            for gate in (silent, answering, silent, gone)], lambda: 0.5)
    elapsed = time.monotonic() - started
    # The silent robot's waits time out (both), the answering and the gone one's do not; all
    # of it within one timeout, not one per robot.
    assert missed == 2 and silent.timeouts == 2 and answering.timeouts == 0 and gone.timeouts == 0
    assert 0.5 <= elapsed < 0.9


# -- the benchmark -----------------------------------------------------------------------------

def test_the_benchmark_measures_each_robot_count_in_turn(capsys):
    from balltrack.services.simulator.benchmark import main

    assert main(["--frames", "2", "--set", "scenario=fleet", "--set", "width=64", "--set", "height=48",
                 "--robots", "0", "3"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["64x48 shadows=False robots=0", "64x48 shadows=False robots=3"]
    assert all("ms CPU/frame" in line for line in lines)
