"""Measured scale: how many simulated robots this machine serves in real time (issue 58, part 3).

For each robot count N (1, 2, 4, 8, 16) it starts, over a real router (the system launcher,
``deploy/launcher.py``): one simulator holding N robots in the ``fleet`` scenario (each robot its
own ball; realtime pacing, 320x240 at 15 Hz) and one ``balltrack run detector+locator+follower
--namespaces robot1,...,robotN`` process (followers with the demo's ``max_size_thresh``, so that
they stop within the referee's distance). Once every robot has been located it measures, for a
window of wall time, at one subscriber of ``**`` of its own:

* per robot, frame -> ``detected_ball_3d`` p50 and p99: the arrival of a robot's position minus
  the arrival of its frame of the same ``seq``, both at this subscriber (one clock, as the
  latency experiment and the soak measure it);
* the share of frames dropped: the difference of each robot's detector stats, ``dropped`` over
  ``received`` (a frame replaced in its robot's slot before the worker took it);
* the real-time factor: simulated time advanced (robot 1's ``clock``) over wall time;
* CPU seconds per robot-second: the CPU time of the router, the simulator and the pipeline
  process (from /proc) over N times the window; their resident memory, summed;
* messages per second: every message this subscriber of ``**`` received through the router
  (the frames included), i.e. what the robots publish.

Each robot is judged on ground truth by its own referee (``fleet.own_ball_referees``) from the
start of its run: after the window the run waits a little longer for any robot not there yet.

``fleet/max_robots`` is the largest N that ran with a real-time factor >= 0.95, less than 1 % of
the frames dropped and every robot's p99 <= 50 ms. Goals: ``fleet/max_robots`` >= 8; every
robot reaches its own ball at that N (at N = 1 when none qualifies). The plot shows latency
and CPU per robot-second against N.

    balltrack experiment fleet --out runs/fleet
    balltrack experiment fleet --quick --out /tmp/fleet      # a short window per N
"""

import io
import os
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import msgpack

from balltrack.common import keys
from balltrack.common.messages import MessageError, decode
from balltrack.common.referee import Referee
from balltrack.common.session import open_session
from balltrack.common.waiting import poll_until
from balltrack.deploy.command import Command
from balltrack.deploy.launcher import start_system
from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, quantile, record_machine_speed
from balltrack.experiments.lags import ArrivalLags
from balltrack.experiments.processes import cpu_seconds, resident_mb
from balltrack.services.simulator.fleet import own_ball_referees, robot_name

NAME = "fleet"
TITLE = "Measured scale: robots served in real time by one simulator and one pipeline process"
ROBOT_COUNTS = (1, 2, 4, 8, 16)
SCENARIO = "fleet"
WIDTH, HEIGHT, RATE_HZ = 320, 240, 15
# The demo's value: with the default 0.1 the fleet's robots stop about 0.59 m from their balls,
# outside the referee's 0.35 m.
MAX_SIZE_THRESH = 0.3
# Real time, per issue 58: every criterion must hold at N for N to count.
MIN_REAL_TIME_FACTOR = 0.95
MAX_DROPPED_SHARE = 0.01
MAX_P99_MS = 50.0
GOAL_MAX_ROBOTS = 8
# Wall seconds measured per N, and how long after the window a robot not yet at its ball may
# still reach it (each run starts with the robots 1.2 m from their balls).
WINDOW_SECONDS_QUICK, WINDOW_SECONDS_FULL = 8.0, 30.0
REACH_GRACE_QUICK, REACH_GRACE_FULL = 8.0, 30.0
LOCATED_TIMEOUT = 120.0  # until every robot has a first position (the pipeline starts, under load)
PROCESSES = ("router", "simulator", "pipeline")


@dataclass
class RobotCounts:
    """One robot's messages as they arrive at the experiment's subscriber."""

    referee: Referee
    lags: ArrivalLags = field(default_factory=ArrivalLags)
    frames: int = 0
    stats: dict | None = None  # its detector's newest stats


