"""Does the simulator keep real time while the whole pipeline runs on this machine?

Starts a router on a free port, the detector, locator and follower (on simulated time) and the
simulator as separate processes (``deploy/launcher.py``), lets them run for ``--seconds``, and
reads the simulator's stats: the real-time factor reached (simulated seconds per wall second),
frames per second and render time, with each process's CPU use. Everything is stopped cleanly at the end (exit
statuses are printed; a non-zero one fails the run).

Example::

    python -m balltrack.experiments.realtime_check                       # 640x480, 30 Hz, realtime
    python -m balltrack.experiments.realtime_check --pacing fast         # as fast as possible
    python -m balltrack.experiments.realtime_check --pacing fast --alone # the simulator by itself
    python -m balltrack.experiments.realtime_check --set encoding=jpeg --seconds 10
"""

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

from balltrack.common.arguments import ArgumentParser, integer  # noqa: E402
from balltrack.common.config import ConfigError, load_config  # noqa: E402
from balltrack.common.messages import decode  # noqa: E402
from balltrack.common.session import open_session  # noqa: E402
from balltrack.common.terminal import exit_with  # noqa: E402
from balltrack.deploy.launcher import SERVICES, LaunchError, start_system  # noqa: E402
from balltrack.experiments.processes import cpu_seconds  # noqa: E402
from balltrack.services.simulator.config import SimulatorConfig  # noqa: E402

WARM_UP_STATS = 3  # stats messages (seconds) left out of the averages: start-up costs


class StatsStream:
    """The ``<service>/stats`` messages of one service, and a wait for the n-th."""

    def __init__(self, session, service: str):
        self.messages: list[dict] = []
        self._changed = threading.Condition()

        def on_sample(sample):
            with self._changed:
                self.messages.append(decode("Stats", sample.payload.to_bytes()))
                self._changed.notify_all()

        self.subscriber = session.declare_subscriber(f"{service}/stats", on_sample)

    def wait_count(self, count: int, timeout: float) -> list[dict]:
        with self._changed:
            if not self._changed.wait_for(lambda: len(self.messages) >= count, timeout):
                raise RuntimeError(f"{len(self.messages)} stats messages after {timeout:g} s, not {count}")
            return list(self.messages)


def simulator_settings(arguments) -> list[str]:
    return [f"width={arguments.width}", f"height={arguments.height}", f"rate_hz={arguments.rate}",
            f"pacing={arguments.pacing}", *arguments.set]


def run(arguments, log_dir: Path) -> int:
    services = ("simulator",) if arguments.alone else SERVICES
    settings = {"simulator": simulator_settings(arguments)} | ({} if arguments.alone else {"follower": ["use_sim_time=true"]})
    system = start_system(log_dir, services, settings, wait=60, output=None)
    session = None
    try:
        session = open_session([system.endpoint], open_timeout=10)
        stats = StatsStream(session, "simulator")
        detector_stats = StatsStream(session, "detector")
        stats.wait_count(WARM_UP_STATS, 60)
        cpu_start = {name: cpu_seconds(system.pid(name)) for name in services}
        wall_start = time.monotonic()
        messages = stats.wait_count(WARM_UP_STATS + arguments.seconds, arguments.seconds + 30)
        wall = time.monotonic() - wall_start
        cpu = {name: (cpu_seconds(system.pid(name)) - cpu_start[name]) / wall for name in services}
        first, last = messages[WARM_UP_STATS - 1], messages[-1]
        wall_span = (last["stamp"] - first["stamp"]) / 1e9
        simulated = (last["frames"] - first["frames"]) / arguments.rate
        print(f"simulator {arguments.width}x{arguments.height} at {arguments.rate:g} Hz, "
              f"pacing={arguments.pacing}, {'alone' if arguments.alone else 'with detector, locator, follower'}"
              f"{', ' + ' '.join(arguments.set) if arguments.set else ''}")
        print(f"  real-time factor {simulated / wall_span:.3f} over {wall_span:.1f} s "
              f"({(last['frames'] - first['frames']) / wall_span:.1f} frames/s); last 5 s: "
              f"{last['real_time_factor']:.3f}")
        print(f"  render {last['render_ms']:.1f} ms/frame; realtime slips (dropped) {last['dropped']}; "
              f"lockstep timeouts {last['lockstep_timeouts']}")
        if detector_stats.messages:
            detector = detector_stats.messages[-1]
            print(f"  detector: {detector['received']} frames received, {detector['dropped']} dropped "
                  f"(newer frame arrived first), {detector['p50_ms']:.1f} ms p50, {detector['p99_ms']:.1f} ms p99")
        print("  CPU (cores): " + ", ".join(f"{name} {share:.2f}" for name, share in cpu.items())
              + f"; machine has {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    finally:
        if session is not None:
            session.close()
        code = system.stop()
        print("  exit statuses: " + ", ".join(f"{name} {child['last_exit']}"
                                              for name, child in system.children().items()))
    return code


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.realtime_check", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=integer(minimum=1), default=20, help="measured wall seconds (default 20)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--rate", type=float, default=30.0, help="camera frames per simulated second")
    parser.add_argument("--pacing", default="realtime", choices=["realtime", "fast", "lockstep"])
    parser.add_argument("--alone", action="store_true", help="no detector, locator or follower")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="another simulator setting, repeatable")
    parser.add_argument("--log-dir", help="keep the run folder (processes' logs) here (default: a temporary one)")
    arguments = parser.parse_args(argv)
    try:  # (the simulator would refuse them too, but only after the router and services started)
        load_config(SimulatorConfig, None, simulator_settings(arguments), section="simulator")
    except ConfigError as error:
        parser.error(str(error))
    try:
        if arguments.log_dir:
            Path(arguments.log_dir).mkdir(parents=True, exist_ok=True)
            return run(arguments, Path(arguments.log_dir))
        with tempfile.TemporaryDirectory(prefix="realtime_check-") as log_dir:
            return run(arguments, Path(log_dir))
    except (LaunchError, OSError) as error:
        print(f"realtime_check: {str(error).splitlines()[0]}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    exit_with(main)
