"""The supervisor: keeps a set of child processes running, everything in one run folder.

A run folder holds::

    launch.json        what to run (written by ``balltrack deploy start``): children in order
    supervisor.pid     the supervisor's pid, while it runs
    supervisor.log     what the supervisor did: starts, exits, restarts, stop
    status.json        live state: per child pid, state, restarts, last exit status
    <child>.pid        a child's pid, while it runs
    <child>.log        a child's output (stdout and stderr), appended across restarts

Rules:

* A child's ``state_files`` (the simulator's clock) are removed before its first start and
  kept for its restarts.
* Children start in order. A child with a ``port`` (the router) must accept TCP connections
  before the next one starts, so services find their router at once. A child with
  ``wait_alive`` must declare its liveliness token (at most ``alive_timeout`` s) before the
  next one starts, at its first start only: ``launcher`` starts the simulator after a ready
  pipeline this way.
* A child that exits with status 0 was asked to stop (services and the router exit 0 only on
  SIGINT/SIGTERM): it is not restarted. Status 2 is a usage or configuration error that a
  restart cannot fix: the child is marked ``failed``. Any other exit (a crash, a signal such as
  SIGKILL, status 1 when the router could not be reached) is restarted after a backoff that
  doubles from ``backoff_initial`` to ``backoff_max`` seconds and resets once the child has run
  ``stable_after`` seconds; ``give_up_after`` quick failures in a row mark it ``failed``.
* SIGINT or SIGTERM to the supervisor stops everything: SIGTERM to the services (in reverse
  order), then to the router, each given ``stop_timeout`` seconds before SIGKILL. The
  supervisor exits 0 when every child exited 0 or was killed by that SIGTERM (a child still
  starting has no handler yet), 1 otherwise; pid files are removed.
* A run folder's disk that is full or failing costs logs, pid files and status.json (written
  again once it can be), never a child's start or restart.
* Children run in their own session (a Ctrl-C in a terminal reaches the supervisor only, which
  then stops them in order) and get SIGTERM from the kernel if the supervisor itself dies.
"""

import ctypes
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from balltrack.common.keys import process_services
from balltrack.common.shutdown import set_from_signal

LOG = logging.getLogger("supervisor")

# Child states, as written to status.json.
STARTING, RUNNING, BACKOFF, EXITED, FAILED, STOPPED = (
    "starting", "running", "backoff", "exited", "failed", "stopped")


@dataclass
class ChildSpec:
    """One process to keep running: its name (``router``, ``detector``...) and command line."""

    name: str
    argv: list[str]
    port: int | None = None  # wait for this local TCP port to accept before starting the next
    env: dict[str, str] = field(default_factory=dict)
    # At the first start, wait for this service's liveliness token before starting the next,
    # so that a pipeline is ready for the simulator's first frame (lockstep needs it).
    wait_alive: bool = False
    # Files the child keeps for the next of its restarts (the simulator's clock): removed before
    # its first start, so that a new supervisor's child starts afresh.
    state_files: list[str] = field(default_factory=list)


@dataclass
class SupervisorSettings:
    backoff_initial: float = 0.5
    backoff_max: float = 10.0
    stable_after: float = 10.0
    give_up_after: int = 5
    stop_timeout: float = 15.0
    ready_timeout: float = 20.0
    alive_timeout: float = 60.0


def describe_exit(returncode: int | None) -> str:
    if returncode is None:
        return "running"
    if returncode < 0:
        try:
            return f"killed by {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exit {returncode}"


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # A zombie is not alive; /proc tells (Linux), elsewhere trust kill(0).
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        return state != "Z"
    except (OSError, IndexError):
        return True


def child_environment(extra: dict[str, str] | None = None) -> dict[str, str]:
    environment = dict(os.environ)
    environment.setdefault("MUJOCO_GL", "egl")
    environment["PYTHONUNBUFFERED"] = "1"
    environment.update(extra or {})
    return environment


def die_with_parent() -> None:
    """In the child before exec: SIGTERM when the supervisor dies (Linux prctl)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def open_for(info: dict, timeout: float):
    """A Zenoh session on the router the launched services use (``info`` of launch.json)."""
    from balltrack.common.session import open_session

    return open_session(info.get("connect") or None, info.get("zenoh_config"), open_timeout=timeout)


def serving_namespaces(info: dict, service: str) -> list[str]:
    """Where ``service`` of a run (``info`` of launch.json) is: under each of its robots
    (``namespaces``) when it serves several, else under the run's ``namespace``."""
    from balltrack.common.keys import SERVICES_OF_MANY_ROBOTS, validate_namespace

    robots = info.get("namespaces") or []
    return robots if robots and service in SERVICES_OF_MANY_ROBOTS else [validate_namespace(info.get("namespace", ""))]


