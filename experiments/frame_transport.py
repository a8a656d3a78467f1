"""What it costs to move a camera frame through the router, and what Zenoh's shared memory saves.

    python -m balltrack.experiments.frame_transport [--count 300] [--rate 30] [--subscribers 3]

Starts a router (``deploy/launcher.py``), then ``--subscribers`` subscriber processes, clients of
the router as the services are, and from this process puts ``--count`` messages at ``--rate`` Hz
on one key: frames the size of a 640x480 ``bgr8`` Image (921,600 bytes of pixels), then small
messages (100 bytes, a Ball3D's size). Each message carries its put time on CLOCK_MONOTONIC,
which Linux keeps system-wide, so each subscriber reads put -> callback (with the copy out of
the payload that the services make) on the sender's clock.

Each runs twice: with Zenoh's shared memory as the services have it (the default,
``transport/shared_memory``: between processes of one host, payloads over 3 KB travel as
references to a shared-memory pool) and with it off in every client (payloads copied through
TCP, as to another host). The last column is the share of arrivals that came as shared memory.

The publisher and the subscribers keep freed memory for the next frame (``common/memory.py``),
as the services that make or take every frame do: without it each new frame-sized buffer
costs a page fault per 4 kB touched.

In the demo the router fans each frame out to the detector, the recorder and the demo's own
subscriber: three subscribers, the default here.
"""

import argparse
import io
import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from balltrack.common.arguments import ArgumentParser, integer, number
from balltrack.common.memory import keep_freed_memory
from balltrack.common.session import client_config
from balltrack.common.terminal import exit_with, print_lines
from balltrack.common.waiting import poll_until
from balltrack.deploy.launcher import start_system

KEY = "bench/frame_transport"
FRAME_BYTES = 640 * 480 * 3
SMALL_BYTES = 100
# A message's first 16 bytes: its put time (CLOCK_MONOTONIC ns) and its index (-1: warm-up).
STAMP_BYTES = 16
START_TIMEOUT = 30.0
# How long the last messages may take to arrive before a run is read as it stands (a message
# that never comes shows in the "arrived" column).
ARRIVAL_TIMEOUT = 5.0
MODES = ("on", "off")


def open_client(endpoint: str, shared_memory: bool):
    """A client session as the services open theirs, with shared memory on or off."""
    import zenoh

    config = client_config([endpoint])
    config.insert_json5("transport/shared_memory/enabled", json.dumps(shared_memory))
    return zenoh.open(config)


def stamped(index: int, template: bytearray) -> bytes:
    """The message of ``index``: the template, stamped now, copied out as an encoder makes its
    bytes (so each mode pays one payload-sized copy, as the services do when they encode)."""
    template[:8] = time.monotonic_ns().to_bytes(8, "little")
    template[8:STAMP_BYTES] = index.to_bytes(8, "little", signed=True)
    return bytes(template)


def subscriber(endpoint: str, shared_memory: bool, expected: int) -> int:
    """A subscriber process: prints ``ready``, then ``warm`` at its first arrival, ``shm`` at
    its first shared-memory one and ``all`` once ``expected`` measured messages have come; when
    its stdin closes, one JSON line: the latencies (ms) of the measured messages and how many
    came as shared memory."""
    keep_freed_memory()  # as the services that take every frame do (common/memory.py)
    session = open_client(endpoint, shared_memory)
    lock = threading.Lock()
    latencies: list[float] = []
    said: set[str] = set()
    counts = {"shared": 0}

    def say(word: str) -> None:
        if word not in said:
            said.add(word)
            print(word, flush=True)

    def on_sample(sample) -> None:
        arrival = time.monotonic_ns()
        payload = sample.payload
        in_shared_memory = payload.as_shm() is not None
        data = payload.to_bytes()
        sent, index = int.from_bytes(data[:8], "little"), int.from_bytes(data[8:16], "little", signed=True)
        with lock:
            say("warm")
            if in_shared_memory:
                say("shm")
            if index >= 0:
                latencies.append((arrival - sent) / 1e6)
                counts["shared"] += in_shared_memory
                if len(latencies) >= expected:
                    say("all")

    entity = session.declare_subscriber(KEY, on_sample)
    print("ready", flush=True)
    sys.stdin.read()  # the parent closes it when it has put everything
    entity.undeclare()
    session.close()
    with lock:
        print(json.dumps({"latencies_ms": latencies, "shared": counts["shared"]}), flush=True)
    return 0


