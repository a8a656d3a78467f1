"""Fuzz campaign: malformed messages to every key and query of the running services (issue 12).

Starts a router and the four services as real processes (the system launcher,
``deploy/launcher.py``) and sends, round after round, one generated payload to every data key of
the key table (``common/keys.py``) and one query to every queryable (``sim/control``,
``camera/camera_info`` and each ``<service>/config``): random bytes, truncated and byte-mutated
valid messages, wrong types, NaN and infinities, huge integers and sizes, lists nested up to
1,000 deep, maps with thousands of keys, strings up to 1 MB, corrupt and lying JPEGs, msgpack
extension types, with valid messages interleaved. Then it checks that nothing crashed (every
process alive, never restarted, its liveliness token present), that every query was answered,
that valid messages are still served (a camera frame gives a detection, its 3D position and a
command; a config read answers; ``sim/control`` obeys) and that resident memory (VmRSS) grew
by less than 50 MB per service.

The simulator renders one frame of the ``chase`` scenario at the start (kept as the valid
camera frame of the final check) and then runs with ``publish_images = false``: its frames
would only compete with the fuzz for the two CPUs.

    balltrack experiment fuzz --out runs/fuzz           # 10,000 messages per key
    balltrack experiment fuzz --quick --out /tmp/fuzz   # 300 per key
"""

import io
import math
import random
import tempfile
import threading
from pathlib import Path

import msgpack
import zenoh

from balltrack.common import keys
from balltrack.common.images import bgr_to_message, image_to_bgr
from balltrack.common.messages import SCHEMAS, decode, encode, header
from balltrack.common.session import open_session
from balltrack.common.status import liveliness_keys
from balltrack.deploy.launcher import SERVICES, start_system
from balltrack.experiments.base import ExperimentResult, Options, Stopwatch, progress
from balltrack.experiments.processes import resident_mb
from balltrack.services.simulator.control import send_command

NAME = "fuzz"
TITLE = "Fuzz campaign: malformed messages to every key and query of the running services"
MEMORY_GROWTH_LIMIT_MB = 50.0
QUERY_TIMEOUT = 10.0
# Ways to spoil a message, each picked equally often; "valid" interleaves good messages.
KINDS = ("random_bytes", "truncated", "mutated_bytes", "wrong_type", "non_finite", "huge_number",
         "deep_nesting", "many_keys", "oversized_string", "extension_type", "bad_jpeg", "valid")
NESTED = "<nested>"
BALL = {"x": 0.1, "y": 0.0, "z": 0.05, "u": 352.0, "v": 240.0, "radius_px": 16.0,
        "image_width": 640, "image_height": 480, "score": 0.9}


def targets(services: tuple[str, ...]) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """(data keys, queryables of ``services``) from the key table, each with the schema of its
    payload. ``camera/camera_info`` is both: published, and answered as a query (any payload)."""
    data = sorted(keys.MESSAGE_OF_KEY.items())
    queries = [(spec.key, spec.message.split(" ->")[0]) for spec in keys.TABLE
               if "->" in spec.message and "<" not in spec.key]
    queries.append((keys.CAMERA_INFO, "CameraInfo"))
    queries += [(keys.config_key(service), "ConfigRequest") for service in services]
    return data, queries


