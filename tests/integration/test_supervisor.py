"""The supervisor's restart policy with tiny stand-in children (no Zenoh, a few seconds)."""

import errno
import json
import os
import signal
import subprocess
import sys
import threading

import pytest

from balltrack.deploy.supervisor import ChildSpec, Supervisor, SupervisorSettings
from tests.harness import wait_until

FAST = SupervisorSettings(backoff_initial=0.05, backoff_max=0.2, stable_after=5.0, give_up_after=3,
                          stop_timeout=2.0)


def child(name: str, code: str) -> ChildSpec:
    return ChildSpec(name, [sys.executable, "-c", code])


def run_in_thread(supervisor: Supervisor) -> tuple[threading.Thread, dict]:
    result = {}
    thread = threading.Thread(target=lambda: result.update(code=supervisor.run()), daemon=True)
    thread.start()
    return thread, result


def wait_ready(run_dir, name: str) -> None:
    """Until the child ``name`` has printed 'ready' (a line of its own: the log's header line
    holds the command, 'ready' included)."""
    log = run_dir / f"{name}.log"
    wait_until(lambda: "ready" in log.read_text().splitlines() if log.exists() else False, 20,
               f"{name} to start")


def status(run_dir) -> dict:
    try:
        return json.loads((run_dir / "status.json").read_text())
    except (OSError, ValueError):
        return {}


def test_exit_0_is_left_alone_crashes_are_retried_then_given_up(tmp_path):
    supervisor = Supervisor(tmp_path, [
        child("done", "pass"),                              # exits 0: asked to stop
        child("crashing", "import sys; sys.exit(3)"),       # crashes at once, every time
        child("misconfigured", "import sys; sys.exit(2)"),  # a usage error: never retried
    ], FAST)
    thread, result = run_in_thread(supervisor)
    thread.join(20)
    assert not thread.is_alive(), "the supervisor should end once no child is left"
    assert result["code"] == 1  # some children failed
    children = status(tmp_path)["children"]
    assert children["done"]["state"] == "exited" and children["done"]["restarts"] == 0
    assert children["misconfigured"]["state"] == "failed" and children["misconfigured"]["restarts"] == 0
    assert children["crashing"]["state"] == "failed" and children["crashing"]["restarts"] == FAST.give_up_after
    assert (tmp_path / "crashing.log").read_text().count("=== ") == FAST.give_up_after + 1
    log_text = (tmp_path / "crashing.log").read_text()
    assert "start #1" in log_text and f"start #{FAST.give_up_after + 1}" in log_text
    assert not list(tmp_path.glob("*.pid"))


def test_a_childs_state_files_are_removed_before_its_first_start_and_kept_for_its_restarts(tmp_path):
    state = tmp_path / "keeper.state"
    state.write_text("left by an earlier supervisor")
    # Says whether it found its state, leaves it, and crashes: restarted until given up.
    code = (f"import pathlib; state = pathlib.Path({str(state)!r}); "
            "print('found' if state.exists() else 'absent', flush=True); state.write_text('kept'); "
            "raise SystemExit(3)")
    spec = ChildSpec("keeper", [sys.executable, "-c", code], state_files=[str(state)])
    thread, _ = run_in_thread(Supervisor(tmp_path, [spec], FAST))
    thread.join(20)
    assert not thread.is_alive()
    found = [line for line in (tmp_path / "keeper.log").read_text().splitlines() if line in ("found", "absent")]
    assert found == ["absent"] + ["found"] * FAST.give_up_after


