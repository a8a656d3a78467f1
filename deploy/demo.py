"""The demo: a simulated robot finds a tennis ball and drives up to it (the paper's basic run).

    python -m balltrack.deploy.demo [--time-limit 60] [--run-dir runs/demo-YYYYmmdd-HHMMSS] [--secure DIR]

Starts a router, the simulator (``chase`` scenario, real-time pacing) and the detector, the
locator and the follower under the supervisor (``deploy/launcher.py``), with the parameter
files of ``deploy/config/demo``: the simulator in a process of its own, the other three in
one (``balltrack run detector+locator+follower``; ``--separate`` or ``--secure``: a process
each). Once every service is alive it restarts the
scenario and watches: the run ends when the robot has reached the ball (ground truth: robot
centre within 0.35 m of the ball's centre and facing it within 10 degrees, held for 1 s of
simulated time: ``common/referee.py``) or when the time limit (wall seconds) is over.

Into the run folder go the services' logs, ``video.mp4`` (the detector's annotated camera
frames, ``image_out``, with the locator's 3D estimate written on them), ``trajectory.png``
(the ball in the camera frame over time and the robot's path, like the paper's Fig. 8),
``velocity.png`` (linear and angular velocity over time, like its Fig. 6), ``frame.png``,
``summary.json`` and ``run.mcap`` (the messages, for ``balltrack play`` and ``balltrack info``,
written by ``balltrack record`` in a process of its own, ``record.log``). Exit status 0 when the ball was reached, 1 otherwise.

Latency is measured here, by wall-clock arrival times at this program's own subscriber: the
simulator's header stamps are *simulated* time, so they cannot be compared with the wall
clock. Every message derived from a frame carries the frame's ``seq``; the latency of a
``detected_ball_3d`` is its arrival time minus the arrival time of the ``camera/image_raw``
with the same ``seq``; the same for the ``detected_ball`` it was located from (the detector's
share of it) and for the first ``cmd_vel`` carrying that ``seq`` (which also includes the wait
for the follower's 10 Hz timer).
"""

import argparse
import json
import math
import os
import signal
import sys
import threading
import time
from importlib import resources
from pathlib import Path

import numpy as np

from balltrack.common import keys as key_table
from balltrack.common.arguments import ArgumentParser, integer, number
from balltrack.common.keys import Keys
from balltrack.common.referee import HOLD_SECONDS, REACH_DISTANCE, REACH_HEADING_DEGREES, Referee, errors
from balltrack.common.session import close_session, open_session, secure_client_path, secure_router_path
from balltrack.common.shutdown import set_from_signal
from balltrack.common.terminal import exit_with
from balltrack.common.waiting import poll_until
from balltrack.deploy.cli import LaunchError, parse_service_overrides
from balltrack.deploy.command import Command
from balltrack.deploy.demo_observer import Observer, VideoWriter
from balltrack.deploy.launcher import SERVICES, start_system
from balltrack.deploy.recording import DEFAULT_KEYS

DEMO_CONFIG = resources.files("balltrack.deploy") / "config" / "demo"
# run.mcap (`balltrack play`, `balltrack info`): every data and stats key but image_tuning
# (subscribing to it would make the detector compute the colour mask for nobody) and image_out
# (video.mp4 shows it; the raw frames are enough to replay the run).
RECORDED_KEYS = tuple(key for key in DEFAULT_KEYS
                      if key not in (key_table.IMAGE_TUNING, key_table.IMAGE_OUT))


# The recorder leaves each message this long before compressing it: the pipeline has answered
# a frame by then (frame -> detected_ball_3d p99 ~12 ms), and the 33 ms frame period leaves
# the rest for the recorder's ~5 ms a frame. Measured in the demo beside the recorder, under
# load: frame -> detected_ball_3d p50 7.2-7.8 -> 6.2-6.4 ms, p99 15-21 -> 10-11 ms.
RECORD_HOLD = 0.015
# And yields a shared core to the pipeline: p99 frame -> detected_ball_3d 18.6/20.6/25.5 ms
# with the recorder at nice 0, 14.5/14.8/21.2 ms at nice 10, three demos each, alternated
# (p50 unchanged, 9.1-9.7 ms on 2026-11-25's slower machine).
RECORD_NICE = 10


