"""Scan-to-map odometry on sequences: ground truth from scenes, the simulator, real logs."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap.datasets.carmen import read_carmen
from scanmap.evaluation.trajectory_errors import ate_rmse, relative_errors
from scanmap.registration import RegistrationConfig, RegistrationStatus, ScanOdometry
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose
from tests.conftest import real_data
from tests.scanmap.registration.scenes import (
    corridor,
    make_scan,
    noisy_odometry,
    office,
    square_room,
    with_odometry,
)


def _poses(planar):
    return np.array([se2_to_pose(*p) for p in planar])


def test_twenty_metre_corridor_with_noisy_odometry_closes_to_centimetres():
    rng = np.random.default_rng(100)
    xs = np.arange(0.5, 20.5, 0.4)
    truth = np.column_stack([xs, 0.1 * np.sin(xs / 3), 0.05 * np.sin(xs / 2)])
    odometry = noisy_odometry(truth, rng, trans_sigma=0.015, rot_sigma=0.01, scale=1.01,
                              yaw_bias=0.005)
    registration = ScanOdometry(initial_pose=se2_to_pose(*truth[0]))
    for i, (pose, odom) in enumerate(zip(truth, odometry, strict=True)):
        scan = make_scan(corridor(), pose, rng, index=i, stamp=3.0 * i, columns=300, rows=40)
        result = registration.register(with_odometry(scan, se2_to_pose(*odom),
                                                     se2_to_pose(*odom)))
        assert result.ok
    ate = ate_rmse(registration.poses, _poses(truth), "se2")
    assert ate < 0.02
    assert ate < ate_rmse(_poses(odometry), _poses(truth), "se2") / 4
    trajectory = registration.trajectory()
    np.testing.assert_allclose(trajectory.times, 3.0 * np.arange(len(xs)))


def test_motion_during_the_scan_is_deskewed():
    rng = np.random.default_rng(101)
    start, end = (0.3, 0.0, 0.1), (0.8, 0.05, 0.3)  # 0.5 m and 11 deg during one scan
    first = make_scan(office(), (0.0, 0.0, 0.0), rng)
    moving = make_scan(office(), start, rng, end_pose=end, index=1, stamp=3.0)
    errors = {}
    for label, odom_end in (("deskewed", end), ("as if static", start)):
        registration = ScanOdometry()
        registration.register(with_odometry(first, np.eye(4), np.eye(4)))
        result = registration.register(with_odometry(moving, se2_to_pose(*start),
                                                     se2_to_pose(*odom_end)))
        assert result.ok
        errors[label] = np.abs(np.subtract(pose_to_se2(result.pose), start))
    assert np.all(errors["deskewed"] < [0.005, 0.005, 0.003])
    assert errors["as if static"].max() > 5 * errors["deskewed"].max()


def test_without_odometry_a_constant_velocity_guess_serves():
    rng = np.random.default_rng(102)
    truth = [(0.2 * i - 1.0, 0.1 * np.sin(i), 0.08 * i) for i in range(8)]
    registration = ScanOdometry(initial_pose=se2_to_pose(*truth[0]))
    for i, pose in enumerate(truth):
        assert registration.register(make_scan(office(), pose, rng, stamp=3.0 * i)).ok
    assert ate_rmse(registration.poses, _poses(truth), "none") < 0.005


def test_after_repeated_failures_the_map_restarts():
    rng = np.random.default_rng(103)
    registration = ScanOdometry()
    registration.register(make_scan(corridor(), (2.0, 0.0, 0.0), rng))
    elsewhere = [make_scan(square_room(3.0), (0.1 * i, 0.0, 0.0), rng, stamp=3.0 * (i + 1))
                 for i in range(4)]
    statuses = [registration.register(scan).status for scan in elsewhere]
    assert statuses[:3] == [RegistrationStatus.NO_OVERLAP] * 3  # the third restarts the map
    assert statuses[3] is RegistrationStatus.OK
    # Failed scans keep their predicted (constant-velocity) poses, not invented ones.
    assert len(registration.poses) == 5


def test_simulated_office_from_the_simulator():
    sim = pytest.importorskip("scanmap_driver.sim")
    scans = list(sim.ideal_scans(sim.builtin_scene("office"), seed=3, scans=3))
    registration = ScanOdometry(initial_pose=scans[0].pose_start)
    for ideal in scans:
        assert registration.register(ideal.scan).ok
    truth = np.array([ideal.pose_start for ideal in scans])
    odometry = np.array([truth[0] @ invert_pose(scans[0].scan.odom_start) @ s.scan.odom_start
                         for s in scans])
    ate = ate_rmse(registration.poses, truth, "se2")
    assert ate < 0.003
    assert ate < ate_rmse(odometry, truth, "se2") / 5


def test_real_intel_log_with_raw_odometry_as_prior():
    log = read_carmen(real_data("carmen/intel-corrected.log.gz"))
    count = 150
    registration = ScanOdometry(RegistrationConfig.for_2d_scans(),
                                initial_pose=se2_to_pose(*log.poses[0]))
    for i in range(count):
        registration.register_points(log.scan_points(i), stamp=log.times[i],
                                     odometry=se2_to_pose(*log.odometry[i]))
    reference = _poses(log.poses[:count])
    ours = relative_errors(registration.poses, reference, 1.0).mean_translation
    wheels = relative_errors(_poses(log.odometry[:count]), reference, 1.0).mean_translation
    assert ours < 0.07
    assert ours < wheels / 2
