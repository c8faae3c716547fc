"""Cameras: video files (raw MJPG packets against an independent AVI parser), rendered
frames (pacing and drop counting against the clock), and the live V4L2 camera's settings
logic against a capture device that refuses some controls.
"""

from __future__ import annotations

import itertools
import logging
import struct
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.camera import (
    CameraConfig,
    EndOfStream,
    RenderedCamera,
    V4L2Camera,
    VideoFileCamera,
    apply_settings,
    fourcc_code,
    missing_frames,
)
from scanmap_driver.errors import DeviceError


def pattern_image(k: int) -> np.ndarray:
    """A 480x640 frame with structure a JPEG keeps: gradient, a red stripe, a number."""
    image = np.zeros((480, 640, 3), np.uint8)
    image[..., 0] = np.linspace(0, 200, 640, dtype=np.uint8)[None, :]
    image[:, 100 + 20 * k: 104 + 20 * k, 2] = 255
    cv2.putText(image, str(k), (300, 240), cv2.FONT_HERSHEY_SIMPLEX, 3, (0, 255, 0), 5)
    return image


def write_avi(path: Path, frames: int, fourcc: str = "MJPG") -> Path:
    writer = cv2.VideoWriter(str(path), fourcc_code(fourcc), 25.0, (640, 480))
    assert writer.isOpened()
    for k in range(frames):
        writer.write(pattern_image(k))
    writer.release()
    return path


def avi_video_chunks(path: Path) -> list[bytes]:
    """The '00dc' chunks of an AVI's movi list, by walking the RIFF structure."""
    data = path.read_bytes()
    chunks = []

    def walk(start: int, end: int) -> None:
        pos = start
        while pos + 8 <= end:
            tag, size = data[pos:pos + 4], struct.unpack("<I", data[pos + 4:pos + 8])[0]
            if tag in (b"RIFF", b"LIST"):
                walk(pos + 12, pos + 8 + size)
            elif tag == b"00dc":
                chunks.append(data[pos + 8:pos + 8 + size])
            pos += 8 + size + (size & 1)

    walk(0, len(data))
    return chunks


# -- dropped frames --------------------------------------------------------------------------

@given(gaps=st.lists(st.integers(1, 5), min_size=1, max_size=30),
       jitter=st.lists(st.floats(-0.24, 0.24), min_size=31, max_size=31))
def test_missing_frames_counts_the_periods_skipped(gaps, jitter):
    period = 0.04
    slots = np.concatenate([[0], np.cumsum(gaps)])
    stamps = (slots + np.array(jitter[:slots.size])) * period
    counted = [missing_frames(a, b, period) for a, b in itertools.pairwise(stamps)]
    assert counted == [g - 1 for g in gaps]


# -- video files -----------------------------------------------------------------------------

def test_video_file_hands_over_the_stored_jpegs_byte_for_byte(tmp_path):
    path = write_avi(tmp_path / "scan_0000.avi", 4)
    stored = avi_video_chunks(path)
    reference = cv2.VideoCapture(str(path))  # OpenCV's own decoding of the same file
    with VideoFileCamera(path) as camera:
        assert camera.raw_mode and camera.fourcc == "MJPG" and camera.frame_count == 4
        for k in range(4):
            frame = camera.read()
            assert frame.index == k and frame.raw_jpeg == stored[k]
            assert frame.timestamp == pytest.approx(k / 25.0)
            ok, decoded = reference.read()
            assert ok and frame.image.shape == (480, 640, 3) and frame.image.dtype == np.uint8
            assert np.abs(frame.image.astype(int) - decoded).mean() < 1.0
            assert np.abs(frame.image.astype(int) - pattern_image(k)).mean() < 4.0
        with pytest.raises(EndOfStream, match="end of video after 4 frames"):
            camera.read()
        assert camera.dropped_frames == 0
    reference.release()


def test_video_file_with_recorded_timestamps_counts_the_gaps(tmp_path):
    path = write_avi(tmp_path / "v.avi", 4)
    stamps = np.array([10.0, 10.04, 10.16, 10.2])  # two frames lost after the second
    with VideoFileCamera(path, timestamps=stamps) as camera:
        assert [camera.read().timestamp for _ in range(4)] == list(stamps)
        assert camera.dropped_frames == 2
    with VideoFileCamera(path, timestamps=stamps[:2]) as camera:
        camera.read()
        camera.read()
        with pytest.raises(DeviceError, match="more frames than the 2 timestamps"):
            camera.read()


