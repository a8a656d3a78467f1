"""Pure parts of deploy: command lines from options, endpoints (the referee: test_referee.py)."""

import pytest

from balltrack.deploy.cli import LaunchError, build_parser, build_specs, endpoint_port, local_endpoint
from balltrack.deploy.supervisor import describe_exit, robot_tokens


def specs_for(*arguments):
    return build_specs(build_parser().parse_args(["start", *arguments]))


def test_a_router_config_files_own_endpoints_stand(tmp_path):
    private = tmp_path / "private.json5"
    private.write_text('{mode: "router", listen: {endpoints: ["tcp/127.0.0.1:7501"]}}')
    specs, info = specs_for("--router", "--router-config", str(private), "--services", "locator")
    router = specs[0].argv
    assert router[router.index("--listen") + 1] == "tcp/127.0.0.1:7501" and specs[0].port == 7501
    assert info["connect"] == ["tcp/127.0.0.1:7501"]
    # (a file without listen endpoints: the default's, and --listen still wins over the file)
    bare = tmp_path / "bare.json5"
    bare.write_text('{mode: "router"}')
    assert specs_for("--router", "--router-config", str(bare), "--services", "locator")[0][0].port == 7447
    assert specs_for("--router", "--router-config", str(private), "--listen", "tcp/127.0.0.1:7502",
                     "--services", "locator")[0][0].port == 7502


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


def test_services_joined_in_one_process_get_their_files_and_settings_by_name(tmp_path):
    (tmp_path / "locator.toml").write_text("ball_radius = 0.04\n")
    specs, info = specs_for("--router", "--listen", "tcp/0.0.0.0:7500", "--config-dir", str(tmp_path),
                            "--services", "detector+locator,simulator", "--set", "detector.v_min=30",
                            "--set", "locator.mode=exact", "--set", "simulator.seed=3")
    assert [spec.name for spec in specs] == ["router", "detector+locator", "simulator"]
    joined = specs[1].argv
    assert joined[1:5] == ["-m", "balltrack", "run", "detector+locator"] and "--peer" in joined
    assert joined[joined.index("--config") + 1] == f"locator={tmp_path / 'locator.toml'}"
    assert [joined[index + 1] for index, item in enumerate(joined) if item == "--set"] == \
        ["detector.v_min=30", "locator.mode=exact"]
    simulator = specs[2].argv
    assert "seed=3" in simulator  # (alone: as before)
    # Liveliness and status go by service, whichever process runs it.
    assert info["services"] == ["detector", "locator", "simulator"]
    assert [spec.wait_alive for spec in specs] == [False, True, False]


def test_the_simulator_keeps_its_clock_in_the_run_folder_for_its_restarts(tmp_path):
    run_dir = tmp_path / "run"
    specs, _ = specs_for("--router", "--listen", "tcp/0.0.0.0:7500", "--run-dir", str(run_dir),
                         "--services", "detector+simulator,locator", "--set", "simulator.seed=3")
    clock = str(run_dir / "simulator.clock")
    joined = specs[1].argv
    settings = [joined[index + 1] for index, item in enumerate(joined) if item == "--set"]
    # (first: a clock_file of the caller's own comes after it and wins)
    assert settings == [f"simulator.clock_file={clock}", "simulator.seed=3"]
    assert specs[1].state_files == [clock] and specs[2].state_files == []


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
    (["--services", "detector,nosuch"], "unknown nosuch"),
    (["--services", " , "], "names no service"),
    (["--set", "rate_hz=3"], "SERVICE.KEY=VALUE"),
    (["--services", "detector", "--set", "follower.rate_hz=3"], "not among --services"),
    (["--listen", "tcp/0.0.0.0:7447"], "need --router"),
    (["--router", "--listen", "tcp/127.0.0.1:0"], "give a port"),
    (["--services", "detector+nosuch"], "unknown nosuch"),
    (["--services", "detector+locator,locator"], "a service may run once"),
    (["--services", "detector+locator", "--set", "follower.rate_hz=3"], "not among --services"),
    (["--secure", "secure", "--services", "detector+locator"], "each runs in a process of its own"),
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



