"""Fuzzed recording folders (`Recording.open`, `Recording.frames`): the index, a scan's
sidecar and the journal of a scan cut short, each mutated. A RecordingError naming the
file, or a recording whose every scan yields its frames or a RecordingError."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.errors import RecordingError
from scanmap_driver.recording import Recording, RecordingWriter
from scanmap_driver.scanner_model import reference_scanner

from .mutations import FUZZ, mutated_bytes, mutated_json, read_within

JPEG = cv2.imencode(".jpg", np.full((480, 640, 3), 90, np.uint8))[1].tobytes()


@pytest.fixture(scope="module")
def original(tmp_path_factory) -> Path:
    """Two finished scans (3 and 2 frames) and one cut short mid-scan (2 frames)."""
    path = tmp_path_factory.mktemp("recording") / "rec"
    writer = RecordingWriter(path, reference_scanner(), "fuzz")
    for stamp, frames in ((1.0, 3), (5.0, 2)):
        with writer.scan(stamp, exposure=0.01) as scan:
            scan.log_motor(stamp, "run", duty=0.7)
            for i in range(frames):
                scan.add_jpeg(JPEG, stamp + 0.04 * (i + 1))
            scan.set_odometry([0.0, 0.0, 0.0], [0.1, 0.0, 0.1])
    cut = writer.scan(9.0)  # never finished: a recorder killed mid-scan
    cut.log_motor(9.0, "run", duty=0.7)
    cut.add_jpeg(JPEG, 9.04)
    cut.add_jpeg(JPEG, 9.08)
    assert [len(r.frame_times) for r in Recording.open(path).scans] == [3, 2, 2]
    return path


def read_everything(folder: Path) -> None:
    """Open the recording and decode every frame of every scan."""
    recording = Recording.open(folder)
    for record in recording.scans:
        assert np.isfinite(record.frame_times).all() and np.isfinite(record.stamp)
        try:
            for frame in recording.frames(record.index):
                assert frame.image.shape == (480, 640, 3)
        except RecordingError:
            pass


@pytest.mark.parametrize("name", ["recording.json", "scan_0000.json"])
@FUZZ
@given(data=st.data())
def test_fuzzed_index_or_sidecar_is_refused_or_read(original, tmp_path_factory, name, data):
    folder = tmp_path_factory.mktemp("fuzz") / "rec"
    shutil.copytree(original, folder)
    tree = json.loads((original / name).read_text())
    (folder / name).write_text(data.draw(mutated_json(tree)))
    read_within(lambda: read_everything(folder), RecordingError, folder)


@FUZZ
@given(data=st.data())
def test_fuzzed_journal_is_refused_or_read(original, tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("fuzz") / "rec"
    shutil.copytree(original, folder)
    journal = folder / "scan_0002.journal"
    journal.write_bytes(data.draw(mutated_bytes(journal.read_bytes())))
    read_within(lambda: read_everything(folder), RecordingError, folder)
