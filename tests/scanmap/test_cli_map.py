"""`scanmap map`: every product written, readable, and scored against the ground truth."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from scanmap import Mapper, reference_scanner
from scanmap.cli import main
from scanmap.io.map_files import load_map, load_ros_map, read_pgm
from scanmap.io.trajectory import read_tum
from scanmap.navigation.floor import FREE, OBSTACLE, UNKNOWN
from scanmap_driver.recording import Recording
from scanmap_driver.sim import builtin_scene
from scanmap_driver.sim.simulate import simulate_ideal


def test_a_recording_becomes_a_map_with_its_errors(office_recording, tmp_path, capsys):
    out = tmp_path / "map"
    assert main(["map", str(office_recording), "--out", str(out)]) == 0
    printed = capsys.readouterr()
    assert "1 scans mapped" in printed.out and "range error" in printed.out
    assert "1/1 [" in printed.err and "scan 0: initialised" in printed.err  # tqdm progress

    report = json.loads((out / "report.json").read_text())
    assert report["input"] == {"path": str(office_recording), "kind": "recording", "scans": 1,
                               "resumed": None, "localised": None}
    record = Recording.open(office_recording).scans[0]
    assert report["mapping"]["recorded_seconds"] == pytest.approx(
        record.frame_times[-1] - record.frame_times[0] + 1 / 25, rel=0.01)
    assert {"decode", "extract", "register", "fuse", "segment", "write"} <= set(
        report["stages"])
    assert report["registration"] == {"degenerate": 0, "fused": 1, "initialised": 1}
    errors = report["errors"]
    assert errors["available"] and errors["range_m"]["p95_abs"] < 0.02
    assert errors["range_m"]["gross"] <= 1e-3 * errors["range_m"]["count"]  # > 5 cm off
    assert "points more than 5 cm off" in printed.out
    assert errors["heading_rad"]["p95_abs"] < np.radians(0.5)
    assert errors["trajectory_m"]["count"] == 1
    assert errors["map"]["obstacle_precision"] > 0.9 and errors["map"]["free_precision"] > 0.98

    trajectory = read_tum(out / "trajectory.tum")
    assert len(trajectory) == 1 and trajectory.times[0] == pytest.approx(record.frame_times[0],
                                                                         abs=0.05)
    np.testing.assert_allclose(trajectory.poses[0], np.eye(4))
    ros = load_ros_map(out / "map.yaml")
    assert ros.data.shape == tuple(report["map"]["cells"])
    assert ros.origin[:2] == tuple(report["map"]["origin"])
    assert read_pgm(out / "map.pgm").shape == ros.data.shape
    state = load_map(out / "map.npz").layers["state"]  # the map file's obstacle layer
    np.testing.assert_array_equal(ros.data == 0, state == FREE)
    # Every obstacle is read back occupied (never unknown, which planners may cross).
    np.testing.assert_array_equal(ros.data == -1, state == UNKNOWN)
    np.testing.assert_array_equal(ros.data == 100, state == OBSTACLE)
    assert (ros.data == 100).sum() > 50
    occupancy = cv2.imread(str(out / "occupancy.png"))
    assert occupancy.shape[:2] == tuple(4 * n for n in ros.data.shape)
    overhead = cv2.imread(str(out / "overhead.png"))
    assert overhead is not None and overhead.shape[0] > 200
    mapper = Mapper.load(out / "map.npz")
    assert len(mapper) == 1 and mapper.model == Recording.open(office_recording).model


def test_a_folder_of_processed_scans_is_mapped_and_its_trajectory_scored(tmp_path, capsys):
    scans = simulate_ideal(builtin_scene("office"), tmp_path / "scans", reference_scanner(),
                           seed=2, scans=3)
    out = tmp_path / "map"
    assert main(["map", str(scans), "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["input"]["kind"] == "scans" and report["mapping"]["speedup"] is None
    assert "load" in report["stages"] and "decode" not in report["stages"]
    errors = report["errors"]
    assert errors["range_m"]["available"] is False  # no per-frame truth for scan files
    assert errors["trajectory_m"]["count"] == 3 and errors["trajectory_m"]["ate_rmse"] < 0.02
    assert len(read_tum(out / "trajectory.tum")) == 3
    assert "3 scans mapped" in capsys.readouterr().out


def test_a_scene_with_drop_offs_is_scored_on_them(tmp_path, capsys):
    """The hazards scene's stairwell and dock: none of them free more than a cell inside,
    nearly all found, the edge within about a cell (the report prints them)."""
    scans = simulate_ideal(builtin_scene("hazards"), tmp_path / "scans", reference_scanner(),
                           seed=1, scans=8)
    out = tmp_path / "map"
    assert main(["map", str(scans), "--out", str(out)]) == 0
    errors = json.loads((out / "report.json").read_text())["errors"]["map"]
    assert errors["free_cells_inside_drop_offs"] == 0
    # the edge measured over enough cells to mean something (19 after 8 scans, 14 since
    # the rim step keeps to where the drop-off was seen from: the rim cells mostly over a
    # hole are UNKNOWN, not FREE, and so no edge of a DROP_OFF's)
    assert errors["drop_off_recall"] > 0.9 and errors["drop_off_edge_cells"] >= 12
    assert errors["drop_off_edge_error_cells"] <= 2.0 and errors["drop_off_edge_within_one"] > 0.9
    assert "drop-offs: recall" in capsys.readouterr().out


def test_input_that_is_not_a_recording_is_a_clear_error(tmp_path, capsys):
    assert main(["map", str(tmp_path / "nothing"), "--out", str(tmp_path / "out")]) == 1
    assert "nothing: neither a recording" in capsys.readouterr().err


def test_a_map_is_resumed_with_new_scans(tmp_path):
    scans = simulate_ideal(builtin_scene("office"), tmp_path / "scans", reference_scanner(),
                           seed=5, scans=5)
    first, later = tmp_path / "first", tmp_path / "later"
    first.mkdir()
    later.mkdir()
    for index in range(5):
        name = f"scan_{index:04d}.npz"
        (scans / name).rename((first if index < 3 else later) / name)
    (scans / "ground_truth").rename(later / "ground_truth")
    assert main(["map", str(first), "--out", str(tmp_path / "map1")]) == 0
    assert main(["map", str(later), "--out", str(tmp_path / "map2"), "--resume",
                 str(tmp_path / "map1" / "map.npz")]) == 0
    report = json.loads((tmp_path / "map2" / "report.json").read_text())
    assert report["registration"] == {"degenerate": 0, "fused": 2, "ok": 2}
    assert report["errors"]["trajectory_m"]["count"] == 5
    assert report["errors"]["trajectory_m"]["ate_rmse"] < 0.02
    assert len(read_tum(tmp_path / "map2" / "trajectory.tum")) == 5
