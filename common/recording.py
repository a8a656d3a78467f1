"""Recordings of balltrack messages in MCAP files, the format ROS 2 bags and Foxglove use.

This is the file side only (no Zenoh): :class:`Recorder` writes messages, :class:`RecordingFile`
reads them back and sums them up. ``balltrack record`` / ``play`` / ``info`` and the demo's
``run.mcap`` are built on it (the Zenoh side is ``deploy/recording.py``).

Layout of a balltrack recording:

* one channel per Zenoh key; the topic is the key as it travelled, namespace included
  (``robot1/camera/image_raw``), and the channel metadata names the ``key`` without it and the
  ``namespace``, so a player can put the messages under another namespace;
* message encoding ``msgpack``: each payload is stored byte for byte, as it was published;
* a schema per message type (``Image``, ``Ball3D``...), encoding ``jsonschema``: the schema's
  name is the contract's message type, its data a short JSON Schema saying so. A key outside the
  contract gets a channel without a schema;
* log time = when the recorder received the message (wall clock, ns); publish time = the
  message's header stamp (simulated time when the simulator is the camera), or the log time
  when the payload has none; sequence = the header's ``seq`` (0 when none);
* zstd-compressed chunks, with the indexes and statistics that ``mcap info`` and readers use.

A key that carries ROS 2 messages (the ROS 2 bridge's ``ros/...`` keys, zenoh-bridge-ros2dds')
gets a channel of message encoding ``cdr`` instead, its payloads byte for byte too, with the
``ros2msg`` schema of its type when the publisher named it (Zenoh encoding
``application/cdr;geometry_msgs/msg/Point``) and the ``ros`` extra is installed: Foxglove and
ROS 2 tools read those channels as they read a ROS 2 bag's.

Other channels (say Foxglove's own message types, next to the msgpack ones) go through
:meth:`Recorder.add_channel` and :meth:`Recorder.write`.
"""

import copy
import json
import os
import threading
from dataclasses import dataclass, field
from typing import IO, Iterable, Iterator

from balltrack.common.messages import unpack_sharing_bins

MESSAGE_ENCODING = "msgpack"
SCHEMA_ENCODING = "jsonschema"
# ROS 2 messages, as ROS 2 bags in MCAP store them.
CDR_ENCODING = "cdr"
ROS2_SCHEMA_ENCODING = "ros2msg"
# MCAP stores the sequence number as uint32 and times as uint64.
MAX_SEQUENCE = (1 << 32) - 1
MAX_TIME = (1 << 64) - 1
# A camera frame is about 1 MB: chunks of 4 MB hold a few of them, so zstd sees more than one
# frame at a time while a reader still needs little memory per chunk.
CHUNK_SIZE = 4 * 1024 * 1024


class RecordingError(RuntimeError):
    """A file that is not a readable recording, or a recording that cannot be written; the
    message is one line."""


def one_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    reason = text[0] if text else ""
    return f"{type(error).__name__}: {reason}" if reason else type(error).__name__


def looks_like_cdr(payload: bytes) -> bool:
    """Whether a payload starts as a CDR-serialised ROS 2 message does: the encapsulation
    header (00 00 or 00 01, then two option bytes of 0). No balltrack message does: a
    msgpack map's first byte is 0x80-0x8f, 0xde or 0xdf."""
    return len(payload) >= 4 and payload[0] == 0 and payload[1] in (0, 1) and payload[2:4] == b"\x00\x00"


def ros2_message_definition(ros_type: str) -> bytes:
    """The ``ros2msg`` schema data of a ROS 2 message type (its definition and those of the
    types it holds, as ROS 2 bags store them); empty when the type is unknown or rosbags (the
    ``ros`` extra) is not installed."""
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        return b""
    try:
        text, _ = get_typestore(Stores.ROS2_HUMBLE).generate_msgdef(ros_type, ros_version=2)
    except Exception:  # (rosbags raises its own errors for a name it does not know)
        return b""
    return text.encode()


