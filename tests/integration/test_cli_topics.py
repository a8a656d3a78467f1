"""The ros2-style commands against a real router and a real locator: topic list/info, pub,
bw, delay, config dump/load."""

import json
import subprocess
import sys
import threading
import time

import pytest

from balltrack.common.messages import encode, header
from tests.harness import Collector, process_environment, start_service, wait_until
from tests.integration.test_pipeline import CAMERA_INFO

PUBLISH_HZ = 20.0


def balltrack(*arguments, cwd=None, timeout=60):
    return subprocess.run([sys.executable, "-m", "balltrack", *arguments], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, env=process_environment())


@pytest.fixture
def camera_info_stream(session, request):
    """CameraInfo stamped with the wall clock (or, parametrised, the clock it names: a function
    of no argument, ns), at PUBLISH_HZ, while the test runs."""
    stop = threading.Event()
    clock = getattr(request, "param", time.time_ns)

    def publish():
        seq = 0
        while not stop.is_set():
            session.put("camera/camera_info",
                        encode("CameraInfo", {**CAMERA_INFO, "header": header(clock(), seq)}))
            seq += 1
            stop.wait(1.0 / PUBLISH_HZ)  # the stream's rate, not a synchronisation

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    yield
    stop.set()
    thread.join(5)


@pytest.fixture
def locator(launch):
    return launch("locator")


def test_topic_list_shows_types_publishers_subscribers_and_rates(router, locator, camera_info_stream):
    listed = balltrack("topic", "list", "--connect", router.endpoint, "--window", "1.5")
    assert listed.returncode == 0, listed.stderr
    rows = {line.split()[0]: line.split() for line in listed.stdout.splitlines()[1:]}
    key, message, rate, publishers, subscribers = rows["camera/camera_info"]
    assert message == "CameraInfo" and 5 < float(rate) < 60 and "locator" in subscribers.split(",")
    assert rows["detected_ball_3d"][1] == "Ball3D" and rows["detected_ball_3d"][3] == "locator"
    assert rows["locator/stats"][1] == "Stats" and rows["locator/stats"][3] == "locator"
    # (no detector: a key with a subscriber only is listed, as ros2 topic list does)
    assert rows["detected_ball"][1:] == ["Ball2D", "0.00", "-", "locator"]


def test_topic_info_describes_one_key(router, locator, camera_info_stream):
    shown = balltrack("topic", "info", "camera/camera_info", "--connect", router.endpoint,
                      "--window", "1.5")
    assert shown.returncode == 0, shown.stderr
    info = json.loads(shown.stdout)
    assert info["type"] == "CameraInfo" and "locator" in info["subscribers"]
    assert info["messages_seen"] > 5 and info["mean_bytes"] > 50


def test_topic_info_of_a_key_no_one_uses_is_an_error_and_of_a_users_own_key_is_not(router, session):
    unknown = balltrack("topic", "info", "myapp/status", "--connect", router.endpoint, "--window", "0.5")
    assert unknown.returncode == 1 and unknown.stdout == ""
    assert unknown.stderr.strip() == ("balltrack topic info: myapp/status: not a key of balltrack's table "
                                      "(balltrack topic list), and no publisher, subscriber or message of it seen in 0.5 s")
    subscriber = session.declare_subscriber("myapp/status", lambda sample: None)
    try:
        shown = balltrack("topic", "info", "myapp/status", "--connect", router.endpoint, "--window", "0.5")
    finally:
        subscriber.undeclare()
    assert shown.returncode == 0, shown.stderr
    assert json.loads(shown.stdout)["type"] == "-"


