"""examples/corridor_map.py makes its recording once, maps it and reports."""

from __future__ import annotations

import json

from scanmap_driver.recording import Recording

from .conftest import run_example


def test_the_recording_is_made_once_then_mapped_and_reported(tmp_path):
    recording, out = tmp_path / "corridor_recording", tmp_path / "corridor_map"
    args = ("--recording", recording, "--scans", 1, "--out", out, "--workers", 1)
    first = run_example("corridor_map", *args)
    assert "simulating 1 scans of the corridor" in first.stdout
    assert len(Recording.open(recording).scans) == 1
    assert not (tmp_path / "corridor_recording.partial").exists()
    assert "1 scans mapped" in first.stdout and "trajectory ATE" in first.stdout
    report = json.loads((out / "report.json").read_text())
    assert report["errors"]["available"] and report["registration"]["fused"] == 1
    assert report["errors"]["range_m"]["p95_abs"] < 0.02
    assert report["errors"]["trajectory_m"]["count"] == 1
    for name in ("map.npz", "map.yaml", "map.pgm", "trajectory.tum", "overhead.png",
                 "occupancy.png"):
        assert (out / name).stat().st_size > 0, name

    video = recording / "scan_0000.avi"
    made = video.stat().st_mtime_ns
    second = run_example("corridor_map", *args)
    assert "using the recording" in second.stdout and "simulating" not in second.stdout
    assert video.stat().st_mtime_ns == made