def test_stop_terminates_and_kills_what_ignores_sigterm(tmp_path):
    stubborn = ("import signal, sys, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
                "print('ready', flush=True); time.sleep(60)")
    polite = "import time; print('ready', flush=True); time.sleep(60)"
    supervisor = Supervisor(tmp_path, [child("polite", polite), child("stubborn", stubborn)], FAST)
    thread, result = run_in_thread(supervisor)
    for name in ("polite", "stubborn"):
        wait_ready(tmp_path, name)
    assert (tmp_path / "stubborn.pid").exists() and (tmp_path / "supervisor.pid").exists()
    supervisor.stop.set()
    thread.join(20)
    assert not thread.is_alive()
    assert result["code"] == 1  # the stubborn child needed SIGKILL
    children = status(tmp_path)["children"]
    assert children["polite"]["last_exit"] == -15 and children["stubborn"]["last_exit"] == -9
    assert all(item["state"] == "stopped" for item in children.values())
    assert status(tmp_path)["supervisor"]["state"] == "stopped"
    assert not list(tmp_path.glob("*.pid"))


def test_a_child_that_the_stop_kills_before_it_handles_sigterm_has_stopped_cleanly(tmp_path):
    # (a service SIGTERMed while still importing: the default action, status -15; the supervisor
    # exited 1 for a stop that went as asked)
    supervisor = Supervisor(tmp_path, [child("starting", "import time; print('ready', flush=True); time.sleep(60)")], FAST)
    thread, result = run_in_thread(supervisor)
    wait_ready(tmp_path, "starting")
    supervisor.stop.set()
    thread.join(20)
    assert not thread.is_alive()
    assert result["code"] == 0
    assert status(tmp_path)["children"]["starting"]["last_exit"] == -15


def mounted_small_disk(path) -> bool:
    """A 256 KiB tmpfs at ``path`` (a disk that fills up for real); False where mounting is not allowed."""
    path.mkdir()
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(path)],
                            capture_output=True, text=True)
    return result.returncode == 0


def test_a_full_log_disk_costs_the_logs_not_the_children(tmp_path):
    run_dir = tmp_path / "run"
    if not mounted_small_disk(run_dir):
        pytest.skip("mounting a small tmpfs needs root (the full-disk case needs a disk that fills up)")
    try:
        supervisor = Supervisor(run_dir, [child("worker", "import time; print('ready', flush=True); time.sleep(120)")],
                                FAST)
        thread, result = run_in_thread(supervisor)
        wait_ready(run_dir, "worker")
        first = supervisor.children[0].popen.pid
        # (fill the disk to the last byte)
        with open(run_dir / "filler", "wb", buffering=0) as filler:
            try:
                while True:
                    filler.write(b"\0" * 4096)
            except OSError as error:
                assert error.errno == errno.ENOSPC
        os.kill(first, signal.SIGKILL)
        restarted = wait_until(lambda: supervisor.children[0].restarts == 1 and supervisor.children[0].pid, 20,
                               "the worker restarted with the disk full")
        assert restarted != first and thread.is_alive()
        (run_dir / "filler").unlink()
        wait_until(lambda: status(run_dir).get("children", {}).get("worker", {}).get("restarts") == 1, 20,
                   "status.json written again once there is room")
        supervisor.stop.set()
        thread.join(20)
        assert result["code"] == 0
    finally:
        subprocess.run(["umount", "-l", str(run_dir)], capture_output=True)


def test_status_of_a_run_folder_exits_3_while_a_child_is_given_up(tmp_path):
    supervisor = Supervisor(tmp_path, [child("worker", "import time; print('ready', flush=True); time.sleep(120)"),
                                       child("crashing", "import sys; sys.exit(3)")], FAST)
    thread, _ = run_in_thread(supervisor)
    try:
        wait_ready(tmp_path, "worker")
        wait_until(lambda: status(tmp_path).get("children", {}).get("crashing", {}).get("state") == "failed", 20,
                   "the crashing child given up")
        result = subprocess.run([sys.executable, "-m", "balltrack", "status", "--run-dir", str(tmp_path),
                                 "--no-network"], capture_output=True, text=True, timeout=60)
        assert result.returncode == 3, result.stdout + result.stderr
        assert "crashing" in result.stdout and "failed" in result.stdout
    finally:
        supervisor.stop.set()
        thread.join(20)
