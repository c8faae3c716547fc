"""Cameras: live V4L2 capture, video files and rendered frames behind one interface.

Every camera delivers `CameraFrame`s: a BGR uint8 image, a timestamp (s, time.monotonic clock
for live cameras, the file's timeline for files), a running index and, where the backend
hands them over, the JPEG bytes the webcam sent, so a recording stores what the camera
delivered without a second lossy encoding (docs/architecture.md).

Live capture (`V4L2Camera`) asks for the reference settings (640x480, 25 frames/s, MJPG)
and the paper's colour-purity settings (fixed low exposure, no sharpening or backlight
compensation, fixed white balance, autofocus off, focus far), reads back what the camera
took and warns about what it refused. Dropped frames are found from timestamp gaps.
"""

from __future__ import annotations

import abc
import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import cv2
import numpy as np

from .errors import DeviceError
from .jpeg import jpeg_to_bgr

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One camera frame.

    image: HxWx3 uint8 BGR. timestamp: seconds (see the module docstring).
    index: 0, 1, 2, ... in delivery order. raw_jpeg: the JPEG the camera delivered, or None.
    """

    image: np.ndarray
    timestamp: float
    index: int
    raw_jpeg: bytes | None = None


class EndOfStream(DeviceError):
    """A finite source (a video file) has no more frames."""


def missing_frames(previous: float, current: float, period: float) -> int:
    """Frames lost between two timestamps of a camera running at `period` seconds/frame."""
    return max(0, round((current - previous) / period) - 1)


class Camera(abc.ABC):
    """A source of frames. `read()` blocks until the next frame (DeviceError on failure)."""

    frame_rate: float = 25.0

    def __init__(self) -> None:
        self.dropped_frames = 0
        self._delivered = 0
        self._last_timestamp: float | None = None

    @abc.abstractmethod
    def read(self) -> CameraFrame:
        """The next frame."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the device or file."""

    def __enter__(self) -> Camera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _deliver(self, image: np.ndarray, timestamp: float, raw_jpeg: bytes | None) -> CameraFrame:
        """Number the frame and count the frames lost since the previous one."""
        if self._last_timestamp is not None:
            self.dropped_frames += missing_frames(self._last_timestamp, timestamp,
                                                  1.0 / self.frame_rate)
        self._last_timestamp = timestamp
        frame = CameraFrame(image, timestamp, self._delivered, raw_jpeg)
        self._delivered += 1
        return frame


def decode_jpeg(data: bytes, where: str) -> np.ndarray:
    """A BGR image from JPEG bytes; DeviceError naming `where` if they are not a JPEG."""
    image = jpeg_to_bgr(data)
    if image is None:
        raise DeviceError(f"{where}: a frame of {len(data)} bytes is not a decodable JPEG")
    return image


def _split_raw(buffer: np.ndarray, where: str) -> tuple[np.ndarray, bytes | None]:
    """(image, JPEG bytes) from what an OpenCV capture returned: either a decoded HxWx3
    image, or (raw mode) a 1xN buffer holding the camera's JPEG."""
    if buffer.ndim == 3 and buffer.shape[2] == 3:
        return buffer, None
    data = np.ascontiguousarray(buffer).tobytes()
    if data[:2] != b"\xff\xd8":
        raise DeviceError(f"{where}: the backend delivered {buffer.shape} {buffer.dtype} data "
                          "that is neither a BGR image nor a JPEG")
    return decode_jpeg(data, where), data


# -- live capture ------------------------------------------------------------------------

@dataclass(frozen=True)
class CameraConfig:
    """What to ask of a live camera; None leaves a control as the camera has it.

    The values are V4L2's (OpenCV passes them through): auto_exposure 1 is manual;
    exposure is in 100 us units (40: 4 ms, low, so the laser core does not bleed into
    green and blue); focus 0 is the far end (infinity) on UVC webcams; sharpness 0 and
    backlight 0 turn the camera's edge and contrast enhancement off; auto_white_balance 0
    keeps the colour balance fixed as the head turns through bright and dark views.
    """

    fourcc: str | None = "MJPG"
    width: int | None = 640
    height: int | None = 480
    fps: float | None = 25.0
    auto_exposure: float | None = 1
    exposure: float | None = 40
    gain: float | None = None
    sharpness: float | None = 0
    backlight: float | None = 0
    contrast: float | None = None
    auto_white_balance: float | None = 0
    autofocus: float | None = 0
    focus: float | None = 0


