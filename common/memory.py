"""Keeping freed memory in the process for the next frame (glibc's malloc).

A service that handles camera frames allocates and frees megabytes a frame: copies of the
frame, planes, patches. By default glibc hands memory back to the system as soon as a few
megabytes are free at the top of its heap, and serves large blocks from mappings of their own
that it unmaps when they are freed; the next frame then takes a page fault for every 4 KB it
touches again: the detector took 6,000-16,000 a second while the demo's ball was large, and
the demo's recorder about 10,000 a second all along, up to 5 us each on this project's
virtual machines. Keeping freed memory makes a frame's memory cost what the last one's did.
Real-time programs do this (ros-realtime's ``minimal_memory_lock`` example turns trimming and
mmap off altogether); here both stay bounded, so a huge frame's memory still goes back.

The processes that take every camera frame call it: the detector service and ``balltrack
record``. Services of small messages do not need it (a few dozen faults a second), and keep
their resident memory as small as their use.
"""

import ctypes
import ctypes.util

# mallopt parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
# Blocks up to this size come from the heap (a 1920x1080 BGR frame is 6.2 MB); larger ones,
# such as a frame of 8192 x 8192 px, still get mappings of their own, returned when freed.
HEAP_BLOCK_LIMIT = 8 << 20
# At most this much free memory is kept at the top of the heap (a frame's churn is a few MB).
KEPT_FREE = 32 << 20


def keep_freed_memory() -> bool:
    """Make glibc keep freed memory for the next frame (see above); False, with nothing
    changed, where the C library is not glibc."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        mallopt = ctypes.CDLL(name).mallopt
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to set
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, HEAP_BLOCK_LIMIT)) and bool(mallopt(M_TRIM_THRESHOLD, KEPT_FREE))
