"""experiments/frame_transport: frames and small messages through a real router to subscriber
processes, with Zenoh's shared memory on and off (a short run; the figures are the benchmark's)."""

import re
import signal
import subprocess
import sys

from tests.harness import Process


def test_frames_reach_every_subscriber_and_shared_memory_carries_them(capsys):
    from balltrack.experiments.frame_transport import main

    assert main(["--count", "15", "--rate", "60", "--subscribers", "2"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if re.match(r"\| [\d,]+ B \|", line)]
    assert len(rows) == 4, rows  # frames and small messages, shared memory on and off
    shares = {}
    for row in rows:
        size, mode, arrived, p50, _p90, _each, share = (cell.strip() for cell in row.strip("|").split("|"))
        assert arrived == "30 of 30", row
        assert float(p50) > 0, row
        shares[(size, mode)] = float(share.rstrip(" %"))
    assert shares[("921,616 B", "on")] == 100  # the warm-up waits for the pool to be in use
    assert shares[("921,616 B", "off")] == 0
    assert shares[("100 B", "on")] == 0  # under Zenoh's 3 KB threshold, always copied

def test_bad_arguments_get_one_line_and_status_2():
    result = subprocess.run([sys.executable, "-m", "balltrack.experiments.frame_transport", "--rate", "0"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0 and "--rate" in result.stderr


def test_sigterm_stops_a_run_with_one_line(log_dir):
    run = Process([sys.executable, "-m", "balltrack.experiments.frame_transport", "--count", "100000"],
                  log_dir / "frame_transport.log")
    run.wait_for_signal_handler(signal.SIGTERM, timeout=60)
    assert run.stop() == 1
    assert run.output() == "frame_transport: stopped by a signal\n"
