"""What watching and bridging cost: ``balltrack view`` (Rerun, then Foxglove) and the ROS 2
bridge beside the running system.

    python -m balltrack.experiments.viewer_cost [--seconds 30]

Starts the whole system (router, simulator in realtime pacing on the ``orbit`` scenario, 640x480
at 30 Hz, detector, locator, follower) and measures, for ``--seconds`` each, in this order:
no viewer, ``balltrack view`` (Rerun, no browser attached: the gRPC server keeps the data for
one), ``balltrack view --foxglove`` with a WebSocket client of this program subscribed to every
channel (so the server encodes and sends everything), the ROS 2 bridge (``balltrack run
ros2_bridge``, its defaults: detected_ball, detected_ball_3d and cmd_vel out to ROS), and no
viewer again. Per phase:

* frame -> ``detected_ball_3d`` latency p50/p99 at this program's subscriber (as the soak and the
  demo measure it): what the viewer adds to the robot's reaction time;
* CPU (% of one core) of the viewer or bridge ("it") and of the detector, which draws ``image_out`` only while
  someone subscribes to it;
* the viewer's own lag, arrival of a message -> shown (its exit line), and what it showed/skipped;
* the bridge's added latency: arrival of a ``detected_ball_3d`` -> arrival of the same stamp's
  ``PointStamped`` on ``ros/detected_ball_3d``, both at this program's subscribers.
"""

import argparse
import io
import json
import re
import tempfile
import threading
import time
from pathlib import Path

from balltrack.common import keys
from balltrack.common.arguments import ArgumentParser, number
from balltrack.common.messages import MessageError, decode
from balltrack.common.network import free_port
from balltrack.common.session import open_session
from balltrack.common.terminal import exit_with
from balltrack.common.waiting import poll_until
from balltrack.deploy.launcher import start_system
from balltrack.experiments.base import quantile
from balltrack.experiments.lags import ArrivalLags
from balltrack.deploy.command import Command
from balltrack.experiments.processes import cpu_seconds
from balltrack.experiments.soak import SCENARIO, Counters

WARM_UP_SECONDS = 5.0  # after a viewer starts: its subscriptions routed, the detector drawing
SUMMARY = re.compile(r"balltrack view: (shown .*)$", re.M)


class FoxgloveClient:
    """Subscribes to every advertised channel of a Foxglove server and counts what arrives."""

    def __init__(self, url: str):
        from websockets.sync.client import connect

        self.messages = 0
        self.bytes = 0
        self._connection = connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None)
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        subscribed: set[int] = set()
        try:
            for frame in self._connection:
                if isinstance(frame, str):
                    message = json.loads(frame)
                    if message.get("op") == "advertise":
                        new = [channel["id"] for channel in message["channels"] if channel["id"] not in subscribed]
                        subscribed.update(new)
                        self._connection.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": channel, "channelId": channel} for channel in new]}))
                else:
                    self.messages += 1
                    self.bytes += len(frame)
        except Exception:  # the connection closed: the phase is over
            return

    def close(self) -> None:
        self._connection.close()
        self._thread.join(timeout=5)


def _measure(counters: Counters, pids: dict[str, int | None], seconds: float) -> dict:
    counters.take()
    cpu_before = {name: cpu_seconds(pid) for name, pid in pids.items()}
    start = time.monotonic()
    time.sleep(seconds)  # the measurement window itself, not a wait for a condition
    elapsed = time.monotonic() - start
    frames, latencies, _ = counters.take()
    row = {"frames_per_s": frames / elapsed, "positions": len(latencies),
           "p50_ms": 1000 * (quantile(latencies, 0.5) or float("nan")),
           "p99_ms": 1000 * (quantile(latencies, 0.99) or float("nan"))}
    for name, pid in pids.items():
        row[f"{name}_cpu_percent"] = 100 * (cpu_seconds(pid) - cpu_before[name]) / elapsed
    return row


def _wait_for_positions(counters: Counters, timeout: float = 120) -> None:
    """Until the system locates the ball (frames go through the whole pipeline)."""
    if not poll_until(counters.located, timeout, interval=0.1):
        raise RuntimeError(f"no detected_ball_3d in {timeout:.0f} s")


