"""Triangulation against independent truth: OpenCV's projection and closed forms."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap_driver.scanner_model import CameraIntrinsics, reference_scanner
from scanmap_driver.transforms import rot_z
from scanmap_driver.triangulation import Reason, pixel_rays, triangulate

DISTORTED = reference_scanner().with_changes(
    camera=CameraIntrinsics(width=640, height=480, fx=1012.0, fy=1018.0, cx=322.4, cy=236.1,
                            distortion=(-0.21, 0.09, 0.0012, -0.0007, -0.02)))


def plane_basis(model):
    """Two unit vectors spanning the laser plane (in head)."""
    n = np.array(model.laser.normal)
    e1 = np.cross(n, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def project_with_opencv(model, points_head):
    """Pixels of head points through OpenCV's own projection (the independent peer)."""
    rotation = model.camera_mount.rotation
    points_cam = (points_head - np.array(model.camera_mount.position)) @ rotation
    pixels, _ = cv2.projectPoints(points_cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                  model.camera.matrix, model.camera.dist_coeffs)
    return pixels.reshape(-1, 2), points_cam[:, 2]


@settings(max_examples=60, deadline=None)
@given(a=st.floats(-3.0, 3.0), b=st.floats(-3.0, 3.0), heading=st.floats(-10.0, 10.0),
       distorted=st.booleans())
def test_round_trip_through_opencv_projection_is_exact(a, b, heading, distorted):
    model = DISTORTED if distorted else reference_scanner()
    e1, e2 = plane_basis(model)
    point = np.array(model.laser.origin) + a * e1 + b * e2
    pixel, depth = project_with_opencv(model, point[None])
    rng = math.hypot(point[0], point[1])
    in_image = (-0.5 <= pixel[0, 0] <= 639.5) and (-0.5 <= pixel[0, 1] <= 479.5)
    # Stay where the distortion polynomial is monotonic (inside the calibrated image).
    cam = (point - np.array(model.camera_mount.position)) @ model.camera_mount.rotation
    in_field = abs(cam[0] / cam[2]) < 0.3 and abs(cam[1] / cam[2]) < 0.22
    if not (depth[0] > 0.05 and in_image and in_field and 0.3 <= rng <= 4.0):
        return
    result = triangulate(model, pixel[:, 0], pixel[:, 1], heading)
    assert result.reason[0] == Reason.VALID
    np.testing.assert_allclose(result.points_head[0], point, rtol=0, atol=1e-9)
    expected_base = rot_z(heading) @ point
    np.testing.assert_allclose(result.points_base[0], expected_base, rtol=0, atol=1e-9)


def test_points_lie_on_laser_plane_and_on_their_pixel_ray():
    model = DISTORTED
    u = np.repeat(np.arange(0, 640, 7.0), 12)
    v = np.tile(np.linspace(0, 479, 12), u.size // 12)
    result = triangulate(model, u, v, 0.7)
    ok = result.valid
    assert ok.sum() > 100
    distance = model.laser.signed_distance(result.points_head[ok])
    assert np.abs(distance).max() < 1e-12
    centre, rays = pixel_rays(model, u[ok], v[ok])
    offsets = result.points_head[ok] - centre
    cross = np.cross(offsets, rays)
    assert np.abs(cross).max() < 1e-12


def test_undistortion_matches_opencv():
    model = DISTORTED
    u, v = np.meshgrid(np.linspace(0, 639, 30), np.linspace(0, 479, 20))
    _, rays = pixel_rays(model, u.ravel(), v.ravel())
    rays_cam = rays @ model.camera_mount.rotation
    ours = rays_cam[:, :2] / rays_cam[:, 2:]
    theirs = cv2.undistortPoints(
        np.column_stack([u.ravel(), v.ravel()]).reshape(-1, 1, 2), model.camera.matrix,
        model.camera.dist_coeffs, R=np.eye(3), P=np.eye(3),
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)).reshape(-1, 2)
    np.testing.assert_allclose(ours, theirs, atol=1e-9)


def test_paper_eq4_is_off_by_a_factor_two_and_ours_is_the_pinhole():
    model = reference_scanner()
    columns, fov = 640, math.radians(35.0)
    paper_c_mu = math.tan(fov / 2) / columns
    paper_edge = math.degrees(math.atan(paper_c_mu * (columns / 2 - 0)))
    assert paper_edge == pytest.approx(8.96, abs=0.01)
    # Our ray through the image edge (u = -0.5, the outer border of pixel 0) at the centre row.
    _, rays = pixel_rays(model, np.array([-0.5]), np.array([model.camera.cy]))
    optical_axis = model.camera_mount.rotation[:, 2]
    angle = math.degrees(math.acos(float(rays[0] @ optical_axis)))
    assert angle == pytest.approx(17.5, abs=1e-6)


