"""Real processes for integration tests: a router on a free port, services, and collectors.

Nothing here sleeps to synchronise: every wait is on a condition (a log line, a liveliness
token, a message) with a deadline, and fails the test with what it was waiting for.
"""

import os
import signal
import subprocess
import sys
import threading
import itertools
import time
from pathlib import Path

import zenoh

from balltrack.common.keys import PROCESS_JOIN, Keys
from balltrack.common.messages import decode, encode
from balltrack.common.network import free_port  # noqa: F401  (tests import it from here too)
from balltrack.common.session import open_session
from balltrack.common.waiting import POLL_INTERVAL, poll_until

REPO = Path(__file__).resolve().parents[1]


def process_environment() -> dict:
    environment = dict(os.environ)
    environment.setdefault("MUJOCO_GL", "egl")
    environment["PYTHONUNBUFFERED"] = "1"
    # A process that hangs on SIGTERM gets SIGABRT from Process.stop: dump its threads' stacks.
    environment["PYTHONFAULTHANDLER"] = "1"
    return environment


def wait_until(condition, timeout: float, what: str, *watched: "Process", every: float = POLL_INTERVAL):
    """Poll ``condition()`` (``common.waiting.poll_until``) until it returns something truthy,
    and return that. Fails the test (AssertionError naming ``what``) after ``timeout`` seconds,
    or as soon as one of the ``watched`` processes has exited, with the end of its output."""
    def checked():
        result = condition()
        for process in [] if result else watched:
            if process.popen.poll() is not None:
                raise AssertionError(f"{process.arguments} exited {process.popen.returncode} while "
                                     f"waiting for {what}:\n{process.output()[-4000:]}")
        return result

    result = poll_until(checked, timeout, every)
    if result is None:
        logs = "".join(f"\n--- {process.arguments}\n{process.output()[-2000:]}" for process in watched)
        raise AssertionError(f"timed out after {timeout} s waiting for {what}{logs}")
    return result


class Process:
    """A child process whose combined output goes to a log file and can be waited on."""

    def __init__(self, arguments: list[str], log_path: Path):
        self.arguments = arguments
        self.log_path = log_path
        self._log = open(log_path, "wb")
        self.popen = subprocess.Popen(arguments, stdout=self._log, stderr=subprocess.STDOUT,
                                      stdin=subprocess.DEVNULL, env=process_environment(),
                                      cwd=REPO)

    def output(self) -> str:
        return self.log_path.read_text(errors="replace")

    def wait_for_output(self, text: str, timeout: float) -> None:
        wait_until(lambda: text in self.output(), timeout, f"{text!r} in its output", self)

    def wait_for_signal_handler(self, signal_number: int, timeout: float) -> None:
        """Wait until the process catches ``signal_number`` (its handler is installed: SigCgt in
        /proc), so that the signal tests the handler, not Python's start-up."""
        def caught() -> bool:
            status = Path(f"/proc/{self.popen.pid}/status").read_text()
            mask = int(next(line for line in status.splitlines() if line.startswith("SigCgt:")).split()[1], 16)
            return bool(mask >> (signal_number - 1) & 1)

        wait_until(caught, timeout, f"a handler of signal {signal_number}", self)

    def stop(self, timeout: float = 15.0) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.send_signal(signal.SIGABRT)  # faulthandler writes every thread's stack
                try:
                    self.popen.wait(5)
                except subprocess.TimeoutExpired:
                    self.popen.kill()
                    self.popen.wait()
                self._log.close()
                raise AssertionError(f"{self.arguments} ignored SIGTERM for {timeout} s:\n{self.output()}")
        self._log.close()
        return self.popen.returncode

    def kill(self) -> None:
        if self.popen.poll() is None:
            self.popen.kill()
            self.popen.wait()


class Router:
    def __init__(self, log_dir: Path, port: int | None = None):
        self.port = port or free_port()
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.process = Process([sys.executable, "-m", "balltrack", "router", "--listen",
                                self.endpoint], log_dir / f"router-{self.port}.log")
        self.process.wait_for_output("listening on", 20)

    def stop(self) -> int:
        return self.process.stop()


def start_service(name: str, endpoint: str, log_dir: Path, *extra: str) -> Process:
    """``name``: a service, or several joined by + in one process (``balltrack run``)."""
    command = (["-m", "balltrack", "run", name] if PROCESS_JOIN in name else ["-m", f"balltrack.services.{name}"])
    return Process([sys.executable, *command, "--connect", endpoint, *extra],
                   log_dir / f"{name}-{time.monotonic_ns()}.log")


