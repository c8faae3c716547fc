"""`scanmap calibrate camera` end to end on the real board images."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import cv2
import pytest

from scanmap.cli import main
from scanmap_driver import ScannerModel, reference_scanner
from scanmap_driver.scanner_model import LaserPlane
from tests.conftest import real_data

CHARUCO_ARGS = ["--board", "charuco", "--squares", "5x7", "--square-size", "0.04",
                "--marker-size", "0.02"]


def charuco_images() -> list[str]:
    folder = real_data("calib/opencv_charuco")
    return [str(folder / f"img_0{i}.jpg") for i in range(4)]


def test_new_file_is_the_reference_scanner_with_the_calibrated_camera(tmp_path, capsys):
    out = tmp_path / "camera.json"
    assert main(["calibrate", "camera", *charuco_images(), *CHARUCO_ARGS,
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "calibrated from 4 of 4 images" in printed
    assert "reference scanner with this camera" in printed
    model = ScannerModel.load(out)
    # OpenCV's own reference from these images: fx 452.5, fy 456.8, cx 317.7, cy 277.8.
    assert model.camera.fx == pytest.approx(452.51, rel=0.02)
    assert model.camera.fy == pytest.approx(456.77, rel=0.02)
    assert model.camera.cx == pytest.approx(317.70, abs=5.0)
    assert model.camera.cy == pytest.approx(277.75, abs=5.0)
    assert (model.camera.width, model.camera.height) == (640, 480)
    reference = reference_scanner()
    assert model.with_changes(camera=reference.camera) == reference


def test_existing_model_keeps_everything_but_the_camera(tmp_path, capsys):
    out = tmp_path / "scanner.json"
    mine = reference_scanner().with_changes(
        name="my scanner",
        laser=LaserPlane.from_angles((-0.07, 0.0, 0.45), math.radians(7.0), math.radians(55.0)))
    mine = mine.with_changes(camera=replace(mine.camera, frame_rate=30.0))
    mine.save(out)
    assert main(["calibrate", "camera", *charuco_images(), *CHARUCO_ARGS,
                 "--out", str(out)]) == 0
    assert f"updated the camera of the scanner model {out}" in capsys.readouterr().out
    model = ScannerModel.load(out)
    assert model.camera.fx == pytest.approx(452.51, rel=0.02)
    assert model.camera.frame_rate == 30.0  # images do not tell it: kept
    assert model.with_changes(camera=mine.camera) == mine


def test_chessboard_on_the_ciclop_captures(tmp_path):
    folder = real_data("laser/ciclop_3dscanscience/4.2_camera_calibration_captures")
    out = tmp_path / "ciclop.json"
    assert main(["calibrate", "camera", *map(str, sorted(folder.glob("frame*.jpg"))),
                 "--board", "chessboard", "--squares", "12x7", "--square-size", "0.013",
                 "--out", str(out)]) == 0
    camera = ScannerModel.load(out).camera
    assert (camera.width, camera.height) == (960, 1280)
    assert camera.fx == pytest.approx(1429.66, rel=0.005)  # the 3DScanScience notebook
    # the reprojection errors, beside it as OpenCV writes them
    stored = cv2.FileStorage(str(tmp_path / "ciclop.camera.yaml"), cv2.FILE_STORAGE_READ)
    assert stored.getNode("camera_matrix").mat()[0, 0] == pytest.approx(camera.fx)
    per_view = stored.getNode("per_view_reprojection_errors").mat().ravel()
    assert per_view.size == 16
    rms = stored.getNode("avg_reprojection_error").real()
    assert 0 < rms < 0.3 and per_view.min() <= rms <= per_view.max()


def test_refuses_to_overwrite_a_file_that_is_not_a_scanner_model(tmp_path, capsys):
    out = tmp_path / "notes.json"
    out.write_text(json.dumps({"format": "something/else"}))
    assert main(["calibrate", "camera", *charuco_images(), *CHARUCO_ARGS,
                 "--out", str(out)]) == 1
    assert "not a scanner model" in capsys.readouterr().err
    assert json.loads(out.read_text()) == {"format": "something/else"}


def test_invalid_existing_model_is_reported_by_field(tmp_path, capsys):
    out = tmp_path / "scanner.json"
    data = reference_scanner().to_dict()
    data["camera"]["fx"] = -1.0
    out.write_text(json.dumps(data))
    assert main(["calibrate", "camera", *charuco_images(), *CHARUCO_ARGS,
                 "--out", str(out)]) == 1
    assert "camera.fx" in capsys.readouterr().err


def test_failed_calibration_writes_nothing(tmp_path, capsys):
    out = tmp_path / "camera.json"
    assert main(["calibrate", "camera", *charuco_images()[:2], *CHARUCO_ARGS,
                 "--out", str(out)]) == 1
    assert "found in 2 of 2 images, 3 needed" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "camera.camera.yaml").exists()


def test_charuco_needs_marker_size(tmp_path, capsys):
    assert main(["calibrate", "camera", *charuco_images(), "--board", "charuco",
                 "--squares", "5x7", "--square-size", "0.04",
                 "--out", str(tmp_path / "c.json")]) == 1
    assert "--marker-size" in capsys.readouterr().err


def test_malformed_squares_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["calibrate", "camera", "a.jpg", "--board", "chessboard", "--squares", "5by7",
              "--square-size", "0.04", "--out", str(tmp_path / "c.json")])
    assert exit_.value.code == 2
    assert "COLSxROWS" in capsys.readouterr().err


def test_calibrate_without_target_prints_its_help(capsys):
    assert main(["calibrate"]) == 2
    assert "camera" in capsys.readouterr().out
