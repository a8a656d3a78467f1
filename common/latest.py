"""Newest-only slots served in turn: how one worker shares itself among several robots' frames.

One process serving several robots (``balltrack run detector --namespaces robot1,robot2``)
has one worker for all their cameras. Each source (a robot's frame key) has a slot holding
the newest item not yet served; an item that arrives while its slot is still full replaces
the one there, which is dropped (and counted, for that source), never queued. ``take`` hands
out full slots in turn, beginning after the source served last: a robot that floods frames
gets one turn in as many as there are robots waiting, like every other, and a robot whose
frames are slow to handle delays each other robot by one frame at most.

No Zenoh here: ``context.py`` puts the samples of each robot's subscriber in and runs the
worker.
"""

import threading
from typing import Generic, Hashable, NamedTuple, TypeVar

Item = TypeVar("Item")


class Taken(NamedTuple):
    """A slot's content as handed to the worker: ``arrived`` counts the items put in since the
    source's last turn (all but the newest were dropped)."""

    source: Hashable
    item: object
    arrived: int


class LatestSlots(Generic[Item]):
    """A newest-only slot per source, taken in turn (see the module doc). Thread-safe: ``put``
    is called from the threads that receive, ``take`` from the worker's."""

    def __init__(self):
        self._sources: list[Hashable] = []  # in the order first seen: the order of turns
        self._full: dict[Hashable, tuple[Item, int]] = {}
        self._next_turn = 0
        self._closed = False
        self._changed = threading.Condition()

    def add(self, source: Hashable) -> None:
        """Give ``source`` its turn in the cycle before any item of it arrives."""
        with self._changed:
            if source not in self._sources:
                self._sources.append(source)

    def put(self, source: Hashable, item: Item) -> None:
        """Keep ``item`` as ``source``'s newest, replacing one not yet taken."""
        with self._changed:
            if self._closed:  # (a subscriber's last samples while the process stops)
                return
            if source not in self._sources:
                self._sources.append(source)
            _, arrived = self._full.get(source, (None, 0))
            self._full[source] = (item, arrived + 1)
            self._changed.notify()

    def take(self, timeout: float | None = None) -> Taken | None:
        """The next full slot in turn, emptied; waits for one. None once closed, or when
        ``timeout`` seconds pass with every slot empty."""
        with self._changed:
            if not self._changed.wait_for(lambda: self._closed or self._full, timeout) or self._closed:
                return None
            count = len(self._sources)
            for step in range(count):
                position = (self._next_turn + step) % count
                source = self._sources[position]
                if source in self._full:
                    item, arrived = self._full.pop(source)
                    self._next_turn = (position + 1) % count
                    return Taken(source, item, arrived)
        raise AssertionError("a full slot of a source not in the cycle")  # (put adds every source)

    def close(self) -> None:
        """End every wait in ``take`` (and every later one) with None; items not yet taken are
        dropped uncounted, as at any stop."""
        with self._changed:
            self._closed = True
            self._full.clear()
            self._changed.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed
