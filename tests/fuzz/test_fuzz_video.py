"""Fuzzed scan videos (our RIFF/MJPG reader, `read_avi_frames` and `Recording.frames`).

Any mutation: frames or a RecordingError naming the video, never another exception or a
hang. Truncation, the common damage: exactly the frames wholly before the cut, byte for
byte (their offsets found in the file are the truth), then a RecordingError."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.errors import RecordingError
from scanmap_driver.recording import Recording, RecordingWriter, read_avi_frames
from scanmap_driver.scanner_model import reference_scanner

from .mutations import FUZZ, mutated_bytes, read_within


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    """A recording of one scan of 6 different frames; (folder, video bytes, JPEGs)."""
    path = tmp_path_factory.mktemp("video") / "rec"
    jpegs = [cv2.imencode(".jpg", np.full((480, 640, 3), 30 * i, np.uint8))[1].tobytes()
             for i in range(6)]
    with RecordingWriter(path, reference_scanner(), "fuzz").scan(0.0) as scan:
        for i, jpeg in enumerate(jpegs):
            scan.add_jpeg(jpeg, 0.04 * (i + 1))
    return path, (path / "scan_0000.avi").read_bytes(), jpegs


def frames_until_error(read) -> tuple[list, bool]:
    """What `read()` yields, and whether it ended with a RecordingError."""
    out = []
    try:
        for item in read():
            out.append(item)
    except RecordingError:
        return out, True
    return out, False


@FUZZ
@given(data=st.data())
def test_fuzzed_video_yields_frames_or_a_recording_error(original, data):
    folder, video, _ = original
    path = folder / "scan_0000.avi"
    try:
        path.write_bytes(data.draw(mutated_bytes(video)))
        recording = Recording.open(folder)
        read_within(lambda: frames_until_error(lambda: recording.frames(0)), RecordingError,
                    path)
    finally:
        path.write_bytes(video)


@FUZZ
@given(cut=st.integers(0, 10**9))
def test_truncated_video_yields_exactly_the_frames_before_the_cut(original, tmp_path_factory,
                                                                  cut):
    _, video, jpegs = original
    cut %= len(video)
    ends, start = [], 0
    for jpeg in jpegs:
        start = video.index(jpeg, start)
        ends.append(start + len(jpeg))
    path = tmp_path_factory.mktemp("cut") / "scan_0000.avi"
    path.write_bytes(video[:cut])
    frames, failed = frames_until_error(lambda: read_avi_frames(path))
    whole = sum(end <= cut for end in ends)
    assert frames == jpegs[:whole]
    assert failed or whole == len(jpegs)