# The robot's side of the demo in one process: a detection reaches the locator and the
# follower as a call instead of waking two more processes on two cores. Frame ->
# detected_ball_3d p50 3.0, 3.1 and 3.0 ms against 3.6, 3.6 and 3.9 in separate processes
# (event mode, demos alternated); 3.4, 3.2 and 3.3 against 3.8, 3.6 and 3.7 in `balltrack
# experiment latency` (frame -> cmd_vel there 3.7 either way: joined, the follower's handler
# follows the locator's on one thread).
JOINED = ("detector+locator+follower", "simulator")


def demo_processes(args) -> tuple[str, ...]:
    """The processes the demo starts: JOINED, or one per service with ``--separate`` or
    ``--secure`` (where each service has its own certificate)."""
    return SERVICES if args.separate or args.secure else JOINED


def start_recording(run_dir: Path, endpoint: str, args, stop: threading.Event) -> Command | None:
    """``balltrack record`` into run.mcap, in a process of its own, once it has subscribed.

    Compressing 30 frames a second holds the interpreter lock for milliseconds at a time (a
    thread meaning to wake after 1 ms woke p99 3 ms, at worst 13 ms late beside the recording
    writer): in this process that would delay the arrivals the demo times."""
    arguments = ["record", "-o", str(run_dir / "run.mcap"), "--connect", endpoint,
                 "--hold", str(RECORD_HOLD), "--nice", str(RECORD_NICE), *RECORDED_KEYS]
    if args.namespace:
        arguments += ["--namespace", args.namespace]
    if args.secure:
        arguments += ["--secure", str(args.secure)]  # as the demo: the operator role
    else:
        # A peer, as the services: their messages reach it over direct links. As a client of
        # the router, every message to it took one more hop, through the router's process,
        # while the pipeline worked on the frame: frame -> detected_ball_3d p50 4.3 and 4.3 ms
        # as a peer against 4.4 and 4.5 (`balltrack experiment latency`, alternated).
        arguments += ["--peer"]
    recorder = Command(arguments, run_dir / "record.log")
    try:
        recorder.wait_for("recording ", 30)  # said once its subscribers are declared
    except RuntimeError as error:
        recorder.stop()
        if not stop.is_set():
            print(f"demo: the recorder did not start: {error}", file=sys.stderr)
        return None
    return recorder


def stop_recording(recorder: Command, run_dir: Path) -> None:
    """Stop the recorder, which writes what it holds and finishes run.mcap."""
    status = recorder.stop(timeout=60)
    if status != 0:
        print(f"demo: the recorder exited with status {status} (see {run_dir}/record.log)", file=sys.stderr)


