"""common/terminal.py: printing into a pipe whose reader goes away."""

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