def valid_messages(frame: dict, configs: dict[str, dict]) -> dict[str, list[dict]]:
    """A few valid messages per schema, the seeds of mutations and the interleaved good ones."""
    small = {"header": header(1, 1), "width": 4, "height": 2, "encoding": "mono8", "data": bytes(8)}
    stamp = header(1, 1)
    return {
        "Image": [small, frame],
        "CameraInfo": [{"header": stamp, "width": 640, "height": 480, "fx": 554.0, "fy": 554.0,
                        "cx": 320.0, "cy": 240.0, "hfov": 1.089, "vfov": 0.855}],
        "Ball2D": [{"header": stamp, **BALL}],
        "Ball2DArray": [{"header": stamp, "balls": [BALL]}, {"header": stamp, "balls": []}],
        "Ball3D": [{"header": stamp, "x": 0.1, "y": 0.0, "z": 2.0, "distance": 2.0}],
        "Twist": [{"header": stamp, "linear": [0.05, 0.0, 0.0], "angular": [0.0, 0.0, 0.1]}],
        "Clock": [{"stamp": 1}],
        "GroundTruth": [{"header": stamp, "robot": {"x": 0.0, "y": 0.0, "yaw": 0.0},
                         "balls": [{"id": "tennis", "radius": 0.033, "position": [1.0, 0.0, 0.033],
                                    "in_camera": [0.0, 0.0, 1.0], "visible": True}]}],
        "SimCommand": [{"op": "place_robot", "x": 0.0, "y": 0.0, "yaw": 0.0},
                       {"op": "set_light", "diffuse": 0.8}, {"op": "reset"},
                       {"op": "place_ball", "id": "tennis", "position": [1.8, 1.0]},
                       {"op": "reset", "scenario": "chase"}],
        "SimReply": [{"ok": True}],
        "Stats": [{"service": "detector", "stamp": 1, "received": 1, "published": 1,
                   "rejected": 0, "dropped": 0, "p50_ms": 1.0, "p99_ms": 2.0}],
        # A read, and a set of a value to what it already is (mutations then hit real fields).
        "ConfigRequest": [{}] + [{"set": {name: value}} for config in configs.values()
                                 for name, value in config.items() if isinstance(value, float)][:8],
        "ConfigReply": [{"ok": True}],
    }


