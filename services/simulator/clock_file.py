"""Simulated time across a simulator's restarts: ``clock_file``.

Within one run simulated time only moves forward, across ``reset`` too (services/simulator/sim.py),
so every key's stamps are monotonic. A simulator that crashed and was started again by the
supervisor would begin again at 0, and every stamp and seq of the deployment would go back. With
``clock_file`` set (``balltrack deploy`` sets it to ``<run folder>/simulator.clock``) it keeps,
once a simulated second, a bound on the stamps and sequence numbers it will have published by its
next write, and a simulator started with that file goes on after the bound: its first frame's
stamp and seq are larger than any of its predecessor's, at most about a simulated second later.
The supervisor removes the file before the simulator's first start, so a new deployment starts
at 0.

The file is one JSON map, ``{"stamp": ns, "seq": n}``, replaced whole (a rename), so a process
killed while writing leaves the previous bound.
"""

import json
import math
import os
from pathlib import Path


class ClockFile:
    """Where a simulator starts its clock, and the bound it records as it runs."""

    def __init__(self, path: str):
        self.path = Path(path)

    def start(self) -> tuple[int, int]:
        """(stamp in ns, frame number) to start from: the recorded bound, or (0, 0) without a file.
        ValueError (with the reason) for a file that is not a bound this module wrote."""
        try:
            text = self.path.read_text()
        except FileNotFoundError:
            return 0, 0
        except OSError as error:
            raise ValueError(f"{self.path}: {error.strerror}") from None
        try:
            recorded = json.loads(text)
            stamp, seq = recorded["stamp"], recorded["seq"]
        except (ValueError, TypeError, KeyError):
            raise ValueError(f"{self.path}: not a simulator clock ({text[:80]!r})") from None
        if not all(isinstance(value, int) and not isinstance(value, bool) and value >= 0
                   for value in (stamp, seq)):
            raise ValueError(f"{self.path}: stamp and seq must be integers >= 0, got {stamp!r}, {seq!r}")
        return stamp, seq

    def record(self, now: float, frame_index: int, next_write: float, period: float) -> None:
        """After the frame at simulated time ``now`` (seq ``frame_index``) was published: bound
        every frame published until the write after the first frame at ``next_write`` or later
        (one period past it). OSError when the file cannot be written."""
        bound = next_write + period
        frames = frame_index + math.ceil((bound - now) / period)
        temporary = self.path.with_name(self.path.name + ".tmp")
        temporary.write_text(json.dumps({"stamp": round(bound * 1e9), "seq": frames}))
        os.replace(temporary, self.path)
