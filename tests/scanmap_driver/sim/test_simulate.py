"""`scanmap simulate`: a recording in the documented format with ground truth, deterministic."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from scanmap.cli import main
from scanmap_driver import Scan, reference_scanner, triangulate
from scanmap_driver.errors import RecordingError
from scanmap_driver.recording import Recording
from scanmap_driver.sim.raster import FLOOR, TruthRaster
from scanmap_driver.sim.scene import load_scene
from scanmap_driver.sim.truth import ScanTruth, truth_path


def _digest(folder):
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "office"
    assert main(["simulate", "office", "--out", str(out), "--scans", "1", "--seed", "7",
                 "--lighting", "bright"]) == 0
    return out


def test_truth_without_its_laser_mask_reads_the_rest_and_refuses_to_be_saved(recorded,
                                                                            tmp_path):
    whole = ScanTruth.load(truth_path(recorded, 0))
    light = ScanTruth.load(truth_path(recorded, 0), mask=False)
    assert light.laser_mask.size == 0
    for key, value in whole.laser.items():
        np.testing.assert_array_equal(light.laser[key], value)
    np.testing.assert_array_equal(light.frame_pose, whole.frame_pose)
    with pytest.raises(RecordingError, match="no laser mask"):
        light.save(tmp_path / "truth.npz")
    assert not (tmp_path / "truth.npz").exists()


def test_truth_read_in_part_holds_those_fields_and_refuses_to_be_saved(recorded, tmp_path):
    whole = ScanTruth.load(truth_path(recorded, 0))
    part = ScanTruth.load(truth_path(recorded, 0), laser=("frame", "base"))
    assert set(part.laser) == {"frame", "base"}
    for key in part.laser:
        np.testing.assert_array_equal(part.laser[key], whole.laser[key])
    np.testing.assert_array_equal(part.laser_mask, whole.laser_mask)
    with pytest.raises(RecordingError, match="lacks the laser fields"):
        part.save(tmp_path / "truth.npz")
    assert not (tmp_path / "truth.npz").exists()
    with pytest.raises(ValueError, match="unknown laser fields"):
        ScanTruth.load(truth_path(recorded, 0), laser=("frame", "colour"))


def test_the_recording_reads_back_with_its_truth(recorded):
    rec = Recording.open(recorded)
    assert rec.source == "simulator" and rec.extra["seed"] == 7
    assert rec.model == reference_scanner()
    record = rec.scans[0]
    assert record.complete and 45 <= record.frame_times.size <= 60
    frames = list(rec.frames(0))
    assert len(frames) == record.frame_times.size
    truth = ScanTruth.load(truth_path(recorded, 0))
    np.testing.assert_allclose(truth.frame_time, record.frame_times)
    assert truth.laser_mask.shape == (len(frames), 480, 640)
    np.testing.assert_allclose(truth.odom_start, record.odom_start)
    # the heading turns once (plus an overlap) over the scan
    assert truth.frame_heading[-1] - truth.frame_heading[0] > 2 * np.pi
    # laser truth of a frame triangulates back and sits where the frame is red
    one = truth.frame(25)
    lit = ~one["shadowed"]
    result = triangulate(rec.model, one["u"][lit], one["v"][lit], one["heading"][lit])
    ok = result.valid
    np.testing.assert_allclose(result.points_base[ok], one["base"][lit][ok], atol=1e-6)
    image = frames[25].image.astype(int)
    redness = image[:, :, 2] - image[:, :, 1]
    primary = one["primary"]
    cols, rows = one["u"][primary].astype(int), np.round(one["v"][primary]).astype(int)
    assert truth.laser_mask[25][rows, cols].mean() > 0.95  # not where the disk covers it
    assert np.mean(redness[rows, cols] - np.median(redness[:, cols], axis=0)) > 15
    scene = load_scene(recorded / "ground_truth" / "scene.json")
    assert scene.name == "office" and scene.ambient == 0.9
    raster = TruthRaster.load(recorded / "ground_truth" / "raster.npz")
    row, col = raster.cell_of(scene.scan_poses[:1])[0]
    assert raster.classes[row, col] == FLOOR
    lines = (recorded / "ground_truth" / "trajectory.txt").read_text().splitlines()
    values = np.array(lines[1].split(), dtype=float)
    np.testing.assert_allclose(values[1:3], truth.pose_start[:2, 3], atol=1e-9)


def test_the_same_seed_gives_the_same_files(recorded, tmp_path):
    again = tmp_path / "again"
    assert main(["simulate", "office", "--out", str(again), "--scans", "1", "--seed", "7",
                 "--lighting", "bright", "--workers", "1"]) == 0
    assert _digest(again) == _digest(recorded)


def test_ideal_mode_writes_processed_scans(tmp_path):
    out = tmp_path / "ideal"
    assert main(["simulate", "corridor", "--out", str(out), "--scans", "2", "--ideal"]) == 0
    scans = [Scan.load(out / f"scan_000{i}.npz") for i in range(2)]
    assert all(len(s) > 20_000 and s.has_odometry for s in scans)
    assert (out / "ground_truth" / "trajectory.txt").is_file()


def test_bad_arguments_fail_clearly(tmp_path, capsys):
    assert main(["simulate", "office", "--out", str(tmp_path), "--scans", "99"]) == 1
    assert "scans: expected 1..24" in capsys.readouterr().err
    assert main(["simulate", "nowhere", "--out", str(tmp_path)]) == 1
    assert "neither a scene file nor a built-in scene" in capsys.readouterr().err