def message_schema(message_type: str) -> bytes:
    """The schema data recorded for a contract message type: a JSON Schema that names it."""
    return json.dumps({
        "title": message_type,
        "description": f"balltrack {message_type} message: one msgpack map, as specified in "
                       "the README's contract (keys and messages)",
        "type": "object",
    }).encode()


def header_fields(payload: bytes) -> tuple[int | None, int | None]:
    """(stamp, seq) of a message, read leniently: a payload that is not a msgpack map with a
    header gives None for what it lacks. ``Clock`` and ``Stats`` carry their stamp at the top."""
    try:
        message = unpack_sharing_bins(bytes(payload))  # (a frame's pixels are not copied)
    except Exception:  # msgpack raises several unrelated exception types; any means "no header"
        return None, None
    if not isinstance(message, dict):
        return None, None
    header = message.get("header")
    source = header if isinstance(header, dict) else message
    stamp, seq = source.get("stamp"), source.get("seq")

    def in_range(value, maximum):
        return value if isinstance(value, int) and not isinstance(value, bool) \
            and 0 <= value <= maximum else None

    return in_range(stamp, MAX_TIME), in_range(seq, MAX_SEQUENCE)


@dataclass
class ChannelCount:
    """One channel of a recording as :meth:`RecordingFile.summary` reports it."""
    topic: str
    key: str
    message_type: str
    message_encoding: str
    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    has_key: bool = False  # its metadata names the Zenoh key it was recorded from (balltrack's)

    @property
    def rate(self) -> float:
        """Messages per second between the first and the last (0 with fewer than two)."""
        if self.count < 2 or self.first_ns is None or self.last_ns == self.first_ns:
            return 0.0
        return (self.count - 1) / ((self.last_ns - self.first_ns) / 1e9)