def test_with_our_router_each_service_is_alive_before_the_next_starts():
    specs, _ = specs_for("--router", "--listen", "tcp/0.0.0.0:7500")
    assert [spec.name for spec in specs] == ["router", "detector", "locator", "follower", "simulator"]
    assert [spec.wait_alive for spec in specs] == [False, True, True, True, False]
    specs, _ = specs_for("--services", "detector,locator", "--connect", "tcp/10.0.0.2:7447")
    assert not any(spec.wait_alive for spec in specs)  # a remote router may not be up yet


@pytest.mark.parametrize("arguments, reason", [(["--time-limit", "nan"], "--time-limit: must be a finite number"),
                                               (["--time-limit", "-1"], "--time-limit: must be greater than 0"),
                                               (["--hold", "-5"], "--hold: must be at least 0")])
def test_demo_refuses_bad_numbers_before_starting_anything(arguments, reason, capsys):
    from balltrack.deploy.demo import main

    with pytest.raises(SystemExit) as exit_info:
        main(arguments)
    assert exit_info.value.code == 2
    assert reason in capsys.readouterr().err.strip().splitlines()[-1]


@pytest.mark.parametrize("arguments, reason", [
    (["--port", "99999"], "--port: must be at most 65535"),
    (["--config-dir", "MISSING"], "--config-dir: MISSING is not a directory"),
    (["--secure", "MISSING"], "--secure: MISSING holds routers for no host"),
    (["--set", "detector:v_min=3"], "expected SERVICE.KEY=VALUE"),
    (["--run-dir", "FILE/run"], "--run-dir: cannot make FILE/run"),
])
def test_demo_refuses_bad_arguments_before_making_a_run_folder(tmp_path, monkeypatch, capsys, arguments, reason):
    from balltrack.deploy.demo import main

    monkeypatch.chdir(tmp_path)  # (where a default run folder would be made)
    (tmp_path / "FILE").write_text("a file, not a folder")
    replaced = {"MISSING": str(tmp_path / "missing"), "FILE/run": str(tmp_path / "FILE" / "run")}
    try:
        status = main([replaced.get(argument, argument) for argument in arguments])
    except SystemExit as exit_info:  # (argparse's own refusals)
        status = exit_info.code
    assert status == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert reason in error.replace(str(tmp_path / "missing"), "MISSING").replace(str(tmp_path / "FILE"), "FILE"), error
    assert not (tmp_path / "runs").exists()


def test_deploy_start_wait_0_still_means_do_not_wait():
    from balltrack.deploy.cli import build_parser

    assert build_parser().parse_args(["start", "--wait", "0"]).wait == 0


def test_services_of_our_own_router_join_it_as_peers(tmp_path):
    specs, _ = specs_for("--router", "--listen", "tcp/0.0.0.0:7500", "--services", "detector,locator")
    assert all("--peer" in spec.argv for spec in specs[1:]) and "--peer" not in specs[0].argv
    # A router elsewhere, a given router or a Zenoh file: the services stay its clients.
    config = tmp_path / "client.json5"
    config.write_text("{}")
    for arguments in (["--services", "detector", "--connect", "tcp/10.0.0.2:7447"],
                      ["--router", "--services", "detector", "--connect", "tcp/10.0.0.2:7447"],
                      ["--router", "--services", "detector", "--zenoh-config", str(config)]):
        specs, _ = specs_for(*arguments)
        assert not any("--peer" in spec.argv for spec in specs), arguments


def test_a_peer_session_listens_on_loopback_only_and_needs_its_router():
    import json

    from balltrack.common.session import PEER_LISTEN, client_config

    config = client_config(["tcp/127.0.0.1:7500"], open_timeout=3, peer=True)
    assert json.loads(config.get_json("mode")) == "peer"
    assert json.loads(config.get_json("listen/endpoints")) == [PEER_LISTEN] == ["tcp/127.0.0.1:0"]
    assert json.loads(config.get_json("connect/exit_on_failure")) is True
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(client_config(["tcp/127.0.0.1:7500"]).get_json("mode")) == "client"
    with pytest.raises(ValueError, match="no Zenoh config file"):
        client_config(None, "client.json5", peer=True)


