"""common/terminal.py: printing into a pipe whose reader goes away."""

import os
import subprocess
import sys

PROGRAM = """
import sys
from balltrack.common.terminal import print_lines
printed = print_lines([f"line {index}" for index in range(200000)])
sys.exit(0 if printed is False else 3)
"""


def test_a_closed_pipe_ends_printing_quietly():
    # the reader takes one line and goes: the writer learns it, without a traceback at exit
    writer = subprocess.Popen([sys.executable, "-c", PROGRAM], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = writer.stdout.readline()
    writer.stdout.close()
    status = writer.wait(timeout=60)
    assert first == b"line 0\n"
    assert status == 0
    assert writer.stderr.read() == b""


COMMAND = """
import sys
from balltrack.common.terminal import exit_with

def main():
    for index in range(int(sys.argv[1])):
        print(f"line {index}")
    return int(sys.argv[2])

exit_with(main)
"""


def run_command(lines: int, status: int, reader_gone: bool) -> subprocess.CompletedProcess:
    """COMMAND with its stdout a pipe whose reader is gone before it starts (the first write
    fails, whatever the pipe's buffer), or a pipe read to the end."""
    if not reader_gone:
        return subprocess.run([sys.executable, "-c", COMMAND, str(lines), str(status)],
                              capture_output=True, timeout=60)
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run([sys.executable, "-c", COMMAND, str(lines), str(status)],
                              stdout=write_end, stderr=subprocess.PIPE, timeout=60)
    finally:
        os.close(write_end)


def test_exit_with_ends_a_command_quietly_when_its_reader_is_gone():
    # plain print, no print_lines: the error comes from wherever main writes
    finished = run_command(lines=10, status=3, reader_gone=True)
    assert finished.returncode == 0
    assert finished.stderr == b""


def test_exit_with_passes_the_status_of_main_on():
    finished = run_command(lines=2, status=3, reader_gone=False)
    assert finished.returncode == 3
    assert finished.stdout == b"line 0\nline 1\n"
