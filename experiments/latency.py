"""Reaction time in the demo: frame -> ``detected_ball_3d`` and frame -> ``cmd_vel``.

Runs the demo (``deploy/demo.py``: router, simulator in real time at 30 Hz, the detector,
locator and follower in one process, ``balltrack record`` writing ``run.mcap``) in each
follower mode (the goals' mode three times, judged on the median run) and reads the latencies
it measured, by wall-clock arrival at its subscriber of a frame and of what was derived from it
(same ``seq``; ``detected_ball`` too, the detector's share):

* ``event``: the follower commands on each detection (``command_on_detection=true``, issue 9's
  mode; the 10 Hz timer stays as the search watchdog);
* ``separate``: the same with the detector, locator and follower in a process each (``--separate``,
  as on separate hosts), alternated with the ``event`` runs: what joining them saves (no goal);
* ``timer``: the paper's default, a command every 100 ms (frame -> ``cmd_vel`` includes the
  wait for the timer; shown for comparison, it has no goal).

Goals (issue 9, on this 2-core machine with the simulator running): frame -> detected_ball_3d
p50 <= 4 ms and p99 <= 12 ms; frame -> cmd_vel p50 <= 5 ms in event mode. Each demo must also
reach the ball, or its figures are not a chase's.

Example::

    balltrack experiment latency --out runs/latency
"""

import json

from balltrack.deploy.command import Command

NAME = "latency"
TITLE = "Reaction time in the demo (frame to 3D position and to command)"

GOAL_BALL_P50_MS = 4.0
GOAL_BALL_P99_MS = 12.0
GOAL_COMMAND_P50_MS = 5.0
EVENT = ["--set", "follower.command_on_detection=true"]
MODES = {"event": EVENT, "separate": [*EVENT, "--separate"], "timer": []}
# Demos in event mode, and as many separate, in a full run (one each with --quick).
EVENT_RUNS = 3


def run_demo(run_dir, extra: list[str], time_limit: float) -> dict:
    """The demo's summary.json after one run in ``run_dir``."""
    demo = Command(["--no-video", "--port", "0", "--run-dir", str(run_dir), "--time-limit", f"{time_limit:g}",
                    *extra], run_dir.parent / f"{run_dir.name}.log", module="balltrack.deploy.demo")
    try:
        demo.popen.wait()
    finally:
        # (interrupted: SIGTERM lets the demo stop the system it started, as its Ctrl-C does)
        demo.stop(timeout=60)
    summary = run_dir / "summary.json"
    if not summary.is_file():
        raise RuntimeError(f"the demo wrote no {summary} (see {run_dir.parent / run_dir.name}.log)")
    return json.loads(summary.read_text())