class FleetObserver:
    """Every message of the fleet, as one subscriber of ``**`` gets them (see the module doc).

    :meth:`take_sample` is the whole of it, without Zenoh: a key, a payload, an arrival time."""

    def __init__(self, robots: int):
        self.lock = threading.Lock()
        self.robots = {name: RobotCounts(referee) for name, referee in own_ball_referees(robots).items()}
        self.messages = 0
        self.clock: list[tuple[float, int]] = []  # (arrival, stamp ns) of robot 1's clock
        self._subscriber = None

    def subscribe(self, session) -> None:
        self._subscriber = session.declare_subscriber("**", self._on_sample)

    def _on_sample(self, sample) -> None:
        self.take_sample(str(sample.key_expr), sample.payload.to_bytes(), time.monotonic())

    def take_sample(self, key: str, payload: bytes, arrival: float) -> None:
        robot, _, rest = key.partition("/")
        with self.lock:
            self.messages += 1
            counts = self.robots.get(robot)
            if counts is None:
                return
            try:
                if rest == keys.IMAGE_RAW:
                    # (only the header is needed: no check of the frame's pixels)
                    seq = msgpack.unpackb(payload, raw=False)["header"]["seq"]
                    counts.frames += 1
                    counts.lags.start(seq, arrival)
                elif rest == keys.DETECTED_BALL_3D:
                    counts.lags.end(decode("Ball3D", payload)["header"]["seq"], arrival)
                elif rest == keys.GROUND_TRUTH:
                    truth = decode("GroundTruth", payload)
                    counts.referee.update(truth["header"]["stamp"] / 1e9, truth)
                elif rest == keys.stats_key("detector"):
                    counts.stats = decode("Stats", payload)
                elif rest == keys.CLOCK and robot == robot_name(1):
                    self.clock.append((arrival, decode("Clock", payload)["stamp"]))
            except (MessageError, ValueError, KeyError, TypeError, msgpack.ExtraData):
                return

    def located(self) -> bool:
        """Whether every robot has had a position since the last :meth:`window_start`, and its
        detector's stats (what the window's drops are counted from)."""
        with self.lock:
            return all(counts.lags.lags and counts.stats for counts in self.robots.values())

    def reached(self) -> bool:
        with self.lock:
            return all(counts.referee.reached for counts in self.robots.values())

    def window_start(self) -> dict:
        """Reset the window's counts; what the window's end is compared with."""
        with self.lock:
            self.messages = 0
            self.clock = self.clock[-1:]
            for counts in self.robots.values():
                counts.frames = 0
                counts.lags.take()
            return {name: counts.stats for name, counts in self.robots.items()}

    def window_end(self, stats_before: dict, seconds: float) -> dict:
        """The window's figures (see :func:`window_figures`)."""
        with self.lock:
            robots = {name: {"lags": counts.lags.take(), "frames": counts.frames,
                             "stats_before": stats_before.get(name), "stats_after": counts.stats}
                      for name, counts in self.robots.items()}
            return window_figures(robots, self.messages, list(self.clock), seconds)

    def close(self) -> None:
        if self._subscriber is not None:
            self._subscriber.undeclare()


def dropped_share(before: dict | None, after: dict | None) -> tuple[int, int]:
    """(frames dropped, frames received) by a robot's detector between two of its stats."""
    if after is None:
        return 0, 0
    before = before or {"dropped": 0, "received": 0}
    return max(0, after["dropped"] - before["dropped"]), max(0, after["received"] - before["received"])


def window_figures(robots: dict[str, dict], messages: int, clock: list[tuple[float, int]],
                   seconds: float) -> dict:
    """Per robot (lags in s, frames, detector stats before and after) to the window's figures:
    per robot p50/p99 (ms), frames/s and dropped share; pooled p50/p99, the worst robot's p99,
    the dropped share of all frames, messages/s and the real-time factor (None without two
    clock readings)."""
    per_robot, pooled, dropped_total, received_total = {}, [], 0, 0
    for name, robot in robots.items():
        dropped, received = dropped_share(robot["stats_before"], robot["stats_after"])
        dropped_total += dropped
        received_total += received
        pooled += robot["lags"]
        p50, p99 = quantile(robot["lags"], 0.5), quantile(robot["lags"], 0.99)
        per_robot[name] = {"p50_ms": None if p50 is None else 1000 * p50,
                           "p99_ms": None if p99 is None else 1000 * p99,
                           "positions": len(robot["lags"]), "frames_per_s": robot["frames"] / seconds,
                           "dropped_share": dropped / received if received else None}
    p99s = [robot["p99_ms"] for robot in per_robot.values()]
    real_time_factor = None
    if len(clock) >= 2 and clock[-1][0] > clock[0][0]:
        real_time_factor = (clock[-1][1] - clock[0][1]) / 1e9 / (clock[-1][0] - clock[0][0])
    p50, p99 = quantile(pooled, 0.5), quantile(pooled, 0.99)
    return {"robots": per_robot,
            "p50_ms": None if p50 is None else 1000 * p50, "p99_ms": None if p99 is None else 1000 * p99,
            # (a robot with no position at all has no p99: it is the worst)
            "worst_p99_ms": None if not p99s or None in p99s else max(p99s),
            "dropped_share": dropped_total / received_total if received_total else None,
            "messages_per_s": messages / seconds, "real_time_factor": real_time_factor}