def _leaves(value, path=()):
    """Every (path, value) of the scalars in a message."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _leaves(item, path + (key,))
    elif isinstance(value, list) and value:
        for index, item in enumerate(value):
            yield from _leaves(item, path + (index,))
    else:
        yield path, value


def _replace(message, path, value):
    if not path:
        return value
    copy = dict(message) if isinstance(message, dict) else list(message)
    copy[path[0]] = _replace(copy[path[0]], path[1:], value)
    return copy


def _pack(message) -> bytes:
    return msgpack.packb(message, use_bin_type=True)


def _jpeg(width: int, height: int, body: bytes) -> bytes:
    """A JPEG start and a start-of-frame segment claiming ``width`` x ``height``, then ``body``."""
    return (b"\xff\xd8\xff\xc0\x00\x11\x08" + height.to_bytes(2, "big") + width.to_bytes(2, "big")
            + b"\x03\x01\x22\x00\x02\x11\x01\x03\x11\x01" + body)


class Generator:
    """Payloads for one schema: ``payload(rng)`` -> (kind, bytes)."""

    def __init__(self, schema: str, seeds: list[dict], real_jpeg: bytes):
        self.schema = schema
        self.seeds = seeds
        self.real_jpeg = real_jpeg

    def payload(self, rng: random.Random) -> tuple[str, bytes]:
        kind = rng.choice(KINDS)
        seed = rng.choice(self.seeds)
        leaves = list(_leaves(seed)) or [((), seed)]
        path, value = rng.choice(leaves)
        if kind == "random_bytes":
            return kind, rng.randbytes(rng.choice((rng.randint(0, 16), rng.randint(0, 2000))))
        if kind in ("truncated", "mutated_bytes"):
            packed = bytearray(_pack(seed))
            if kind == "truncated":
                return kind, bytes(packed[:rng.randrange(len(packed))])
            for _ in range(rng.randint(1, 8)):
                packed[rng.randrange(len(packed))] = rng.randrange(256)
            return kind, bytes(packed)
        if kind == "wrong_type":
            wrong = rng.choice([None, True, "text", b"bytes", [1, 2], {"a": 1}, 3, 2.5, []])
            return kind, _pack(_replace(seed, path, wrong))
        if kind == "non_finite":
            return kind, _pack(_replace(seed, path, rng.choice([math.nan, math.inf, -math.inf])))
        if kind == "huge_number":
            huge = rng.choice([(1 << 63) - 1, (1 << 64) - 1, -(1 << 63), 1e308, -1e308, 10 ** 18])
            if rng.random() < 0.3 and self.schema == "Image":  # a claimed frame of 10^9 pixels
                return kind, _pack({**seed, "width": 40_000, "height": 40_000})
            if rng.random() < 0.2:  # a list of 65,536 items where a few are expected
                return kind, _pack(_replace(seed, path, [0.0] * 65_536))
            return kind, _pack(_replace(seed, path, huge))
        if kind == "deep_nesting":
            depth = rng.choice((40, 200, 600, 1000))
            packed = _pack(_replace(seed, path, NESTED))
            return kind, packed.replace(_pack(NESTED), b"\x91" * (depth - 1) + b"\x90")
        if kind == "many_keys":
            count = rng.choice((100, 4096, 5000))
            extra = {f"k{index}": index for index in range(count)}
            if isinstance(seed, dict) and isinstance(seed.get("header"), dict) and rng.random() < 0.5:
                return kind, _pack({**seed, "header": {**seed["header"], **extra}})
            return kind, _pack({**seed, **extra} if isinstance(seed, dict) else extra)
        if kind == "oversized_string":
            text = "x" * int(math.exp(rng.uniform(math.log(1_000), math.log(1_000_000))))
            where = rng.random()
            if where < 0.4 or not isinstance(seed, dict):
                return kind, _pack(_replace(seed, path, text))
            if where < 0.7 and isinstance(seed.get("header"), dict):
                field = rng.choice(("frame_id", "extra"))
                return kind, _pack({**seed, "header": {**seed["header"], field: text}})
            return kind, _pack({**seed, "extra": text})
        if kind == "extension_type":
            extension = rng.choice([msgpack.ExtType(rng.randrange(128), rng.randbytes(8)),
                                    msgpack.Timestamp(rng.randrange(1 << 32), 0)])
            return kind, _pack(_replace(seed, path, extension))
        if kind == "bad_jpeg" and self.schema == "Image":
            side = rng.choice((8192, 4000, 640))
            width, height, data = rng.choice([
                (side, side, _jpeg(side, side, rng.randbytes(64))),    # lying: a tiny file
                (side, side, _jpeg(640, 480, rng.randbytes(64))),      # size disagrees
                (640, 480, b"\xff\xd8" + rng.randbytes(rng.randint(2, 500))),  # corrupt
                (640, 480, self.real_jpeg[:rng.randrange(4, len(self.real_jpeg))]),  # truncated
                (640, 480, self.real_jpeg[:300] + rng.randbytes(300) + self.real_jpeg[600:]),
            ])
            return kind, _pack({"header": header(1, 1), "width": width, "height": height,
                                "encoding": "jpeg", "data": data})
        return "valid", _pack(seed)


def _label(key: str, is_query: bool) -> str:
    """``camera/camera_info`` is both published and queried: its two rows need two names."""
    return f"{key} (query)" if is_query and key in keys.MESSAGE_OF_KEY else key


class Watch:
    """The newest messages of a few keys, to wait for an answer to a valid message."""

    def __init__(self, session, key: str, schema: str, keep: int = 200):
        self.messages: list[dict] = []
        self._changed = threading.Condition()

        def on_sample(sample):
            try:
                message = decode(schema, sample.payload.to_bytes())
            except ValueError:
                return
            with self._changed:
                self.messages = self.messages[-keep:] + [message]
                self._changed.notify_all()

        self.subscriber = session.declare_subscriber(key, on_sample)

    def wait(self, predicate, timeout: float):
        with self._changed:
            self._changed.wait_for(lambda: any(predicate(m) for m in self.messages), timeout)
            return next((m for m in self.messages if predicate(m)), None)


def query(session, key: str, payload: bytes) -> bytes | None:
    """One query; the first reply's payload, or None when nobody answered in time."""
    for reply in session.get(key, payload=payload, timeout=QUERY_TIMEOUT):
        if reply.ok is not None:
            return reply.ok.payload.to_bytes()
        return reply.err.payload.to_bytes()
    return None


def read_config(session, service: str) -> dict | None:
    answer = query(session, keys.config_key(service), b"")
    try:
        reply = decode("ConfigReply", answer) if answer else None
    except ValueError:
        return None
    return reply["config"] if reply and reply["ok"] else None


def alive_tokens(session) -> set[str]:
    return {key.split("/", 1)[1] for key in liveliness_keys(session, "alive/*", timeout=5.0)}


def run(options: Options) -> ExperimentResult:
    result = ExperimentResult(NAME, TITLE, mode="zenoh", quick=options.quick)
    clock = Stopwatch()
    per_key = options.budget(300, 10_000)
    rng = random.Random(options.seed)
    data_keys, query_keys = targets(SERVICES)
    with tempfile.TemporaryDirectory(prefix="balltrack-fuzz-") as folder, \
            start_system(Path(folder), output=io.StringIO()) as system:
        session = open_session([system.endpoint], open_timeout=10)
        try:
            _campaign(result, system, session, rng, per_key, data_keys, query_keys, options)
        finally:
            session.close()
    result.seconds = clock.seconds
    return result


