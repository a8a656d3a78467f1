"""The supervisor and launcher (``balltrack deploy``) and the subscriber example, as users run them.

Real processes on a free port in a temporary run folder; every wait is on a condition (a file's
content, a liveliness token, a line of output) with a deadline.
"""

import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from balltrack.common.messages import encode, header
from balltrack.deploy.supervisor import pid_alive
from tests.harness import (REPO, Collector, Liveliness, Process, client, free_port, process_environment,
                           wait_until)

SERVICES = ["detector", "locator", "follower"]


def deploy(*arguments: str, timeout: float = 90.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "balltrack.deploy", *arguments], cwd=REPO, env=process_environment(),
                          capture_output=True, text=True, timeout=timeout)


def status_of(run_dir: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "balltrack", "status", "--run-dir", str(run_dir), "--json"],
                          cwd=REPO, env=process_environment(), capture_output=True, text=True, timeout=60)


def read_status(run_dir: Path) -> dict:
    try:
        return json.loads((run_dir / "status.json").read_text())
    except (OSError, ValueError):
        return {}


@pytest.fixture
def started(tmp_path):
    """Router + detector + locator + follower under a background supervisor; stopped at the end."""
    run_dir = tmp_path / "run"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    result = deploy("start", "--router", "--listen", endpoint, "--services", ",".join(SERVICES),
                    "--run-dir", str(run_dir), "--set", "follower.rate_hz=5", "--wait", "60")
    assert result.returncode == 0, result.stdout + result.stderr
    yield run_dir, endpoint
    supervisor = read_status(run_dir).get("supervisor", {}).get("pid")
    if supervisor and pid_alive(supervisor):  # the test failed before its own stop
        deploy("stop", "--run-dir", str(run_dir))


def test_supervisor_restarts_a_killed_service_and_stops_cleanly(started):
    run_dir, endpoint = started
    result = status_of(run_dir)
    assert result.returncode == 0, result.stdout + result.stderr
    status = json.loads(result.stdout)
    assert status["supervisor"]["running"]
    assert status["children"]["router"]["running"]
    for name in SERVICES:
        child = status["children"][name]
        assert child["running"] and child["alive"] and child["restarts"] == 0, (name, child)
    # The --set reached the follower: its parameter file is the command line.
    assert "rate_hz=5" in " ".join(status["children"]["follower"]["argv"])

    session = client(endpoint)
    try:
        liveliness = Liveliness(session)
        liveliness.wait("locator", alive=True, timeout=10)
        old_pid = int((run_dir / "locator.pid").read_text())
        os.kill(old_pid, signal.SIGKILL)
        liveliness.wait("locator", alive=False, timeout=15)
        child = wait_until(lambda: (lambda c: c if c.get("restarts") == 1 and c.get("state") == "running"
                                  and c.get("pid") not in (None, old_pid) else None)(
            read_status(run_dir).get("children", {}).get("locator", {})), 30, "the locator's restart")
        assert child["last_exit"] == -signal.SIGKILL
        liveliness.wait("locator", alive=True, timeout=30)
    finally:
        session.close()
    assert "locator killed by SIGKILL" in (run_dir / "supervisor.log").read_text()

    status = json.loads(status_of(run_dir).stdout)
    assert status["children"]["locator"]["alive"] and status["children"]["locator"]["restarts"] == 1
    pids = [child["pid"] for child in status["children"].values()] + [status["supervisor"]["pid"]]

    result = deploy("stop", "--run-dir", str(run_dir))
    assert result.returncode == 0, result.stdout + result.stderr
    final = read_status(run_dir)
    assert final["supervisor"]["state"] == "stopped" and final["supervisor"]["exit_code"] == 0
    for name, child in final["children"].items():
        assert child["state"] == "stopped" and child["last_exit"] == 0, (name, child)
    assert not list(run_dir.glob("*.pid"))
    assert not [pid for pid in pids if pid_alive(pid)]
    # The locator's log holds both runs.
    assert (run_dir / "locator.log").read_text().count("=== ") == 2


