"""common/memory.py: freed memory stays in the process for the next frame, or goes back to
the system when released."""

import subprocess
import sys

import pytest

from balltrack.common.memory import glibc_function

# A frame's worth of churn: blocks allocated, touched and freed together, more in all than
# glibc's default trim threshold (twice the largest block freed so far) keeps.
FRAMES = """
import resource, sys
import numpy as np
from balltrack.common.memory import keep_freed_memory
if sys.argv[1] == "keep":
    assert keep_freed_memory()
def frame():
    blocks = [np.ones(2 << 20, np.uint8) for _ in range(6)]
    del blocks
for _ in range(3):
    frame()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    frame()
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 10)
"""


def faults_per_frame(mode: str) -> float:
    result = subprocess.run([sys.executable, "-c", FRAMES, mode], capture_output=True, text=True,
                            timeout=60, check=True)
    return float(result.stdout)


def test_a_frames_memory_is_not_faulted_in_again():
    if glibc_function("mallopt") is None:
        pytest.skip("the C library is not glibc: nothing to set")
    # 12 MB a frame is 3,072 pages: by default all of them are faulted in again every frame
    assert faults_per_frame("default") > 1000
    assert faults_per_frame("keep") < 50


# Blocks freed in the middle of the heap (one kept after them): glibc keeps them resident
# until told otherwise.
RELEASE = """
import sys
import numpy as np
from balltrack.common.memory import release_freed_memory
def resident_mb():
    return int(open("/proc/self/statm").read().split()[1]) * 4096 / 1e6
blocks = [np.ones(100_000, np.uint8) for _ in range(300)]
kept = np.ones(100_000, np.uint8)
del blocks
before = resident_mb()
assert release_freed_memory()
print(before - resident_mb())
"""


def test_freed_memory_amid_the_heap_goes_back_when_released():
    if glibc_function("malloc_trim") is None:
        pytest.skip("the C library is not glibc: nothing to release")
    result = subprocess.run([sys.executable, "-c", RELEASE], capture_output=True, text=True,
                            timeout=60, check=True)
    assert float(result.stdout) > 20  # of the 30 MB freed