def robot_tokens(info: dict, services: list[str]) -> set[tuple[str, str]]:
    """The liveliness tokens ``(namespace, service)`` that ``services`` declare when alive
    (:func:`serving_namespaces`)."""
    return {(namespace, service) for service in services for namespace in serving_namespaces(info, service)}


def wait_alive(info: dict, services: list[str], timeout: float, stop: threading.Event | None = None,
               failed=lambda: False) -> set[str]:
    """Wait until every service in ``services`` has its ``alive/<service>`` token (under each
    robot's namespace, for one serving several: :func:`robot_tokens`), or ``stop`` is set, or
    ``failed()`` is true; the services still missing (``robot1/detector`` for one robot's)."""
    import zenoh

    from balltrack.common.keys import Keys, alive_token
    from balltrack.common.session import SessionOpenError, close_session

    deadline = time.monotonic() + timeout
    needed = robot_tokens(info, services)
    namespaces = sorted({namespace for namespace, _ in needed})
    try:
        session = open_for(info, timeout)
    except SessionOpenError:
        return set(services)
    alive: set[tuple[str, str]] = set()
    changed = threading.Condition()

    def on_token(sample):
        token = alive_token(str(sample.key_expr))
        if token is None:
            return
        with changed:
            (alive.add if sample.kind == zenoh.SampleKind.PUT else alive.discard)(token)
            changed.notify_all()

    # (a namespace each: a secure profile's viewer may read only its own robot's keys)
    subscribers = [session.liveliness().declare_subscriber(Keys(namespace)("alive/*"), on_token, history=True)
                   for namespace in namespaces]
    try:
        with changed:
            while not needed <= alive and time.monotonic() < deadline:
                if (stop is not None and stop.is_set()) or failed():
                    break
                changed.wait(min(0.2, max(0.0, deadline - time.monotonic())))
            missing = needed - alive
    finally:
        for subscriber in subscribers:
            subscriber.undeclare()
        close_session(session)  # (a router out of reach already shows as services missing)
    robots = len(namespaces) > 1
    return {f"{namespace}/{service}" if robots and namespace else service for namespace, service in missing}


def write_json_atomically(path: Path, data: dict) -> None:
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        temporary.write_text(json.dumps(data, indent=2) + "\n")
    except OSError:
        temporary.unlink(missing_ok=True)  # (a part-written file would hold the space)
        raise
    os.replace(temporary, path)


class Child:
    def __init__(self, spec: ChildSpec, run_dir: Path):
        self.spec = spec
        self.run_dir = run_dir
        self.popen: subprocess.Popen | None = None
        self.state = STARTING
        self.restarts = 0
        self.quick_failures = 0
        self.last_exit: int | None = None
        self.started_at: float | None = None  # time.monotonic() of the current start
        self.started_wall: float | None = None
        self.next_start = 0.0
        self._log_handle = None

    @property
    def log_path(self) -> Path:
        return self.run_dir / f"{self.spec.name}.log"

    @property
    def pid_path(self) -> Path:
        return self.run_dir / f"{self.spec.name}.pid"

    @property
    def pid(self) -> int | None:
        return self.popen.pid if self.popen is not None and self.popen.poll() is None else None

    def start(self) -> None:
        # A full or failing log disk costs the logs, never the child: a robot must not stop
        # because its run folder filled up.
        try:
            self._log_handle = open(self.log_path, "ab")
            stamp = time.strftime("%Y-%m-%d %H:%M:%S")
            self._log_handle.write(f"=== {stamp} start #{self.restarts + 1}: "
                                   f"{' '.join(self.spec.argv)}\n".encode())
            self._log_handle.flush()
        except OSError as error:
            LOG.warning("%s: %s not written (%s)", self.spec.name, self.log_path.name, error)
        output = self._log_handle if self._log_handle is not None else subprocess.DEVNULL
        self.popen = subprocess.Popen(
            self.spec.argv, stdout=output, stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL, env=child_environment(self.spec.env),
            start_new_session=True, preexec_fn=die_with_parent if sys.platform == "linux" else None)
        try:
            self.pid_path.write_text(f"{self.popen.pid}\n")
        except OSError as error:
            LOG.warning("%s: %s not written (%s)", self.spec.name, self.pid_path.name, error)
        self.started_at = time.monotonic()
        self.started_wall = time.time()
        self.state = RUNNING

    def reap(self) -> int | None:
        """The exit status if the child has exited since the last call (pid file removed)."""
        if self.popen is None or self.state not in (RUNNING, STARTING):
            return None
        returncode = self.popen.poll()
        if returncode is None:
            return None
        self._closed(returncode)
        return returncode

    def _closed(self, returncode: int) -> None:
        self.last_exit = returncode
        self.pid_path.unlink(missing_ok=True)
        if self._log_handle is not None:
            try:
                self._log_handle.close()
            except OSError:  # (what it buffered could not be written: the disk is full)
                pass
            self._log_handle = None

    def terminate(self) -> None:
        if self.popen is not None and self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)

    def wait_stopped(self, deadline: float) -> int | None:
        """Wait for a child sent SIGTERM; SIGKILL at ``deadline``. Its exit status."""
        if self.popen is None or self.state not in (RUNNING, STARTING):
            return None
        try:
            returncode = self.popen.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            LOG.warning("%s ignored SIGTERM; sending SIGKILL", self.spec.name)
            self.popen.kill()
            returncode = self.popen.wait()
        self._closed(returncode)
        self.state = STOPPED
        return returncode

    def status(self) -> dict:
        return {"pid": self.pid, "state": self.state, "restarts": self.restarts,
                "last_exit": self.last_exit,
                "last_exit_text": describe_exit(self.last_exit) if self.last_exit is not None else None,
                "started": self.started_wall, "log": str(self.log_path), "argv": self.spec.argv}


