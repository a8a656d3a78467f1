"""Keeping freed memory in the process for the next frame (glibc's malloc).

A service that handles camera frames allocates and frees megabytes a frame: copies of the
frame, planes, patches. By default glibc hands memory back to the system as soon as a few
megabytes are free at the top of its heap, and serves large blocks from mappings of their own
that it unmaps when they are freed; the next frame then takes a page fault for every 4 KB it
touches again, thousands a second for a service of 640x480 frames at 30 Hz, each costing
microseconds on a virtual machine. Keeping freed memory makes a frame's memory cost what the
last one's did.
Real-time programs do this (ros-realtime's ``minimal_memory_lock`` example turns trimming and
mmap off altogether); here both stay bounded, so a huge frame's memory still goes back.

The processes that take every camera frame call it: the detector service and ``balltrack
record``; and those that make them, the simulator and camera services, whose frames reach
their subscribers sooner when each message is made in kept memory rather than fresh memory
(``python -m balltrack.experiments.frame_transport`` measures a frame's trip).
Services of small messages do not need it (a few dozen faults a second), and keep their
resident memory as small as their use. ``release_freed_memory`` does the opposite, once:
for a large structure rebuilt rarely (the simulator's scenario reload).
"""

import ctypes

# mallopt parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
# Blocks up to this size come from the heap (a 1920x1080 BGR frame is 6.2 MB); larger ones,
# such as a frame of 8192 x 8192 px, still get mappings of their own, returned when freed.
HEAP_BLOCK_LIMIT = 8 << 20
# At most this much free memory is kept at the top of the heap (a frame's churn is a few MB).
KEPT_FREE = 32 << 20


def glibc_function(name: str):
    """The C library's function ``name`` (glibc's malloc tuning), or None where there is none
    (macOS). Looked up among the process's own symbols, where the C library already is:
    ``ctypes.util.find_library`` would start a subprocess (~4 ms) at each call."""
    try:
        return getattr(ctypes.CDLL(None), name)
    except (OSError, AttributeError):
        return None


def keep_freed_memory() -> bool:
    """Make glibc keep freed memory for the next frame (see above); False, with nothing
    changed, where the C library is not glibc."""
    mallopt = glibc_function("mallopt")
    if mallopt is None:
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, HEAP_BLOCK_LIMIT)) and bool(mallopt(M_TRIM_THRESHOLD, KEPT_FREE))


def release_freed_memory() -> bool:
    """Hand what the process has freed back to the system now, wherever it lies in the heap
    (glibc's malloc_trim); False where the C library is not glibc.

    For the rare moment a large structure is rebuilt: freed in the middle of the heap, its
    memory would otherwise stay resident. 60 of the simulator's scenario reloads (a MuJoCo
    model, its data and renderer each) left 39 MB so, 11 MB with this after each.
    """
    malloc_trim = glibc_function("malloc_trim")
    if malloc_trim is None:
        return False
    malloc_trim.argtypes, malloc_trim.restype = (ctypes.c_size_t,), ctypes.c_int
    malloc_trim(0)
    return True