_PROPERTIES = {
    "fourcc": cv2.CAP_PROP_FOURCC, "width": cv2.CAP_PROP_FRAME_WIDTH,
    "height": cv2.CAP_PROP_FRAME_HEIGHT, "fps": cv2.CAP_PROP_FPS,
    "auto_exposure": cv2.CAP_PROP_AUTO_EXPOSURE, "exposure": cv2.CAP_PROP_EXPOSURE,
    "gain": cv2.CAP_PROP_GAIN, "sharpness": cv2.CAP_PROP_SHARPNESS,
    "backlight": cv2.CAP_PROP_BACKLIGHT, "contrast": cv2.CAP_PROP_CONTRAST,
    "auto_white_balance": cv2.CAP_PROP_AUTO_WB, "autofocus": cv2.CAP_PROP_AUTOFOCUS,
    "focus": cv2.CAP_PROP_FOCUS,
}


@dataclass(frozen=True)
class SettingResult:
    """One requested setting and what the camera reports it took."""

    name: str
    requested: Any
    actual: Any
    accepted: bool


def fourcc_code(text: str) -> int:
    """The integer FOURCC OpenCV uses for a 4-character code."""
    return cv2.VideoWriter.fourcc(*text)


def fourcc_text(code: float) -> str:
    """The 4-character code of an OpenCV FOURCC value ('' if none)."""
    value = int(code)
    if value <= 0:
        return ""
    return value.to_bytes(4, "little").decode("ascii", errors="replace")


def apply_settings(capture: Any, settings: CameraConfig) -> list[SettingResult]:
    """Ask `capture` (a cv2.VideoCapture) for each setting in order, read each back, and
    warn about what the camera refused or changed."""
    results = []
    for item in fields(settings):
        wanted = getattr(settings, item.name)
        if wanted is None:
            continue
        prop = _PROPERTIES[item.name]
        if item.name == "fourcc":
            capture.set(prop, fourcc_code(wanted))
            actual: Any = fourcc_text(capture.get(prop))
            accepted = actual == wanted
        else:
            capture.set(prop, float(wanted))
            actual = float(capture.get(prop))
            accepted = math.isclose(actual, float(wanted), rel_tol=0.01, abs_tol=0.5)
        results.append(SettingResult(item.name, wanted, actual, accepted))
        if not accepted:
            log.warning("camera refused %s=%s (it reports %s)", item.name, wanted, actual)
    return results


