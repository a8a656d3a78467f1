"""Recordings, as ``ros2 bag`` does: record, play, info (MCAP files, see common/recording.py).

    balltrack record -o run.mcap                      # every data and stats key until Ctrl-C
    balltrack record -o frames.mcap camera/image_raw camera/camera_info --duration 10
    balltrack play run.mcap --rate 2 --keys camera/image_raw
    balltrack info run.mcap

Each works in a pipe and stops within a fraction of a second on SIGINT or SIGTERM; ``record``
then finishes its file (a file cut short by SIGKILL is still readable up to its last chunk).
"""

import json
import os
import sys
import threading
import time
from datetime import datetime, timezone

from balltrack.cli.output import Output
from balltrack.common.terminal import silence_closed_stdout
from balltrack.cli.session import close_or_report, networked, open_or_report, refused_for_role
from balltrack.common.arguments import seconds, unwritable_reason, zero_or
from balltrack.common.memory import keep_freed_memory
from balltrack.common.recording import RecordingError, RecordingFile
from balltrack.common.session import peer_conflict
from balltrack.common.shutdown import stop_on_signals
from balltrack.deploy.recording import (DEFAULT_KEYS, MAX_QUEUED_BYTES, Recording, check_played_keys, play,
                                        select_topics, wait_routed)


def _fail(args, reason: str, status: int) -> int:
    print(f"balltrack {args.command}: {reason}", file=sys.stderr)
    return status


def _open(args) -> RecordingFile | int:
    try:
        return RecordingFile(args.file)
    except RecordingError as error:
        return _fail(args, str(error), 2)


