import logging
import os
import sys

from balltrack.common.shutdown import catch_early_stops

catch_early_stops()  # (before the service's imports: a stop during them is not lost)
from balltrack.services.detector.service import main  # noqa: E402

status = main()
# llvmlite's JIT (numba, the detector's compiled functions) can crash a process in its exit
# handlers (numba/llvmlite#1421: MCJIT and __cxa_atexit). Seen once in a fresh clone's CI: the
# detector logged "stopped", then died by SIGSEGV. By here its session is closed and its threads
# joined, so the process ends without running the exit handlers, its output flushed first.
logging.shutdown()
sys.stdout.flush()
sys.stderr.flush()
os._exit(status)