class V4L2Camera(Camera):
    """A webcam through OpenCV's V4L2 backend.

    device: an index (0 for /dev/video0) or a device path. When the camera streams MJPG,
    the capture runs in raw mode (CAP_PROP_CONVERT_RGB 0) so each frame keeps the JPEG
    the camera sent; it is decoded here. Timestamps are the driver's buffer times
    (CLOCK_MONOTONIC, like time.monotonic) when the driver provides them, else the host's
    time at read. `settings_report` lists what was requested and what the camera took.
    """

    def __init__(self, device: int | str = 0, settings: CameraConfig | None = None,
                 capture_factory: Callable[..., Any] = cv2.VideoCapture) -> None:
        super().__init__()
        self.name = f"/dev/video{device}" if isinstance(device, int) else str(device)
        capture = capture_factory(device, cv2.CAP_V4L2)
        if not capture.isOpened():
            why = "busy or not a camera" if os.path.exists(self.name) else "no such device"
            raise DeviceError(f"camera {self.name}: cannot open it with V4L2 ({why})")
        self._capture = capture
        self.settings_report = apply_settings(capture, settings or CameraConfig())
        fps = float(capture.get(cv2.CAP_PROP_FPS))
        self.frame_rate = fps if fps > 0 else 25.0
        self.fourcc = fourcc_text(capture.get(cv2.CAP_PROP_FOURCC))
        self.raw_mode = self.fourcc == "MJPG" and bool(capture.set(cv2.CAP_PROP_CONVERT_RGB, 0))
        if not self.raw_mode:
            log.warning("camera %s: streaming %r, frames are decoded by the driver and a "
                        "recording will re-encode them", self.name, self.fourcc)
        self._device_clock: bool | None = None

    def read(self) -> CameraFrame:
        ok, buffer = self._capture.read()
        host_time = time.monotonic()
        if not ok or buffer is None:
            raise DeviceError(f"camera {self.name}: no frame (unplugged, or the driver timed out)")
        image, jpeg = _split_raw(buffer, f"camera {self.name}")
        return self._deliver(image, self._timestamp(host_time), jpeg)

    def _timestamp(self, host_time: float) -> float:
        """The driver's buffer time if it is on the monotonic clock, else the host's."""
        device_time = float(self._capture.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0
        if self._device_clock is None:
            self._device_clock = 0.0 < host_time - device_time < 1.0
            if not self._device_clock:
                log.info("camera %s: driver timestamps are not monotonic-clock times; "
                         "using the host's read time", self.name)
        return device_time if self._device_clock else host_time

    def close(self) -> None:
        self._capture.release()


# -- files -------------------------------------------------------------------------------

class VideoFileCamera(Camera):
    """Frames of a video file (an MJPG AVI of a recording) through OpenCV's FFmpeg backend.

    MJPG files are read packet by packet (CAP_PROP_FORMAT -1), so `raw_jpeg` is the stored
    JPEG, byte for byte. timestamps: one per frame (a recording's frame times); without
    them the file's presentation times are used. read() raises EndOfStream at the end.
    """

    def __init__(self, path: str | os.PathLike[str],
                 timestamps: np.ndarray | None = None) -> None:
        super().__init__()
        self.path = str(path)
        if not os.path.isfile(self.path):
            raise DeviceError(f"{self.path}: video file not found")
        capture = cv2.VideoCapture(self.path, cv2.CAP_FFMPEG)
        if not capture.isOpened():
            raise DeviceError(f"{self.path}: not a video file OpenCV can read")
        self._capture = capture
        fps = float(capture.get(cv2.CAP_PROP_FPS))
        self.frame_rate = fps if fps > 0 else 25.0
        self.fourcc = fourcc_text(capture.get(cv2.CAP_PROP_FOURCC))
        self.raw_mode = self.fourcc == "MJPG" and bool(capture.set(cv2.CAP_PROP_FORMAT, -1))
        self.frame_count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        self._timestamps = None if timestamps is None else np.asarray(timestamps, np.float64)

    def read(self) -> CameraFrame:
        ok, buffer = self._capture.read()
        if not ok or buffer is None:
            raise EndOfStream(f"{self.path}: end of video after {self._delivered} frames")
        image, jpeg = _split_raw(buffer, self.path)
        if self._timestamps is None:
            timestamp = float(self._capture.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0
        elif self._delivered < self._timestamps.size:
            timestamp = float(self._timestamps[self._delivered])
        else:
            raise DeviceError(f"{self.path}: more frames than the {self._timestamps.size} "
                              "timestamps given")
        return self._deliver(image, timestamp, jpeg)

    def close(self) -> None:
        self._capture.release()


# -- rendered frames ---------------------------------------------------------------------

class RenderedCamera(Camera):
    """A live camera whose frames come from `render(t)` at time `t`: a BGR image, or the
    JPEG bytes of an MJPG frame (kept as raw_jpeg, as a webcam's).

    It paces itself like a webcam: frame k is due at start + k / frame_rate (monotonic
    clock) and is rendered for that time. A renderer slower than the frame rate makes the
    camera skip the frames it missed, which are counted as dropped. jpeg_quality: encode
    each rendered image as an MJPG webcam would (raw_jpeg set, image decoded from it);
    None keeps the image. The simulator renders for the simulated firmware's head angle.
    """

    def __init__(self, render: Callable[[float], np.ndarray | bytes],
                 frame_rate: float = 25.0, jpeg_quality: int | None = 90) -> None:
        super().__init__()
        self.render = render
        self.frame_rate = frame_rate
        self.jpeg_quality = jpeg_quality
        self._start: float | None = None
        self._slot = 0
        self._closed = threading.Event()

    def read(self) -> CameraFrame:
        if self._closed.is_set():
            raise DeviceError("rendered camera: closed")
        period = 1.0 / self.frame_rate
        now = time.monotonic()
        if self._start is None:
            self._start = now
        due = self._start + self._slot * period
        if now > due + period:
            self._slot = math.floor((now - self._start) / period)
            due = self._start + self._slot * period
        if self._closed.wait(max(0.0, due - time.monotonic())):
            raise DeviceError("rendered camera: closed")
        self._slot += 1
        rendered = self.render(due)
        if isinstance(rendered, bytes):
            return self._deliver(decode_jpeg(rendered, "rendered camera"), due, rendered)
        image = np.ascontiguousarray(rendered, dtype=np.uint8)
        jpeg = None
        if self.jpeg_quality is not None:
            ok, encoded = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY,
                                                       self.jpeg_quality])
            if not ok:
                raise DeviceError("rendered camera: JPEG encoding failed")
            jpeg = encoded.tobytes()
            image = decode_jpeg(jpeg, "rendered camera")
        return self._deliver(image, due, jpeg)

    def close(self) -> None:
        self._closed.set()
