"""``balltrack record``, ``play`` and ``info`` as processes against a real router.

record: known messages published while it runs are in the file byte for byte, with arrival
times as log times, header stamps as publish times and header seqs as sequence numbers, and
``info`` counts them. play: a fresh subscriber receives the recorded payloads byte for byte and
in order (``--rate 0``, ``--keys``, ``--start``, ``--namespace``, ``--loop``). Bad files and
bad arguments: one line on stderr, exit 2.
"""

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import zenoh

from balltrack.common.messages import encode, header
from balltrack.common.recording import Recorder, RecordingFile
from tests.harness import REPO, Process, process_environment, wait_matched

BALLTRACK = [sys.executable, "-m", "balltrack"]


def balltrack(*arguments: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([*BALLTRACK, *arguments], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO, env=process_environment())


def ball3d(seq: int) -> bytes:
    return encode("Ball3D", {"header": header(5_000_000 * seq, seq), "x": 0.01 * seq,
                             "y": 0.0, "z": 1.5, "distance": 1.5})


def image(seq: int, width: int = 640, height: int = 480) -> bytes:
    pixels = bytes((seq + index) % 256 for index in range(256)) * (width * height * 3 // 256)
    return encode("Image", {"header": header(5_000_000 * seq, seq), "width": width,
                            "height": height, "encoding": "rgb8", "data": pixels})


class Received:
    """Every (key, payload) arriving on a key expression, in order, with waits."""

    def __init__(self, session, key_expression: str):
        self.items: list[tuple[str, bytes]] = []
        self._changed = threading.Condition()

        def on_sample(sample):
            with self._changed:
                self.items.append((str(sample.key_expr), sample.payload.to_bytes()))
                self._changed.notify_all()

        self.subscriber = session.declare_subscriber(key_expression, on_sample)

    def wait_count(self, count: int, timeout: float = 30) -> list:
        with self._changed:
            assert self._changed.wait_for(lambda: len(self.items) >= count, timeout), \
                f"{len(self.items)} of {count} messages"
            return list(self.items)


def test_record_writes_what_was_published_and_info_counts_it(router, session, tmp_path):
    path = tmp_path / "run.mcap"
    recorder = Process([*BALLTRACK, "record", "-o", str(path), "--connect", router.endpoint,
                        "--progress", "0.1"], tmp_path / "record.log")
    recorder.wait_for_output("recording", 30)
    block = {"congestion_control": zenoh.CongestionControl.BLOCK}
    publishers = {key: session.declare_publisher(key, **block)
                  for key in ("detected_ball_3d", "camera/image_raw", "clock", "detector/stats")}
    for publisher in publishers.values():
        wait_matched(publisher)
    sent = []  # (key, payload, seq or None, stamp or None)
    before = time.time_ns()
    for seq in range(1, 21):
        sent.append(("detected_ball_3d", ball3d(seq), seq, 5_000_000 * seq))
        if seq % 4 == 0:
            sent.append(("camera/image_raw", image(seq), seq, 5_000_000 * seq))
        sent.append(("clock", encode("Clock", {"stamp": 77 + seq}), None, 77 + seq))
    sent.append(("detected_ball_3d", b"\xc1 not msgpack", None, None))  # recorded as it came
    sent.append(("detector/stats", encode("Stats", {
        "service": "detector", "stamp": 99, "received": 1, "published": 1, "rejected": 0,
        "dropped": 0, "p50_ms": 1.0, "p99_ms": 2.0}), None, 99))
    for key, payload, _, _ in sent:
        publishers[key].put(payload)
    recorder.wait_for_output(f"{len(sent)} messages written", 30)
    after = time.time_ns()
    assert recorder.stop() == 0, recorder.output()
    assert f"recorded {len(sent)} messages" in recorder.output()

    info = balltrack("info", str(path), "--json")
    assert info.returncode == 0, info.stderr
    summary = json.loads(info.stdout)
    counts = {item["key"]: (item["type"], item["count"]) for item in summary["keys"]
              if item["encoding"] == "msgpack"}
    assert counts == {"detected_ball_3d": ("Ball3D", 21), "camera/image_raw": ("Image", 5),
                      "clock": ("Clock", 20), "detector/stats": ("Stats", 1)}
    # beside them, for Foxglove: the valid Ball3D as scenes, the frames as JPEG
    viewing = {item["topic"]: (item["type"], item["encoding"], item["count"]) for item in summary["keys"]
               if item["encoding"] != "msgpack"}
    assert viewing == {"/scene": ("foxglove.SceneUpdate", "protobuf", 20),
                       "/camera/image": ("foxglove.CompressedImage", "protobuf", 5)}
    assert summary["messages"] == len(sent) + 25 and summary["complete"]
    table = balltrack("info", str(path))
    assert table.returncode == 0 and "camera/image_raw" in table.stdout, table.stderr

    with RecordingFile(path) as recording:
        recorded = [message for message in recording.messages() if message.message_encoding == "msgpack"]
    for key in publishers:  # per key, in publishing order (keys interleave by arrival)
        mine = [item for item in sent if item[0] == key]
        theirs = [message for message in recorded if message.topic == key]
        assert [message.payload for message in theirs] == [item[1] for item in mine]
        for (_, _, seq, stamp), message in zip(mine, theirs):
            assert before <= message.log_time <= after
            assert message.publish_time == (message.log_time if stamp is None else stamp)
            assert message.sequence == (seq or 0)
    assert [message.log_time for message in recorded] == sorted(m.log_time for m in recorded)


def test_held_messages_wait_and_are_all_written_at_stop(router, session, tmp_path):
    path = tmp_path / "held.mcap"
    recorder = Process([*BALLTRACK, "record", "-o", str(path), "--connect", router.endpoint,
                        "--hold", "10", "--progress", "0.1", "--nice", "5", "detected_ball_3d"],
                       tmp_path / "record.log")
    recorder.wait_for_output("recording", 30)
    # --nice: every thread of the recorder, Zenoh's included, runs at least 5 below this test's
    # priority (the writer thread lowers its own to 19).
    threads = list((Path("/proc") / str(recorder.popen.pid) / "task").iterdir())
    priorities = [os.getpriority(os.PRIO_PROCESS, int(thread.name)) for thread in threads]
    assert len(threads) > 2 and min(priorities) == os.getpriority(os.PRIO_PROCESS, 0) + 5, priorities
    publisher = session.declare_publisher("detected_ball_3d", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_matched(publisher)
    for seq in range(1, 11):
        publisher.put(ball3d(seq))
    # All ten arrived and none is written yet: each is held 10 s after its arrival...
    recorder.wait_for_output("0 messages written, 10 waiting", 30)
    # ...but stopping does not wait out the hold, and loses none of them.
    assert recorder.stop() == 0, recorder.output()
    assert "recorded 10 messages" in recorder.output()
    with RecordingFile(path) as recording:
        payloads = [message.payload for message in recording.messages() if message.message_encoding == "msgpack"]
    assert payloads == [ball3d(seq) for seq in range(1, 11)]


def known_recording(path, count: int = 12, namespace: str = "") -> list[tuple[str, bytes]]:
    """A file of ``count`` Ball3D and every third an Image, log times 1 s apart. The images are
    160x120 (57 kB, one Zenoh batch): under load a router may drop a message of many fragments
    on its way to a slow subscriber (eclipse-zenoh/zenoh#1494, #2258), which is not what these
    tests are about; full frames are replayed in tests/e2e/test_recording_replay.py."""
    prefix = f"{namespace}/" if namespace else ""
    recorder = Recorder(path)
    written = []
    for seq in range(count):
        for key, message_type, payload in (("detected_ball_3d", "Ball3D", ball3d(seq)),
                                           ("camera/image_raw", "Image", image(seq, 160, 120))):
            if key == "camera/image_raw" and seq % 3:
                continue
            channel = recorder.msgpack_channel(prefix + key, key, namespace, message_type)
            recorder.write_payload(channel, payload, arrival_ns=1_700_000_000_000_000_000
                                   + seq * 1_000_000_000)
            written.append((prefix + key, payload))
    recorder.close()
    return written


def test_play_publishes_the_payloads_in_order(router, session, tmp_path):
    path = tmp_path / "known.mcap"
    written = known_recording(path)
    received = Received(session, "**")
    result = balltrack("play", str(path), "--rate", "0", "--connect", router.endpoint)
    assert result.returncode == 0, result.stderr
    assert f"published {len(written)} messages" in result.stdout
    assert received.wait_count(len(written)) == written


def test_play_keys_start_and_namespace(router, session, tmp_path):
    path = tmp_path / "known.mcap"
    written = known_recording(path, namespace="robot1")
    received = Received(session, "**")
    # Only the images, from 4.5 s into the recording, moved to robot2.
    result = balltrack("play", str(path), "--rate", "0", "--keys", "camera/image_raw",
                       "--start", "4.5", "--namespace", "robot2", "--connect", router.endpoint)
    assert result.returncode == 0, result.stderr
    expected = [("robot2/camera/image_raw", payload) for key, payload in written
                if key == "robot1/camera/image_raw"][2:]  # images at 0, 3 s skipped
    assert received.wait_count(len(expected)) == expected
    missing = balltrack("play", str(path), "--keys", "cmd_vel", "--connect", router.endpoint)
    assert missing.returncode == 2 and "cmd_vel" in missing.stderr
    assert len(missing.stderr.strip().splitlines()) == 1
    # (the recording's messages are 1 s apart, the last 11 s after the first)
    late = balltrack("play", str(path), "--start", "11.5", "--connect", router.endpoint)
    assert late.returncode == 2 and late.stdout == ""
    assert late.stderr.strip() == ("balltrack play: --start 11.5 s is past the recording's end (11.000 s after "
                                   "its first message): nothing to play")


def test_play_loop_repeats_until_stopped(router, session, tmp_path):
    path = tmp_path / "known.mcap"
    written = known_recording(path, count=3)
    received = Received(session, "**")
    player = Process([*BALLTRACK, "play", str(path), "--rate", "0", "--loop", "--connect",
                      router.endpoint], tmp_path / "play.log")
    items = received.wait_count(3 * len(written) + 1)
    assert player.stop() == 0, player.output()
    assert items[: 3 * len(written)] == written * 3
    assert "complete passes" in player.output()


def test_bad_files_and_arguments_are_one_line_and_exit_2(router, tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"this is not an MCAP file at all")
    cases = [("info", str(garbage)), ("info", str(tmp_path / "missing.mcap")),
             ("play", str(garbage), "--connect", router.endpoint),
             ("play", str(tmp_path / "missing.mcap"), "--connect", router.endpoint),
             ("play", str(garbage), "--rate", "-1", "--connect", router.endpoint),
             ("play", str(garbage), "--rate", "fast"),
             # (as record's: a bad endpoint or config file, said before the file is read)
             ("play", str(garbage), "--connect", "localhost:7447"),
             ("play", str(garbage), "--zenoh-config", str(tmp_path / "missing.json5")),
             ("record", "--connect", router.endpoint),  # no -o
             ("record", "-o", str(tmp_path / "x.mcap"), "--duration", "0"),
             ("record", "-o", str(tmp_path / "x.mcap"), "--hold", "-0.1"),
             ("record", "-o", str(tmp_path / "x.mcap"), "--nice", "20"),
             ("record", "-o", str(tmp_path / "x.mcap"), "--peer", "--secure", str(tmp_path))]
    for arguments in cases:
        result = balltrack(*arguments)
        assert result.returncode == 2, (arguments, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in result.stderr, (arguments, result.stderr)


def test_record_stops_after_duration_and_info_works_in_a_pipe(router, tmp_path):
    path = tmp_path / "short.mcap"
    result = balltrack("record", "-o", str(path), "--duration", "0.5", "--connect", router.endpoint)
    assert result.returncode == 0, result.stderr
    assert "recorded 0 messages" in result.stdout
    known_recording(path)
    piped = subprocess.run(f"{sys.executable} -m balltrack info {path} | head -1", shell=True,
                           capture_output=True, text=True, cwd=REPO, env=process_environment(),
                           timeout=60)
    assert piped.returncode == 0 and piped.stdout.startswith("File:")
    assert "Traceback" not in piped.stderr and "Broken pipe" not in piped.stderr, piped.stderr


def test_play_refuses_a_channel_whose_name_is_no_zenoh_key_before_playing(router, tmp_path):
    # (a file of another writer: zenoh's traceback when its publisher was declared, status 1)
    path = tmp_path / "odd.mcap"
    recorder = Recorder(path)
    channel = recorder.msgpack_channel("/weird topic", "/weird topic", "", None)
    recorder.write_payload(channel, ball3d(1), 1_000)
    recorder.close()
    result = balltrack("play", str(path), "--connect", router.endpoint)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == ("balltrack play: channel '/weird topic': '/weird topic' is not a Zenoh key, "
                             "so it cannot be played\n")