def median_run(summaries: list[dict], key: str, metric: str) -> float:
    """The median over runs of one latency figure (for an even count, the upper middle run's:
    a figure some run measured, never an average of two)."""
    values = sorted(summary["latency_ms"][key][metric] for summary in summaries)
    return values[len(values) // 2]


def run(options) -> "ExperimentResult":
    from balltrack.experiments.base import ExperimentResult, Stopwatch, record_machine_speed

    clock = Stopwatch()
    result = ExperimentResult(NAME, TITLE, mode="zenoh", quick=options.quick)
    record_machine_speed(result)
    folder = options.out / NAME
    folder.mkdir(parents=True, exist_ok=True)
    # The goals' mode is run several times: one demo's p50 moves by a few tenths of a
    # millisecond from run to run on this machine (5.5 then 5.7 ms, back to back), as much
    # as a change being measured; the goals read the median run. The timer mode has no goal.
    # (event and separate alternate, so that the machine's changes from minute to minute
    # fall on both alike)
    schedule = [mode for _ in range(options.budget(1, EVENT_RUNS)) for mode in ("event", "separate")] + ["timer"]
    rows, summaries = [], {mode: [] for mode in MODES}
    for mode in schedule:
        index = len(summaries[mode])
        name = mode if index == 0 else f"{mode}_{index + 1}"
        summary = run_demo(folder / name, MODES[mode], 60.0)
        summaries[mode].append(summary)
        latency = summary["latency_ms"]
        stats = summary.get("service_stats", {})
        detector_ms = stats.get("detector", {}).get("p50_ms")
        locator_ms = stats.get("locator", {}).get("p50_ms")
        rows.append([name, "yes" if summary["reached"] else "no",
                     f"{latency['detected_ball']['p50_ms']:.1f}",
                     f"{latency['detected_ball_3d']['p50_ms']:.1f} / {latency['detected_ball_3d']['p99_ms']:.1f}",
                     f"{latency['cmd_vel']['p50_ms']:.1f} / {latency['cmd_vel']['p99_ms']:.1f}",
                     "-" if detector_ms is None else f"{detector_ms:.1f}",
                     "-" if locator_ms is None else f"{locator_ms:.2f}",
                     latency["detected_ball_3d"]["count"]])
    for mode, runs in summaries.items():
        result.figure(f"{mode}/runs", len(runs))
        result.figure(f"{mode}/reached", all(summary["reached"] for summary in runs))
        for key in ("detected_ball", "detected_ball_3d", "cmd_vel"):
            for metric in ("p50_ms", "p99_ms", "count"):
                result.figure(f"{mode}/{key}/{metric}", median_run(runs, key, metric))
            result.figure(f"{mode}/{key}/p50_ms_each_run",
                          [summary["latency_ms"][key]["p50_ms"] for summary in runs])
        for service in ("detector", "locator"):
            handlers = sorted(value for value in (summary.get("service_stats", {}).get(service, {}).get("p50_ms")
                                                  for summary in runs) if value is not None)
            result.figure(f"{mode}/{service}_handler_p50_ms",
                          handlers[len(handlers) // 2] if handlers else None)
        result.figure(f"{mode}/render_ms", runs[0].get("service_stats", {}).get("simulator", {}).get("render_ms"))
        result.figure(f"{mode}/cmd_vel_per_s", runs[0]["messages_per_s"].get("cmd_vel"))
    event = summaries["event"]
    ball_p50 = median_run(event, "detected_ball_3d", "p50_ms")
    ball_p99 = median_run(event, "detected_ball_3d", "p99_ms")
    command_p50 = median_run(event, "cmd_vel", "p50_ms")
    reached = all(summary["reached"] for summary in event)
    runs_text = f"median of {len(event)} runs" if len(event) > 1 else "one run"
    result.goal("ball_3d", f"frame -> detected_ball_3d p50 <= {GOAL_BALL_P50_MS:g} ms and p99 <= "
                           f"{GOAL_BALL_P99_MS:g} ms in the demo (event mode, ball reached)",
                f"<= {GOAL_BALL_P50_MS:g} / {GOAL_BALL_P99_MS:g} ms",
                f"{ball_p50:.1f} / {ball_p99:.1f} ms ({runs_text})",
                reached and ball_p50 <= GOAL_BALL_P50_MS and ball_p99 <= GOAL_BALL_P99_MS)
    result.goal("cmd_vel", f"frame -> cmd_vel p50 <= {GOAL_COMMAND_P50_MS:g} ms in the demo, "
                           "follower in event mode (ball reached)",
                f"<= {GOAL_COMMAND_P50_MS:g} ms", f"{command_p50:.1f} ms ({runs_text})",
                reached and command_p50 <= GOAL_COMMAND_P50_MS)
    result.table(["run (follower mode)", "reached", "frame -> detected_ball p50 (ms)", "frame -> 3D p50 / p99 (ms)",
                  "frame -> cmd_vel p50 / p99 (ms)", "detector handler p50 (ms)",
                  "locator handler p50 (ms)", "frames"], rows,
                 f"Each demo run in the order run (arrival times at the demo's subscriber); the goals "
                 f"read the median of the {len(event)} event-mode run{'s' if len(event) > 1 else ''}. "
                 f"Handler times are each service's own (in one process, the detector's leaves "
                 f"out the locator's and follower's handlers that its put of detected_ball runs):")
    separate = summaries["separate"]
    result.table(["event mode, median run", "frame -> detected_ball p50 (ms)", "frame -> 3D p50 / p99 (ms)",
                  "frame -> cmd_vel p50 (ms)"],
                 [[label, f"{median_run(runs, 'detected_ball', 'p50_ms'):.1f}",
                   f"{median_run(runs, 'detected_ball_3d', 'p50_ms'):.1f} / {median_run(runs, 'detected_ball_3d', 'p99_ms'):.1f}",
                   f"{median_run(runs, 'cmd_vel', 'p50_ms'):.1f}"]
                  for label, runs in (("detector, locator, follower in one process (the demo's default)", event),
                                      ("a process each (--separate)", separate))],
                 "What running the three in one process saves (the runs above, alternated):")
    result.compare("frame -> cmd_vel", "not reported (10 Hz control loop)",
                   f"p50 {command_p50:.1f} ms (event mode), "
                   f"{median_run(summaries['timer'], 'cmd_vel', 'p50_ms'):.1f} ms (10 Hz timer)")
    result.settings = {"demo": "chase scenario, 640x480 at 30 Hz, real time, run.mcap recorded, "
                               "detector+locator+follower in one process (separate: one each)",
                       "runs": ", ".join(str(folder / row[0]) for row in rows)}
    result.seconds = clock.seconds
    return result