class Subscribers:
    """The subscriber processes of one run; their output in log files."""

    def __init__(self, endpoint: str, shared_memory: bool, count: int, expected: int, folder: Path, name: str):
        self.logs = [folder / f"{name}-subscriber-{index}.log" for index in range(count)]
        self.processes = []
        for log in self.logs:
            with open(log, "w") as output:
                self.processes.append(subprocess.Popen(
                    [sys.executable, "-m", "balltrack.experiments.frame_transport", "--subscriber", endpoint,
                     "--shared-memory", "on" if shared_memory else "off", "--expect", str(expected)],
                    stdin=subprocess.PIPE, stdout=output, stderr=subprocess.STDOUT, text=True))

    def all_said(self, word: str) -> bool:
        for process, log in zip(self.processes, self.logs):
            if process.poll() is not None:
                raise RuntimeError(f"a subscriber exited with {process.returncode}: {log.read_text()[-400:]}")
        return all(word in log.read_text().split() for log in self.logs)

    def finish(self) -> list[dict]:
        results = []
        for process, log in zip(self.processes, self.logs):
            process.stdin.close()
            try:
                process.wait(30)
            except subprocess.TimeoutExpired:
                raise RuntimeError(f"a subscriber did not finish in 30 s: {log.read_text()[-400:]}") from None
            results.append(json.loads(log.read_text().strip().splitlines()[-1]))
        return results

    def kill(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.kill()
                process.wait()


def measure(endpoint: str, mode: str, size: int, count: int, rate: float, subscribers: int,
            folder: Path) -> dict:
    """One run (``mode`` one of ``MODES``): the subscribers' latencies of ``count`` messages of
    ``size`` bytes."""
    template = bytearray(size)
    shared_memory = mode == "on"
    session = open_client(endpoint, shared_memory)
    group = Subscribers(endpoint, shared_memory, subscribers, count, folder, f"{mode}-{size}")
    try:
        if not poll_until(lambda: group.all_said("ready"), START_TIMEOUT):
            raise RuntimeError(f"the subscribers did not start in {START_TIMEOUT:g} s")
        publisher = session.declare_publisher(KEY)
        # Warm-up until every route is in place (and, for frames with shared memory on, until
        # the lazily made shared-memory pool is in use), so the measured messages are alike.
        wanted = "shm" if shared_memory and size > SMALL_BYTES else "warm"

        def warmed() -> bool:
            publisher.put(stamped(-1, template))
            return group.all_said(wanted)

        if not poll_until(warmed, START_TIMEOUT, interval=1.0 / rate):
            raise RuntimeError(f"the subscribers did not all say {wanted!r} in {START_TIMEOUT:g} s")
        period = 1.0 / rate
        due = time.monotonic()
        for index in range(count):
            due += period
            publisher.put(stamped(index, template))
            time.sleep(max(0.0, due - time.monotonic()))  # (pacing: the next message's time)
        poll_until(lambda: group.all_said("all"), ARRIVAL_TIMEOUT)
        results = group.finish()
        publisher.undeclare()
    finally:
        group.kill()
        session.close()
    latencies = [value for result in results for value in result["latencies_ms"]]
    received = len(latencies)
    return {"size": size, "mode": mode, "subscribers": subscribers, "sent": count,
            "received": received, "p50_ms": statistics.median(latencies) if latencies else None,
            "p90_ms": statistics.quantiles(latencies, n=10)[-1] if received > 1 else None,
            "subscriber_p50_ms": [statistics.median(result["latencies_ms"]) if result["latencies_ms"] else None
                                  for result in results],
            "shared_share": sum(result["shared"] for result in results) / received if received else 0.0}


def row(result: dict) -> str:
    def ms(value) -> str:
        return "-" if value is None else f"{value:.2f}"

    payload = f"{result['size']:,} B"
    return (f"| {payload} | {result['mode']} | {result['received']} of "
            f"{result['sent'] * result['subscribers']} | {ms(result['p50_ms'])} | {ms(result['p90_ms'])} | "
            f"{' / '.join(ms(value) for value in result['subscriber_p50_ms'])} | {100 * result['shared_share']:.0f} % |")


def run_all(args) -> list[dict]:
    """Frames, then small messages, each with shared memory on and off, over one router."""
    results = []
    with tempfile.TemporaryDirectory(prefix="frame-transport-") as folder, \
            start_system(Path(folder) / "run", services=(), output=io.StringIO()) as system:
        for size in (FRAME_BYTES + STAMP_BYTES, SMALL_BYTES):
            for mode in MODES:
                results.append(measure(system.endpoint, mode, size, args.count, args.rate,
                                       args.subscribers, Path(folder)))
    return results


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.frame_transport", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=integer(minimum=1), default=300, help="messages per run (default 300)")
    parser.add_argument("--rate", type=number(above=0.0), default=30.0, help="messages per second (default 30)")
    parser.add_argument("--subscribers", type=integer(minimum=1), default=3,
                        help="subscriber processes (default 3, as the demo's frames have)")
    parser.add_argument("--subscriber", metavar="ENDPOINT", help=argparse.SUPPRESS)
    parser.add_argument("--shared-memory", choices=("on", "off"), default="on", help=argparse.SUPPRESS)
    parser.add_argument("--expect", type=integer(minimum=1), default=1, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.subscriber:
        return subscriber(args.subscriber, args.shared_memory == "on", args.expect)
    keep_freed_memory()  # as the services that publish every frame do (common/memory.py)
    # (SIGTERM ends a run as Ctrl-C does, see exit_with: the subscribers and the router are
    # stopped on the way out)
    try:
        results = run_all(args)
    except (RuntimeError, OSError) as error:
        print(f"frame_transport: {error}", file=sys.stderr)
        return 1
    lines = [f"put -> subscriber callback over a router on this host, {args.count} messages at "
             f"{args.rate:g} Hz to each of {args.subscribers} subscriber processes:",
             "| payload | shared memory | arrived | p50 (ms) | p90 (ms) | p50 per subscriber (ms) "
             "| came as shared memory |",
             "| --- | --- | --- | --- | --- | --- | --- |", *(row(result) for result in results)]
    print_lines(lines)  # (quietly, when the reader has gone: `| head`)
    return 0


if __name__ == "__main__":
    exit_with(main)
