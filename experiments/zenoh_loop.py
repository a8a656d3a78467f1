"""Closed-loop runs over Zenoh: the real service processes, the simulator in lockstep pacing.

:class:`ZenohLoop` starts, with the system launcher (``deploy/launcher.py``), a router on a free
local port and the detector, locator, follower (``use_sim_time``) and simulator (``pacing =
lockstep``, so that the results do not depend on the machine's load) processes, then runs one
scenario after another:

1. ``reset`` to an empty scenario (no ball) for 1.2 simulated seconds, so that the follower's
   detection timeout passes and the next run starts from a lost target, as a fresh start would;
2. ``reset`` to the run's scenario (a TOML file written for it);
3. judge every ``sim/ground_truth`` frame until the run is over, recording ``cmd_vel`` (and
   ``detected_ball_3d`` for a recorded run).

Process logs go to a temporary run folder; a failure message quotes the end of the logs.
"""

import math
import queue
import tempfile
import threading
from dataclasses import fields
from pathlib import Path
from typing import Any

import msgpack

from balltrack.common import keys
from balltrack.deploy.launcher import System, start_system
from balltrack.experiments.rig import scenario_data, write_scenario
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.follower.config import FollowerConfig

STARTUP_TIMEOUT = 90.0
STALL_TIMEOUT = 20.0
SETTLE_SECONDS = 1.2