def test_video_file_in_another_codec_is_decoded_without_jpeg(tmp_path):
    path = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(path), fourcc_code("FFV1"), 25.0, (640, 480))
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write FFV1")
    for k in range(2):
        writer.write(pattern_image(k))
    writer.release()
    with VideoFileCamera(path) as camera:
        frame = camera.read()
        assert not camera.raw_mode and frame.raw_jpeg is None
        assert np.array_equal(frame.image, pattern_image(0))  # FFV1 is lossless


def test_bad_video_files_are_device_errors(tmp_path):
    with pytest.raises(DeviceError, match="video file not found"):
        VideoFileCamera(tmp_path / "none.avi")
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"RIFF not really")
    with pytest.raises(DeviceError, match=r"junk\.avi"):
        VideoFileCamera(junk).read()


# -- rendered frames -------------------------------------------------------------------------

def test_rendered_camera_paces_frames_and_renders_for_their_time():
    seen = []

    def render(t):
        seen.append(t)
        return np.full((4, 6, 3), int(t * 1000) % 256, np.uint8)

    with RenderedCamera(render, frame_rate=50.0, jpeg_quality=None) as camera:
        start = time.monotonic()
        frames = [camera.read() for _ in range(10)]
        elapsed = time.monotonic() - start
    stamps = np.array([f.timestamp for f in frames])
    assert np.allclose(np.diff(stamps), 0.02) and stamps.tolist() == seen
    assert elapsed >= 9 * 0.02 - 1e-3
    assert all(np.array_equal(f.image, render(f.timestamp)) for f in frames)
    assert [f.index for f in frames] == list(range(10))


