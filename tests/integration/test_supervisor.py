"""The supervisor's restart policy with tiny stand-in children (no Zenoh, a few seconds)."""

import json
import sys
import threading

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
