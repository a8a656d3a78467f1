"""What the ROS 2 bridge costs: its CPU time and the latency it adds per message, over loopback.

    python -m balltrack.experiments.ros2_bridge_latency [--count 300] [--rate 30]

Starts a router and the bridge (``deploy/launcher.py``), then for two streams publishes
``--count`` messages at ``--rate`` Hz and times each one from ``put`` to its arrival, all in
this process (one clock):

- ``Ball3D`` on ``detected_ball_3d`` -> ``geometry_msgs/msg/PointStamped`` on ``ros/detected_ball_3d``;
- a 640x480 rgb8 ``sensor_msgs/msg/Image`` in CDR on ``ros/camera/image_raw`` -> balltrack's
  ``Image`` on ``camera/image_raw``.

Each stream is measured a second time without the bridge: the same payload from one client
session of this process to another (one hop through the router instead of two), so the
difference of the medians is what the bridge adds. CPU is the bridge process's user + system time
(``/proc/<pid>/stat``) over each stream, per message. Linux only (``/proc``).
"""

import argparse
import os
import statistics
import tempfile
import threading
import time

import numpy as np

from balltrack.common.arguments import ArgumentParser, integer, number
from balltrack.common.messages import encode, header
from balltrack.common.session import open_session
from balltrack.common.terminal import exit_with
from balltrack.deploy.launcher import start_system
from balltrack.experiments.processes import cpu_seconds
from balltrack.services.ros2_bridge import convert

def ball3d(index: int) -> bytes:
    return encode("Ball3D", {"header": header(index, index, "camera_optical"),
                             "x": 0.1, "y": 0.2, "z": 1.5, "distance": 1.52})


def ros_image(index: int, pixels: np.ndarray) -> bytes:
    types = convert.TYPESTORE.types
    height, width = pixels.shape[:2]
    message = types[convert.IMAGE](
        header=types["std_msgs/msg/Header"](stamp=convert.ros_time(index), frame_id="camera"),
        height=height, width=width, encoding="rgb8", is_bigendian=0, step=width * 3,
        data=pixels.reshape(-1))
    return convert.serialize(message, convert.IMAGE)


def stream(sessions, publish_key: str, receive_key: str, payloads: list[bytes], index_of, rate: float,
           pid: int | None) -> dict:
    """Publish ``payloads[:-1]`` at ``rate``; the arrival latencies (ms) and the bridge's CPU.
    The last payload is the warm-up: sent until one arrives, so every route is in place."""
    sent: dict[int, int] = {}
    latencies: list[float] = []
    done, warm = threading.Event(), threading.Event()
    measured = payloads[:-1]

    def on_sample(sample):
        arrived = time.perf_counter_ns()
        index = index_of(sample.payload.to_bytes())
        if index == len(measured):
            warm.set()
        elif index in sent:
            latencies.append((arrived - sent[index]) / 1e6)
            if len(latencies) == len(measured):
                done.set()

    sender, receiver = sessions
    subscriber = receiver.declare_subscriber(receive_key, on_sample)
    publisher = sender.declare_publisher(publish_key)
    deadline = time.monotonic() + 10.0
    while not warm.is_set():
        if time.monotonic() > deadline:
            raise RuntimeError(f"nothing arrived on {receive_key} for 10 s")
        publisher.put(payloads[-1])
        warm.wait(0.05)
    cpu_before = cpu_seconds(pid) if pid else 0.0
    next_time = time.perf_counter()
    for index, payload in enumerate(measured):
        sent[index] = time.perf_counter_ns()
        publisher.put(payload)
        next_time += 1.0 / rate
        time.sleep(max(0.0, next_time - time.perf_counter()))
    done.wait(10.0)
    cpu = (cpu_seconds(pid) - cpu_before) if pid else 0.0
    subscriber.undeclare()
    publisher.undeclare()
    ordered = sorted(latencies)
    return {"received": len(latencies), "sent": len(measured),
            "p50_ms": statistics.median(ordered) if ordered else float("nan"),
            "p99_ms": ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))] if ordered else float("nan"),
            "cpu_ms_per_message": 1000.0 * cpu / len(measured)}


def main(argv=None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.ros2_bridge_latency", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=integer(minimum=1), default=300, help="messages per stream")
    parser.add_argument("--rate", type=number(above=0), default=30.0, help="messages per second")
    args = parser.parse_args(argv)

    pixels = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    # One more than measured: the last is the warm-up.
    balls = [ball3d(index) for index in range(args.count + 1)]
    images = [ros_image(index, pixels) for index in range(args.count + 1)]

    def stamp_of_point_stamped(data: bytes) -> int:
        return convert.stamp_from_ros(convert.deserialize(data, convert.POINT_STAMPED).header)

    def stamp_of_ros_image(data: bytes) -> int:
        return convert.stamp_from_ros(convert.deserialize(data, convert.IMAGE).header)

    def stamp_of_msgpack(data: bytes) -> int:
        import msgpack
        return msgpack.unpackb(data)["header"]["stamp"]

    with tempfile.TemporaryDirectory() as run_dir:
        system = start_system(run_dir, ("ros2_bridge",), output=open(os.devnull, "w"))
        try:
            pid = system.pid("ros2_bridge")
            # Two clients, so the direct path is one hop through the router (a session delivers
            # its own puts to its own subscribers without the router) and the bridged path two.
            sessions = [open_session([system.endpoint], open_timeout=10) for _ in range(2)]
            rows = [
                ("Ball3D -> ros/detected_ball_3d (bridge)",
                 stream(sessions, "detected_ball_3d", "ros/detected_ball_3d", balls, stamp_of_point_stamped,
                        args.rate, pid)),
                ("Ball3D, same payload, no bridge",
                 stream(sessions, "bench/direct", "bench/direct", balls, stamp_of_msgpack, args.rate, None)),
                ("Image 640x480 rgb8 ros/camera/image_raw -> camera/image_raw (bridge)",
                 stream(sessions, "ros/camera/image_raw", "camera/image_raw", images, stamp_of_msgpack,
                        args.rate, pid)),
                ("Image, same CDR payload, no bridge",
                 stream(sessions, "bench/direct", "bench/direct", images, stamp_of_ros_image, args.rate, None)),
            ]
            for session in sessions:
                session.close()
        finally:
            system.stop()
    print(f"{args.count} messages per stream at {args.rate:g} Hz over loopback (one router)")
    for name, row in rows:
        cpu = f"  bridge CPU {row['cpu_ms_per_message']:.2f} ms/message" if "(bridge)" in name else ""
        print(f"  {name}: {row['received']}/{row['sent']} arrived, p50 {row['p50_ms']:.2f} ms, "
              f"p99 {row['p99_ms']:.2f} ms{cpu}")
    for label, bridged, direct in (("Ball3D", rows[0][1], rows[1][1]), ("Image", rows[2][1], rows[3][1])):
        print(f"  added by the bridge, {label}: p50 {bridged['p50_ms'] - direct['p50_ms']:.2f} ms; "
              f"CPU {bridged['cpu_ms_per_message'] * args.rate / 10:.1f} % of a core at {args.rate:g} Hz")
    return 0


if __name__ == "__main__":
    exit_with(main)
