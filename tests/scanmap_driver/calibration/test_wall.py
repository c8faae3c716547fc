"""Wall calibration against a known true scanner: recovered parameters and range error."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap_driver.calibration.wall import apply_corrections, calibrate_wall
from scanmap_driver.errors import CalibrationError
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.transforms import rot_z
from scanmap_driver.triangulation import project_head_points, triangulate

TRUE_CORRECTIONS = {"laser_normal_1": 0.004, "laser_normal_2": -0.003,
                    "vertical_separation": 0.006, "camera_tilt": -0.005,
                    "camera_height": 0.01, "zero_offset": 0.02}


def plane_line_pixels(model, heading, plane_normal, plane_offset, rng):
    """Integer-u pixels where the laser stripe on a plane (base_link) is seen, and truth."""
    # The plane in head: n_h . p = offset, with n_h = Rz(-heading) n.
    n_plane = rot_z(-heading) @ plane_normal
    n_laser = np.array(model.laser.normal)
    direction = np.cross(n_laser, n_plane)
    direction /= np.linalg.norm(direction)
    # A point on both planes: least-norm solution of the two plane equations.
    a = np.vstack([n_laser, n_plane])
    b = np.array([n_laser @ np.array(model.laser.origin), plane_offset])
    base_point = np.linalg.lstsq(a, b, rcond=None)[0]
    line = base_point + np.linspace(-12, 12, 40001)[:, None] * direction
    pixels = project_head_points(model, line)
    ok = np.isfinite(pixels).all(axis=1) & (pixels[:, 0] > 0) & (pixels[:, 0] < 560) \
        & (pixels[:, 1] > 0) & (pixels[:, 1] < 479)
    cam = (line - np.array(model.camera_mount.position)) @ model.camera_mount.rotation
    ok &= cam[:, 2] > 0.05
    if ok.sum() < 2:
        return np.zeros((0, 2)), np.zeros((0, 3))
    pixels, line = pixels[ok], line[ok]
    order = np.argsort(pixels[:, 0])
    pixels, line = pixels[order], line[order]
    u = np.arange(np.ceil(pixels[0, 0]), np.floor(pixels[-1, 0]) + 1)
    v = np.interp(u, pixels[:, 0], pixels[:, 1]) + rng.normal(0, 0.05, u.size)
    truth = np.column_stack([np.interp(u, pixels[:, 0], line[:, k]) for k in range(3)])
    return np.column_stack([u, v]), truth


def wall_scan(true_model, distance, decoded_heading_shift, seed=0):
    """Observations of a wall `distance` ahead plus the floor, over 50 headings."""
    rng = np.random.default_rng(seed)
    us, vs, hs, truths = [], [], [], []
    for heading in np.linspace(-np.pi, np.pi, 50, endpoint=False):
        for normal, offset in (([1.0, 0, 0], distance), ([0, 0, 1.0], 0.0)):
            pix, truth = plane_line_pixels(true_model, heading, np.array(normal), offset, rng)
            rng_h = np.hypot(truth[:, 0], truth[:, 1])
            keep = (rng_h > 0.3) & (rng_h < 4.0)
            if normal[0] == 1.0:  # the wall: only where the head looks at it
                keep &= (rot_z(heading) @ truth.T)[0] > 0
            us.append(pix[keep, 0])
            vs.append(pix[keep, 1])
            hs.append(np.full(keep.sum(), heading - decoded_heading_shift))
            truths.append((rot_z(heading) @ truth[keep].T).T)
    return (np.concatenate(us), np.concatenate(vs), np.concatenate(hs),
            np.concatenate(truths))


@pytest.fixture(scope="module")
def scene():
    nominal = reference_scanner()
    true_model = apply_corrections(nominal, TRUE_CORRECTIONS)
    return nominal, true_model, wall_scan(true_model, 2.0, TRUE_CORRECTIONS["zero_offset"])


def test_recovers_parameters_and_ranges(scene):
    nominal, _, (u, v, heading, truth) = scene
    result = calibrate_wall(nominal, u, v, heading, distance=2.0)
    assert result.require_supported() is result.model
    for name, value in TRUE_CORRECTIONS.items():
        assert result.values[name] == pytest.approx(value, abs=4 * result.sigmas[name] + 1e-4)
    model = result.require_supported()
    shift = result.values["zero_offset"]
    points = triangulate(model, u, v, heading + shift).points_base
    error = np.linalg.norm(points - truth, axis=1)
    assert np.nanpercentile(error, 95) < 0.01
    # The uncalibrated model is centimetres off: the test can tell the difference.
    raw = triangulate(nominal, u, v, heading).points_base
    assert np.nanpercentile(np.linalg.norm(raw - truth, axis=1), 95) > 0.05


def test_free_wall_direction_leaves_zero_offset_undetermined(scene):
    nominal, _, (u, v, heading, _) = scene
    result = calibrate_wall(nominal, u, v, heading, distance=2.0, facing=False,
                            fit=("laser_normal_1", "zero_offset", "wall_azimuth"))
    assert "zero_offset" in result.undetermined or "wall_azimuth" in result.undetermined
    with pytest.raises(CalibrationError, match="do not determine"):
        result.require_supported()


def test_wall_only_cannot_determine_height():
    nominal = reference_scanner()
    u, v, heading, truth = wall_scan(nominal, 2.0, 0.0)
    wall_only = truth[:, 2] > 0.2
    result = calibrate_wall(nominal, u[wall_only], v[wall_only], heading[wall_only], 2.0)
    assert "camera_height" in result.undetermined


def test_bad_input():
    nominal = reference_scanner()
    with pytest.raises(CalibrationError, match="wall distance"):
        calibrate_wall(nominal, [1.0], [1.0], [0.0], distance=float("nan"))
    with pytest.raises(CalibrationError, match="points near a wall"):
        calibrate_wall(nominal, np.full(10, 300.0), np.full(10, 200.0), np.zeros(10), 2.0)
    with pytest.raises(CalibrationError, match="differ in length"):
        calibrate_wall(nominal, [1.0, 2.0], [1.0], [0.0], 2.0)
