"""Recording Zenoh keys into an MCAP file and playing one back (the file side is
``common/recording.py``). Used by ``balltrack record`` / ``play`` and by the demo (run.mcap).

A :class:`Recording` subscribes to keys on an open session and writes what arrives; Zenoh's
callbacks only take the arrival time and queue the payload, a thread of its own compresses and
writes, so a recording never slows the subscriber it shares a session with (the demo's). When
the writer falls behind by more than ``max_queued_bytes`` of payloads, what arrives is dropped
and counted rather than memory growing without bound. With ``hold`` the writer leaves each
message alone for that long after its arrival (the demo: 15 ms, after the pipeline's answer).

:func:`play` publishes a recording's payloads, byte for byte, with the recorded timing (log-time
differences divided by ``rate``) or as fast as possible (``rate`` 0).

With ``foxglove`` (the default when the ``view`` extra is installed) a recording also holds
Foxglove-typed channels (``deploy/foxglove_messages.py``: /camera/image, /image, /scene, /tf,
/cmd_vel) made from the valid messages, so Foxglove opens the file directly; the msgpack
channels stay byte for byte, and only they are played back.
"""

import collections
import os
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable

import zenoh

from balltrack.common.keys import SERVICES, TABLE, Keys, stats_key
from balltrack.common.messages import MessageError, decode
from balltrack.common.recording import (CDR_ENCODING, MESSAGE_ENCODING, ChannelCount, Recorder, RecordingFile,
                                        looks_like_cdr)
from balltrack.common.waiting import poll_until

# Every key whose messages have a schema: the fixed data keys of the contract, then stats.
DATA_KEYS = tuple(spec.key for spec in TABLE if "<" not in spec.key and "->" not in spec.message)
DEFAULT_KEYS = DATA_KEYS + tuple(stats_key(service) for service in SERVICES)
# The Zenoh encoding of ROS 2 messages (the ROS 2 bridge adds ";<type>", e.g.
# "application/cdr;geometry_msgs/msg/Point").
CDR_KEY_ENCODING = str(zenoh.Encoding.APPLICATION_CDR)
# Payloads a recording holds while its writer catches up (a few hundred camera frames); what
# arrives past them is dropped and counted.
MAX_QUEUED_BYTES = 256 << 20


def foxglove_converter():
    """The Foxglove conversions (``deploy/foxglove_messages.py``), or None without the
    foxglove-sdk package (the ``view`` extra)."""
    try:
        from balltrack.deploy import foxglove_messages
    except ImportError:
        return None
    return foxglove_messages


