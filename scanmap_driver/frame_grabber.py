"""The camera read in its own thread, so a slow consumer never blocks the camera."""

from __future__ import annotations

import threading

from .camera import Camera, CameraFrame
from .drop_oldest_queue import DropOldestQueue
from .errors import DeviceError


class FrameGrabber:
    """Reads a camera in its own thread into a `DropOldestQueue`, so the camera is never
    blocked by the consumer; frames dropped for lack of room are counted in `overflow`.
    A camera error reaches the consumer through `get` as a DeviceError.
    """

    def __init__(self, camera: Camera, capacity: int = 100) -> None:
        self.camera = camera
        self._frames: DropOldestQueue[CameraFrame] = DropOldestQueue(capacity)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="frame-grabber", daemon=True)
        self._thread.start()

    @property
    def overflow(self) -> int:
        """Frames dropped because the consumer fell behind."""
        return self._frames.dropped

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._frames.put(self.camera.read())
            except BaseException as exc:  # handed to the consumer
                self._frames.fail(exc)
                return

    def get(self, timeout: float) -> CameraFrame | None:
        """The oldest buffered frame; None after `timeout` s; DeviceError if the camera failed."""
        try:
            return self._frames.get(timeout)
        except Exception as exc:
            raise DeviceError(f"camera failed: {exc}") from exc

    def discard(self) -> None:
        """Drop the buffered frames (taken before the current scan began)."""
        self._frames.clear()

    def stop(self) -> None:
        """Stop reading (the thread ends after the camera's current read)."""
        self._stop.set()
        self._thread.join(timeout=2.0)
