"""Ray origins of a scan: the camera centre of each point's frame, in map."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap.grid.rays import camera_centres, laser_origins, scan_rays
from scanmap_driver.errors import ScanError
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import HeadMount, reference_scanner
from scanmap_driver.transforms import se2_to_pose, transform_points


def tilted_model():
    return reference_scanner().with_changes(
        head_mount=HeadMount(position=(0.1, -0.05, 0.02), roll=0.02, pitch=-0.03))


def test_camera_centres_follow_the_head_pose():
    model = tilted_model()
    headings = np.random.default_rng(0).uniform(-4, 4, 50)
    camera = np.array([model.camera_mount.position])
    expected = np.vstack([transform_points(model.head_pose(h), camera) for h in headings])
    np.testing.assert_allclose(camera_centres(model, headings), expected, atol=1e-12)


def random_scan(n: int = 40, frames: int = 5) -> Scan:
    rng = np.random.default_rng(1)
    frame = rng.integers(0, frames, n)
    return Scan(points=rng.uniform(-3, 3, (n, 3)), colors=np.zeros((n, 3), np.uint8),
                time=np.zeros(n), heading=frame * 1.3, frame_index=frame,
                range_sigma=np.zeros(n))


def test_scan_rays_with_one_pose_and_with_a_pose_per_frame():
    model, scan = tilted_model(), random_scan()
    pose = se2_to_pose(1.0, -2.0, 0.4)
    points, origins = scan_rays(scan, model, pose)
    np.testing.assert_allclose(points, transform_points(pose, scan.points))
    np.testing.assert_allclose(origins, transform_points(pose,
                                                         camera_centres(model, scan.heading)))
    per_frame = np.stack([se2_to_pose(0.1 * f, 0.0, 0.05 * f) for f in range(5)])
    points, origins = scan_rays(scan, model, per_frame)
    for i in range(len(scan)):
        p = per_frame[scan.frame_index[i]]
        np.testing.assert_allclose(points[i], transform_points(p, scan.points[i:i + 1])[0])
        np.testing.assert_allclose(
            origins[i], transform_points(p, camera_centres(model, scan.heading[i:i + 1]))[0])


def test_each_points_heading_turns_its_camera_centre():
    """Points of one frame in a run, sorted, with headings that change within the frame
    (and repeat across frames): every origin is its own heading's camera centre."""
    model, scan = tilted_model(), random_scan(60, 3)
    order = np.argsort(scan.frame_index, kind="stable")
    heading = np.repeat([0.2, 0.2, 1.1, -2.0, 0.2, 3.0], 10)
    scan = Scan(points=scan.points[order], colors=scan.colors, time=scan.time,
                heading=heading, frame_index=scan.frame_index[order],
                range_sigma=scan.range_sigma)
    per_frame = np.stack([se2_to_pose(0.3 * f, 1.0, 0.2 * f) for f in range(3)])
    _, origins = scan_rays(scan, model, per_frame)
    for i in range(len(scan)):
        centre = camera_centres(model, heading[i:i + 1])
        np.testing.assert_allclose(
            origins[i], transform_points(per_frame[scan.frame_index[i]], centre)[0],
            atol=1e-12)


def test_the_laser_origins_are_the_emitter_turned_with_the_head():
    """Each point's laser origin: the emitter (`model.laser.origin`, in the head mount)
    turned by its heading, then by the head's mount and its frame's pose; the emitter
    lies on the laser plane, 0.5 m below the reference camera."""
    model, scan = tilted_model(), random_scan()
    per_frame = np.stack([se2_to_pose(0.1 * f, 0.2, -0.3 * f) for f in range(5)])
    emitters = laser_origins(scan, model, per_frame)
    emitter = np.array([model.laser.origin])
    for i in range(len(scan)):
        in_base = transform_points(model.head_pose(scan.heading[i]), emitter)
        np.testing.assert_allclose(
            emitters[i], transform_points(per_frame[scan.frame_index[i]], in_base)[0],
            atol=1e-12)
    level = reference_scanner()
    centre = camera_centres(level, np.zeros(1))[0]
    np.testing.assert_allclose(laser_origins(random_scan(1, 1), level)[0],
                               centre - [0.0, 0.0, 0.5], atol=1e-12)


@pytest.mark.parametrize("pose", [np.eye(3), np.full((4, 4), np.nan), np.stack([np.eye(4)] * 2)])
def test_bad_poses_are_scan_errors(pose):
    with pytest.raises(ScanError):
        scan_rays(random_scan(), reference_scanner(), pose)
