"""A bounded hand-over between threads that never blocks the producer.

The frame grabber hands camera frames to the scanning loop through it, and continuous
scanning hands scans to their consumer: when the consumer falls behind, the oldest item
is dropped (and counted) instead of stalling the camera or the scanner.
"""

from __future__ import annotations

import collections
import threading
from typing import Generic, TypeVar

T = TypeVar("T")


class DropOldestQueue(Generic[T]):
    """A bounded hand-over from a producer thread that never waits: when it is full, the
    oldest item is dropped (counted in `dropped`). The producer's error is handed to the
    consumer once the items before it are taken."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity: expected >= 1, got {capacity}")
        self.capacity = capacity
        self.dropped = 0
        self.added = 0
        self._items: collections.deque[T] = collections.deque()
        self._ready = threading.Condition()
        self._error: BaseException | None = None

    def put(self, item: T) -> None:
        """Add an item, dropping the oldest when full."""
        with self._ready:
            if len(self._items) >= self.capacity:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)
            self.added += 1
            self._ready.notify_all()

    def fail(self, error: BaseException) -> None:
        """The producer ended with `error`."""
        with self._ready:
            self._error = error
            self._ready.notify_all()

    def get(self, timeout: float) -> T | None:
        """The oldest item; None after `timeout` s; raises the producer's error when drained."""
        with self._ready:
            if not self._ready.wait_for(lambda: self._items or self._error, timeout):
                return None
            if self._items:
                return self._items.popleft()
            raise self._error  # type: ignore[misc]

    def clear(self) -> None:
        """Drop every queued item (not counted)."""
        with self._ready:
            self._items.clear()