def _size(size: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{size:.1f} GiB"


def _when(nanoseconds: int | None) -> str:
    if nanoseconds is None:
        return "-"
    # (both to the millisecond below: the clock time and the seconds agree to the digit)
    milliseconds = nanoseconds // 1_000_000
    moment = datetime.fromtimestamp(milliseconds / 1e3, timezone.utc).astimezone()
    return f"{moment:%Y-%m-%d %H:%M:%S}.{milliseconds % 1000:03d} ({milliseconds // 1000}.{milliseconds % 1000:03d})"


def command_record(args) -> int:
    if not 0 <= args.hold <= 10:
        return _fail(args, "--hold: must be 0 to 10 seconds", 2)
    if not 0 <= args.nice <= 19:
        return _fail(args, "--nice: must be 0 to 19", 2)
    conflict = peer_conflict(args)
    if conflict:
        return _fail(args, conflict, 2)
    unwritable = unwritable_reason(args.output)
    if unwritable:  # (before waiting for a router, which may take long or never answer)
        return _fail(args, f"cannot write {args.output}: {unwritable}", 2)
    if args.nice:
        os.nice(args.nice)  # before the session: threads take the priority of their creator
    keep_freed_memory()  # (frames come and go at 30 a second)
    stop = stop_on_signals()
    session = open_or_report(args, stop)
    if session is None:
        return 1
    out = Output(stop)
    keys = args.keys or DEFAULT_KEYS
    try:
        try:
            recording = Recording(session, args.output, keys, args.namespace,
                                  foxglove=False if args.no_foxglove else None, hold=args.hold)
        except RecordingError as error:
            return _fail(args, str(error), 1)
        except Exception as error:  # e.g. a key expression Zenoh refuses
            return _fail(args, f"cannot subscribe: {str(error).strip().splitlines()[0]}", 2)
        print(f"balltrack record: recording {len(keys)} key(s) into {args.output} "
              f"(Ctrl-C to stop)", file=sys.stderr, flush=True)
        started = time.monotonic()
        deadline = None if args.duration is None else started + args.duration
        while True:
            wait = args.progress or None
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                wait = remaining if wait is None else min(wait, remaining)
            if stop.wait(wait):
                break
            if args.progress:
                counts = recording.counts
                print(f"balltrack record: {counts.written} messages written, "
                      f"{counts.received - counts.written} waiting, {counts.dropped} dropped",
                      file=sys.stderr, flush=True)
        counts = recording.close()
        elapsed = time.monotonic() - started
    finally:
        close_or_report(args, session)
    out.line(f"recorded {counts.written} messages in {elapsed:.1f} s into {args.output}"
             + (f" ({counts.dropped} dropped: compressing and writing fell {MAX_QUEUED_BYTES >> 20} MB "
                  "behind what arrived)"
                if counts.dropped else ""))
    for topic, count in sorted(counts.per_topic.items()):
        out.line(f"  {topic:<28} {count:>8}")
    if out.closed:
        silence_closed_stdout()
    return 0


def command_play(args) -> int:
    recording = _open(args)
    if isinstance(recording, int):
        return recording
    with recording:
        try:
            topics = select_topics(recording, args.keys)
            check_played_keys(recording, topics, args.namespace)
            duration = recording.summary(rates=False).duration
        except ValueError as error:
            return _fail(args, str(error), 2)
        except RecordingError as error:
            return _fail(args, str(error), 2)
        if args.start > duration:
            return _fail(args, f"--start {args.start:g} s is past the recording's end ({duration:.3f} s "
                               "after its first message): nothing to play", 2)
        if refused_for_role(args, "puts", [channel.key for channel in recording.channels() if channel.topic in topics]):
            return 2
        stop = stop_on_signals()
        session = open_or_report(args, stop)
        if session is None:
            return 1
        out = Output(stop)
        started = time.monotonic()
        try:
            counts = play(session, recording, stop, rate=args.rate, loop=args.loop,
                          topics=topics, start_seconds=args.start, namespace=args.namespace)
        except RecordingError as error:
            return _fail(args, str(error), 1)
        finally:
            if not stop.is_set():  # the end of the file: let the router take what is queued
                _wait_routed(args, session)
            close_or_report(args, session)
    elapsed = time.monotonic() - started
    out.line(f"published {counts.published} messages in {elapsed:.1f} s "
             f"({counts.passes} complete pass{'es' if counts.passes != 1 else ''})")
    for key, count in sorted(counts.per_topic.items()):
        out.line(f"  {key:<28} {count:>8}")
    if out.closed:
        silence_closed_stdout()
    return 0


def _wait_routed(args, session) -> None:
    """Closing a session drops what it has not sent yet (the last frames of a recording): wait
    until a marker put after them came back through the router to a second session."""
    echo = open_or_report(args)
    if echo is not None:
        try:
            if not wait_routed(session, echo, args.timeout):
                print(f"balltrack play: the router did not confirm the last messages in "
                      f"{args.timeout:g} s; some may be lost", file=sys.stderr)
        finally:
            echo.close()


def command_info(args) -> int:
    recording = _open(args)
    if isinstance(recording, int):
        return recording
    with recording:
        try:
            summary = recording.summary()
        except RecordingError as error:
            return _fail(args, str(error), 2)
    out = Output(threading.Event())
    if args.json:
        out.line(json.dumps({
            "file": summary.path, "size": summary.size, "complete": summary.complete,
            "duration": summary.duration, "start_ns": summary.start_ns, "end_ns": summary.end_ns,
            "messages": summary.count,
            "keys": [{"topic": channel.topic, "key": channel.key, "type": channel.message_type,
                      "encoding": channel.message_encoding, "count": channel.count,
                      "rate": round(channel.rate, 3)} for channel in summary.channels]}))
    else:
        lines = [f"File:      {summary.path}"
                 + ("" if summary.complete else "  (not finalised: read up to its last chunk)"),
                 f"Size:      {_size(summary.size)}",
                 f"Duration:  {summary.duration:.3f} s",
                 f"Start:     {_when(summary.start_ns)}",
                 f"End:       {_when(summary.end_ns)}",
                 f"Messages:  {summary.count}",
                 f"Keys:      {len(summary.channels)}"]
        width = max([len(channel.topic) for channel in summary.channels] + [3])
        type_width = max([len(channel.message_type) for channel in summary.channels] + [12])
        lines.append(f"  {'key':<{width}}  {'type':<{type_width}} {'count':>8} {'rate':>10}  encoding")
        for channel in summary.channels:
            lines.append(f"  {channel.topic:<{width}}  {channel.message_type or '-':<{type_width}} "
                         f"{channel.count:>8} {channel.rate:>8.2f}/s  {channel.message_encoding}")
        for line in lines:
            if not out.line(line):
                break
    if out.closed:
        silence_closed_stdout()
    return 0


def register(commands) -> None:
    record = networked(commands, "record", "record keys into an MCAP file", command_record, peer=True)
    record.add_argument("-o", "--output", required=True, metavar="FILE.mcap",
                        help="the file to write (replaced if it exists)")
    record.add_argument("keys", nargs="*", metavar="KEY",
                        help="keys or key expressions (default: every data and stats key)")
    record.add_argument("--duration", type=seconds(above=0), default=None, metavar="S",
                        help="stop after S seconds (default: at Ctrl-C or SIGTERM)")
    record.add_argument("--no-foxglove", action="store_true",
                        help="only the msgpack channels (default: also Foxglove-typed channels "
                             "for viewing, when foxglove-sdk is installed)")
    record.add_argument("--progress", type=seconds(minimum=0), default=0.0, metavar="S",
                        help="print the messages written so far every S seconds on stderr")
    record.add_argument("--hold", type=float, default=0.0, metavar="S",
                        help="leave each message S seconds after it arrives before compressing "
                             "and writing it (0-10, default 0): on a small machine beside the "
                             "pipeline, 0.015 does the work after the pipeline has answered a "
                             "frame rather than beside it")
    record.add_argument("--nice", type=int, default=0, metavar="N",
                        help="lower the recorder's CPU priority by N (0-19, default 0), so that "
                             "it yields a shared core to the pipeline")
    replay = networked(commands, "play", "publish a recording again", command_play)
    # No namespace given: the recorded keys as they were; --namespace NS moves them under NS.
    replay.set_defaults(namespace=None)
    replay.add_argument("file", metavar="FILE.mcap")
    replay.add_argument("--rate", type=zero_or(0.001, 1e6, "as fast as possible"), default=1.0,
                        help="speed factor of the recorded timing; 0 = as fast as possible")
    replay.add_argument("--loop", action="store_true", help="start again at the end, until stopped")
    replay.add_argument("--keys", nargs="+", metavar="K", default=None,
                        help="play only these keys (as recorded, with or without namespace)")
    replay.add_argument("--start", type=seconds(minimum=0), default=0.0, metavar="S",
                        help="skip the first S seconds of the recording")
    info = commands.add_parser("info", help="what a recording holds (keys, types, counts, rates)",
                               description="what a recording holds, as `ros2 bag info`")
    info.add_argument("file", metavar="FILE.mcap")
    info.add_argument("--json", action="store_true", help="one JSON object instead of a table")
    info.set_defaults(handler=command_info)
