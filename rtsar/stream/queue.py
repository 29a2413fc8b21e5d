"""Bounded queues between the pipeline's threads; capacity counted in pulses (or lines).

Every queue has a size, so memory is bounded whatever the source does; ``get_batch`` takes all
the work waiting up to a cap (adaptive micro-batching: small batches while the pipeline keeps up,
larger ones when it falls behind).
"""

from __future__ import annotations

import threading
import time
from collections import deque


class Closed(Exception):
    """Raised by BoundedQueue.put after close()."""


class BoundedQueue:
    """FIFO with a capacity in units (pulses or lines); ``get_batch`` takes what is waiting."""

    def __init__(self, capacity: int, name: str = "queue"):
        self.capacity = max(1, int(capacity))
        self.name = name
        self._items: deque = deque()
        self._size = 0
        self._closed = False
        self._cv = threading.Condition()
        self.high_water = 0  # the most units ever held

    def put(self, item, block: bool = True) -> bool:
        """Add ``item`` (len(item) units).  Non-blocking: False if it does not fit."""
        n = len(item)
        with self._cv:
            while self._size > 0 and self._size + n > self.capacity:
                if self._closed:
                    raise Closed(self.name)
                if not block:
                    return False
                self._cv.wait(0.1)
            if self._closed:
                raise Closed(self.name)
            self._items.append(item)
            self._size += n
            self.high_water = max(self.high_water, self._size)
            self._cv.notify_all()
            return True

    def get_batch(
        self,
        max_units: int,
        timeout: float | None = None,
        at_least: int = 1,
        hold_s: float = 0.0,
        split=None,
    ) -> list | None:
        """Wait for at least one item, then take items while they fit in ``max_units`` (without
        ``split``, the first item whole whatever its size).

        ``at_least`` > 1: wait, up to ``hold_s`` after the first item, for that many units (or
        the close), then take what is there.  ``split(item, k)`` (the items' own, e.g.
        ShotBatch.split): the item that would pass ``max_units``, the first one too, gives its
        first k units and leaves the rest first in line, so the units taken are ``max_units``
        where that many wait, whatever the items' sizes (a source catching up releases several
        shots an item).  Returns [] on timeout and None once the queue is closed and empty.
        """
        deadline = None if timeout is None else time.perf_counter() + timeout
        with self._cv:
            while not self._items:
                if self._closed:
                    return None
                left = None if deadline is None else deadline - time.perf_counter()
                if left is not None and left <= 0:
                    return []
                self._cv.wait(0.1 if left is None else min(left, 0.1))
            if at_least > 1 and self._size < at_least and not self._closed:
                until = time.perf_counter() + hold_s
                while self._size < at_least and not self._closed:
                    left = until - time.perf_counter()
                    if left <= 0:
                        break
                    self._cv.wait(left)
            out, taken = [], 0
            while self._items and (not out or taken < max_units):
                head = self._items[0]
                if split and taken + len(head) > max_units > taken:
                    item, self._items[0] = split(head, max_units - taken)
                elif not out or taken + len(head) <= max_units:
                    item = self._items.popleft()
                else:
                    break
                taken += len(item)
                out.append(item)
            self._size -= taken
            self._cv.notify_all()
            return out

    def close(self) -> None:
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    @property
    def size(self) -> int:
        return self._size