class Collector:
    """Collects decoded messages of one key, with their arrival times (``time.monotonic()``),
    and waits for a condition on them.

    ``message``: the schema to decode (None: keep the raw key and payload); a payload that does
    not decode is counted in ``rejected`` and never satisfies a condition. ``keep`` makes what is
    kept of a decoded message, None to leave it out.
    """

    def __init__(self, session, key: str, message: str | None, keep=lambda message: message):
        self.messages: list[dict] = []
        self.items: list[tuple[float, dict]] = []  # (arrival, message), in step with messages
        self.rejected: list[str] = []
        self._changed = threading.Condition()

        def on_sample(sample):
            arrival = time.monotonic()
            payload = sample.payload.to_bytes()
            if message is None:
                kept = {"key": str(sample.key_expr), "payload": payload}
            else:
                try:
                    kept = keep(decode(message, payload))
                except ValueError as error:
                    with self._changed:
                        self.rejected.append(str(error))
                    return
            if kept is None:
                return
            with self._changed:
                self.messages.append(kept)
                self.items.append((arrival, kept))
                self._changed.notify_all()

        self.subscriber = session.declare_subscriber(key, on_sample)

    def wait_for(self, predicate, timeout: float, what: str = "condition"):
        """Wait until ``predicate(messages)`` is truthy; return its value."""
        return self._wait(lambda: predicate(self.messages), timeout, what)

    def wait_for_items(self, predicate, timeout: float, what: str = "condition"):
        """Wait until ``predicate(items)`` is truthy, items being (arrival, message); return its value."""
        return self._wait(lambda: predicate(self.items), timeout, what)

    def _wait(self, condition, timeout: float, what: str):
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                result = condition()
                if result:
                    return result
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise AssertionError(f"timed out after {timeout} s waiting for {what}; "
                                         f"{len(self.messages)} messages, last: "
                                         f"{self.messages[-1] if self.messages else None}")
                self._changed.wait(remaining)

    def wait_count(self, count: int, timeout: float):
        self.wait_for(lambda messages: len(messages) >= count, timeout, f"{count} messages")
        return list(self.messages)

    def wait_after(self, moment: float, timeout: float, what: str, count: int = 1) -> list:
        """The first ``count`` messages that arrived after ``moment``, as (arrival, message)."""
        def found(items):
            new = [item for item in items if item[0] > moment]
            return new[:count] if len(new) >= count else None

        return self.wait_for_items(found, timeout, what)

    def close(self):
        if self.subscriber is not None:
            self.subscriber.undeclare()
            self.subscriber = None


class Liveliness:
    """Tracks ``alive/*`` tokens so a test can wait for a service to come up or go away."""

    def __init__(self, session, namespace: str = ""):
        self.keys = Keys(namespace)
        self.alive: set[str] = set()
        self._changed = threading.Condition()

        def on_sample(sample):
            name = self.keys.strip(str(sample.key_expr)).split("/", 1)[1]
            with self._changed:
                if sample.kind == zenoh.SampleKind.PUT:
                    self.alive.add(name)
                else:
                    self.alive.discard(name)
                self._changed.notify_all()

        self.subscriber = session.liveliness().declare_subscriber(self.keys("alive/*"), on_sample,
                                                                   history=True)

    def wait(self, name: str, alive: bool = True, timeout: float = 30.0) -> None:
        with self._changed:
            if not self._changed.wait_for(lambda: (name in self.alive) == alive, timeout):
                state = "alive" if alive else "gone"
                raise AssertionError(f"{name} not {state} after {timeout} s (alive: {self.alive})")


def query_config(session, service: str, changes: dict | None = None, namespace: str = "",
                 timeout: float = 5.0) -> dict:
    request = encode("ConfigRequest", {"set": changes} if changes else {})
    for reply in session.get(Keys(namespace)(f"{service}/config"), payload=request, timeout=timeout):
        if reply.ok is not None:
            return decode("ConfigReply", reply.ok.payload.to_bytes())
    raise AssertionError(f"{service}/config did not answer")


