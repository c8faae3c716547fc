"""Offline input: recordings assembled in parallel yet in order, scan folders, bad input."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from scanmap.datasets.recordings import ScanSource
from scanmap_driver.errors import RecordingError
from scanmap_driver.processing import recording_scans
from scanmap_driver.recording import Recording, RecordingWriter, read_avi_frames


@pytest.fixture(scope="module")
def three_scans(office_recording, tmp_path_factory):
    """The office recording's scan, recorded three times (4 s apart): scans to assemble."""
    recording = Recording.open(office_recording)
    record = recording.scans[0]
    jpegs = list(read_avi_frames(record.video))
    out = tmp_path_factory.mktemp("three_scans")
    writer = RecordingWriter(out, recording.model, source="test")
    for k in range(3):
        with writer.scan(stamp=record.stamp + 4 * k) as scan:
            for jpeg, t in zip(jpegs, record.frame_times, strict=True):
                scan.add_jpeg(jpeg, t + 4 * k)
            scan.set_odometry(np.zeros(3), np.zeros(3))
    return out


def test_a_recording_is_assembled_in_parallel_and_delivered_in_order(three_scans):
    source = ScanSource.open(three_scans, workers=2)
    assert source.kind == "recording" and source.count == 3
    items = list(source)
    assert [item.scan.index for item in items] == [0, 1, 2]
    serial = [scan for scan, _, _ in recording_scans(Recording.open(three_scans))]
    for item, scan in zip(items, serial, strict=True):
        np.testing.assert_array_equal(item.scan.points, scan.points)
        assert item.scan.stamp == scan.stamp and item.error is None
        assert item.summary["points"] == len(scan)
        assert item.timing.cpu["decode"] > 0 and item.timing.cpu["extract"] > 0
    frames = Recording.open(three_scans).scans[0].frame_times
    period = 1.0 / source.model.camera.frame_rate
    assert source.sweep_seconds() == pytest.approx(3 * (frames[-1] - frames[0] + period))


def test_by_default_one_thread_assembles_per_cpu_the_process_may_use(three_scans):
    """The default follows the process's CPU affinity (a container's cpuset, taskset),
    not the machine's count: pinned to one CPU in a child process, one worker."""
    pinned = (f"import os; os.sched_setaffinity(0, {{min(os.sched_getaffinity(0))}}); "
              f"from scanmap.datasets.recordings import ScanSource; "
              f"print(ScanSource.open({str(three_scans)!r}).workers)")
    out = subprocess.run([sys.executable, "-c", pinned], capture_output=True, text=True,
                         check=True, timeout=120)
    assert out.stdout.split() == ["1"]
    assert ScanSource.open(three_scans).workers == len(os.sched_getaffinity(0))


def test_a_folder_of_scan_files_is_read_in_order(three_scans, tmp_path):
    for scan, _, _ in recording_scans(Recording.open(three_scans)):
        scan.save(tmp_path / f"scan_{scan.index:04d}.npz")
    source = ScanSource.open(tmp_path)
    assert source.kind == "scans" and source.count == 3 and source.sweep_seconds() is None
    assert [item.scan.index for item in source] == [0, 1, 2]


def test_input_that_is_neither_is_a_clear_error(tmp_path):
    with pytest.raises(RecordingError, match="neither a recording"):
        ScanSource.open(tmp_path)
    with pytest.raises(RecordingError, match="neither a recording"):
        ScanSource.open(tmp_path / "missing")


def test_a_recording_without_a_scan_is_a_clear_error(office_recording, tmp_path):
    """A recording stopped before its first turn lists no scans: said so, naming its
    index, not an IndexError where the report scores the empty trajectory."""
    RecordingWriter(tmp_path, Recording.open(office_recording).model, source="test")
    with pytest.raises(RecordingError, match=r"recording\.json: lists no scans"):
        ScanSource.open(tmp_path)


def test_a_scan_with_an_unreadable_encoder_comes_empty_with_the_reason(office_recording,
                                                                       tmp_path):
    model = Recording.open(office_recording).model
    writer = RecordingWriter(tmp_path, model, source="test")
    with writer.scan(stamp=0.0) as scan:
        for k in range(3):
            scan.add_image(np.zeros((model.camera.height, model.camera.width, 3), np.uint8),
                           0.04 * (k + 1))
    item = next(iter(ScanSource.open(tmp_path)))
    assert len(item.scan) == 0 and "unreadable" in item.error and item.summary is None