def test_a_simulator_restarted_by_the_supervisor_goes_on_with_its_clock(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    # Left by an earlier deployment in the same folder: a new deployment starts at 0 all the same.
    (run_dir / "simulator.clock").write_text('{"stamp": 500000000000, "seq": 15000}')
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    result = deploy("start", "--router", "--listen", endpoint, "--services", "simulator", "--run-dir", str(run_dir),
                    "--set", "simulator.publish_images=false", "--set", "simulator.width=160",
                    "--set", "simulator.height=120", "--wait", "60")
    assert result.returncode == 0, result.stdout + result.stderr
    session = client(endpoint)
    try:
        truths = Collector(session, "sim/ground_truth", "GroundTruth")
        liveliness = Liveliness(session)
        first = truths.wait_for(lambda messages: messages[:5] if len(messages) >= 5 else None, 30, "frames")[0]
        assert first["header"]["stamp"] < 100 * 10**9 and first["header"]["seq"] < 3000, first["header"]
        old_pid = int((run_dir / "simulator.pid").read_text())
        os.kill(old_pid, signal.SIGKILL)
        liveliness.wait("simulator", alive=False, timeout=15)
        before = len(truths.messages)
        liveliness.wait("simulator", alive=True, timeout=60)
        truths.wait_for(lambda messages: len(messages) >= before + 5, 30, "frames of the restarted simulator")
    finally:
        session.close()
        stopped = deploy("stop", "--run-dir", str(run_dir))
    assert stopped.returncode == 0, stopped.stdout + stopped.stderr
    assert read_status(run_dir)["children"]["simulator"]["restarts"] == 1
    # Across the restart, stamps and sequence numbers only go forward.
    stamps = [truth["header"]["stamp"] for truth in truths.messages]
    seqs = [truth["header"]["seq"] for truth in truths.messages]
    assert all(a < b for a, b in zip(stamps, stamps[1:])), (before, stamps[before - 3:before + 3])
    assert all(a < b for a, b in zip(seqs, seqs[1:])), (before, seqs[before - 3:before + 3])


def test_start_rejects_bad_options_and_a_bad_config(tmp_path):
    result = deploy("start", "--services", "detector,nosuch", "--run-dir", str(tmp_path / "a"))
    assert result.returncode == 2 and "unknown nosuch" in result.stderr
    result = deploy("start", "--set", "max_size_thresh=0.3", "--run-dir", str(tmp_path / "b"))
    assert result.returncode == 2 and "SERVICE.KEY=VALUE" in result.stderr
    # A parameter the follower refuses: exit 2 is not restarted; start reports it and stops.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    run_dir = tmp_path / "c"
    result = deploy("start", "--router", "--listen", endpoint, "--services", "follower",
                    "--set", "follower.filter_value=1.5", "--run-dir", str(run_dir), "--wait", "30")
    assert result.returncode == 1, result.stdout + result.stderr
    assert "failed: follower" in result.stderr and "filter_value" in result.stderr
    status = read_status(run_dir)
    assert status["children"]["follower"]["state"] == "failed"
    assert status["children"]["follower"]["restarts"] == 0
    assert status["supervisor"]["state"] == "stopped"
    assert not list(run_dir.glob("*.pid"))


def test_status_of_a_run_folder_shows_each_service_of_a_joined_process(tmp_path):
    run_dir = tmp_path / "run"
    started = deploy("start", "--router", "--listen", f"tcp/127.0.0.1:{free_port()}", "--services",
                     "locator+follower", "--run-dir", str(run_dir), "--wait", "60")
    assert started.returncode == 0, started.stdout + started.stderr
    try:
        shown = status_of(run_dir)
        assert shown.returncode == 0, shown.stdout + shown.stderr
        joined = json.loads(shown.stdout)["children"]["locator+follower"]
        # (it showed '-', as if not a service: only single services were looked up)
        assert joined["alive"] is True
        assert {name: entry["alive"] for name, entry in joined["services"].items()} == {"locator": True, "follower": True}
        text = subprocess.run([sys.executable, "-m", "balltrack", "status", "--run-dir", str(run_dir)], cwd=REPO,
                              env=process_environment(), capture_output=True, text=True, timeout=60).stdout
        rows = {line.split()[0]: line.split() for line in text.splitlines()[2:]}
        assert rows["locator+follower"][5] == "yes" and rows["locator"][1] == "yes" and rows["follower"][1] == "yes"
    finally:
        assert deploy("stop", "--run-dir", str(run_dir)).returncode == 0


def test_one_process_serves_each_robot_of_a_simulated_fleet(tmp_path):
    run_dir = tmp_path / "run"
    robots = ["robot1", "robot2"]
    started = deploy("start", "--router", "--listen", f"tcp/127.0.0.1:{free_port()}", "--services",
                     "detector+locator+follower,simulator", "--namespaces", ",".join(robots),
                     "--set", "simulator.robots=2", "--set", "simulator.scenario=fleet",
                     "--set", "simulator.width=160", "--set", "simulator.height=120",
                     "--run-dir", str(run_dir), "--wait", "60")
    assert started.returncode == 0, started.stdout + started.stderr
    try:
        def each_robot_served() -> dict | None:
            shown = status_of(run_dir)
            assert shown.returncode == 0, shown.stdout + shown.stderr
            children = json.loads(shown.stdout)["children"]
            detectors = [children["detector+locator+follower"]["services"][f"{robot}/detector"] for robot in robots]
            return children if all((entry["stats"] or {}).get("received", 0) > 0 for entry in detectors) else None

        children = wait_until(each_robot_served, 90, "each robot's detector receiving its frames")
        joined = children["detector+locator+follower"]
        assert joined["alive"] is True and children["simulator"]["alive"] is True
        assert {name: entry["alive"] for name, entry in joined["services"].items()} == {
            f"{robot}/{service}": True for robot in robots for service in SERVICES}
    finally:
        assert deploy("stop", "--run-dir", str(run_dir)).returncode == 0


def test_start_refuses_a_router_port_that_another_router_holds(router, tmp_path):
    # (the services would join that router, ours failing to listen and restarted for ever)
    listen = f"tcp/127.0.0.1:{router.port}"
    result = deploy("start", "--router", "--listen", listen, "--services", "locator",
                    "--run-dir", str(tmp_path / "run"))
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stderr.strip() == (f"deploy start: --listen {listen}: port {router.port} is in use "
                                     "(another router? stop it, or give --listen another port)")
    assert not (tmp_path / "run" / "supervisor.pid").exists()


def test_example_subscriber_prints_ball_positions(router, session, tmp_path):
    example = Process([sys.executable, str(REPO / "examples" / "subscribe_ball3d.py"), "--connect",
                       router.endpoint, "--count", "2", "--validate"], tmp_path / "example.log")
    try:
        example.wait_for_output("listening on detected_ball_3d", 20)
        publisher = session.declare_publisher("detected_ball_3d")
        ball = {"header": {**header(123, 7), "frame_id": "camera_optical"},
                "x": 0.1, "y": 0.05, "z": 1.5, "distance": 1.504}
        deadline = time.monotonic() + 20
        # Publish until the example has printed twice (its subscription reaches the router
        # asynchronously, so the first samples may go nowhere).
        while example.popen.poll() is None and time.monotonic() < deadline:
            publisher.put(encode("Ball3D", ball))
            try:
                example.popen.wait(0.1)
            except subprocess.TimeoutExpired:
                pass
        assert example.popen.wait(5) == 0, example.output()
        assert "seq      7  x +0.100  y +0.050  z 1.500  distance 1.504 m" in example.output()
        publisher.undeclare()
    finally:
        example.kill()


def test_example_subscriber_in_a_pipe_ends_quietly_when_the_reader_goes(router, session, tmp_path):
    # `subscribe_ball3d.py | head -2`: the example prints from Zenoh's thread, where a closed
    # pipe must still end the program (not leave it listening for ever).
    example = subprocess.Popen([sys.executable, str(REPO / "examples" / "subscribe_ball3d.py"), "--connect",
                                router.endpoint], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               env=process_environment())
    try:
        # (on stderr: stdout holds only the positions)
        assert example.stderr.readline().startswith(b"listening on detected_ball_3d")
        publisher = session.declare_publisher("detected_ball_3d")
        ball = {"header": {**header(123, 7), "frame_id": "camera_optical"},
                "x": 0.1, "y": 0.05, "z": 1.5, "distance": 1.504}
        line = b""
        deadline = time.monotonic() + 20
        # (its subscription reaches the router asynchronously: publish until it prints)
        while not line:
            assert time.monotonic() < deadline, "the example printed no ball"
            publisher.put(encode("Ball3D", ball))
            ready, _, _ = select.select([example.stdout], [], [], 0.1)
            if ready:
                line = example.stdout.readline()
        assert line.startswith(b"seq      7")
        example.stdout.close()
        deadline = time.monotonic() + 20
        while example.poll() is None:
            assert time.monotonic() < deadline, "the example went on after its reader left"
            publisher.put(encode("Ball3D", ball))
            try:
                example.wait(0.1)
            except subprocess.TimeoutExpired:
                pass
        assert example.returncode == 0
        assert example.stderr.read() == b""
        publisher.undeclare()
    finally:
        example.kill()
        example.wait(5)
