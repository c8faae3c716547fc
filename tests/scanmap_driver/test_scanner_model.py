"""Scanner model: JSON round trip, validation naming the field, degenerate calibration."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from scanmap_driver.errors import CalibrationError
from scanmap_driver.scanner_model import (
    FORMAT,
    LaserPlane,
    ScannerModel,
    reference_scanner,
)


def test_json_round_trip_is_exact(tmp_path):
    model = reference_scanner()
    path = tmp_path / "scanner.json"
    model.save(path)
    loaded = ScannerModel.load(path)
    assert loaded == model
    assert json.loads(path.read_text())["format"] == FORMAT


def test_reference_geometry_matches_the_documented_numbers():
    model = reference_scanner()
    assert model.camera.fx == pytest.approx(320 / math.tan(math.radians(17.5)))
    # Vertical baseline of 0.5 m: the camera's distance to the plane is 0.5 m * |n_z|.
    assert model.camera_mount.position[2] - model.laser.origin[2] == pytest.approx(0.5)
    assert model.camera_mount.position[:2] == model.laser.origin[:2]
    assert model.baseline == pytest.approx(0.5 * abs(model.laser.normal[2]), rel=1e-12)
    # The optical axis is pitched down by the tilt b and points along head x.
    axis = model.camera_mount.rotation[:, 2]
    assert math.degrees(math.atan2(-axis[2], axis[0])) == pytest.approx(18.0)
    # Image u points down, so the encoder disk (below the lens) is at the bottom of the view.
    assert model.camera_mount.rotation[:, 0] @ np.array([0, 0, 1.0]) < -0.9


def test_laser_plane_contains_the_aperture():
    model = reference_scanner()
    assert model.laser.signed_distance(np.array(model.laser.origin)) == 0.0


def _mutated(path, value):
    data = reference_scanner().to_dict()
    node = data
    for key in path[:-1]:
        node = node[key]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


@pytest.mark.parametrize(("path", "value", "message"), [
    (("format",), "scanmap.scanner/0", "format"),
    (("camera", "fx"), KeyError, "camera: missing field"),
    (("camera", "fx"), -3.0, "camera.fx"),
    (("camera", "fy"), float("nan"), "camera.fy"),
    (("camera", "width"), 640.5, "camera.width"),
    (("camera", "distortion"), [0.0, 0.0], "camera.distortion"),
    (("camera", "gain"), 1.0, "unknown field(s) gain"),
    (("laser", "normal"), [0.0, 0.0, 0.0], "laser.normal"),
    (("laser", "origin"), "up", "laser.origin"),
    (("encoder", "code"), "01012", "encoder.code"),
    (("encoder", "inner_radius"), 0.2, "inner_radius < outer_radius"),
    (("limits", "max_range"), 0.1, "min_range < max_range"),
    (("camera_mount", "tilt"), True, "camera_mount.tilt"),
])
def test_bad_fields_are_named(tmp_path, path, value, message):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(_mutated(path, value)))
    with pytest.raises(CalibrationError) as err:
        ScannerModel.load(bad)
    assert message in str(err.value)
    assert str(bad) in str(err.value)


def test_camera_on_the_laser_plane_is_a_degenerate_calibration():
    model = reference_scanner()
    with pytest.raises(CalibrationError, match="lies on the laser plane"):
        model.with_changes(laser=LaserPlane.from_point_normal(
            model.camera_mount.position, model.laser.normal))


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(CalibrationError, match="not found"):
        ScannerModel.load(tmp_path / "absent.json")
    broken = tmp_path / "broken.json"
    broken.write_text("{ not json")
    with pytest.raises(CalibrationError, match="not valid JSON"):
        ScannerModel.load(broken)


def test_unnormalised_normal_in_a_file_is_normalised(tmp_path):
    data = reference_scanner().to_dict()
    data["laser"]["normal"] = [2 * n for n in data["laser"]["normal"]]
    path = tmp_path / "s.json"
    path.write_text(json.dumps(data))
    loaded, reference = ScannerModel.load(path).laser, reference_scanner().laser
    assert loaded.origin == reference.origin
    np.testing.assert_allclose(loaded.normal, reference.normal, rtol=0, atol=1e-15)
    assert np.linalg.norm(loaded.normal) == pytest.approx(1.0, abs=1e-15)


def test_a_saved_model_loads_back_bit_for_bit(tmp_path):
    model = reference_scanner()
    model.save(tmp_path / "s.json")
    assert ScannerModel.load(tmp_path / "s.json") == model