class Supervisor:
    """Starts ``specs`` in order and keeps them running until ``stop`` is set."""

    def __init__(self, run_dir: Path, specs: list[ChildSpec],
                 settings: SupervisorSettings | None = None, info: dict | None = None):
        self.run_dir = Path(run_dir)
        self.settings = settings or SupervisorSettings()
        self.children = [Child(spec, self.run_dir) for spec in specs]
        self.info = dict(info or {})
        self.state = STARTING
        self.exit_code: int | None = None
        self.stop = threading.Event()
        self._status_error: str | None = None  # why the last status.json was not written

    # -- status -------------------------------------------------------------------------
    def write_status(self) -> None:
        try:
            write_json_atomically(self.run_dir / "status.json", {
                "supervisor": {"pid": os.getpid(), "state": self.state, "exit_code": self.exit_code,
                               "updated": time.time(), **self.info},
                "children": {child.spec.name: child.status() for child in self.children},
            })
        except OSError as error:
            # (supervising goes on: status.json is a report, kept until it can be written again)
            if str(error) != self._status_error:
                LOG.warning("status.json not written (%s); supervising goes on", error)
            self._status_error = str(error)
        else:
            self._status_error = None

    # -- running ------------------------------------------------------------------------
    def _wait_for_port(self, child: Child) -> bool:
        deadline = time.monotonic() + self.settings.ready_timeout
        while time.monotonic() < deadline and not self.stop.is_set():
            if child.popen.poll() is not None:
                return False
            try:
                with socket.create_connection(("127.0.0.1", child.spec.port), timeout=0.5):
                    return True
            except OSError:
                self.stop.wait(0.1)
        return False

    def _start(self, child: Child) -> None:
        if child.restarts == 0:
            for state_file in child.spec.state_files:
                try:
                    Path(state_file).unlink(missing_ok=True)
                except OSError as error:
                    LOG.warning("%s: %s not removed (%s)", child.spec.name, state_file, error.strerror)
        child.start()
        LOG.info("started %s (pid %d)%s", child.spec.name, child.popen.pid,
                 f", restart {child.restarts}" if child.restarts else "")
        if child.spec.port and not self._wait_for_port(child):
            if not self.stop.is_set():
                LOG.warning("%s is not accepting connections on port %d", child.spec.name,
                            child.spec.port)
        if child.spec.wait_alive and child.restarts == 0:
            missing = wait_alive(self.info, process_services(child.spec.name), self.settings.alive_timeout, self.stop,
                                 failed=lambda: child.popen.poll() is not None)
            if missing and not self.stop.is_set() and child.popen.poll() is None:
                LOG.warning("%s is not alive after %.0f s; starting the next anyway", child.spec.name,
                            self.settings.alive_timeout)
        self.write_status()

    def _on_exit(self, child: Child, returncode: int) -> None:
        name, settings = child.spec.name, self.settings
        ran = time.monotonic() - (child.started_at or time.monotonic())
        if returncode == 0:
            child.state = EXITED
            LOG.info("%s exited 0 (asked to stop): not restarted", name)
        elif returncode == 2:
            child.state = FAILED
            LOG.error("%s exited 2 (usage or configuration error, see %s): not restarted",
                      name, child.log_path)
        else:
            child.quick_failures = child.quick_failures + 1 if ran < settings.stable_after else 1
            if child.quick_failures > settings.give_up_after:
                child.state = FAILED
                LOG.error("%s %s; %d quick failures in a row: giving up (see %s)", name,
                          describe_exit(returncode), child.quick_failures - 1, child.log_path)
            else:
                delay = min(settings.backoff_initial * 2 ** (child.quick_failures - 1),
                            settings.backoff_max)
                child.state = BACKOFF
                child.next_start = time.monotonic() + delay
                LOG.warning("%s %s after %.1f s; restart %d in %.1f s", name,
                            describe_exit(returncode), ran, child.restarts + 1, delay)
        self.write_status()

    def _stop_children(self) -> bool:
        """SIGTERM to services (reverse order), then to the rest; True if all exited 0."""
        self.state = "stopping"
        self.write_status()
        clean = True
        routers = [child for child in self.children if child.spec.port]
        services = [child for child in reversed(self.children) if not child.spec.port]
        for group in (services, routers):
            for child in group:
                child.terminate()
            deadline = time.monotonic() + self.settings.stop_timeout
            for child in group:
                was_running = child.state in (RUNNING, STARTING)
                returncode = child.wait_stopped(deadline)
                if was_running:
                    LOG.info("%s stopped (%s)", child.spec.name, describe_exit(returncode))
                    # (killed by our own SIGTERM: it stopped as asked, before its handler was
                    # installed, as a service still starting up does)
                    clean = clean and returncode in (0, -signal.SIGTERM)
                elif child.state == BACKOFF:
                    child.state = STOPPED
        return clean

    def run(self) -> int:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        pid_file = self.run_dir / "supervisor.pid"
        pid_file.write_text(f"{os.getpid()}\n")
        try:
            self.write_status()
            for child in self.children:
                if self.stop.is_set():
                    break
                self._start(child)
            if not self.stop.is_set():
                self.state = RUNNING
                self.write_status()
                LOG.info("running %s", ", ".join(child.spec.name for child in self.children))
            while not self.stop.is_set():
                now = time.monotonic()
                for child in self.children:
                    returncode = child.reap()
                    if returncode is not None:
                        self._on_exit(child, returncode)
                    elif child.state == BACKOFF and now >= child.next_start:
                        child.restarts += 1
                        self._start(child)
                    elif (child.state == RUNNING and child.quick_failures
                          and now - child.started_at >= self.settings.stable_after):
                        child.quick_failures = 0
                if self._status_error is not None:  # (the disk may have room again)
                    self.write_status()
                if all(child.state in (EXITED, FAILED) for child in self.children):
                    LOG.info("no child left to supervise")
                    break
                self.stop.wait(0.1)
            clean = self._stop_children()
            failed = [child.spec.name for child in self.children if child.state == FAILED]
            self.exit_code = 0 if clean and not failed else 1
            self.state = "stopped"
            LOG.info("stopped (exit %d)%s", self.exit_code,
                     f"; failed: {', '.join(failed)}" if failed else "")
            self.write_status()
            return self.exit_code
        finally:
            for child in self.children:
                if child.popen is not None and child.popen.poll() is None:
                    child.popen.kill()
                    child.popen.wait()
                child.pid_path.unlink(missing_ok=True)
            pid_file.unlink(missing_ok=True)


def load_launch(run_dir: Path) -> tuple[list[ChildSpec], dict]:
    data = json.loads((run_dir / "launch.json").read_text())
    specs = [ChildSpec(**child) for child in data["children"]]
    return specs, data.get("info", {})


def save_launch(run_dir: Path, specs: list[ChildSpec], info: dict) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomically(run_dir / "launch.json",
                          {"children": [asdict(spec) for spec in specs], "info": info})


def supervise(run_dir: Path, settings: SupervisorSettings | None = None, log_file: bool = False) -> int:
    """Run a run folder's launch.json until SIGINT/SIGTERM (``python -m balltrack.deploy supervise``, whose
    stderr is supervisor.log, or ``start --foreground``, which logs to both with ``log_file``)."""
    log_format = "%(asctime)s %(name)s %(levelname)s %(message)s"
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format=log_format)
    if log_file:
        handler = logging.FileHandler(Path(run_dir) / "supervisor.log")
        handler.setFormatter(logging.Formatter(log_format))
        logging.getLogger().addHandler(handler)
    specs, info = load_launch(run_dir)
    supervisor = Supervisor(run_dir, specs, settings, info)
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, lambda *_: set_from_signal(supervisor.stop))
    return supervisor.run()
