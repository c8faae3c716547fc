"""Ideal scans: points on the true surfaces, noise as the triangulation error model says."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scanmap_driver import reference_scanner
from scanmap_driver.sim import builtin_scene, ideal_scans
from scanmap_driver.sim.laser_stripe import head_poses
from scanmap_driver.sim.scene import Motion
from scanmap_driver.transforms import invert_pose, pose_to_se2, transform_points
from scanmap_driver.triangulation import project_head_points

from .scene_sdf import surface_distance


@pytest.fixture(scope="module")
def corridor_scans():
    return list(ideal_scans(builtin_scene("corridor"), seed=5, scans=3))


def _map_points(ideal, points):
    out = np.empty_like(points, dtype=np.float64)
    for frame, pose in enumerate(ideal.frame_poses):
        rows = ideal.scan.frame_index == frame
        out[rows] = transform_points(pose, points[rows])
    return out


def test_true_points_lie_on_the_scene_surfaces(corridor_scans):
    scene = builtin_scene("corridor")
    for ideal in corridor_scans:
        world = _map_points(ideal, ideal.true_points)
        # Cylinders are built from flat sides touching the circle: < 0.5 mm off it.
        assert surface_distance(scene, world).max() < 5e-4
        assert len(ideal.scan) > 20_000


def test_a_full_turn_of_frames_from_floor_to_about_one_metre(corridor_scans):
    ideal = corridor_scans[0]
    assert ideal.frame_headings[-1] - ideal.frame_headings[0] >= 2 * np.pi
    world = _map_points(ideal, ideal.true_points)
    assert world[:, 2].min() < 0.01 and 0.9 < world[:, 2].max() < 1.1
    ranges = np.hypot(ideal.scan.points[:, 0], ideal.scan.points[:, 1])
    assert ranges.min() >= 0.3 and ranges.max() <= 4.0


def test_noise_follows_the_triangulation_error_model(corridor_scans):
    model = reference_scanner()
    residuals = []
    for ideal in corridor_scans:
        error = ideal.scan.points.astype(np.float64) - ideal.true_points
        residuals.append(np.linalg.norm(error, axis=1)
                         * np.sign(np.einsum("ij,ij->i", error, ideal.true_points))
                         / ideal.scan.range_sigma)
    z = np.concatenate(residuals)
    # float32 storage adds ~1e-7 m; range_sigma is for model.pixel_sigma = 0.1 px.
    assert model.pixel_sigma == 0.1
    assert abs(z.std() - 1.0) < 0.05
    assert abs(z.mean()) < 0.05


def test_one_point_per_image_column_and_frame(corridor_scans):
    model = reference_scanner()
    ideal = corridor_scans[1]
    _, base_head = head_poses(model, ideal.frame_poses, ideal.frame_headings)
    for frame in (0, 20, 40):
        rows = ideal.scan.frame_index == frame
        head = transform_points(invert_pose(base_head[frame]), ideal.true_points[rows])
        u = project_head_points(model, head)[:, 0]
        np.testing.assert_allclose(u, np.round(u), atol=1e-6)
        assert np.unique(np.round(u)).size == u.size


def test_deterministic_for_a_seed():
    scene = builtin_scene("office")
    a = next(ideal_scans(scene, seed=3, scans=1))
    b = next(ideal_scans(scene, seed=3, scans=1))
    c = next(ideal_scans(scene, seed=4, scans=1))
    np.testing.assert_array_equal(a.scan.points, b.scan.points)
    np.testing.assert_array_equal(a.scan.colors, b.scan.colors)
    assert len(a.scan) != len(c.scan) or not np.array_equal(a.scan.points, c.scan.points)


def test_zero_noise_gives_the_true_points():
    ideal = next(ideal_scans(builtin_scene("office"), seed=1, scans=1, pixel_sigma=1e-12))
    np.testing.assert_allclose(ideal.scan.points, ideal.true_points, atol=1e-6)


def test_odometry_follows_the_true_motion_with_drift(corridor_scans):
    first, last = corridor_scans[0], corridor_scans[-1]
    true_step = pose_to_se2(invert_pose(first.pose_start) @ last.pose_start)
    odom_step = pose_to_se2(invert_pose(first.scan.odom_start) @ last.scan.odom_start)
    assert first.scan.has_odometry
    assert np.hypot(*true_step[:2]) == pytest.approx(0.8, abs=0.05)
    assert np.hypot(odom_step[0] - true_step[0], odom_step[1] - true_step[1]) < 0.05
    assert odom_step != true_step


def test_the_robot_can_keep_driving_during_a_scan():
    scene = dataclasses.replace(builtin_scene("corridor"), motion=Motion(speed=0.2, yaw_rate=0.0))
    ideal = next(ideal_scans(scene, seed=2, scans=1))
    duration = ideal.plan.frame_times[-1] - ideal.plan.frame_times[0]
    travel = ideal.pose_end[:3, 3] - ideal.pose_start[:3, 3]
    assert np.linalg.norm(travel) == pytest.approx(0.2 * duration, rel=1e-9)
    # every frame's points are in that frame's base_link: in map they lie on the walls
    world = _map_points(ideal, ideal.true_points)
    assert surface_distance(scene, world).max() < 5e-4
    odom = pose_to_se2(invert_pose(ideal.scan.odom_start) @ ideal.scan.odom_end)
    assert np.hypot(*odom[:2]) == pytest.approx(0.2 * duration, rel=0.05)
