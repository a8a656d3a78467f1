"""Soak: the whole system chasing a ball that never stops, for many minutes (issue 12).

Starts a router and the four services as real processes (the system launcher,
``deploy/launcher.py``), the simulator in realtime pacing on the ``orbit`` scenario (the ball
circles the robot, so the chase never ends), and every minute prints and records:

* frames published (``camera/image_raw`` messages seen by this program's subscriber),
* frames the detector dropped (the difference of its ``detector/stats`` ``dropped`` counter),
* latency frame -> ``detected_ball_3d``, p50 and p99: the arrival time of a ``detected_ball_3d``
  minus the arrival of the ``camera/image_raw`` with the same ``seq``, both at this program's own
  subscriber (one clock, as ``deploy/demo.py`` measures it),
* resident memory (VmRSS from /proc) of the router and each service,
* restarts, from the supervisor's status.

Goals: no restarts; resident memory growth per process below 20 MB after the warm-up (the first
minute: allocator arenas, Zenoh buffers and MuJoCo's caches grow once).

    balltrack experiment soak --out runs/soak               # 30 minutes
    balltrack experiment soak --minutes 10 --out runs/soak
    balltrack experiment soak --quick --out /tmp/soak       # 2 minutes
"""

import io
import math
import tempfile
import threading
import time
from pathlib import Path

import msgpack

from balltrack.common import keys
from balltrack.common.messages import MessageError, decode
from balltrack.common.session import open_session
from balltrack.deploy.launcher import SERVICES, start_system
from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, quantile
from balltrack.experiments.lags import ArrivalLags
from balltrack.experiments.processes import resident_mb

NAME = "soak"
TITLE = "Soak: the full system chasing a circling ball for many minutes"
SCENARIO = "orbit"
MINUTES_FULL = 30
MINUTES_QUICK = 2
MEMORY_GROWTH_LIMIT_MB = 20.0
PROCESSES = ("router", *SERVICES)


class Counters:
    """This program's subscriber: frame and position arrival times by ``seq``, latest stats."""

    def __init__(self, session):
        self.lock = threading.Lock()
        self.frames = 0
        self.frame_to_position = ArrivalLags()
        self.stats: dict[str, dict] = {}
        self._subscribers = [
            session.declare_subscriber(keys.IMAGE_RAW, self._on_image),
            session.declare_subscriber(keys.DETECTED_BALL_3D, self._on_position),
            session.declare_subscriber("*/stats", self._on_stats),
        ]

    def _on_image(self, sample) -> None:
        arrival = time.monotonic()
        try:  # only the header is needed; decoding the whole frame would cost CPU for nothing
            seq = msgpack.unpackb(sample.payload.to_bytes(), raw=False)["header"]["seq"]
        except (ValueError, KeyError, TypeError, msgpack.ExtraData):
            return
        with self.lock:
            self.frames += 1
            self.frame_to_position.start(seq, arrival)

    def _on_position(self, sample) -> None:
        arrival = time.monotonic()
        try:
            seq = decode("Ball3D", sample.payload.to_bytes())["header"]["seq"]
        except MessageError:
            return
        with self.lock:
            self.frame_to_position.end(seq, arrival)

    def _on_stats(self, sample) -> None:
        try:
            message = decode("Stats", sample.payload.to_bytes())
        except MessageError:
            return
        with self.lock:
            self.stats[message["service"]] = message

    def take(self) -> tuple[int, list[float], dict[str, dict]]:
        """(frames, latencies) since the last call, and the newest stats per service."""
        with self.lock:
            frames, self.frames = self.frames, 0
            return frames, self.frame_to_position.take(), dict(self.stats)

    def located(self) -> bool:
        """Whether a position has come since the last ``take``."""
        with self.lock:
            return bool(self.frame_to_position.lags)

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()


def _milliseconds(value: float | None) -> float | None:
    return None if value is None else round(1000.0 * value, 1)


def run(options: Options) -> ExperimentResult:
    minutes = getattr(options, "minutes", None) or (MINUTES_QUICK if options.quick else MINUTES_FULL)
    result = ExperimentResult(NAME, TITLE, mode="zenoh", quick=options.quick)
    clock = Stopwatch()
    settings = {"simulator": [f"scenario={SCENARIO}", "pacing=realtime"]}
    with tempfile.TemporaryDirectory(prefix="balltrack-soak-") as folder, \
            start_system(Path(folder), settings=settings, output=io.StringIO()) as system:
        session = open_session([system.endpoint], open_timeout=10)
        try:
            rows = _soak(system, session, minutes)
        finally:
            session.close()
    _report(result, rows, minutes)
    result.seconds = clock.seconds
    return result