class BridgeLag:
    """Arrival of each ``detected_ball_3d`` and of its ROS 2 twin, matched by header stamp."""

    def __init__(self, session):
        from balltrack.services.ros2_bridge import convert

        self.ball_to_twin = ArrivalLags(keep=1000)
        self._lock = threading.Lock()

        def on_ball(sample):
            arrival = time.monotonic()
            try:
                stamp = decode("Ball3D", sample.payload.to_bytes())["header"]["stamp"]
            except MessageError:
                return
            with self._lock:
                self.ball_to_twin.start(stamp, arrival)

        def on_ros(sample):
            arrival = time.monotonic()
            stamp = convert.stamp_from_ros(convert.deserialize(sample.payload.to_bytes(), convert.POINT_STAMPED).header)
            with self._lock:
                self.ball_to_twin.end(stamp, arrival, once=True)

        self._subscribers = [session.declare_subscriber(keys.DETECTED_BALL_3D, on_ball),
                             session.declare_subscriber("ros/" + keys.DETECTED_BALL_3D, on_ros)]

    def take(self) -> list[float]:
        """The lags (s) since the last call."""
        with self._lock:
            return self.ball_to_twin.take()

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()


def _summary(command: Command) -> str:
    command.stop()
    found = SUMMARY.search(command.output())
    return found.group(1) if found else "(no summary line)"


def main(argv=None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.viewer_cost", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=number(above=0), default=30.0, help="measurement window per phase")
    args = parser.parse_args(argv)
    rows = []
    settings = {"simulator": [f"scenario={SCENARIO}", "pacing=realtime"]}
    with tempfile.TemporaryDirectory(prefix="balltrack-viewer-cost-") as folder, \
            start_system(Path(folder) / "run", settings=settings, output=io.StringIO()) as system:
        session = open_session([system.endpoint], open_timeout=10)
        counters = Counters(session)
        try:
            _wait_for_positions(counters)
            detector = {"detector": system.pid("detector")}
            rows.append(("no viewer", _measure(counters, detector, args.seconds), ""))

            rerun = Command(["view", "--connect", system.endpoint, "--port", str(free_port()),
                             "--grpc-port", str(free_port())], Path(folder) / "rerun.log")
            rerun.wait_for("Rerun viewer on")
            time.sleep(WARM_UP_SECONDS)
            row = _measure(counters, {**detector, "viewer": rerun.pid}, args.seconds)
            rows.append(("Rerun (no browser)", row, _summary(rerun)))

            port = free_port()
            foxglove = Command(["view", "--foxglove", "--connect", system.endpoint, "--port", str(port)],
                               Path(folder) / "foxglove.log")
            foxglove.wait_for("Foxglove server on")
            client = FoxgloveClient(f"ws://127.0.0.1:{port}")
            time.sleep(WARM_UP_SECONDS)
            row = _measure(counters, {**detector, "viewer": foxglove.pid}, args.seconds)
            received = client.messages
            client.close()
            rows.append((f"Foxglove (1 client, {received / args.seconds:.0f} msg/s)", row,
                         _summary(foxglove)))

            bridge = Command(["run", "ros2_bridge", "--connect", system.endpoint], Path(folder) / "bridge.log")
            lag = BridgeLag(session)
            try:
                bridge.wait_for("routes:")
                time.sleep(WARM_UP_SECONDS)
                lag.take()
                row = _measure(counters, {**detector, "viewer": bridge.pid}, args.seconds)
                lags = lag.take()
            finally:
                lag.close()
                bridge.stop()
            rows.append(("ROS 2 bridge", row, f"{len(lags)} PointStamped; detected_ball_3d -> ros/detected_ball_3d "
                         f"p50 {1000 * (quantile(lags, 0.5) or float('nan')):.2f} ms, "
                         f"p99 {1000 * (quantile(lags, 0.99) or float('nan')):.2f} ms"))

            rows.append(("no viewer, again", _measure(counters, detector, args.seconds), ""))
        finally:
            counters.close()
            session.close()
    print(f"{args.seconds:g} s per phase, 640x480 at 30 Hz, scenario {SCENARIO}")
    print(f"{'phase':<40} {'frames/s':>8} {'p50 ms':>7} {'p99 ms':>7} {'detector %':>10} {'it %':>9}")
    for name, row, _ in rows:
        viewer = row.get("viewer_cpu_percent")
        print(f"{name:<40} {row['frames_per_s']:>8.1f} {row['p50_ms']:>7.1f} {row['p99_ms']:>7.1f} "
              f"{row['detector_cpu_percent']:>10.1f} {'-' if viewer is None else f'{viewer:.1f}':>9}")
    for name, _, summary in rows:
        if summary:
            print(f"  {name}: {summary}")
    return 0


if __name__ == "__main__":
    exit_with(main)
