"""Pure parts of deploy: command lines from options, endpoints, the demo's referee."""

import math

import pytest

from balltrack.deploy.cli import LaunchError, build_parser, build_specs, endpoint_port, local_endpoint
from balltrack.deploy.demo import Goal
from balltrack.deploy.supervisor import describe_exit


def specs_for(*arguments):
    return build_specs(build_parser().parse_args(["start", *arguments]))


def test_router_first_and_services_connect_to_it(tmp_path):
    (tmp_path / "follower.toml").write_text("max_size_thresh = 0.3\n")
    specs, info = specs_for("--router", "--listen", "tcp/0.0.0.0:7500", "--services", "locator,follower",
                            "--namespace", "robot1", "--config-dir", str(tmp_path),
                            "--set", "follower.rate_hz=20")
    assert [spec.name for spec in specs] == ["router", "locator", "follower"]
    assert specs[0].port == 7500 and "--listen" in specs[0].argv
    follower = specs[2].argv
    assert follower[follower.index("--connect") + 1] == "tcp/127.0.0.1:7500"
    assert follower[follower.index("--namespace") + 1] == "robot1"
    assert follower[follower.index("--config") + 1] == str(tmp_path / "follower.toml")
    assert follower[follower.index("--set") + 1] == "rate_hz=20"
    assert "--config" not in specs[1].argv  # no locator.toml in the folder
    assert info["connect"] == ["tcp/127.0.0.1:7500"] and info["namespace"] == "robot1"


def test_without_router_services_use_the_given_endpoint_or_the_zenoh_file(tmp_path):
    specs, info = specs_for("--services", "detector", "--connect", "tcp/10.0.0.2:7447")
    assert [spec.name for spec in specs] == ["detector"]
    assert specs[0].argv[specs[0].argv.index("--connect") + 1] == "tcp/10.0.0.2:7447"
    config = tmp_path / "client.json5"
    config.write_text("{}")
    specs, info = specs_for("--services", "detector", "--zenoh-config", str(config))
    assert "--connect" not in specs[0].argv and str(config) in specs[0].argv
    assert info["connect"] == []


@pytest.mark.parametrize("arguments, message", [
    (["--services", "detector,camera"], "unknown camera"),
    (["--set", "rate_hz=3"], "SERVICE.KEY=VALUE"),
    (["--services", "detector", "--set", "follower.rate_hz=3"], "not among --services"),
    (["--listen", "tcp/0.0.0.0:7447"], "need --router"),
    (["--router", "--listen", "tcp/127.0.0.1:0"], "give a port"),
])
def test_bad_options_are_refused(arguments, message):
    with pytest.raises(LaunchError, match=message):
        specs_for(*arguments)


def test_endpoints():
    assert endpoint_port("tcp/0.0.0.0:7447") == 7447
    assert endpoint_port("tcp/[::]:7448") == 7448
    assert endpoint_port("tcp/host") is None
    assert local_endpoint("tcp/0.0.0.0:7447") == "tcp/127.0.0.1:7447"
    assert local_endpoint("tcp/[::]:7447") == "tcp/127.0.0.1:7447"
    assert local_endpoint("tcp/192.168.1.10:7447") == "tcp/192.168.1.10:7447"
    assert describe_exit(-9) == "killed by SIGKILL" and describe_exit(2) == "exit 2"


def truth(x, y, yaw, ball=(1.0, 0.0)):
    return {"robot": {"x": x, "y": y, "yaw": yaw},
            "balls": [{"id": "tennis", "radius": 0.033, "position": [*ball, 0.033],
                       "in_camera": [0, 0, 1], "visible": True}]}


def test_goal_needs_distance_heading_and_hold():
    goal = Goal(distance=0.35, heading_degrees=10, hold=1.0)
    assert Goal.errors(truth(0.0, 0.0, 0.0)) == pytest.approx((1.0, 0.0))
    assert not goal.update(0.0, truth(0.7, 0.0, 0.0))            # too far
    assert not goal.update(0.5, truth(0.7, 0.0, math.radians(20)))  # facing away
    assert not goal.update(1.0, truth(0.7, 0.0, 0.0))            # close and facing: starts the hold
    assert not goal.update(1.5, truth(0.7, 0.0, math.radians(5)))
    assert goal.update(2.0, truth(0.72, 0.0, 0.0))
    assert goal.reached_at == 1.0
    interrupted = Goal(distance=0.35, heading_degrees=10, hold=1.0)
    interrupted.update(0.0, truth(0.7, 0.0, 0.0))
    interrupted.update(0.5, truth(0.0, 0.0, 0.0))  # drove away: the hold restarts
    assert not interrupted.update(1.2, truth(0.7, 0.0, 0.0))