def run(args) -> int:
    run_dir = Path(args.run_dir or f"runs/demo-{time.strftime('%Y%m%d-%H%M%S')}").resolve()
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"--run-dir: cannot make {run_dir}: {error.strerror}") from None
    config_dir = Path(args.config_dir).resolve()
    settings = parse_service_overrides(args.overrides, list(SERVICES))
    stop = threading.Event()

    def on_signal(*_):
        if stop.is_set():  # a second Ctrl-C: stop waiting for anything
            raise KeyboardInterrupt
        set_from_signal(stop)

    for signal_number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signal_number, on_signal)

    referee = Referee(args.reach_distance, args.reach_heading, args.hold)
    system = None
    session = observer = video = recording = None
    reached = False
    started_wall = time.monotonic()
    result: dict = {}
    try:
        print(f"balltrack demo: run folder {run_dir}", flush=True)
        try:
            system = start_system(run_dir, demo_processes(args), settings, config_dir, args.namespace, args.port,
                                  wait=args.start_timeout, secure=args.secure, host=args.host)
        except LaunchError as error:
            print(f"demo: {error}", file=sys.stderr)
            return 1
        endpoint = system.endpoint
        print(f"  router on {endpoint}; watch it from another terminal: balltrack status --connect "
              f"{endpoint}" + (f" --secure {args.secure}" if args.secure else ""), flush=True)
        # With a secure profile the demo is its operator: it watches and resets the simulator.
        # Otherwise it joins its router as a peer, as the services do: it times their messages
        # as an app on their host receives them (see common/session.py).
        session = open_session([endpoint], str(secure_client_path(args.secure, "operator")) if args.secure else None,
                               open_timeout=10, peer=not args.secure)
        video = None if args.no_video else VideoWriter(run_dir / "video.mp4", 30.0, {})
        if video is not None:
            video.start()
        observer = Observer(session, args.namespace, referee, video)
        recording = start_recording(run_dir, endpoint, args, stop)
        if recording is None:
            return 1
        # The pipeline is up once the detector answers frames; then the scenario restarts so the
        # run starts with every service ready.
        if not poll_until(lambda: observer.counts[key_table.DETECTED_BALLS] > 0
                          and observer.latest_truth is not None, args.start_timeout, stop=stop):
            if not stop.is_set():
                print("demo: the pipeline produced no detected_balls in time", file=sys.stderr)
            return 1
        from balltrack.services.simulator.control import send_command

        reply = send_command(session, {"op": "reset"}, args.namespace)
        if not reply["ok"]:
            print(f"demo: sim/control reset failed: {reply.get('error')}", file=sys.stderr)
            return 1
        seen = observer.counts[key_table.GROUND_TRUTH]
        poll_until(lambda: observer.counts[key_table.GROUND_TRUTH] > seen, 10, stop=stop)
        observer.begin(observer.latest_truth[0])
        print(f"demo: all services alive; scenario restarted; chasing (limit {args.time_limit:.0f} s)",
              flush=True)
        chase_wall = time.monotonic()
        next_report = chase_wall + 5
        while not observer.reached.is_set() and not stop.is_set():
            now = time.monotonic()
            if now - chase_wall >= args.time_limit:
                break
            if now >= next_report:
                next_report += 5
                with observer.lock:
                    if observer.truths:
                        t, truth = observer.truths[-1]
                        distance, heading = errors(truth)
                        print(f"  t={t:5.1f} s  distance {distance:.2f} m  heading error "
                              f"{math.degrees(heading):5.1f} deg", flush=True)
            observer.reached.wait(0.2)
        reached = observer.reached.is_set()
        chase_seconds = time.monotonic() - chase_wall
        with observer.lock:
            final_t, final_truth = observer.truths[-1] if observer.truths else (0.0, None)
        result = summarise(args, observer, referee, reached, final_t, final_truth, chase_seconds, endpoint,
                           run_dir)
        result["interrupted"] = stop.is_set() and not reached
    finally:
        if observer is not None:
            observer.close()
        if recording is not None:
            stop_recording(recording, run_dir)
        if session is not None and (reason := close_session(session)):
            print(f"demo: {reason}", file=sys.stderr)
        if system is not None:
            code = system.stop()
            if code != 0:
                print(f"demo: the supervisor stopped with status {code} (see {run_dir}/supervisor.log)",
                      file=sys.stderr)
            result["supervisor_exit"] = code
        if video is not None:
            video.finish()
    write_outputs(run_dir, observer, video, result)
    print_summary(result)
    print(f"  total wall time {time.monotonic() - started_wall:.1f} s", flush=True)
    return 0 if reached else 1


