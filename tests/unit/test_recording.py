"""The MCAP file side of recordings (common/recording.py): what is written is read back
byte for byte, with the times and sequence numbers the README specifies."""

import json
import os
import threading

import msgpack
import pytest

from balltrack.common.messages import encode, header
from balltrack.common.recording import (MESSAGE_ENCODING, SCHEMA_ENCODING, Recorder,
                                        RecordingError, RecordingFile, header_fields)


def ball3d(seq: int, stamp: int) -> bytes:
    return encode("Ball3D", {"header": header(stamp, seq), "x": 0.1 * seq, "y": 0.0, "z": 1.0,
                             "distance": 1.0 + seq})


def test_header_fields_are_read_leniently():
    assert header_fields(ball3d(7, 123)) == (123, 7)
    assert header_fields(encode("Clock", {"stamp": 55})) == (55, None)
    assert header_fields(b"\xc1 not msgpack") == (None, None)
    assert header_fields(msgpack.packb([1, 2])) == (None, None)
    assert header_fields(msgpack.packb({"header": {"stamp": -1, "seq": 1 << 40}})) == (None, None)
    assert header_fields(msgpack.packb({"header": {"stamp": True, "seq": "3"}})) == (None, None)


def test_written_messages_read_back_with_times_schema_and_counts(tmp_path):
    path = tmp_path / "r.mcap"
    recorder = Recorder(path)
    balls = recorder.msgpack_channel("robot1/detected_ball_3d", "detected_ball_3d", "robot1",
                                     "Ball3D")
    assert recorder.msgpack_channel("robot1/detected_ball_3d", "detected_ball_3d", "robot1",
                                    "Ball3D") == balls
    other = recorder.msgpack_channel("robot1/custom", "custom", "robot1", None)
    written = []
    for seq in range(1, 6):
        payload = ball3d(seq, 1000 * seq)
        recorder.write_payload(balls, payload, arrival_ns=10_000_000_000 + seq)
        written.append(("robot1/detected_ball_3d", payload, 10_000_000_000 + seq, 1000 * seq, seq))
    recorder.write_payload(other, b"\x00\x01garbage", arrival_ns=10_000_000_009)
    written.append(("robot1/custom", b"\x00\x01garbage", 10_000_000_009, 10_000_000_009, 0))
    recorder.close()

    with RecordingFile(path) as recording:
        read = [(m.topic, m.payload, m.log_time, m.publish_time, m.sequence)
                for m in recording.messages()]
        assert read == written
        assert {m.key for m in recording.messages()} == {"detected_ball_3d", "custom"}
        summary = recording.summary()
    assert summary.complete and summary.count == 6
    assert summary.start_ns == 10_000_000_001 and summary.end_ns == 10_000_000_009
    by_topic = {channel.topic: channel for channel in summary.channels}
    assert by_topic["robot1/detected_ball_3d"].message_type == "Ball3D"
    assert by_topic["robot1/detected_ball_3d"].count == 5
    assert by_topic["robot1/custom"].message_type == "" and by_topic["robot1/custom"].count == 1
    assert all(channel.message_encoding == MESSAGE_ENCODING for channel in summary.channels)

    from mcap.reader import make_reader

    with open(path, "rb") as stream:  # what other MCAP tools see
        mcap_summary = make_reader(stream).get_summary()
    schema = next(iter(mcap_summary.schemas.values()))
    assert (schema.name, schema.encoding) == ("Ball3D", SCHEMA_ENCODING)
    assert json.loads(schema.data)["title"] == "Ball3D"
    assert {chunk.compression for chunk in mcap_summary.chunk_indexes} == {"zstd"}
    channel = next(c for c in mcap_summary.channels.values() if c.topic == "robot1/custom")
    assert channel.schema_id == 0 and channel.metadata == {"key": "custom", "namespace": "robot1"}


def test_topics_and_start_select_messages(tmp_path):
    path = tmp_path / "r.mcap"
    recorder = Recorder(path)
    first = recorder.msgpack_channel("a", "a", "", "Ball3D")
    second = recorder.msgpack_channel("b", "b", "", "Ball3D")
    for seq in range(10):
        recorder.write_payload(first if seq % 2 else second, ball3d(seq, seq),
                               arrival_ns=seq * 10**9)
    recorder.close()
    with RecordingFile(path) as recording:
        assert [m.sequence for m in recording.messages(["a"])] == [1, 3, 5, 7, 9]
        assert [m.sequence for m in recording.messages(None, 4 * 10**9)] == [4, 5, 6, 7, 8, 9]


def test_a_recording_cut_short_is_read_up_to_its_last_chunk(tmp_path):
    path = tmp_path / "cut.mcap"
    recorder = Recorder(path, chunk_size=200)  # a chunk every message or two
    channel = recorder.msgpack_channel("detected_ball_3d", "detected_ball_3d", "", "Ball3D")
    for seq in range(50):
        recorder.write_payload(channel, ball3d(seq, seq), arrival_ns=seq + 1)
    recorder.close()
    whole = path.read_bytes()
    cut = tmp_path / "cut-short.mcap"
    cut.write_bytes(whole[: len(whole) // 2])  # what a SIGKILLed recorder leaves: no summary
    with RecordingFile(cut) as recording:
        summary = recording.summary()
        sequences = [m.sequence for m in recording.messages()]
        assert not summary.complete
        assert 0 < summary.count < 50 and summary.count == len(sequences)
        assert sequences == list(range(len(sequences)))
        # (read whole once, then kept: each caller gets its own copy)
        summary.channels[0].count = -1
        assert recording.summary(rates=False).count == len(sequences)


@pytest.mark.parametrize("content", [b"", b"hello, not mcap", b"\x89MCAP0\r\n" + b"\x00" * 40])
def test_what_is_not_a_recording_is_one_line_error(tmp_path, content):
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    with pytest.raises(RecordingError) as raised:
        with RecordingFile(path) as recording:
            recording.summary()
            list(recording.messages())
    assert "\n" not in str(raised.value) and str(path) in str(raised.value)


def test_missing_file_and_unwritable_path_are_one_line_errors(tmp_path):
    with pytest.raises(RecordingError, match="cannot read"):
        RecordingFile(tmp_path / "missing.mcap")
    with pytest.raises(RecordingError, match="cannot write"):
        Recorder(tmp_path / "no" / "such" / "folder.mcap")


@pytest.mark.skipif(not hasattr(os, "setpriority"), reason="per-thread nice is Linux's")
def test_the_writer_thread_yields_the_cpu_and_only_it():
    from balltrack.deploy.recording import lower_priority

    seen = {}

    def writer():
        lower_priority()
        seen["writer"] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    thread = threading.Thread(target=writer)
    thread.start()
    thread.join()
    assert seen["writer"] == 19
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) < 19


def test_info_times_agree_to_the_millisecond():
    from balltrack.cli.recording import _when

    # (.8976 s: the clock time and the seconds both read .897, neither rounded up)
    shown = _when(1_796_195_070_897_600_000)
    assert shown.endswith(".897 (1796195070.897)"), shown
    assert _when(None) == "-"
