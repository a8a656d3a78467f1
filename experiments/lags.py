"""Lags between the arrivals of two related messages at an experiment's subscriber: a frame and
the position derived from it (matched by ``seq``), a message and its twin through a bridge
(matched by header stamp).

Not thread-safe on its own: the subscribers' callbacks that feed it hold their owner's lock.

Example::

    lags = ArrivalLags()
    lags.start(frame_seq, time.monotonic())      # on each frame
    lags.end(position_seq, time.monotonic())     # on each position: its lag is kept
    recent = lags.take()                         # the lags (s) since the last take
"""


class ArrivalLags:
    """Arrival times of first messages by key, and the lag to each matching second message.

    At most ``keep`` first messages wait for their match: past that the older half is dropped
    (what is derived comes within a second; a first message with no match would otherwise be
    kept forever)."""

    def __init__(self, keep: int = 2000):
        self.lags: list[float] = []
        self._started: dict[int, float] = {}
        self._keep = keep

    def start(self, key: int, arrival: float) -> None:
        """A first message arrived (the earliest arrival of a key counts)."""
        self._started.setdefault(key, arrival)
        if len(self._started) > self._keep:
            for old in sorted(self._started)[:self._keep // 2]:
                del self._started[old]

    def end(self, key: int, arrival: float, once: bool = False) -> None:
        """A second message arrived: its lag is kept if its first one is known. ``once``: the
        first message matches no later one."""
        started = self._started.pop(key, None) if once else self._started.get(key)
        if started is not None:
            self.lags.append(arrival - started)

    def take(self) -> list[float]:
        """The lags kept since the last call."""
        lags, self.lags = self.lags, []
        return lags