def test_range_sigma_matches_finite_difference():
    model = DISTORTED
    u = np.repeat(np.arange(10.0, 640.0, 60.0), 12)
    v = np.tile(np.arange(10.0, 480.0, 40.0), u.size // 12)
    valid = triangulate(model, u, v, 0.0).valid
    u, v = u[valid], v[valid]
    assert u.size > 20
    base = triangulate(model, u, v, 0.0)
    h = 1e-4
    plus = triangulate(model, u, v + h, 0.0).points_head
    minus = triangulate(model, u, v - h, 0.0).points_head
    numeric = np.linalg.norm(plus - minus, axis=1) / (2 * h) * model.pixel_sigma
    np.testing.assert_allclose(base.range_sigma, numeric, rtol=1e-5)


def test_reference_scanner_whole_pixel_error_at_4m_is_about_5cm():
    model = reference_scanner().with_changes(pixel_sigma=1.0)
    u = np.repeat(np.arange(0.0, 560.0), 480)
    v = np.tile(np.arange(480.0), 560)
    result = triangulate(model, u, v, 0.0)
    rng = np.hypot(result.points_head[:, 0], result.points_head[:, 1])
    far = result.valid & (rng > 3.8)
    assert far.sum() > 100
    assert 0.04 < np.median(result.range_sigma[far]) < 0.06
    z = result.points_head[result.valid, 2]
    assert z.min() < 0.05 and z.max() > 0.95  # floor to about 1 m


class TestHardCases:
    def test_ray_nearly_parallel_to_laser_plane_is_rejected(self):
        model = reference_scanner()
        n_cam = model.camera_mount.rotation.T @ np.array(model.laser.normal)
        # Pixels on the plane's horizon line n . [x, y, 1] = 0, inside the image.
        x = (np.arange(640.0) - model.camera.cx) / model.camera.fx
        y = -(n_cam[0] * x + n_cam[2]) / n_cam[1]
        v = model.camera.cy + model.camera.fy * y
        inside = (v > 0) & (v < 479)
        assert inside.any()
        u = np.arange(640.0)[inside]
        result = triangulate(model, u, v[inside] + 1e-9, 0.0)
        assert (result.reason == Reason.PARALLEL).all()
        assert np.isnan(result.points_base).all() and np.isnan(result.range_sigma).all()

    def test_intersection_behind_camera_is_rejected(self):
        model = reference_scanner()
        u = np.repeat(np.arange(0.0, 640.0, 8.0), 60)
        v = np.tile(np.arange(0.0, 480.0, 8.0), 80)
        result = triangulate(model, u, v, 0.0)
        behind = result.reason == Reason.BEHIND_CAMERA
        assert behind.any()
        # Independent check: those rays meet the plane at negative ray parameter.
        centre, rays = pixel_rays(model, u[behind], v[behind])
        n = np.array(model.laser.normal)
        t = ((np.array(model.laser.origin) - centre) @ n) / (rays @ n)
        assert (t < 0).all()

    @pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
    def test_nan_and_inf_inputs(self, bad):
        model = reference_scanner()
        result = triangulate(model, np.array([bad, 300.0, 300.0]),
                             np.array([200.0, bad, 200.0]), np.array([0.0, 0.0, bad]))
        assert (result.reason == Reason.NAN_INPUT).all()
        assert np.isnan(result.points_base).all()

    def test_pixels_outside_the_image(self):
        model = reference_scanner()
        result = triangulate(model, np.array([-1.0, 640.0, 10.0]),
                             np.array([10.0, 10.0, 480.0]), 0.0)
        assert (result.reason == Reason.OUTSIDE_IMAGE).all()

    def test_range_limits_and_no_huge_points(self):
        model = reference_scanner()
        u = np.repeat(np.arange(0.0, 640.0, 2.0), 240)
        v = np.tile(np.arange(0.0, 480.0, 2.0), 320)
        result = triangulate(model, u, v, 1.0)
        rng = np.hypot(result.points_head[:, 0], result.points_head[:, 1])
        assert (result.reason == Reason.TOO_FAR).any()
        ok = result.valid
        assert (rng[ok] >= model.min_range).all() and (rng[ok] <= model.max_range).all()
        near = reference_scanner().with_changes(min_range=2.0)
        assert (triangulate(near, u, v, 1.0).reason == Reason.TOO_NEAR).any()

    def test_undistortion_failure_is_flagged_not_wrong(self):
        wild = DISTORTED.with_changes(camera=CameraIntrinsics(
            width=640, height=480, fx=300.0, fy=300.0, cx=320.0, cy=240.0,
            distortion=(-2.0, 5.0, 0.0, 0.0, -20.0)))
        u = np.array([0.0, 639.0, 0.0, 639.0])
        v = np.array([0.0, 0.0, 479.0, 479.0])
        result = triangulate(wild, u, v, 0.0)
        bad = result.reason == Reason.UNDISTORT_FAILED
        assert bad.any()
        assert np.isnan(result.points_base[bad]).all()

    def test_empty_and_mismatched_input(self):
        model = reference_scanner()
        result = triangulate(model, np.array([]), np.array([]), 0.0)
        assert result.points_base.shape == (0, 3)
        with pytest.raises(ValueError, match="differ"):
            triangulate(model, np.array([1.0]), np.array([1.0, 2.0]), 0.0)


def test_head_mount_tilt_is_applied_after_heading():
    from scanmap_driver.scanner_model import HeadMount
    from scanmap_driver.transforms import rot_x

    model = reference_scanner().with_changes(
        head_mount=HeadMount(position=(0.1, -0.2, 0.3), roll=0.05, pitch=0.0))
    result = triangulate(model, np.array([300.0]), np.array([200.0]), 0.4)
    expected = rot_x(0.05) @ (rot_z(0.4) @ result.points_head[0]) + np.array([0.1, -0.2, 0.3])
    np.testing.assert_allclose(result.points_base[0], expected, atol=1e-12)
