"""Continuous scanning: the `Scanner`'s scans back to back in a background thread."""

from __future__ import annotations

import threading
from collections.abc import Iterator

from .drop_oldest_queue import DropOldestQueue
from .scanner import ScanFailed, Scanner, ScanResult


class ContinuousScanning:
    """Scans back to back in a background thread, handed over through a bounded queue.

    When the consumer falls behind, the oldest queued scan is dropped (counted in
    `dropped_scans`): the scanner and the camera never wait for the consumer. A fault ends
    the thread with the motor braked; `get` raises it once the queued scans are taken.
    """

    def __init__(self, scanner: Scanner, capacity: int = 2) -> None:
        self.scanner = scanner
        self._scans: DropOldestQueue[ScanResult] = DropOldestQueue(capacity)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="continuous-scanning",
                                        daemon=True)

    @property
    def dropped_scans(self) -> int:
        """Scans dropped because the consumer fell behind."""
        return self._scans.dropped

    @property
    def scans_taken(self) -> int:
        """Scans completed so far."""
        return self._scans.added

    def __enter__(self) -> ContinuousScanning:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> None:
        """Start scanning."""
        self._thread.start()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._scans.put(self.scanner.scan(keep_running=True, cancel=self._stop))
        except BaseException as exc:  # handed to the consumer
            if not (isinstance(exc, ScanFailed) and exc.reason == "cancelled"):
                self._scans.fail(exc)
        finally:
            self.scanner.motor.stop_safely()

    def get(self, timeout: float) -> ScanResult | None:
        """The oldest queued scan; None after `timeout` s; the thread's fault once drained."""
        return self._scans.get(timeout)

    def __iter__(self) -> Iterator[ScanResult]:
        """Scans until a fault (raised) or stop()."""
        while not self._stop.is_set():
            result = self.get(timeout=0.5)
            if result is not None:
                yield result

    def stop(self) -> None:
        """Cancel the current scan (the motor is braked at once) and end the thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=self.scanner.settings.frame_timeout + 5.0)
        self.scanner.motor.stop_safely()