def test_rendered_camera_jpeg_is_what_it_delivers():
    with RenderedCamera(lambda t: pattern_image(1), frame_rate=100.0, jpeg_quality=80) as camera:
        frame = camera.read()
    assert frame.raw_jpeg[:2] == b"\xff\xd8"
    decoded = cv2.imdecode(np.frombuffer(frame.raw_jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(frame.image, decoded)
    assert np.abs(decoded.astype(int) - pattern_image(1)).mean() < 4.0


def test_rendered_camera_passes_a_renderers_own_jpeg_through():
    jpeg = cv2.imencode(".jpg", pattern_image(3), [cv2.IMWRITE_JPEG_QUALITY, 70])[1].tobytes()
    with RenderedCamera(lambda t: jpeg, frame_rate=100.0, jpeg_quality=90) as camera:
        frame = camera.read()
    assert frame.raw_jpeg is jpeg
    assert np.array_equal(frame.image, cv2.imdecode(np.frombuffer(jpeg, np.uint8), 1))


def test_slow_renderer_makes_the_camera_drop_frames_and_count_them():
    def slow(t):
        time.sleep(0.05)  # 2.5 periods of a 50 frames/s camera
        return np.zeros((2, 2, 3), np.uint8)

    with RenderedCamera(slow, frame_rate=50.0, jpeg_quality=None) as camera:
        frames = [camera.read() for _ in range(6)]
    slots = np.rint((np.array([f.timestamp for f in frames]) - frames[0].timestamp) / 0.02)
    assert camera.dropped_frames == int(slots[-1]) - 5 >= 5


def test_closing_a_rendered_camera_ends_a_waiting_read():
    camera = RenderedCamera(lambda t: np.zeros((2, 2, 3), np.uint8), frame_rate=0.5)
    camera.read()
    timer_start = time.monotonic()
    threading.Timer(0.1, camera.close).start()
    with pytest.raises(DeviceError, match="closed"):
        camera.read()
    assert time.monotonic() - timer_start < 1.0


# -- live capture settings -------------------------------------------------------------------

class PickyCapture:
    """A V4L2 device as OpenCV shows it: it takes some controls, clamps or ignores others,
    and in raw mode hands over the JPEG buffer (1xN) with driver timestamps."""

    def __init__(self, device, api) -> None:
        self.api = api
        self.values = {cv2.CAP_PROP_FOURCC: float(fourcc_code("YUYV")),
                       cv2.CAP_PROP_FPS: 30.0, cv2.CAP_PROP_FRAME_WIDTH: 1280.0,
                       cv2.CAP_PROP_FRAME_HEIGHT: 720.0, cv2.CAP_PROP_CONVERT_RGB: 1.0}
        self.refused = {cv2.CAP_PROP_FOCUS, cv2.CAP_PROP_AUTOFOCUS}  # fixed-focus webcam
        self.set_order = []
        self.start = time.monotonic()
        self.frames = 0
        self.timestamp = 0.0
        self.jpeg = cv2.imencode(".jpg", pattern_image(2))[1]

    def isOpened(self):
        return True

    def set(self, prop, value):
        self.set_order.append(prop)
        if prop in self.refused:
            return False
        if prop == cv2.CAP_PROP_FPS:
            value = 30.0 if value > 25.0 else value  # takes 25
        if prop == cv2.CAP_PROP_EXPOSURE:
            value = max(value, 50.0)  # its shortest exposure is 5 ms
        self.values[prop] = float(value)
        return True

    def get(self, prop):
        if prop == cv2.CAP_PROP_POS_MSEC:
            return self.timestamp * 1000.0
        return self.values.get(prop, -1.0)

    def read(self):
        """Frame k is exposed at start + 0.04 k and returned a few ms later."""
        self.frames += 1
        self.timestamp = self.start + 0.04 * self.frames
        time.sleep(max(0.0, self.timestamp + 0.003 - time.monotonic()))
        if self.values[cv2.CAP_PROP_CONVERT_RGB]:
            return True, pattern_image(2)
        return True, self.jpeg.reshape(1, -1)

    def release(self):
        pass


def test_live_settings_are_read_back_and_refusals_warned(caplog):
    capture = PickyCapture(0, cv2.CAP_V4L2)
    with caplog.at_level(logging.WARNING, "scanmap_driver.camera"):
        report = apply_settings(capture, CameraConfig())
    by_name = {r.name: r for r in report}
    assert by_name["fourcc"].accepted and by_name["fourcc"].actual == "MJPG"
    assert by_name["width"].accepted and by_name["fps"].actual == 25.0
    assert not by_name["focus"].accepted and not by_name["autofocus"].accepted
    assert not by_name["exposure"].accepted and by_name["exposure"].actual == 50.0
    assert "gain" not in by_name and "contrast" not in by_name  # left as the camera has them
    warned = caplog.text
    assert "camera refused focus=0" in warned and "camera refused exposure=40" in warned
    assert "fourcc" not in warned
    # the format is negotiated before the frame size, and both before the controls
    order = capture.set_order
    assert order.index(cv2.CAP_PROP_FOURCC) < order.index(cv2.CAP_PROP_FRAME_WIDTH) \
        < order.index(cv2.CAP_PROP_EXPOSURE)


def test_live_camera_keeps_the_delivered_jpeg_and_driver_timestamps():
    with V4L2Camera(0, capture_factory=PickyCapture) as camera:
        assert camera.raw_mode and camera.frame_rate == 25.0
        frames = [camera.read() for _ in range(3)]
        capture = camera._capture
    assert all(f.raw_jpeg == capture.jpeg.tobytes() for f in frames)
    assert np.array_equal(frames[0].image, cv2.imdecode(capture.jpeg, cv2.IMREAD_COLOR))
    assert np.allclose(np.diff([f.timestamp for f in frames]), 0.04)
    assert frames[-1].timestamp == pytest.approx(capture.timestamp)


def test_missing_webcam_is_a_device_error():
    with pytest.raises(DeviceError, match="/dev/video97: cannot open it with V4L2"):
        V4L2Camera("/dev/video97")


def test_real_webcam_if_present():
    if not Path("/dev/video0").exists():
        pytest.skip("no webcam at /dev/video0")
    with V4L2Camera(0) as camera:
        frame = camera.read()
        assert frame.image.ndim == 3 and frame.image.dtype == np.uint8
        assert {r.name for r in camera.settings_report} >= {"fourcc", "width", "fps"}