def test_a_secure_router_started_here_is_dialled_as_its_profile_names_it(tmp_path):
    from balltrack.deploy.secure import init_profile

    # (a profile whose certificate lacks 127.0.0.1: its clients' own endpoint is the one to dial)
    init_profile(tmp_path / "profile", ["127.0.0.2"], port=7603, local=False)
    specs, info = specs_for("--router", "--secure", str(tmp_path / "profile"), "--services", "locator")
    assert info["connect"] == [] and "--connect" not in specs[1].argv
    # (a --listen of its own: this host's address for it, as without a profile)
    specs, info = specs_for("--router", "--secure", str(tmp_path / "profile"), "--listen", "tls/0.0.0.0:7604",
                            "--services", "locator")
    assert info["connect"] == ["tls/127.0.0.1:7604"]


def test_a_robots_services_start_with_the_robots_credentials_copied_to_it(tmp_path):
    import shutil

    from balltrack.deploy.secure import init_profile

    init_profile(tmp_path / "fleet", ["robot1"], robots=["robot1", "robot2"])
    # On robot1: its router's folder and its own roles' (deploy start watches as robot1's viewer).
    on_robot = tmp_path / "on-robot"
    for folder in ("robot1", "robots/robot1"):
        shutil.copytree(tmp_path / "fleet" / folder, on_robot / folder)
    specs, info = specs_for("--router", "--secure", str(on_robot), "--namespace", "robot1",
                            "--services", "simulator,follower")
    assert [spec.name for spec in specs] == ["router", "simulator", "follower"]
    assert info["zenoh_config"] == str((on_robot / "robots" / "robot1" / "viewer" / "client.json5").resolve())
    with pytest.raises(LaunchError, match="no .*robots/robot2/simulator/client.json5 nor"):
        specs_for("--router", "--secure", str(on_robot), "--namespace", "robot2", "--services", "simulator")


def test_namespaces_go_to_the_processes_that_serve_several_robots():
    specs, info = specs_for("--router", "--listen", "tcp/127.0.0.1:7500", "--services",
                            "detector+locator+follower,simulator", "--namespaces", "robot1,robot2",
                            "--set", "simulator.robots=2")
    joined, simulator = specs[1].argv, specs[2].argv
    assert joined[joined.index("--namespaces") + 1] == "robot1,robot2" and "--namespace" not in joined
    # (the simulator holds the robots itself, each under its own namespace)
    assert "--namespaces" not in simulator and "--namespace" not in simulator
    assert info["namespaces"] == ["robot1", "robot2"] and info["namespace"] == ""
    assert specs_for("--services", "locator")[1]["namespaces"] == []


def test_each_robot_of_a_process_serving_several_must_be_alive():
    info = {"namespace": "", "namespaces": ["robot1", "robot2"]}
    assert robot_tokens(info, ["detector", "locator"]) == {("robot1", "detector"), ("robot2", "detector"),
                                                           ("robot1", "locator"), ("robot2", "locator")}
    assert robot_tokens(info, ["simulator"]) == {("", "simulator")}
    assert robot_tokens({"namespace": "robot3"}, ["follower"]) == {("robot3", "follower")}


@pytest.mark.parametrize("arguments, reason", [
    (["--namespaces", "auto"], "--namespaces auto: not under the supervisor"),
    (["--namespaces", "robot1,robot1"], "'robot1' is listed twice"),
    (["--namespaces", "robot1", "--namespace", "fleet"], "not with --namespace"),
    (["--namespaces", "robot1", "--secure", "no-profile", "--services", "locator"], "no-profile is no profile of robot robot1"),
    (["--namespaces", "robot1", "--services", "detector,camera"], "camera serves one robot per process"),
    (["--namespaces", "robot1", "--services", "detector+simulator"], "detector+simulator serves one robot"),
])
def test_namespaces_that_cannot_be_served_are_refused(arguments, reason):
    with pytest.raises(LaunchError, match=reason.replace("+", r"\+")):
        specs_for(*arguments)