def lower_priority() -> None:
    """Make the calling thread yield the CPU to everything else (Linux: per-thread nice 19).
    Compressing frames is background work; on a small machine it must not take a core from
    the services whose messages it records while they work on a fresh frame."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
    except (AttributeError, OSError):  # not Linux, or not permitted: record at normal priority
        pass


@dataclass
class RecordingCounts:
    received: int = 0
    written: int = 0
    dropped: int = 0  # the writer was more than max_queued_bytes behind
    per_topic: dict[str, int] = field(default_factory=dict)


class Recording:
    """Records ``keys`` (contract keys without namespace, or key expressions) under
    ``namespace`` from ``session`` into ``path`` until :meth:`close`."""

    def __init__(self, session, path, keys: Iterable[str] = DEFAULT_KEYS, namespace: str = "",
                 max_queued_bytes: int = MAX_QUEUED_BYTES, metadata: dict[str, str] | None = None,
                 foxglove: bool | None = None, hold: float = 0.0):
        self.keys = Keys(namespace)
        self._foxglove = foxglove_converter() if foxglove is not False else None
        if foxglove and self._foxglove is None:
            raise RuntimeError("Foxglove channels need the foxglove-sdk package "
                               "(pip install 'balltrack[view]')")
        self._foxglove_channels: dict[str, int] = {}
        self.recorder = Recorder(path, metadata={"namespace": self.keys.namespace,
                                                 **(metadata or {})})
        self.counts = RecordingCounts()
        # (topic, payload, arrival ns); None asks the writer to finish
        self._pending: collections.deque = collections.deque()
        self._pending_bytes, self._max_queued_bytes = 0, max_queued_bytes
        self._changed = threading.Condition()
        # Each message waits `hold` seconds after its arrival before it is compressed and
        # written (until close): beside a pipeline on a small machine, the work then falls after
        # the pipeline has answered the frame instead of beside it.
        self._hold, self._closing = hold, threading.Event()
        self._writer = threading.Thread(target=self._write_queued, name="recording-writer",
                                        daemon=True)
        self._writer.start()
        self._subscribers = []
        try:
            for key in dict.fromkeys(keys):
                self._subscribers.append(session.declare_subscriber(self.keys(key),
                                                                    self._on_sample))
        except Exception:
            self.close()
            raise

    def _on_sample(self, sample) -> None:
        arrival = time.time_ns()
        payload = sample.payload.to_bytes()
        with self._changed:
            if self._pending_bytes + len(payload) > self._max_queued_bytes:
                self.counts.dropped += 1
                return
            self.counts.received += 1
            self._pending.append((str(sample.key_expr), payload, arrival, sample.encoding))
            self._pending_bytes += len(payload)
            self._changed.notify_all()  # the writer, and wait_received

    def _write_queued(self) -> None:
        lower_priority()
        while True:
            with self._changed:
                self._changed.wait_for(lambda: self._pending)
                item = self._pending.popleft()
                if item is None:
                    return
                self._pending_bytes -= len(item[1])
            topic, payload, arrival, encoding = item
            if self._hold > 0:
                self._closing.wait(arrival / 1e9 + self._hold - time.time())
            key = self.keys.strip(topic)
            message_type = self.keys.message_of(topic)
            # (its text here, not in Zenoh's callback, which stays short)
            named, _, ros_type = str(encoding).partition(";")
            named_cdr = named == CDR_KEY_ENCODING
            if message_type is None and (named_cdr or looks_like_cdr(payload)):
                # (a ROS 2 message: the bridge names its type in the encoding, after the ";")
                channel = self.recorder.cdr_channel(topic, key, self.keys.namespace,
                                                    ros_type if named_cdr and ros_type else None)
                self.recorder.write(channel, payload, arrival, arrival)
            else:
                channel = self.recorder.msgpack_channel(topic, key, self.keys.namespace, message_type)
                self.recorder.write_payload(channel, payload, arrival)
            if self._foxglove is not None and message_type is not None:
                self._write_foxglove(topic, key, payload, arrival)
            with self._changed:
                self.counts.written += 1
                self.counts.per_topic[topic] = self.counts.per_topic.get(topic, 0) + 1

    def wait_received(self, count: int, timeout: float) -> bool:
        """True once ``count`` messages have arrived (written or queued), False after ``timeout``."""
        with self._changed:
            return self._changed.wait_for(lambda: self.counts.received >= count, timeout)

    def _write_foxglove(self, topic: str, key: str, payload: bytes, arrival: int) -> None:
        message_type = self._foxglove.RECORDED_TYPES.get(key)
        if message_type is None:
            return
        try:
            message = decode(message_type, payload)
            converted = self._foxglove.recorded_messages(key, message)
        except MessageError:  # recorded as it came on its msgpack channel; nothing to view
            return
        prefix = f"/{self.keys.namespace}" if self.keys.namespace else ""
        for foxglove_topic, item in converted:
            schema_name, schema_encoding, schema_data, encoding, data = self._foxglove.mcap_encoding(item)
            channel = self._foxglove_channels.get(prefix + foxglove_topic)
            if channel is None:
                channel = self._foxglove_channels[prefix + foxglove_topic] = self.recorder.add_channel(
                    prefix + foxglove_topic, schema_name, schema_encoding, schema_data, encoding,
                    {"source": topic})
            self.recorder.write(channel, data, arrival, message["header"]["stamp"],
                                message["header"]["seq"])

    def close(self) -> RecordingCounts:
        """Stop subscribing, write what is queued, finalise the file; returns the counts."""
        for subscriber in self._subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # the session may be closed already; the file still gets finished
                pass
        self._subscribers = []
        self._closing.set()
        if self._writer.is_alive():
            with self._changed:
                self._pending.append(None)  # after what is queued: all of it gets written
                self._changed.notify()
            self._writer.join()
        self.recorder.close()
        return self.counts


@dataclass
class PlayCounts:
    published: int = 0
    passes: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)


def select_topics(recording: RecordingFile, wanted: Iterable[str] | None) -> list[str]:
    """The recorded topics to play: all, or those whose topic or key (without the recorded
    namespace) is in ``wanted``: the channels of Zenoh keys that balltrack recorded (msgpack,
    and CDR of ROS 2 keys), not the Foxglove ones (for viewing) nor those of other recorders (a
    ROS 2 bag's). ValueError names a wanted key the recording lacks, and says so when it has
    channels but none of them to play."""
    every = recording.channels()
    channels = [channel for channel in every if playable(channel)]
    if not wanted:
        if every and not channels:
            shown = "; ".join(f"{channel.topic}: {unplayable(channel)}" for channel in every[:3])
            raise ValueError(f"no channel of the recording is one balltrack recorded from a Zenoh key "
                             f"({shown}{'; ...' if len(every) > 3 else ''}): nothing to play")
        return [channel.topic for channel in channels]
    chosen = []
    for name in wanted:
        matches = [channel.topic for channel in channels if name in (channel.topic, channel.key)]
        if not matches:
            recorded = ", ".join(channel.topic for channel in channels) or "none"
            other = [channel for channel in every if channel.topic == name]
            if other:
                # (`balltrack info` lists every kind)
                raise ValueError(f"{name!r} is {unplayable(other[0])}: play publishes the keys balltrack "
                                 f"recorded (recorded: {recorded})")
            raise ValueError(f"{name!r} is not in the recording (recorded: {recorded})")
        chosen.extend(match for match in matches if match not in chosen)
    return chosen


def check_played_keys(recording: RecordingFile, topics: list[str], namespace: str | None) -> None:
    """ValueError naming the first of ``topics`` whose key, as ``play`` would put it (under
    ``namespace`` when not None), Zenoh refuses: a file of another writer may name its channels
    anyhow ("/weird topic")."""
    target = Keys(namespace) if namespace is not None else None
    for channel in recording.channels():
        if channel.topic in topics:
            key = target(channel.key) if target is not None else channel.topic
            try:
                zenoh.KeyExpr(key)
            except zenoh.ZError:
                raise ValueError(f"channel {channel.topic!r}: {key!r} is not a Zenoh key, so it cannot be "
                                 "played") from None


def playable(channel: ChannelCount) -> bool:
    """A channel balltrack recorded from a Zenoh key: msgpack, or CDR with the key in its
    metadata (a ROS 2 bag's CDR channels have none)."""
    return channel.message_encoding == MESSAGE_ENCODING or (
        channel.message_encoding == CDR_ENCODING and channel.has_key)


def unplayable(channel: ChannelCount) -> str:
    """What a channel that play leaves out is, in a few words."""
    if channel.message_encoding == CDR_ENCODING:
        return "a ROS 2 (CDR) channel of another recorder"
    if channel.message_encoding in ("protobuf", "json"):
        return "a Foxglove channel, for viewing"
    return f"a channel of message encoding {channel.message_encoding!r}"


def play(session, recording: RecordingFile, stop: threading.Event, rate: float = 1.0,
         loop: bool = False, topics: Iterable[str] | None = None, start_seconds: float = 0.0,
         namespace: str | None = None,
         on_message: Callable[[str, int], None] | None = None) -> PlayCounts:
    """Publish the recording until it ends (or forever with ``loop``) or ``stop`` is set.

    Each pass starts ``start_seconds`` after the recording's first message; the wait before a
    message is its log-time distance from the pass's first one, divided by ``rate`` (0: no
    wait). ``namespace`` (when not None) replaces the recorded one. Payloads are put with
    congestion control BLOCK: a recording is replayed whole, a slow link slows the replay.
    """
    topics = list(topics) if topics is not None else select_topics(recording, None)
    target = Keys(namespace) if namespace is not None else None
    publishers: dict[str, object] = {}
    counts = PlayCounts()
    summary = recording.summary(rates=False)
    if summary.start_ns is None:
        return counts
    start_ns = summary.start_ns + int(start_seconds * 1e9)
    try:
        while not stop.is_set():
            first_log = None
            wall_start = time.monotonic()
            for message in recording.messages(topics, start_ns):
                if first_log is None:
                    first_log, wall_start = message.log_time, time.monotonic()
                if rate > 0:
                    due = wall_start + (message.log_time - first_log) / 1e9 / rate
                    delay = due - time.monotonic()
                    if delay > 0 and stop.wait(delay):
                        break
                if stop.is_set():
                    break
                key = target(message.key) if target is not None else message.topic
                publisher = publishers.get(key)
                if publisher is None:
                    # (a ROS 2 key's samples as the ROS 2 bridge put them: CDR, with the type)
                    encoding = (zenoh.Encoding.APPLICATION_CDR.with_schema(message.message_type)
                                if message.message_encoding == CDR_ENCODING else zenoh.Encoding.ZENOH_BYTES)
                    publisher = publishers[key] = session.declare_publisher(
                        key, congestion_control=zenoh.CongestionControl.BLOCK, encoding=encoding)
                publisher.put(message.payload)
                counts.published += 1
                counts.per_topic[key] = counts.per_topic.get(key, 0) + 1
                if on_message is not None:
                    on_message(key, len(message.payload))
            else:
                counts.passes += 1
                if loop and first_log is not None:
                    continue
            break
    finally:
        for publisher in publishers.values():
            publisher.undeclare()
    return counts


def wait_routed(session, echo_session, timeout: float) -> bool:
    """True once everything ``session`` put before this call has reached the router.

    A marker put by ``session`` (BLOCK, the data priority: it queues behind the data) is waited
    for at ``echo_session``, a second session on the same router; the router forwards in order,
    so once the marker is back the router holds all that came before it. Zenoh has no flush,
    and a closed session drops what it had not yet sent.
    """
    # A verbatim chunk (@...): no wildcard matches it, so `record '**'` never sees the marker.
    key = f"@balltrack/play/{session.zid()}/routed"
    arrived = threading.Event()
    subscriber = echo_session.declare_subscriber(key, lambda _sample: arrived.set())
    publisher = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    try:
        deadline = time.monotonic() + timeout
        if not poll_until(lambda: publisher.matching_status.matching, timeout, interval=0.01):
            return False  # the router has not told us of the echo
        publisher.put(b"")
        return arrived.wait(max(0.0, deadline - time.monotonic()))
    finally:
        publisher.undeclare()
        subscriber.undeclare()