def in_real_time(row: dict) -> bool:
    """Whether a robot count's row meets issue 58's real-time criteria."""
    return (row.get("real_time_factor") is not None and row["real_time_factor"] >= MIN_REAL_TIME_FACTOR
            and row.get("dropped_share") is not None and row["dropped_share"] < MAX_DROPPED_SHARE
            and row.get("worst_p99_ms") is not None and row["worst_p99_ms"] <= MAX_P99_MS)


def max_robots(rows: dict[int, dict]) -> int:
    """The largest robot count whose row is in real time (0 when none is)."""
    return max((robots for robots, row in rows.items() if in_real_time(row)), default=0)


def measure(robots: int, folder: Path, window: float, grace: float) -> dict:
    """One robot count: start the system, wait until every robot is located, measure a window."""
    settings = {"simulator": [f"scenario={SCENARIO}", f"robots={robots}", "pacing=realtime",
                              f"width={WIDTH}", f"height={HEIGHT}", f"rate_hz={RATE_HZ}"]}
    observer = FleetObserver(robots)
    namespaces = ",".join(robot_name(index + 1) for index in range(robots))
    with start_system(folder, services=("simulator",), settings=settings, output=io.StringIO()) as system:
        session = open_session([system.endpoint], open_timeout=10)
        observer.subscribe(session)
        pipeline = Command(["run", "detector+locator+follower", "--connect", system.endpoint,
                            "--namespaces", namespaces, "--set", f"follower.max_size_thresh={MAX_SIZE_THRESH}"],
                           folder / "pipeline.log")
        try:
            def located() -> bool:
                if pipeline.popen.poll() is not None:
                    raise RuntimeError(f"the pipeline exited ({pipeline.popen.returncode}): {pipeline.output()[-500:]}")
                return observer.located()

            if not poll_until(located, LOCATED_TIMEOUT, interval=0.1):
                # (the run folder goes with the experiment's temporary folder: the logs' ends here)
                raise RuntimeError(f"not every robot located in {LOCATED_TIMEOUT:.0f} s; simulator: "
                                   f"{system.log('simulator', 3)!r}; pipeline: {pipeline.output()[-300:]!r}")
            pids = {"router": system.pid("router"), "simulator": system.pid("simulator"), "pipeline": pipeline.pid}
            stats_before = observer.window_start()
            cpu_before = {name: cpu_seconds(pid) for name, pid in pids.items()}
            observer_before = time.process_time()
            started = time.monotonic()
            time.sleep(window)  # the measurement window itself, not a wait for a condition
            seconds = time.monotonic() - started
            cpu = {name: cpu_seconds(pid) - cpu_before[name] for name, pid in pids.items()}
            # (this program's own subscriber takes every frame too: a load beside the system's)
            observer_cpu = time.process_time() - observer_before
            memory = {name: resident_mb(pid) for name, pid in pids.items()}
            row = observer.window_end(stats_before, seconds)
            poll_until(observer.reached, grace, interval=0.2)
        finally:
            observer.close()
            session.close()
            pipeline.stop()
    with observer.lock:
        referees = {name: counts.referee for name, counts in observer.robots.items()}
    row.update({"seconds": seconds, "cpu_seconds": cpu, "observer_cpu_seconds": observer_cpu,
                "cores_used": sum(cpu.values()) / seconds,
                "cpu_per_robot_second": sum(cpu.values()) / (robots * seconds),
                "rss_mb": memory, "rss_total_mb": sum(value or 0.0 for value in memory.values()),
                "reached": sum(referee.reached for referee in referees.values()),
                "reached_at": {name: referee.reached_at for name, referee in referees.items()},
                "closest_m": {name: referee.closest for name, referee in referees.items()}})
    return row


