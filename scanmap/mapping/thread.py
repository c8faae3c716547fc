"""Online mapping: a background thread feeds the Mapper while queries are served.

The thread takes scans from a source - a `ContinuousScanning` (its items carry `.scan`),
any iterable of scans - or from `submit` (a bounded queue: the caller waits when the
mapper is `capacity` scans behind). Registration, fusion and the obstacle field run in
the thread (the Numba kernels release the GIL); a controller polls `mapper.obstacles`
from its own thread meanwhile.

Failures are not hidden. A scan the mapper rejects (a ScanmapError: points beyond the
map's extent, a malformed scan) is skipped and kept in `errors`. When the source fails
(the scanner faulted) or anything else goes wrong, the thread ends, `error` holds the
exception, and the obstacle map is marked FAULTED so every query reports no clearance.
When the source simply ends, the data age and queries become STALE after `max_age`.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Iterator
from typing import Any, Protocol

from scanmap_driver.errors import MapError, ScanmapError
from scanmap_driver.scan import Scan


class ScanSink(Protocol):
    """What the thread drives: a `Mapper` (`add` a scan, `obstacles` to mark faulted)."""

    obstacles: Any

    def add(self, scan: Scan) -> Any: ...

_END = object()  # marks the end of submitted scans
_POLL = 0.1  # s: how often a waiting thread looks at the stop flag


class MappingThread:
    """Runs `mapper.add` on each scan in a background thread (see the module docstring)."""

    def __init__(self, mapper: ScanSink, source: Iterable | None = None, capacity: int = 4
                 ) -> None:
        if capacity < 1:
            raise MapError(f"MappingThread.capacity: expected >= 1, got {capacity}")
        self.mapper = mapper
        self._source = source
        self._queue: queue.Queue = queue.Queue(capacity)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scanmap-mapper", daemon=True)
        self.mapped = 0
        self.errors: list[ScanmapError] = []
        self.error: BaseException | None = None

    def start(self) -> None:
        """Start mapping."""
        self._thread.start()

    @property
    def running(self) -> bool:
        """True until the source ends, `stop` or a fault."""
        return self._thread.is_alive()

    def submit(self, scan: Scan, timeout: float | None = None) -> None:
        """Queue a scan (waits while `capacity` scans are queued; MapError on timeout or
        when the thread maps a source of its own or no longer runs)."""
        if self._source is not None:
            raise MapError("MappingThread.submit: this thread maps its own source")
        if not self.running:
            raise MapError("MappingThread.submit: the mapping thread is not running"
                           + (f" ({self.error})" if self.error else ""))
        try:
            self._queue.put(scan, timeout=timeout)
        except queue.Full:
            raise MapError(f"MappingThread.submit: the mapper is {self._queue.maxsize} scans "
                           f"behind and did not catch up within {timeout} s") from None

    def close(self) -> None:
        """No more scans will be submitted: the thread ends after the queued ones."""
        self._queue.put(_END)

    def join(self, timeout: float | None = None) -> bool:
        """Wait for the thread to end; True when it has."""
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def stop(self, timeout: float | None = None) -> bool:
        """Stop after the scan being mapped (a blocking source must be stopped by its
        owner, e.g. `ContinuousScanning.stop`); True when the thread has ended."""
        self._stop.set()
        return self.join(timeout)

    def _items(self) -> Iterator:
        if self._source is not None:
            yield from self._source
            return
        while not self._stop.is_set():
            try:
                item = self._queue.get(timeout=_POLL)
            except queue.Empty:
                continue
            if item is _END:
                return
            yield item

    def _run(self) -> None:
        try:
            for item in self._items():
                if self._stop.is_set():
                    break
                try:
                    self.mapper.add(getattr(item, "scan", item))
                    self.mapped += 1
                except ScanmapError as exc:
                    self.errors.append(exc)
        except BaseException as exc:  # the source failed, or a bug: fail safe and keep it
            self.error = exc
            self.mapper.obstacles.set_fault(f"mapping stopped: {exc}")
