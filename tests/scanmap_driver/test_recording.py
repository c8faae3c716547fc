"""Raw recordings: the folder format, byte-exact frames, OpenCV compatibility, damage."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from scanmap_driver import reference_scanner
from scanmap_driver.errors import RecordingError
from scanmap_driver.recording import (
    FORMAT,
    INDEX_NAME,
    SCAN_FORMAT,
    Recording,
    RecordingWriter,
    read_avi_frames,
)


def _frames(n: int) -> list[np.ndarray]:
    out = []
    ramp = np.linspace(0, 120, 640, dtype=np.float32)
    for i in range(n):
        image = np.full((480, 640, 3), 40 + 10 * i, np.uint8)
        image[300:] = (ramp[None, :, None] + np.array([10, 60, 30]) + 5 * i).astype(np.uint8)
        image[100:140, 30 * i:30 * i + 25] = (20, 30, 230)
        out.append(image)
    return out


def _jpeg(image: np.ndarray) -> bytes:
    return cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()


@pytest.fixture
def recording(tmp_path):
    """A recording of two scans (5 and 3 frames) written from JPEG bytes."""
    images = _frames(5)
    jpegs = [_jpeg(i) for i in images]
    writer = RecordingWriter(tmp_path / "rec", reference_scanner(), "test",
                             extra={"note": "unit test"})
    with writer.scan(stamp=1.0, exposure=0.008) as scan:
        for i, jpeg in enumerate(jpegs):
            scan.add_jpeg(jpeg, 1.0 + 0.04 * i)
        scan.log_motor(1.0, "run", duty=0.7)
        scan.log_motor(3.0, "stop", duty=0.0)
        scan.set_odometry([0.0, 0.0, 0.0], [0.1, 0.0, 0.02])
    with writer.scan(stamp=9.0) as scan:
        for i, image in enumerate(images[:3]):
            scan.add_image(image, 9.0 + 0.04 * i)
    return tmp_path / "rec", jpegs, images


def test_round_trip_keeps_every_field_and_the_jpeg_bytes(recording):
    path, jpegs, images = recording
    rec = Recording.open(path)
    assert rec.source == "test" and rec.extra == {"note": "unit test"}
    assert rec.model == reference_scanner()
    assert rec.software["name"] == "scanmap"
    first, second = rec.scans
    assert first.complete and first.stamp == 1.0 and first.exposure == 0.008
    np.testing.assert_allclose(first.frame_times, 1.0 + 0.04 * np.arange(5))
    assert first.motor_log[0] == {"t": 1.0, "command": "run", "duty": 0.7}
    np.testing.assert_allclose(first.odom_end[:2, 3], [0.1, 0.0])
    assert np.isnan(second.odom_start).all() and second.exposure is None
    assert list(read_avi_frames(first.video)) == jpegs  # byte for byte
    for frame, jpeg in zip(rec.frames(0), jpegs, strict=True):
        np.testing.assert_array_equal(frame.image, cv2.imdecode(
            np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR))
    frames = list(rec.frames(1))
    assert [f.index for f in frames] == [0, 1, 2]
    assert np.abs(frames[2].image.astype(int) - images[2]).mean() < 2.0
    index = json.loads((path / INDEX_NAME).read_text())
    assert index["format"] == FORMAT and index["scans"][1]["frames"] == 3
    assert json.loads((path / "scan_0000.json").read_text())["format"] == SCAN_FORMAT


def test_opencv_reads_our_videos_and_we_read_opencvs(recording, tmp_path):
    path, _, images = recording
    capture = cv2.VideoCapture(str(path / "scan_0000.avi"))
    assert capture.get(cv2.CAP_PROP_FRAME_COUNT) == 5
    assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(25.0)
    decoded = []
    while True:
        ok, image = capture.read()
        if not ok:
            break
        decoded.append(image)
    assert len(decoded) == 5
    # the same JPEGs; decoders differ only in chroma upsampling at sharp colour edges
    assert np.abs(decoded[3].astype(int) - images[3]).mean() < 2.0
    writer = cv2.VideoWriter(str(tmp_path / "cv.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 25,
                             (640, 480))
    for image in images:
        writer.write(image)
    writer.release()
    theirs = list(read_avi_frames(tmp_path / "cv.avi"))
    assert len(theirs) == 5
    assert np.abs(cv2.imdecode(np.frombuffer(theirs[1], np.uint8), cv2.IMREAD_COLOR)
                  .astype(int) - images[1]).mean() < 3.0


def test_a_truncated_video_keeps_the_frames_before_the_damage(recording):
    path, jpegs, _ = recording
    video = path / "scan_0000.avi"
    data = video.read_bytes()
    cut = data.index(jpegs[3]) + len(jpegs[3]) // 2  # in the middle of frame 3
    video.write_bytes(data[:cut])
    rec = Recording.open(path)
    kept = []
    with pytest.raises(RecordingError, match=r"scan_0000\.avi") as info:
        for frame in rec.frames(0):
            kept.append(frame)
    assert len(kept) == 3
    assert "truncated" in str(info.value)


def test_a_damaged_frame_is_named(recording):
    path, jpegs, _ = recording
    video = path / "scan_0000.avi"
    data = bytearray(video.read_bytes())
    start = bytes(data).index(jpegs[2])
    data[start:start + len(jpegs[2])] = b"\x00" * len(jpegs[2])  # frame 2 wiped
    video.write_bytes(bytes(data))
    kept = []
    with pytest.raises(RecordingError, match=r"scan_0000\.avi: frame 2: not a complete JPEG"):
        for frame in Recording.open(path).frames(0):
            kept.append(frame)
    assert len(kept) == 2


def test_fewer_frames_than_the_sidecar_says_is_an_error(recording):
    path, _, _ = recording
    side = path / "scan_0001.json"
    data = json.loads(side.read_text())
    data["frame_times"].append(99.0)
    side.write_text(json.dumps(data))
    index = json.loads((path / INDEX_NAME).read_text())
    index["scans"][1]["frames"] = 4
    (path / INDEX_NAME).write_text(json.dumps(index))
    with pytest.raises(RecordingError, match="ends after 3 of 4 frames"):
        list(Recording.open(path).frames(1))


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d.pop("motor_log"), "missing field(s) motor_log"),
    (lambda d: d.update(speed=1), "unknown field(s) speed"),
    (lambda d: d.update(frame_times=[1.0, 1.0, 1.1, 1.2, 1.3]), "expected increasing times"),
    (lambda d: d.update(frame_times=[1.0, 1.1]), "frame_times: 2 times"),
    (lambda d: d.update(odometry={"start": [0, 0], "end": [0, 0, 0]}), "odometry.start"),
    (lambda d: d.update(exposure=-1.0), "exposure: expected >= 0.0"),
    (lambda d: d.update(index=3), "index: expected 0"),
    (lambda d: d["motor_log"].append({"command": "run"}), "motor_log[2]"),
])
def test_bad_sidecars_fail_naming_the_field(recording, change, message):
    path, _, _ = recording
    side = path / "scan_0000.json"
    data = json.loads(side.read_text())
    change(data)
    side.write_text(json.dumps(data))
    with pytest.raises(RecordingError, match=r"scan_0000\.json") as info:
        Recording.open(path)
    assert message in str(info.value)


def test_bad_index_fails_naming_the_field(recording):
    path, _, _ = recording
    index = json.loads((path / INDEX_NAME).read_text())
    index["scanner"]["camera"]["fx"] = -1
    (path / INDEX_NAME).write_text(json.dumps(index))
    with pytest.raises(RecordingError, match=r"recording\.json: scanner: camera\.fx"):
        Recording.open(path)
    with pytest.raises(RecordingError, match="not a recording folder"):
        Recording.open(path / "missing")


def test_a_scan_cut_short_by_a_fault_keeps_its_frames(tmp_path):
    writer = RecordingWriter(tmp_path, reference_scanner(), "camera")
    images = _frames(2)
    with pytest.raises(RuntimeError, match="camera vanished"), writer.scan(stamp=0.0) as scan:
        scan.add_image(images[0], 0.1)
        scan.add_image(images[1], 0.14)
        raise RuntimeError("camera vanished")
    rec = Recording.open(tmp_path)
    assert not rec.scans[0].complete
    assert len(list(rec.frames(0))) == 2


def test_frame_times_must_increase(tmp_path):
    writer = RecordingWriter(tmp_path, reference_scanner(), "camera")
    with pytest.raises(RecordingError, match="does not increase"), \
            writer.scan(stamp=0.0) as scan:
        scan.add_jpeg(_jpeg(_frames(1)[0]), 0.5)
        scan.add_jpeg(_jpeg(_frames(1)[0]), 0.5)