def failed_row(robots: int, error: str) -> dict:
    """The row of a robot count whose system did not start, or whose robots were not all located."""
    names = [robot_name(index + 1) for index in range(robots)]
    return {"robots": {name: {"p50_ms": None, "p99_ms": None, "positions": 0, "frames_per_s": None,
                              "dropped_share": None} for name in names},
            "p50_ms": None, "p99_ms": None, "worst_p99_ms": None, "dropped_share": None, "messages_per_s": None,
            "real_time_factor": None, "seconds": 0.0, "cpu_seconds": dict.fromkeys(PROCESSES),
            "observer_cpu_seconds": None, "cores_used": None, "cpu_per_robot_second": None,
            "rss_mb": dict.fromkeys(PROCESSES), "rss_total_mb": None, "reached": 0,
            "reached_at": dict.fromkeys(names), "closest_m": dict.fromkeys(names), "error": error}


def run(options: Options) -> ExperimentResult:
    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, mode="zenoh", quick=options.quick)
    record_machine_speed(result)
    window = WINDOW_SECONDS_QUICK if options.quick else WINDOW_SECONDS_FULL
    grace = REACH_GRACE_QUICK if options.quick else REACH_GRACE_FULL
    rows: dict[int, dict] = {}
    with tempfile.TemporaryDirectory(prefix="balltrack-fleet-") as folder:
        for robots in ROBOT_COUNTS:
            try:
                rows[robots] = measure(robots, Path(folder) / f"robots_{robots}", window, grace)
            except RuntimeError as error:  # (a system that did not start or locate: that N is not served)
                print(f"[fleet] {robots} robots: {error}", flush=True)
                rows[robots] = failed_row(robots, str(error))
                continue
            row = rows[robots]
            print(f"[fleet] {robots} robots: real time x{_text(row['real_time_factor'], '.2f')}, "
                  f"p50 {_text(row['p50_ms'], '.1f')} ms, worst p99 {_text(row['worst_p99_ms'], '.1f')} ms, "
                  f"dropped {_text(row['dropped_share'], '.1%')}, "
                  f"{row['cpu_per_robot_second']:.3f} CPU s per robot-second, reached {row['reached']}/{robots}",
                  flush=True)
    report(result, rows, window, options.out)
    result.seconds = clock.seconds
    return result


def per_second(cpu: float | None, seconds: float) -> float | None:
    """CPU seconds per second (None when not measured)."""
    return None if cpu is None or not seconds else round(cpu / seconds, 4)