def put_until(put, collector: "Collector", predicate, timeout: float, every: float, what: str):
    """Call ``put(attempt)`` (0, 1, ...) and wait up to ``every`` seconds for
    ``predicate(collector.messages)``; again until it holds, and return its value. A put can be
    lost on its way (before a new subscription has reached the writer, or a fragment of a large
    message under load), and a service may drop a message it cannot use yet. AssertionError
    after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    for attempt in itertools.count():
        put(attempt)
        try:
            return collector.wait_for(predicate, min(every, max(0.01, deadline - time.monotonic())), what)
        except AssertionError:
            if time.monotonic() >= deadline:
                raise AssertionError(f"no {what} in {timeout} s of putting again every {every} s") from None


def wait_matched(publisher, timeout: float = 20) -> None:
    """Until the router has told this session of a subscriber on the publisher's key: a client
    sends a put only where it knows of one, and a service's liveliness token may reach it
    before its subscriptions do."""
    wait_until(lambda: publisher.matching_status.matching, timeout,
               f"a subscriber on {publisher.key_expr}", every=0.02)


def client(endpoint: str):
    return open_session([endpoint], open_timeout=10)


def garbage_payloads(good: dict) -> list[tuple[str, bytes]]:
    """Every kind of bad input a subscriber must survive, derived from a good message."""
    import msgpack

    def pack(message):
        return msgpack.packb(message, use_bin_type=True)

    number_fields = [name for name, value in good.items()
                     if isinstance(value, float) and name != "header"]
    first_number = number_fields[0] if number_fields else None
    cases = [
        ("empty payload", b""),
        ("not msgpack", b"\xc1\x00garbage\xff"),
        ("a list, not a map", pack([1, 2, 3])),
        ("missing fields", pack({"header": good.get("header")})),
        ("wrong header type", pack({**good, "header": "yesterday"})),
    ]
    if first_number:
        cases += [
            ("NaN", pack({**good, first_number: float("nan")})),
            ("inf", pack({**good, first_number: float("inf")})),
            ("wrong type", pack({**good, first_number: "three"})),
        ]
    if "data" in good:
        cases += [
            ("data length disagrees", pack({**good, "data": good["data"][:-7]})),
            ("claimed 100000 x 100000 frame", pack({**good, "width": 100000, "height": 100000})),
            ("corrupt JPEG", pack({**good, "encoding": "jpeg", "data": b"\xff\xd8\xff\xe0" + bytes(64)})),
            ("lying JPEG size", pack({**good, "encoding": "jpeg", "width": 50000, "height": 50000,
                                      "data": b"\xff\xd8\xff\xc0\x00\x11\x08\xc3\x50\xc3\x50" + bytes(40)})),
        ]
    return cases


TENNIS_BGR = (40, 235, 205)  # yellow-green, as a tennis ball looks under white light


def floor_image(width: int = 640, height: int = 480, seed: int = 0):
    """A grey, slightly textured floor under a lighter wall: a plausible ball-free frame."""
    import numpy as np

    generator = np.random.default_rng(seed)
    image = np.empty((height, width, 3), np.uint8)
    image[: height // 2] = (170, 165, 160)
    image[height // 2:] = (95, 100, 105)
    noise = generator.normal(0, 4, image.shape)
    return np.clip(image + noise, 0, 255).astype(np.uint8)


def draw_ball(image, u: float, v: float, radius: float, colour=TENNIS_BGR):
    """A shaded disc (lit from above-left) centred at (u, v), drawn with sub-pixel accuracy."""
    import cv2
    import numpy as np

    height, width = image.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    distance = np.hypot(xs - u, ys - v)
    coverage = np.clip(radius + 0.5 - distance, 0.0, 1.0)[..., None]
    shade = np.clip(1.05 - 0.35 * ((xs - u + ys - v) / max(radius, 1.0) + 1) / 2, 0.6, 1.0)[..., None]
    ball = np.array(colour, np.float32)[None, None, :] * shade
    blended = image.astype(np.float32) * (1 - coverage) + ball * coverage
    return cv2.GaussianBlur(np.clip(blended, 0, 255).astype(np.uint8), (3, 3), 0)


def fully_in_view(in_camera, radius: float, width: int = 640, height: int = 480,
                  hfov: float = 1.089, margin_px: float = 2.0) -> bool:
    """Whether a ball (centre in the camera optical frame) is wholly inside the image: a ball
    cut by the border shows less than its size, so its distance cannot be judged from it."""
    import math

    x, y, z = in_camera
    if z <= radius:
        return False
    focal = (width / 2) / math.tan(hfov / 2)
    u, v = width / 2 + focal * x / z, height / 2 + focal * y / z
    reach = focal * math.tan(math.asin(min(1.0, radius / math.dist(in_camera, (0, 0, 0))))) + margin_px
    # Off axis the silhouette stretches outward by about 1/cos^2 of the angle: widen the reach.
    stretch = 1.0 + (x * x + y * y) / (z * z)
    return (reach * stretch <= u <= width - reach * stretch
            and reach * stretch <= v <= height - reach * stretch)