@dataclass
class Summary:
    path: str
    size: int
    channels: list[ChannelCount] = field(default_factory=list)
    start_ns: int | None = None
    end_ns: int | None = None
    complete: bool = True  # False: no summary section (the recorder was killed); counts are scanned

    @property
    def count(self) -> int:
        return sum(channel.count for channel in self.channels)

    @property
    def duration(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9


@dataclass(frozen=True)
class RecordedMessage:
    topic: str
    key: str  # the key without the recording's namespace
    message_type: str  # "" when the channel has no schema
    payload: bytes
    log_time: int
    publish_time: int
    sequence: int
    message_encoding: str = MESSAGE_ENCODING
    has_key: bool = False  # its channel's metadata names the Zenoh key (balltrack recorded it)


class Recorder:
    """Writes an MCAP file; safe to call from several threads. ``close()`` finalises it (the
    summary and indexes readers use); a file never closed is still readable up to its last
    complete chunk."""

    def __init__(self, path: str | os.PathLike, library: str = "balltrack",
                 chunk_size: int = CHUNK_SIZE, metadata: dict[str, str] | None = None):
        from mcap.writer import CompressionType, Writer

        try:
            self._file: IO[bytes] = open(path, "wb")
        except OSError as error:
            raise RecordingError(f"cannot write {path}: {error.strerror}") from None
        self.path = str(path)
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library=library)
        if metadata:
            self._writer.add_metadata("balltrack", {str(k): str(v) for k, v in metadata.items()})
        self._lock = threading.RLock()  # msgpack_channel registers under the same lock
        self._schemas: dict[tuple[str, str], int] = {}
        self._channels: dict[str, int] = {}
        self.bytes = 0
        self.closed = False

    def add_channel(self, topic: str, schema_name: str = "", schema_encoding: str = "",
                    schema_data: bytes = b"", message_encoding: str = MESSAGE_ENCODING,
                    metadata: dict[str, str] | None = None) -> int:
        """Register a channel (and its schema, once per name and encoding); returns its id.
        An empty ``schema_name`` means no schema (schema id 0)."""
        with self._lock:
            schema_id = 0
            if schema_name:
                schema_id = self._schemas.get((schema_name, schema_encoding), 0)
                if not schema_id:
                    schema_id = self._writer.register_schema(schema_name, schema_encoding,
                                                             schema_data)
                    self._schemas[(schema_name, schema_encoding)] = schema_id
            channel_id = self._writer.register_channel(topic, message_encoding, schema_id,
                                                       dict(metadata or {}))
            self._channels[topic] = channel_id
            return channel_id

    def msgpack_channel(self, topic: str, key: str, namespace: str,
                        message_type: str | None) -> int:
        """The channel of a balltrack key (created on first use)."""
        with self._lock:
            existing = self._channels.get(topic)
            if existing:
                return existing
            metadata = {"key": key, "namespace": namespace}
            if message_type:
                return self.add_channel(topic, message_type, SCHEMA_ENCODING,
                                        message_schema(message_type), MESSAGE_ENCODING, metadata)
            return self.add_channel(topic, message_encoding=MESSAGE_ENCODING, metadata=metadata)

    def cdr_channel(self, topic: str, key: str, namespace: str, ros_type: str | None) -> int:
        """The channel of a key that carries ROS 2 messages (created on first use), with the
        ``ros2msg`` schema of ``ros_type`` when it is known."""
        with self._lock:
            existing = self._channels.get(topic)
            if existing:
                return existing
            metadata = {"key": key, "namespace": namespace}
            definition = ros2_message_definition(ros_type) if ros_type else b""
            if definition:
                return self.add_channel(topic, ros_type, ROS2_SCHEMA_ENCODING, definition, CDR_ENCODING, metadata)
            return self.add_channel(topic, message_encoding=CDR_ENCODING, metadata=metadata)

    def write(self, channel_id: int, payload: bytes, log_time: int, publish_time: int,
              sequence: int = 0) -> None:
        with self._lock:
            if self.closed:
                return
            self._writer.add_message(channel_id, log_time=log_time, data=payload,
                                     publish_time=publish_time, sequence=sequence)
            self.bytes += len(payload)

    def write_payload(self, channel_id: int, payload: bytes, arrival_ns: int) -> None:
        """A msgpack message as the contract specifies: publish time and sequence from its
        header, the arrival time as log time."""
        stamp, seq = header_fields(payload)
        self.write(channel_id, payload, arrival_ns, arrival_ns if stamp is None else stamp,
                   seq or 0)

    def close(self) -> None:
        with self._lock:
            if self.closed:
                return
            self.closed = True
            try:
                self._writer.finish()
            finally:
                self._file.close()


