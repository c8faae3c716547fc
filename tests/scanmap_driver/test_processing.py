"""`scanmap process`: recording to scan files, damaged videos keep what came before."""

from __future__ import annotations

import json
import shutil

import numpy as np

from scanmap.cli import main
from scanmap_driver.scan import Scan


def test_process_writes_scans_and_summary(office_recording, tmp_path):
    out = tmp_path / "scans"
    assert main(["process", str(office_recording), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    entry = summary["scans"][0]
    scan = Scan.load(out / "scan_0000.npz")
    assert entry["points"] == len(scan) > 10_000 and entry["complete"]
    assert entry["lines_rejected"]["no_stripe"] > 0
    assert (out / "scan_0000.ply").stat().st_size > 10 * len(scan)


def test_truncated_video_keeps_the_frames_before(office_recording, tmp_path, capsys):
    damaged = tmp_path / "damaged"
    shutil.copytree(office_recording, damaged)
    video = damaged / "scan_0000.avi"
    data = video.read_bytes()
    video.write_bytes(data[: int(len(data) * 0.6)])
    out = tmp_path / "scans"
    assert main(["process", str(damaged), "--out", str(out), "--no-ply"]) == 0
    entry = json.loads((out / "summary.json").read_text())["scans"][0]
    assert not entry["complete"] and "scan_0000.avi" in entry["error"]
    scan = Scan.load(out / "scan_0000.npz")
    assert 0 < entry["frames"] < 54 and len(scan) > 0
    assert np.all(scan.frame_index < entry["frames"])
    assert "incomplete scans: [0]" in capsys.readouterr().out


def test_missing_recording_is_a_clear_error(tmp_path, capsys):
    assert main(["process", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 1
    assert "not a recording folder" in capsys.readouterr().err