def _campaign(result, system, session, rng, per_key, data_keys, query_keys, options) -> None:
    frames = Watch(session, keys.IMAGE_RAW, "Image", keep=20)
    detections = Watch(session, keys.DETECTED_BALL, "Ball2D")
    positions = Watch(session, keys.DETECTED_BALL_3D, "Ball3D")
    commands = Watch(session, keys.CMD_VEL, "Twist")
    truths = Watch(session, keys.GROUND_TRUTH, "GroundTruth")
    # A real rendered frame that the detector finds the ball in: the valid frame of the checks.
    # (Any detection whose frame is still among the kept ones: the first detections come when
    # the detector has warmed up, and their frames may be older than the kept 20 by then.
    # Frames keep arriving, so the wait looks again at each.)
    frame = frames.wait(lambda image: any(ball["header"]["seq"] == image["header"]["seq"]
                                          for ball in detections.messages), 60)
    if frame is None:
        raise RuntimeError("no simulator frame with a detection within 60 s"
                           f" ({len(detections.messages)} detections, none of a kept frame)")
    configs = {service: read_config(session, service) for service in SERVICES}
    if any(config is None for config in configs.values()):
        raise RuntimeError(f"a service does not answer its config: {configs}")
    query(session, keys.config_key("simulator"), encode("ConfigRequest", {"set": {"publish_images": False}}))
    configs["simulator"]["publish_images"] = False
    real_jpeg = bgr_to_message(image_to_bgr(frame), 1, 1, encoding="jpeg")["data"]
    seeds = valid_messages(frame, configs)
    generators = {schema: Generator(schema, seeds[schema], real_jpeg) for schema in SCHEMAS}

    def checks(seq: int) -> dict[str, bool]:
        """Valid messages served: frame -> detection -> 3D position and command; config reads;
        sim/control obeys; ground truth flows."""
        served = {"detector": False, "locator": False, "follower": False}
        for attempt in range(3):  # a frame still in flight from the simulator may overtake ours
            sent_seq = seq + attempt
            session.put(keys.IMAGE_RAW, encode("Image", {**frame, "header": header(sent_seq, sent_seq)}))
            ours = lambda message: seq <= message["header"]["seq"] <= sent_seq  # noqa: E731
            served["detector"] = detections.wait(ours, 20) is not None
            served["locator"] = positions.wait(ours, 20) is not None
            served["follower"] = commands.wait(ours, 5) is not None
            if all(served.values()):
                break
        reply = send_command(session, {"op": "place_robot", "x": 0.0, "y": 0.0, "yaw": 0.0},
                             timeout=QUERY_TIMEOUT)
        newest = truths.messages[-1]["header"]["seq"] if truths.messages else -1
        served["simulator"] = bool(reply.get("ok")) and truths.wait(
            lambda m: m["header"]["seq"] > newest, 20) is not None
        for service in SERVICES:
            served[f"{service} config"] = read_config(session, service) is not None
        return served

    before_checks = checks(10 ** 9)
    memory_start = {service: resident_mb(system.pid(service)) for service in SERVICES}
    pids_before = {service: system.pid(service) for service in SERVICES}

    block = {"congestion_control": zenoh.CongestionControl.BLOCK}
    publishers = {key: session.declare_publisher(key, **block) for key, _ in data_keys}
    sent = {_label(key, False): 0 for key, _ in data_keys}
    sent.update({_label(key, True): 0 for key, _ in query_keys})
    kinds: dict[str, int] = {}
    unanswered: dict[str, int] = {key: 0 for key, _ in query_keys}
    # The first tenth of the rounds warms up: allocator arenas, buffers, a first scenario
    # reload grow once; the growth that would reveal a leak is measured from there on.
    warm_up = max(30, per_key // 10)
    memory_before = dict(memory_start)
    for round_index in progress(range(per_key), desc="fuzz rounds", options=options, unit="round"):
        if round_index == warm_up:
            memory_before = {service: resident_mb(system.pid(service)) for service in SERVICES}
        for key, schema in data_keys:
            kind, payload = generators[schema].payload(rng)
            publishers[key].put(payload)
            sent[_label(key, False)] += 1
            kinds[kind] = kinds.get(kind, 0) + 1
        for key, schema in query_keys:
            kind, payload = generators[schema].payload(rng)
            if query(session, key, payload) is None:
                unanswered[key] += 1
            sent[_label(key, True)] += 1
            kinds[kind] = kinds.get(kind, 0) + 1
    for publisher in publishers.values():
        publisher.undeclare()

    # Settings a valid-looking mutation may have changed go back before the checks.
    for service, config in configs.items():
        query(session, keys.config_key(service), encode("ConfigRequest", {"set": config}))
    send_command(session, {"op": "reset", "scenario": "chase"}, timeout=QUERY_TIMEOUT)
    after_checks = checks(10 ** 9 + 10)
    memory_after = {service: resident_mb(system.pid(service)) for service in SERVICES}
    children = system.children()
    tokens = alive_tokens(session)
    crashed = [service for service in SERVICES
               if system.pid(service) != pids_before[service] or service not in tokens
               or children.get(service, {}).get("restarts", 0)]

    total = sum(sent.values())
    for key, count in sent.items():
        result.figure(f"sent/{key}", count)
    for kind, count in sorted(kinds.items()):
        result.figure(f"kinds/{kind}", count)
    result.figure("sent/total", total)
    result.figure("crashes", len(crashed))
    result.figure("unanswered_queries", sum(unanswered.values()))
    for name, ok in after_checks.items():
        result.figure(f"served_after/{name.replace(' ', '_')}", ok)
    growth = {}
    for service in SERVICES:
        result.figure(f"rss_mb/{service}/start", memory_start[service])
        result.figure(f"rss_mb/{service}/before", memory_before[service])
        result.figure(f"rss_mb/{service}/after", memory_after[service])
        if memory_before[service] is not None and memory_after[service] is not None:
            growth[service] = memory_after[service] - memory_before[service]
        result.figure(f"rss_mb/{service}/growth", growth.get(service))

    result.settings.update({"messages per key": per_key, "seed": options.seed,
                            "keys": len(data_keys), "queryables": len(query_keys)})
    result.table(["key", "messages sent", "unanswered queries"],
                 [[_label(key, False), sent[_label(key, False)], "-"] for key, _ in data_keys]
                 + [[_label(key, True), sent[_label(key, True)], unanswered[key]]
                    for key, _ in query_keys])
    result.table(["service", "RSS at start (MB)", "RSS after warm-up (MB)", "RSS after (MB)",
                  "growth after warm-up (MB)", "valid served before", "valid served after"],
                 [[service, memory_start[service], memory_before[service], memory_after[service],
                   growth.get(service), before_checks[service], after_checks[service]]
                  for service in SERVICES])
    result.goal("crashes", "no process crashed (alive, not restarted, liveliness token present)",
                "0", f"{len(crashed)}" + (f" ({', '.join(crashed)})" if crashed else ""),
                not crashed and len(growth) == len(SERVICES))
    result.goal("answered", "every query answered", "0 unanswered",
                f"{sum(unanswered.values())} unanswered of "
                f"{sum(sent[_label(key, True)] for key, _ in query_keys)}",
                sum(unanswered.values()) == 0)
    failed = [name for name, ok in after_checks.items() if not ok]
    result.goal("served_after", "valid messages served after the storm (detection, 3D position, "
                "command, sim/control, ground truth, config reads)", "all",
                "all" if not failed else f"failed: {', '.join(failed)}", not failed)
    worst = max(growth.values()) if growth else math.inf
    result.goal("memory", "resident memory growth per service after the warm-up rounds",
                f"< {MEMORY_GROWTH_LIMIT_MB:g} MB",
                f"max {worst:.1f} MB", worst < MEMORY_GROWTH_LIMIT_MB)
    result.notes.append(f"{total} messages to {len(data_keys)} keys and {len(query_keys)} "
                        f"queryables ({per_key} each), {len(KINDS)} kinds of payload. Memory "
                        f"growth is counted from the end of {warm_up} warm-up rounds (allocator "
                        f"arenas and a first scenario reload grow once); the table also shows "
                        f"the resident memory at the start.")
    print(f"fuzz: {total} messages, {len(crashed)} crashes, "
          f"{sum(unanswered.values())} unanswered queries, served after: "
          f"{'all' if not failed else ', '.join(failed)}, RSS growth "
          + ", ".join(f"{service} {value:+.1f} MB" for service, value in growth.items()))