class RecordingFile:
    """An MCAP file opened for reading; :class:`RecordingError` (one line) when it is not one."""

    def __init__(self, path: str | os.PathLike):
        from mcap.reader import SeekingReader

        self.path = str(path)
        try:
            self._file: IO[bytes] = open(path, "rb")
        except OSError as error:
            raise RecordingError(f"cannot read {path}: {error.strerror}") from None
        try:
            self._reader = SeekingReader(self._file)
        except Exception as error:  # the mcap library's errors come from several places
            self._file.close()
            from mcap.exceptions import InvalidMagic

            reason = "it does not start with the MCAP magic" if isinstance(error, InvalidMagic) \
                else one_line(error)
            raise RecordingError(f"{path} is not an MCAP file ({reason})") from None
        try:
            self._summary = self._reader.get_summary()
        except Exception:  # no footer: a recording whose writer never finished; still readable
            self._summary = None
        if self._summary is None:  # ...but only if it got as far as its header record
            try:
                self._reader.get_header()
            except Exception as error:
                self._file.close()
                raise RecordingError(f"{path} is not an MCAP file (no header record: "
                                     f"{one_line(error)})") from None
        self.size = os.fstat(self._file.fileno()).st_size
        # What a file without a summary section gave when it was read whole (see ``summary``)
        self._read_whole: Summary | None = None

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *_):
        self.close()

    @property
    def complete(self) -> bool:
        return self._summary is not None

    def _records(self, topics: Iterable[str] | None, start_ns: int | None) -> Iterator:
        from mcap.reader import NonSeekingReader

        topics = None if topics is None else list(topics)
        if self._summary is not None and self._summary.chunk_indexes:
            yield from self._reader.iter_messages(topics=topics, starting_at=start_ns,
                                                  log_time_order=True)
            return
        # No index: read in file order, which is the order the recorder wrote (arrival order),
        # and stop quietly where a killed recorder's file ends.
        self._file.seek(0)
        reader = NonSeekingReader(self._file)
        iterator = reader.iter_messages(topics=topics, starting_at=start_ns, log_time_order=False)
        while True:
            try:
                item = next(iterator)
            except StopIteration:
                return
            except Exception as error:
                if self._summary is None:
                    return
                raise RecordingError(f"{self.path}: {one_line(error)}") from None
            yield item

    def messages(self, topics: Iterable[str] | None = None,
                 start_ns: int | None = None) -> Iterator[RecordedMessage]:
        """Messages in log-time order, of ``topics`` only when given, from ``start_ns`` on."""
        try:
            for schema, channel, message in self._records(topics, start_ns):
                yield RecordedMessage(
                    topic=channel.topic, key=channel.metadata.get("key", channel.topic),
                    message_type=schema.name if schema is not None else "",
                    payload=bytes(message.data), log_time=message.log_time,
                    publish_time=message.publish_time, sequence=message.sequence,
                    message_encoding=channel.message_encoding, has_key="key" in channel.metadata)
        except RecordingError:
            raise
        except Exception as error:  # a corrupt chunk, a bad record: one line, never a traceback
            raise RecordingError(f"{self.path}: damaged recording ({one_line(error)})") from None

    def channels(self) -> list[ChannelCount]:
        """Every channel with its key, message type and count (without first and last times)."""
        return self.summary(rates=False).channels

    def summary(self, rates: bool = True) -> Summary:
        """Channels, counts and times; ``rates`` also reads every message's time for the
        channels' first and last (a file without a summary section is read whole anyway)."""
        result = Summary(path=self.path, size=self.size, complete=self.complete)
        if self._summary is not None:
            statistics = self._summary.statistics
            counts = statistics.channel_message_counts if statistics else {}
            for channel_id, channel in sorted(self._summary.channels.items()):
                schema = self._summary.schemas.get(channel.schema_id)
                result.channels.append(ChannelCount(
                    topic=channel.topic, key=channel.metadata.get("key", channel.topic),
                    message_type=schema.name if schema else "",
                    message_encoding=channel.message_encoding,
                    count=counts.get(channel_id, 0), has_key="key" in channel.metadata))
            if statistics and statistics.message_count:
                result.start_ns = statistics.message_start_time
                result.end_ns = statistics.message_end_time
            if rates:  # the summary has counts per channel, but not their first and last times
                self._times(result)
            return result
        # (read whole once: play asks for the channels, then the keys, then the times)
        if self._read_whole is None:
            self._times(result, count=True)
            self._read_whole = result
        return copy.deepcopy(self._read_whole)

    def _times(self, result: Summary, count: bool = False) -> None:
        by_topic = {channel.topic: channel for channel in result.channels}
        for message in self.messages():
            channel = by_topic.get(message.topic)
            if channel is None:
                channel = by_topic[message.topic] = ChannelCount(
                    topic=message.topic, key=message.key, message_type=message.message_type,
                    message_encoding=message.message_encoding, has_key=message.has_key)
                result.channels.append(channel)
            if count:
                channel.count += 1
            if channel.first_ns is None:
                channel.first_ns = message.log_time
            channel.last_ns = message.log_time
            if count:
                result.start_ns = message.log_time if result.start_ns is None \
                    else min(result.start_ns, message.log_time)
                result.end_ns = message.log_time if result.end_ns is None \
                    else max(result.end_ns, message.log_time)