def _setting(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return ",".join(str(item) for item in value)
    return str(value)


def config_settings(config, skip: tuple[str, ...] = ()) -> list[str]:
    """``key=value`` for every field of ``config`` that differs from the defaults."""
    defaults = type(config)()
    return [f"{item.name}={_setting(getattr(config, item.name))}" for item in fields(config)
            if item.name not in skip and getattr(config, item.name) != getattr(defaults, item.name)]


class ZenohLoop:
    """Router + simulator (lockstep) + detector + locator + follower, driven run by run."""

    def __init__(self, out: Path, follower: FollowerConfig, detector: DetectorConfig,
                 simulator_settings: dict[str, Any] | None = None):
        self.follower = follower
        self.detector = detector
        self.simulator_settings = simulator_settings or {}
        self._temporary = tempfile.TemporaryDirectory(prefix="balltrack-tracking-")
        self.folder = Path(self._temporary.name)
        self.system: System | None = None
        self.session = None
        self._subscribers = []
        self._truths: queue.Queue = queue.Queue()
        self._lock = threading.Lock()
        self._commands: list[dict] = []
        self._estimates: dict[int, tuple[float, float, float]] = {}
        self._record = False
        self._run_count = 0

    # -- start and stop -------------------------------------------------------------------------

    def __enter__(self) -> "ZenohLoop":
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _start(self) -> None:
        from balltrack.common.session import open_session

        self.blank = write_scenario(scenario_data(name="blank", description="no ball"),
                                    self.folder / "blank.toml")
        simulator_sets = {"scenario": str(self.blank), "pacing": "lockstep",
                          **self.simulator_settings}
        settings = {"simulator": [f"{key}={_setting(value)}" for key, value in simulator_sets.items()],
                    "detector": config_settings(self.detector),
                    "follower": [*config_settings(self.follower, skip=("use_sim_time",)), "use_sim_time=true"]}
        self.system = start_system(self.folder / "run", settings=settings, wait=STARTUP_TIMEOUT,
                                   output=None)
        self.session = open_session([self.system.endpoint], open_timeout=10)

        def on_truth(sample) -> None:
            self._truths.put(msgpack.unpackb(sample.payload.to_bytes(), raw=False))

        def on_command(sample) -> None:
            with self._lock:
                self._commands.append(msgpack.unpackb(sample.payload.to_bytes(), raw=False))

        def on_estimate(sample) -> None:
            if not self._record:
                return
            message = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
            with self._lock:
                self._estimates[message["header"]["stamp"]] = (message["x"], message["y"], message["z"])

        self._subscribers = [self.session.declare_subscriber(keys.GROUND_TRUTH, on_truth),
                             self.session.declare_subscriber(keys.CMD_VEL, on_command),
                             self.session.declare_subscriber(keys.DETECTED_BALL_3D, on_estimate)]

    def close(self) -> None:
        for subscriber in self._subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # noqa: BLE001  (closing anyway)
                pass
        self._subscribers = []
        if self.session is not None:
            self.session.close()
            self.session = None
        if self.system is not None:
            self.system.stop()  # services first, the router last
            self.system = None
        self._temporary.cleanup()

    # -- runs -----------------------------------------------------------------------------------

    def _command(self, request: dict) -> None:
        from balltrack.services.simulator.control import send_command

        reply = send_command(self.session, request, timeout=10.0)
        if not reply.get("ok"):
            raise RuntimeError(f"sim/control {request.get('op')}: {reply.get('error')}")

    def _next_truth(self) -> dict:
        try:
            return self._truths.get(timeout=STALL_TIMEOUT)
        except queue.Empty:
            troubled = [f"{name} {child['state']} ({child['restarts']} restarts)"
                        for name, child in self.system.children().items()
                        if child["state"] != "running" or child["restarts"]]
            log = self.system.log("simulator", 8).replace("\n", " | ")
            raise RuntimeError(f"no ground truth for {STALL_TIMEOUT:g} s (not running or restarted: "
                               f"{', '.join(troubled) or 'none'}); simulator log: {log}") from None

    def _drain(self) -> None:
        while True:
            try:
                self._truths.get_nowait()
            except queue.Empty:
                return

    def run(self, spec, record: bool = False):
        """One run of ``spec`` (a tracking.RunSpec); returns a tracking.Outcome."""
        from balltrack.experiments.tracking import Judge, Outcome, _append_trace, _new_trace

        self._run_count += 1
        # 1. No ball until the follower has timed out.
        self._command({"op": "reset", "scenario": str(self.blank)})
        self._drain()
        start = None
        while True:
            truth = self._next_truth()
            if truth["balls"]:
                continue  # a frame from before the reset
            stamp = truth["header"]["stamp"] / 1e9
            start = stamp if start is None else start
            if stamp - start >= SETTLE_SECONDS:
                break
        # 2. The run's scenario.
        path = write_scenario(spec.scenario, self.folder / f"run_{self._run_count}.toml")
        with self._lock:
            self._commands = []
            self._estimates = {}
        self._record = record
        self._command({"op": "reset", "scenario": str(path)})
        outcome = Outcome(spec.category, spec.index)
        judge = Judge(outcome)
        trace = _new_trace() if record else None
        truths = []
        origin = None
        while True:
            truth = self._next_truth()
            if not truth["balls"]:
                continue  # still the blank scenario
            stamp = truth["header"]["stamp"]
            origin = stamp if origin is None else origin
            elapsed = (stamp - origin) / 1e9
            robot = (truth["robot"]["x"], truth["robot"]["y"], truth["robot"]["yaw"])
            ball = truth["balls"][0]
            truths.append((stamp, elapsed, robot, ball))
            if judge.update(elapsed, truth):
                break
        self._record = False
        with self._lock:
            commands = [command for command in self._commands
                        if command.get("time", command["header"]["stamp"]) >= origin]
            estimates = dict(self._estimates)
        for command in commands:
            mode = command.get("mode", "")
            outcome.modes[mode] = outcome.modes.get(mode, 0) + 1
            outcome.last_mode = mode
        if trace is not None:
            by_time = sorted(commands, key=lambda c: c.get("time", c["header"]["stamp"]))
            command_index = 0
            for stamp, elapsed, robot, ball in truths:
                command = None
                while (command_index < len(by_time)
                       and by_time[command_index].get("time", 0) <= stamp):
                    item = by_time[command_index]
                    command = (item["linear"][0], item["angular"][2], item.get("mode", ""))
                    command_index += 1
                _append_trace(trace, elapsed, robot, ball["position"], ball["in_camera"],
                              estimates.get(stamp), command)
        outcome.trace = trace
        if not math.isfinite(outcome.final_distance):
            raise RuntimeError("run ended without ground truth")
        return outcome