def summarise(args, observer: Observer, referee: Referee, reached: bool, final_t: float, final_truth,
              chase_seconds: float, endpoint: str, run_dir: Path) -> dict:
    distance, heading = errors(final_truth) if final_truth else (None, None)
    camera_distance = None
    if final_truth and final_truth["balls"]:
        camera_distance = math.dist([0, 0, 0], final_truth["balls"][0]["in_camera"])
    with observer.lock:
        counts = dict(observer.counts)
        stats = dict(observer.stats)
    rates = {key: round(count / chase_seconds, 2) if chase_seconds > 0 else None for key, count in counts.items()}
    simulator = stats.get("simulator", {})
    return {
        "reached": reached,
        "time_to_reach_s": referee.reached_at,
        "time_limit_s": args.time_limit,
        "criteria": referee.criteria(),
        "chase_simulated_s": final_t,
        "chase_wall_s": chase_seconds,
        "final_distance_m": distance,
        "final_camera_distance_m": camera_distance,
        "final_heading_error_deg": math.degrees(heading) if heading is not None else None,
        "final_robot": final_truth["robot"] if final_truth else None,
        "latency_ms": observer.latencies(),
        "messages": counts,
        "messages_per_s": rates,
        "real_time_factor": simulator.get("real_time_factor"),
        "service_stats": stats,
        "endpoint": endpoint,
        "run_dir": str(run_dir),
    }


def write_outputs(run_dir: Path, observer: Observer | None, video: VideoWriter | None, result: dict) -> None:
    files = {}
    if observer is not None and (observer.truths or observer.estimates):
        from balltrack.deploy.figures import plot_trajectory, plot_velocity

        with observer.lock:
            estimates, truths, commands = list(observer.estimates), list(observer.truths), list(observer.commands)
        title = "reached" if result.get("reached") else "not reached"
        if result.get("time_to_reach_s") is not None:
            title = f"reached in {result['time_to_reach_s']:.1f} s"
        plot_trajectory(run_dir / "trajectory.png", estimates, truths, f"balltrack demo: {title}")
        plot_velocity(run_dir / "velocity.png", commands, truths, f"balltrack demo: {title}")
        files.update(trajectory=str(run_dir / "trajectory.png"), velocity=str(run_dir / "velocity.png"))
    if (run_dir / "run.mcap").is_file():
        files["recording"] = str(run_dir / "run.mcap")
    if video is not None and video.written:
        import cv2

        files["video"] = str(run_dir / "video.mp4")
        picture = video.picture if video.picture is not None else video.last_image
        if picture is not None:
            cv2.imwrite(str(run_dir / "frame.png"), picture)
            files["frame"] = str(run_dir / "frame.png")
            if "trajectory" in files:
                overview = overview_image(picture, cv2.imread(files["trajectory"]))
                cv2.imwrite(str(run_dir / "overview.png"), overview, [cv2.IMWRITE_PNG_COMPRESSION, 9])
                files["overview"] = str(run_dir / "overview.png")
        result["video_frames"] = video.written
    result["files"] = files
    (run_dir / "summary.json").write_text(json.dumps(result, indent=2, default=str) + "\n")
    files["summary"] = str(run_dir / "summary.json")


def overview_image(frame: np.ndarray, trajectory: np.ndarray, height: int = 300) -> np.ndarray:
    """The camera frame with its overlay beside the trajectory figure, both ``height`` px high
    (the README's picture)."""
    import cv2

    def scaled(image):
        return cv2.resize(image, (round(image.shape[1] * height / image.shape[0]), height),
                          interpolation=cv2.INTER_AREA)

    gap = np.full((height, 8, 3), 255, np.uint8)
    return np.hstack([scaled(frame), gap, scaled(trajectory)])


def _ms(value) -> str:
    return "-" if value is None else f"{value:.1f} ms"


