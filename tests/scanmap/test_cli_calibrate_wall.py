"""`scanmap calibrate wall` on a rendered wall scan made with a scanner that differs from
the nominal one: the calibrated model must triangulate like the true one."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scanmap.cli import main
from scanmap_driver import ScannerModel, reference_scanner, triangulate
from scanmap_driver.calibration.wall import apply_corrections
from scanmap_driver.sim import load_scene
from scanmap_driver.sim.simulate import simulate_recording

DISTANCES = (1.2, 3.0)
TRUE_CORRECTIONS = {"laser_normal_1": 0.003, "vertical_separation": -0.005,
                    "camera_tilt": 0.004, "camera_height": 0.008}


@pytest.fixture(scope="module")
def wall_recording(tmp_path_factory):
    """Two rendered wall scans, near and far, by a scanner that is not the nominal one."""
    folder = tmp_path_factory.mktemp("wall")
    true_model = apply_corrections(reference_scanner(), TRUE_CORRECTIONS)
    for distance in DISTANCES:
        scene = {"format": "scanmap.scene/1", "name": "wall",
                 "floor": {"color": [120, 110, 100]}, "ambient": 0.6,
                 "objects": [{"type": "box", "center": [distance + 0.05, 0.0, 1.25],
                              "size": [0.1, 10.0, 2.5], "color": [210, 205, 200]}],
                 "scan_poses": [[0.0, 0.0, 0.0]]}
        (folder / f"wall{distance}.json").write_text(json.dumps(scene))
        simulate_recording(load_scene(folder / f"wall{distance}.json"),
                           folder / f"rec{distance}", true_model, seed=3)
    reference_scanner().save(folder / "nominal.json")
    return folder, true_model


def wall_args(folder, distances=DISTANCES):
    return ([str(folder / f"rec{d}") for d in DISTANCES]
            + ["--distance", *map(str, distances)])


def range_differences(model, other):
    """|P_model - P_other| for the same pixels, binned by range (m): {bin: p95}."""
    u = np.repeat(np.arange(0.0, 560.0, 4.0), 120)
    v = np.tile(np.arange(0.0, 480.0, 4.0), 140)
    a = triangulate(model, u, v, 0.0)
    b = triangulate(other, u, v, 0.0)
    ok = a.valid & b.valid
    diff = np.linalg.norm(a.points_head[ok] - b.points_head[ok], axis=1)
    rng = np.hypot(b.points_head[ok, 0], b.points_head[ok, 1])
    return {f"{lo}-{hi}": float(np.percentile(diff[(rng >= lo) & (rng < hi)], 95))
            for lo, hi in ((0.8, 1.2), (3.5, 4.0))}


def test_wall_calibration_recovers_the_true_scanner(wall_recording, capsys):
    folder, true_model = wall_recording
    out = folder / "calibrated.json"
    assert main(["calibrate", "wall", *wall_args(folder),
                 "--scanner", str(folder / "nominal.json"), "--out", str(out)]) == 0
    calibrated = ScannerModel.load(out)
    after = range_differences(calibrated, true_model)
    before = range_differences(reference_scanner(), true_model)
    assert after["0.8-1.2"] < 0.01 and after["3.5-4.0"] < 0.02
    assert before["3.5-4.0"] > 3 * after["3.5-4.0"]  # the nominal model was measurably off
    assert "camera_tilt" in capsys.readouterr().out


def test_wrong_distance_is_refused(wall_recording, capsys):
    folder, _ = wall_recording
    out = folder / "never.json"
    code = main(["calibrate", "wall", *wall_args(folder, (2.2, 3.9)),
                 "--scanner", str(folder / "nominal.json"), "--out", str(out)])
    assert code == 1 and not out.exists()
    assert "points near a wall" in capsys.readouterr().err