def _text(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def report(result: ExperimentResult, rows: dict[int, dict], window: float, out: Path) -> None:
    """Figures, the table per N, ``max_robots``, the goals and the plot."""
    for robots, row in rows.items():
        prefix = f"robots_{robots}"
        for name in ("real_time_factor", "p50_ms", "p99_ms", "worst_p99_ms", "dropped_share",
                     "messages_per_s", "cpu_per_robot_second", "cores_used", "observer_cpu_seconds",
                     "rss_total_mb", "reached"):
            result.figure(f"{prefix}/{name}", row[name])
        result.figure(f"{prefix}/window_s", row["seconds"])
        if "error" in row:
            result.figure(f"{prefix}/error", row["error"])
        for process in PROCESSES:
            result.figure(f"{prefix}/cpu_seconds/{process}", row["cpu_seconds"][process])
            result.figure(f"{prefix}/rss_mb/{process}", row["rss_mb"][process])
        for robot, figures in row["robots"].items():
            for name, value in figures.items():
                result.figure(f"{prefix}/{robot}/{name}", value)
            result.figure(f"{prefix}/{robot}/reached_at_s", row["reached_at"][robot])
            result.figure(f"{prefix}/{robot}/closest_m", row["closest_m"][robot])
    best = result.figure("max_robots", max_robots(rows))
    result.table(["robots", "real-time factor", "3D p50 / p99 (ms, all robots)", "worst robot's p99 (ms)",
                  "frames dropped", "CPU s per robot-second", "cores used", "resident memory (MB, total)",
                  "messages/s", "reached its ball", "in real time"],
                 [[robots, _text(row["real_time_factor"], ".2f"),
                   f"{_text(row['p50_ms'], '.1f')} / {_text(row['p99_ms'], '.1f')}",
                   _text(row["worst_p99_ms"], ".1f"), _text(row["dropped_share"], ".1%"),
                   _text(row["cpu_per_robot_second"], ".3f"), _text(row["cores_used"], ".2f"),
                   _text(row["rss_total_mb"], ".0f"), _text(row["messages_per_s"], ".0f"), f"{row['reached']}/{robots}",
                   "yes" if in_real_time(row) else f"no: {row['error'].split(';')[0]}" if "error" in row else "no"]
                  for robots, row in rows.items()],
                 f"Per robot count, a window of {window:g} s after every robot was located; CPU and memory "
                 "of the router, the simulator and the pipeline process (cores used: their CPU seconds "
                 f"per second, of the machine's {os.cpu_count()}); messages as received by one "
                 "subscriber of ** (frames included):")
    result.table(["robots", *[f"{process} CPU s per robot-second" for process in PROCESSES],
                  "this program's CPU s per second"],
                 [[robots, *[per_second(row["cpu_seconds"][process], row["seconds"] * robots) for process in PROCESSES],
                   per_second(row["observer_cpu_seconds"], row["seconds"])] for robots, row in rows.items()],
                 "Where the CPU goes (this program, which takes every message, is not counted above):")
    result.table(["robots", *[f"robot{index} p50 / p99 (ms)" for index in range(1, 5)], "..."],
                 [[robots, *[f"{_text(figures['p50_ms'], '.1f')} / {_text(figures['p99_ms'], '.1f')}"
                             for figures in list(row["robots"].values())[:4]]
                   + [""] * (4 - min(4, robots)), "" if robots <= 4 else f"(+{robots - 4}, in results.json)"]
                  for robots, row in rows.items()],
                 "Frame -> detected_ball_3d per robot (the first four; every robot's are figures):")
    result.goal("max_robots", f"robots served in real time (real-time factor >= {MIN_REAL_TIME_FACTOR:g}, "
                              f"< {MAX_DROPPED_SHARE:.0%} of frames dropped, every robot's p99 <= "
                              f"{MAX_P99_MS:g} ms), 320x240 at 15 Hz", f">= {GOAL_MAX_ROBOTS}", str(best),
                best >= GOAL_MAX_ROBOTS)
    judged = best if best in rows else min(rows)
    reached = rows[judged]["reached"]
    result.goal("reached", "in the fleet scenario every robot reaches its own ball (ground truth, its own "
                           "referee), at max_robots (at the fewest robots when none ran in real time)",
                f"{judged}/{judged}", f"{reached}/{judged}", reached == judged)
    result.settings = {"scenario": SCENARIO, "camera": f"{WIDTH}x{HEIGHT} at {RATE_HZ} Hz", "pacing": "realtime",
                       "pipeline": "one balltrack run detector+locator+follower --namespaces robot1,...",
                       "follower": f"max_size_thresh={MAX_SIZE_THRESH}", "window": f"{window:g} s per robot count"}
    plot(result, rows, out)


def plot(result: ExperimentResult, rows: dict[int, dict], out: Path) -> None:
    import matplotlib.pyplot as plt

    counts = list(rows)
    figure, (latency, cpu) = plt.subplots(1, 2, figsize=(10, 4))

    def series(name: str) -> list[float]:
        return [float("nan") if rows[robots][name] is None else rows[robots][name] for robots in counts]

    latency.plot(counts, series("p50_ms"), "o-", label="p50 (all robots)")
    latency.plot(counts, series("p99_ms"), "s-", label="p99 (all robots)")
    latency.plot(counts, series("worst_p99_ms"), "^--", label="p99 (worst robot)")
    latency.axhline(MAX_P99_MS, color="grey", linestyle=":", label=f"{MAX_P99_MS:g} ms")
    latency.set(xscale="log", xlabel="robots", ylabel="frame -> detected_ball_3d (ms)", title="Latency")
    cpu.plot(counts, series("cpu_per_robot_second"), "o-", color="tab:red")
    cpu.set(xscale="log", xlabel="robots", ylabel="CPU s per robot-second", title="CPU (router + simulator + pipeline)")
    for axes in (latency, cpu):
        axes.set_xticks(counts, [str(robots) for robots in counts])
        axes.grid(True, alpha=0.3)
    latency.legend(fontsize=8)
    result.save_plot(figure, out, "fleet.png")