def print_summary(result: dict) -> None:
    if not result.get("messages"):
        return
    if result["reached"]:
        print(f"\nREACHED the ball in {result['time_to_reach_s']:.1f} s of simulated time", flush=True)
    elif result.get("interrupted"):
        print(f"\nINTERRUPTED after {result['chase_wall_s']:.0f} s: not reached", flush=True)
    else:
        print(f"\nNOT reached within {result['time_limit_s']:.0f} s", flush=True)
    if result["final_distance_m"] is not None:
        print(f"  final distance {result['final_distance_m']:.3f} m (robot centre to ball centre; "
              f"camera to ball {result['final_camera_distance_m']:.3f} m), heading error "
              f"{result['final_heading_error_deg']:.1f} deg")
    if result.get("real_time_factor") is not None:
        print(f"  simulation real-time factor {result['real_time_factor']:.2f}")
    for name, figures in result["latency_ms"].items():
        print(f"  latency frame -> {name:<16} p50 {_ms(figures['p50_ms'])}, p99 {_ms(figures['p99_ms'])} "
              f"({figures['count']} frames)")
    print("  messages received by the demo (count, per second):")
    for key, count in result["messages"].items():
        print(f"    {key:<20} {count:>6} {result['messages_per_s'][key] or 0:>7.1f}/s")
    for name, path in result.get("files", {}).items():
        print(f"  {name:<10} {path}")
    sys.stdout.flush()


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="python -m balltrack.deploy.demo", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--time-limit", type=number(above=0), default=60.0, metavar="SECONDS",
                        help="give up after this many wall seconds of chase (default 60)")
    parser.add_argument("--run-dir", metavar="DIR", help="default runs/demo-YYYYmmdd-HHMMSS")
    parser.add_argument("--port", type=integer(minimum=0, maximum=65535), default=7447,
                        help="the router's port on 127.0.0.1 (a free one if taken, or 0; default 7447)")
    parser.add_argument("--namespace", default="", metavar="NS")
    parser.add_argument("--config-dir", default=str(DEMO_CONFIG), metavar="DIR",
                        help="parameter files <service>.toml (default deploy/config/demo)")
    parser.add_argument("--set", action="append", default=[], dest="overrides",
                        metavar="SERVICE.KEY=VALUE", help="a service parameter, repeatable")
    parser.add_argument("--reach-distance", type=number(above=0), default=REACH_DISTANCE, metavar="M",
                        help=f"robot centre to ball centre (default {REACH_DISTANCE})")
    parser.add_argument("--reach-heading", type=number(above=0), default=REACH_HEADING_DEGREES, metavar="DEG",
                        help=f"facing the ball within (default {REACH_HEADING_DEGREES:g})")
    parser.add_argument("--hold", type=number(minimum=0), default=HOLD_SECONDS, metavar="SECONDS",
                        help=f"simulated seconds the reach must hold (default {HOLD_SECONDS:g})")
    parser.add_argument("--start-timeout", type=number(above=0), default=90.0, metavar="SECONDS",
                        help="how long the services may take to come up (default 90)")
    parser.add_argument("--no-video", action="store_true", help="no video.mp4 (saves CPU)")
    parser.add_argument("--separate", action="store_true",
                        help="run the detector, locator and follower in a process each, as on "
                             "separate hosts (default: the three in one process)")
    parser.add_argument("--secure", metavar="DIR", help="a secure profile (balltrack secure init): TLS, "
                        "passwords, access control; the demo is its operator")
    parser.add_argument("--host", metavar="NAME", help="with --secure: the profile's host whose router runs "
                        "here (default: the only one)")
    return parser


def check_arguments(args) -> None:
    """ValueError or LaunchError for an argument that cannot work, before a run folder is made
    or a process started."""
    Keys(args.namespace)
    if not Path(args.config_dir).is_dir():
        raise ValueError(f"--config-dir: {args.config_dir} is not a directory")
    parse_service_overrides(args.overrides, list(SERVICES))
    if args.secure:
        secure_router_path(args.secure, args.host)
        secure_client_path(args.secure, "operator")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        check_arguments(args)
        return run(args)
    except (LaunchError, ValueError) as error:
        print(f"demo: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    os.environ.setdefault("MUJOCO_GL", "egl")
    exit_with(main)