def test_pub_validates_then_publishes_once_or_at_a_rate(router, session):
    received = Collector(session, "cmd_vel", "Twist")
    once = balltrack("pub", "cmd_vel", "{linear: [0.1, 0, 0], angular: [0, 0, 0.5]}",
                     "--connect", router.endpoint)
    assert once.returncode == 0, once.stderr
    (twist,) = received.wait_for(lambda messages: messages[:1], 10, "one cmd_vel")
    assert twist["linear"][0] == 0.1 and twist["angular"][2] == 0.5 and twist["header"]["seq"] == 0

    repeated = balltrack("pub", "cmd_vel", '{"linear": [0, 0, 0], "angular": [0, 0, 0.3]}',
                         "--rate", "50", "--count", "5", "--connect", router.endpoint)
    assert repeated.returncode == 0, repeated.stderr
    burst = received.wait_for(lambda messages: messages[1:] if len(messages) >= 6 else None, 10)
    assert [message["header"]["seq"] for message in burst] == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("arguments, reason", [
    (["cmd_vel", "{linear: [1, 2]}"], "linear"),
    (["cmd_vel", "[1, 2, 3]"], "map"),
    (["cmd_vel", "{linear: [1, 2, 3"], "YAML"),
    (["no/such/key", "{}"], "--type"),
])
def test_pub_rejects_bad_messages_with_one_line(arguments, reason):
    refused = balltrack("pub", *arguments, "--connect", "tcp/127.0.0.1:9", "--timeout", "1")
    assert refused.returncode == 2
    assert reason in refused.stderr and len(refused.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("command, text", [("bw", "kB/s"), ("delay", "delay mean")])
def test_bw_and_delay_report_the_stream(router, session, camera_info_stream, command, text):
    shown = balltrack(command, "camera/camera_info", "--window", "1", "--count", "2",
                      "--connect", router.endpoint)
    assert shown.returncode == 0, shown.stderr
    lines = shown.stdout.splitlines()
    assert len(lines) == 2 and text in lines[-1], shown.stdout
    if command == "delay":
        mean_ms = float(lines[-1].split("delay mean ")[1].split(" ms")[0])
        assert 0 <= mean_ms < 5000  # stamped with the wall clock just before sending
        assert "not wall-clock" not in shown.stdout


# (a simulator's stamps: its time since the start, seconds where the wall clock has 1.7e9)
@pytest.mark.parametrize("camera_info_stream", [lambda: 5_000_000_000], indirect=True)
def test_delay_of_stamps_on_another_clock_says_so(router, session, camera_info_stream):
    shown = balltrack("delay", "camera/camera_info", "--window", "1", "--count", "1",
                      "--connect", router.endpoint)
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.strip().endswith("(the stamps are not wall-clock time: a simulator's? try --use-sim-time)")


def test_config_dump_then_load_restores_parameters(router, locator, tmp_path):
    dumped = balltrack("config", "dump", "locator", "--connect", router.endpoint)
    assert dumped.returncode == 0, dumped.stderr
    saved = tmp_path / "locator.yaml"
    saved.write_text(dumped.stdout.replace("ball_radius: 0.033", "ball_radius: 0.05"))
    assert "ball_radius: 0.05" in saved.read_text()

    loaded = balltrack("config", "load", "locator", str(saved), "--connect", router.endpoint)
    assert loaded.returncode == 0, loaded.stderr
    now = balltrack("config", "locator", "--connect", router.endpoint)
    assert json.loads(now.stdout)["ball_radius"] == 0.05

    (tmp_path / "bad.yaml").write_text("ball_radius: -3\n")
    refused = balltrack("config", "load", "locator", str(tmp_path / "bad.yaml"), "--connect",
                        router.endpoint)
    assert refused.returncode == 2 and "ball_radius" in refused.stderr
    missing = balltrack("config", "load", "locator", str(tmp_path / "none.yaml"))
    assert missing.returncode == 2 and "none.yaml" in missing.stderr
    (tmp_path / "binary.yaml").write_bytes(b"\xff\xfe\x00")
    binary = balltrack("config", "load", "locator", str(tmp_path / "binary.yaml"))
    assert binary.returncode == 2
    assert binary.stderr == f"balltrack config: {tmp_path / 'binary.yaml'}: not YAML (not UTF-8 text)\n"


def test_topic_list_from_the_root_types_and_names_other_namespaces_keys(router, log_dir):
    # (as `ros2 topic list` shows /robot1/cmd_vel: its type, and the follower, not a session id)
    robot = start_service("locator+follower", router.endpoint, log_dir, "--namespace", "robot1")
    try:
        def rows():
            listed = balltrack("topic", "list", "--connect", router.endpoint, "--window", "1.5")
            assert listed.returncode == 0, listed.stderr
            return {line.split()[0]: line.split() for line in listed.stdout.splitlines()[1:]}

        def named(table):  # (its liveliness token may reach the router after its publishers)
            row = table.get("robot1/cmd_vel", [])
            return table if row[1:2] + row[3:4] == ["Twist", "follower"] else None

        found = wait_until(lambda: named(rows()), 60, "robot1/cmd_vel listed as the follower's Twist",
                           robot, every=0.1)
        assert found["robot1/locator/stats"][1] == "Stats" and found["robot1/locator/stats"][3] == "locator"
        info = json.loads(balltrack("topic", "info", "robot1/cmd_vel", "--connect", router.endpoint,
                                    "--window", "0.5").stdout)
        assert (info["type"], info["declared_publisher"], info["publishers"]) == ("Twist", "follower", ["follower"])
    finally:
        assert robot.stop() == 0, robot.output()


def test_topic_list_and_info_name_only_the_sessions_that_declared_a_key(router, launch, log_dir):
    # (the router lists itself beside every declaration it routes: taken for a session, it
    # was named after every service alive, "detector+follower+locator", on every key)
    joined = start_service("detector+follower", router.endpoint, log_dir, "--peer")
    try:
        launch("locator")

        def subscribers():
            listed = balltrack("topic", "list", "--connect", router.endpoint, "--window", "0.5")
            info = balltrack("topic", "info", "camera/image_raw", "--connect", router.endpoint, "--window", "0.5")
            assert listed.returncode == 0 and info.returncode == 0, listed.stderr + info.stderr
            rows = {line.split()[0]: line.split() for line in listed.stdout.splitlines()[1:]}
            found = (rows.get("detected_ball", [""] * 5)[4], json.loads(info.stdout)["subscribers"])
            return found if "locator" in found[0] and found[1] else None

        found = wait_until(subscribers, 60, "the subscribers of detected_ball and camera/image_raw", joined,
                           every=0.1)
        # (which of a joined process's services subscribes is not told: the process is named)
        assert found == ("locator", ["detector+follower"])
    finally:
        assert joined.stop() == 0, joined.output()