def _soak(system, session, minutes: int) -> list[dict]:
    counters = Counters(session)
    pids = {name: system.pid(name) for name in PROCESSES}
    rows = []
    try:
        start = time.monotonic()
        # The minutes start now; what came during startup is not counted (the detector's drop
        # counter too, if its first stats are in; else minute 1 holds the startup's drops).
        _, _, stats = counters.take()
        dropped_before = stats.get("detector", {}).get("dropped", 0)
        print(f"{'min':>3} {'frames':>6} {'dropped':>7} {'p50 ms':>7} {'p99 ms':>7} "
              + " ".join(f"{name[:9]:>9}" for name in PROCESSES) + "  restarts", flush=True)
        for minute in range(1, minutes + 1):
            # Sleeping to the minute's end is the measurement itself, not a synchronisation.
            time.sleep(max(0.0, start + 60.0 * minute - time.monotonic()))
            frames, latencies, stats = counters.take()
            dropped_now = stats.get("detector", {}).get("dropped")
            dropped = None if dropped_now is None else max(0, dropped_now - dropped_before)
            dropped_before = dropped_before if dropped_now is None else dropped_now
            children = system.children()
            row = {
                "minute": minute, "frames": frames, "dropped": dropped,
                "positions": len(latencies),
                "p50_ms": _milliseconds(quantile(latencies, 0.5)),
                "p99_ms": _milliseconds(quantile(latencies, 0.99)),
                "rss_mb": {name: resident_mb(system.pid(name)) for name in PROCESSES},
                "restarts": {name: children.get(name, {}).get("restarts", 0)
                             + (system.pid(name) != pids[name]) for name in PROCESSES},
            }
            rows.append(row)
            memory = " ".join("        -" if row["rss_mb"][name] is None
                              else f"{row['rss_mb'][name]:9.1f}" for name in PROCESSES)
            print(f"{minute:3d} {frames:6d} {_text(dropped):>7} {_text(row['p50_ms']):>7} "
                  f"{_text(row['p99_ms']):>7} {memory}  {sum(row['restarts'].values())}", flush=True)
    finally:
        counters.close()
    return rows


def _text(value) -> str:
    return "-" if value is None else f"{value:g}" if isinstance(value, float) else str(value)


def _report(result: ExperimentResult, rows: list[dict], minutes: int) -> None:
    result.settings.update({"minutes": minutes, "scenario": SCENARIO, "pacing": "realtime",
                            "warm-up": "the first minute"})
    for row in rows:
        prefix = f"minute_{row['minute']:02d}"
        for name in ("frames", "dropped", "positions", "p50_ms", "p99_ms"):
            result.figure(f"{prefix}/{name}", row[name])
        for process, value in row["rss_mb"].items():
            result.figure(f"{prefix}/rss_mb/{process}", value)
    result.table(["minute", "frames published", "dropped by detector", "3D positions",
                  "latency p50 (ms)", "latency p99 (ms)",
                  *[f"{name} RSS (MB)" for name in PROCESSES], "restarts"],
                 [[row["minute"], row["frames"], row["dropped"], row["positions"], row["p50_ms"],
                   row["p99_ms"], *[None if row["rss_mb"][name] is None
                                    else round(row["rss_mb"][name], 1) for name in PROCESSES],
                   sum(row["restarts"].values())] for row in rows],
                 caption="per minute of the soak; frames and latencies are counted at this "
                         "program's own subscriber")
    last = rows[-1] if rows else None
    restarts = {name: (last["restarts"][name] if last else 0) for name in PROCESSES}
    growth: dict[str, float] = {}
    if len(rows) >= 2:
        for name in PROCESSES:
            before, after = rows[0]["rss_mb"][name], rows[-1]["rss_mb"][name]
            if before is not None and after is not None:
                growth[name] = after - before
    for name in PROCESSES:
        result.figure(f"restarts/{name}", restarts[name])
        result.figure(f"rss_growth_mb/{name}", None if name not in growth else round(growth[name], 2))
    total_restarts = sum(restarts.values())
    result.figure("restarts/total", total_restarts)
    result.goal("restarts", "no process restarted or replaced", "0", str(total_restarts),
                total_restarts == 0 and bool(rows))
    worst = max(growth.values()) if len(growth) == len(PROCESSES) else math.inf
    result.goal("memory", "resident memory growth per process after the warm-up minute",
                f"< {MEMORY_GROWTH_LIMIT_MB:g} MB",
                "not measured" if worst == math.inf else f"max {worst:.1f} MB",
                worst < MEMORY_GROWTH_LIMIT_MB)
    frames = [row["frames"] for row in rows]
    if frames:
        result.figure("frames_per_minute/min", min(frames))
    result.notes.append("Memory growth is from the end of minute 1 to the end of the run; the "
                        "latency pairs a 3D position with the frame of the same seq, both as "
                        "they arrived at the experiment's subscriber.")
    print(f"soak: {len(rows)} minutes, {total_restarts} restarts, RSS growth "
          + ", ".join(f"{name} {value:+.1f} MB" for name, value in growth.items()))
