"""Does the simulator keep real time while the whole pipeline runs on this machine?

Starts a router on a free port, the detector, locator and follower (on simulated time) and the
simulator as separate processes, lets them run for ``--seconds``, and reads the simulator's
stats: the real-time factor reached (simulated seconds per wall second), frames per second and
render time, with each process's CPU use. Everything is stopped cleanly at the end (exit
statuses are printed; a non-zero one fails the run).

Example::

    python -m experiments.realtime_check                       # 640x480, 30 Hz, realtime
    python -m experiments.realtime_check --pacing fast         # as fast as possible
    python -m experiments.realtime_check --pacing fast --alone # the simulator by itself
    python -m experiments.realtime_check --set encoding=jpeg --seconds 10
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

from tests.harness import Collector, Liveliness, Router, client, start_service  # noqa: E402

PIPELINE = (("detector",), ("locator",), ("follower", "--set", "use_sim_time=true"))
WARM_UP_STATS = 3  # stats messages (seconds) left out of the averages: start-up costs


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux /proc), 0 if unavailable."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def run(arguments, log_dir: Path) -> int:
    router = Router(log_dir)
    session = client(router.endpoint)
    liveliness = Liveliness(session)
    processes = {}
    try:
        if not arguments.alone:
            for name, *extra in PIPELINE:
                processes[name] = start_service(name, router.endpoint, log_dir, *extra)
            for name in processes:
                liveliness.wait(name, timeout=60)
        stats = Collector(session, "simulator/stats", "Stats")
        detector_stats = Collector(session, "detector/stats", "Stats")
        settings = [f"width={arguments.width}", f"height={arguments.height}",
                    f"rate_hz={arguments.rate}", f"pacing={arguments.pacing}", *arguments.set]
        processes["simulator"] = start_service(
            "simulator", router.endpoint, log_dir, *[item for pair in settings for item in ("--set", pair)])
        liveliness.wait("simulator", timeout=60)
        stats.wait_count(WARM_UP_STATS, 60)
        cpu_start = {name: cpu_seconds(process.popen.pid) for name, process in processes.items()}
        wall_start = time.monotonic()
        messages = stats.wait_count(WARM_UP_STATS + arguments.seconds, arguments.seconds + 30)
        wall = time.monotonic() - wall_start
        cpu = {name: (cpu_seconds(process.popen.pid) - cpu_start[name]) / wall
               for name, process in processes.items()}
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
        codes = {name: process.stop() for name, process in reversed(list(processes.items()))}
        session.close()
        codes["router"] = router.stop()
        print("  exit statuses: " + ", ".join(f"{name} {code}" for name, code in codes.items()))
    return 0 if not any(codes.values()) else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.realtime_check", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=int, default=20, help="measured wall seconds (default 20)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--rate", type=float, default=30.0, help="camera frames per simulated second")
    parser.add_argument("--pacing", default="realtime", choices=["realtime", "fast", "lockstep"])
    parser.add_argument("--alone", action="store_true", help="no detector, locator or follower")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="another simulator setting, repeatable")
    parser.add_argument("--log-dir", help="keep the processes' logs here (default: a temporary directory)")
    arguments = parser.parse_args(argv)
    if arguments.log_dir:
        Path(arguments.log_dir).mkdir(parents=True, exist_ok=True)
        return run(arguments, Path(arguments.log_dir))
    with tempfile.TemporaryDirectory(prefix="realtime_check-") as log_dir:
        return run(arguments, Path(log_dir))


if __name__ == "__main__":
    sys.exit(main())
