"""The issue's hard cases, each against ground truth from the ray-cast scenes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from scanmap.registration import (
    LocalMap,
    OdometryNoiseConfig,
    Prior,
    RegistrationConfig,
    RegistrationStatus,
    ScanOdometry,
    prepare_source,
    register_scan,
)
from scanmap.registration.lie import between, pose_exp
from scanmap.registration.recovery import _search, coarse_search
from scanmap_driver.errors import RegistrationError
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose, wrap_angle
from tests.scanmap.registration.scenes import (
    Scene,
    corridor,
    make_scan,
    office,
    round_room,
    square_room,
    with_odometry,
)

CONFIG = RegistrationConfig()
NOISE = OdometryNoiseConfig()


def _map_of(scene, poses, rng):
    local_map = LocalMap(CONFIG.map_voxel_size, CONFIG.map_radius, CONFIG.map_max_count,
                         CONFIG.min_plane_points, CONFIG.flatness)
    for i, pose in enumerate(poses):
        scan = make_scan(scene, pose, rng)
        source = prepare_source(scan.points, CONFIG, scan.range_sigma)
        t = se2_to_pose(*pose)
        local_map.insert(source.cloud @ t[:3, :3].T + t[:3, 3], i + 1, source.cloud_variance)
    return local_map


def _register(scene, map_poses, truth, guess, rng, threshold=0.1, step=(0.3, 0.0, 0.0)):
    """Register a scan taken at `truth` against a map of `map_poses`, from `guess`."""
    local_map = _map_of(scene, map_poses, rng)
    scan = make_scan(scene, truth, rng)
    source = prepare_source(scan.points, CONFIG, scan.range_sigma)
    prior = Prior(se2_to_pose(*guess), NOISE.odometry_covariance(se2_to_pose(*step)))
    return register_scan(source, local_map, prior, threshold, CONFIG), prior


def _error(result, truth):
    x, y, yaw = pose_to_se2(result.pose)
    return np.array([x - truth[0], y - truth[1], float(wrap_angle(yaw - truth[2]))])


def test_featureless_corridor_follows_odometry_along_its_axis():
    rng = np.random.default_rng(10)
    truth, guess = (0.6, 0.03, 0.02), (0.66, -0.01, -0.01)
    result, prior = _register(corridor(with_features=False), [(0.0, 0.0, 0.0), (0.3, 0.0, 0.0)],
                              truth, guess, rng)
    assert result.status is RegistrationStatus.OK and result.degenerate
    (direction,) = result.degenerate_directions
    assert abs(direction[0]) > 0.99  # the corridor's axis, x
    error = _error(result, truth)
    assert abs(error[1]) < 0.002 and abs(error[2]) < 0.001  # the walls fix y and yaw
    # Along the axis the pose is the prior's, not an invention, and so is the uncertainty.
    assert between(prior.pose, result.pose) @ direction == pytest.approx(0.0, abs=5e-4)
    assert result.covariance[0, 0] == pytest.approx(prior.covariance[0, 0], rel=0.05)
    assert result.covariance[1, 1] < 0.01 * prior.covariance[1, 1]


def test_a_corridor_with_features_is_not_degenerate():
    rng = np.random.default_rng(11)
    truth = (7.9, 0.0, 0.05)  # a box 1 m ahead
    result, _ = _register(corridor(), [(7.3, 0.0, 0.0), (7.6, 0.0, 0.0)], truth,
                          (7.92, 0.01, 0.06), rng)
    assert result.status is RegistrationStatus.OK and not result.degenerate
    assert np.all(np.abs(_error(result, truth)) < [0.005, 0.002, 0.002])


def test_a_pits_walls_below_the_floor_fix_a_featureless_corridors_axis():
    # The corridor's walls leave x to odometry (above); a pit in the floor ahead shows its
    # walls below the floor, and planar registration matches them as it matches walls.
    rng = np.random.default_rng(10)
    scene = replace(corridor(with_features=False), pits=[((2.0, -0.3, -0.3), (2.5, 0.3, 0.0))])
    truth = (0.6, 0.03, 0.02)
    result, _ = _register(scene, [(0.0, 0.0, 0.0), (0.3, 0.0, 0.0)], truth,
                          (0.615, -0.01, -0.01), rng)  # odometry 1.5 cm long
    assert result.status is RegistrationStatus.OK and not result.degenerate
    assert np.all(np.abs(_error(result, truth)) < [0.005, 0.002, 0.002])


def test_a_scan_without_overlap_is_refused():
    rng = np.random.default_rng(12)
    local_map = _map_of(corridor(), [(2.0, 0.0, 0.0)], rng)
    elsewhere = make_scan(square_room(3.0), (0.0, 0.0, 0.0), rng)  # another place entirely
    source = prepare_source(elsewhere.points, CONFIG, elsewhere.range_sigma)
    prior = Prior(se2_to_pose(2.3, 0.0, 0.0), NOISE.odometry_covariance(se2_to_pose(0.3, 0, 0)))
    result = register_scan(source, local_map, prior, 0.1, CONFIG)
    assert result.status is RegistrationStatus.NO_OVERLAP and not result.ok
    np.testing.assert_array_equal(result.pose, prior.pose)
    with pytest.raises(RegistrationError, match="no_overlap"):
        result.raise_for_status()


def test_large_initial_error_is_recovered():
    rng = np.random.default_rng(13)
    truth = (0.3, -0.2, 0.4)
    guess = (0.3 + 0.3 * np.cos(1.0), -0.2 + 0.3 * np.sin(1.0), 0.4 + np.deg2rad(20))
    result, _ = _register(office(), [(0.0, 0.0, 0.3), (0.15, -0.1, 0.35)], truth, guess, rng)
    assert result.status is RegistrationStatus.OK and result.recovered
    assert np.all(np.abs(_error(result, truth)) < [0.005, 0.005, 0.002])


@pytest.mark.parametrize("seed", range(4))
def test_the_coarse_search_chooses_as_the_exhaustive_one(seed):
    """Branch and bound changes how much is scored, never the pose or the scores."""
    rng = np.random.default_rng(seed)
    local_map = _map_of(office(), [(0.0, 0.0, 0.3), (0.15, -0.1, 0.35)], rng)
    scan = make_scan(office(), (0.3, -0.2, 0.4), rng)
    source = prepare_source(scan.points, CONFIG, scan.range_sigma)
    guess = se2_to_pose(0.3 + rng.uniform(-0.4, 0.4), -0.2 + rng.uniform(-0.4, 0.4),
                        0.4 + rng.uniform(-0.4, 0.4))
    fast = coarse_search(source, local_map, guess, CONFIG)
    exhaustive = _search(source, local_map, guess, CONFIG, exhaustive=True)
    np.testing.assert_array_equal(fast[0], exhaustive[0])
    assert fast[1:] == exhaustive[1:] and fast[1] > fast[2]


def test_symmetric_room_keeps_the_nearest_solution():
    rng = np.random.default_rng(14)
    truth = (0.2, -0.1, 0.1)
    result, _ = _register(square_room(4.0), [(0.0, 0.0, 0.0)], truth, (0.27, -0.04, 0.17),
                          rng)
    assert result.status is RegistrationStatus.OK
    assert np.all(np.abs(_error(result, truth)) < [0.005, 0.005, 0.002])


def test_round_room_rotation_is_degenerate_and_taken_from_odometry():
    rng = np.random.default_rng(15)
    truth, guess = (0.2, 0.1, 0.3), (0.23, 0.08, 0.33)
    result, prior = _register(round_room(2.5), [(0.0, 0.0, 0.0)], truth, guess, rng)
    assert result.status is RegistrationStatus.OK and result.degenerate
    (direction,) = result.degenerate_directions
    # The symmetry: turning about the room's centre, i.e. in the body frame a yaw rate 1
    # with the velocity of the robot's origin on that circle.
    pose = result.pose
    velocity = pose[:3, :3].T @ np.cross([0.0, 0.0, 1.0], pose[:3, 3] - [0.0, 0.0, 0.0])
    expected = np.array([*velocity[:2], 0, 0, 0, 1.0])
    assert abs(direction @ expected) / np.linalg.norm(expected) > 0.99
    # Along it the result stays with the prior (the conditional mean given the walls),
    # far from the truth it cannot see, and keeps the prior's uncertainty.
    along_truth = between(prior.pose, se2_to_pose(*truth)) @ direction
    assert abs(between(prior.pose, result.pose) @ direction) < 0.3 * abs(along_truth)
    assert direction @ result.covariance @ direction > 0.5 * direction @ prior.covariance \
        @ direction
    # Across the symmetry the walls place the robot: its distance to the centre is right.
    assert np.hypot(*pose[:2, 3]) == pytest.approx(np.hypot(*truth[:2]), abs=0.003)


def _with_box(x: float):
    """The featureless corridor with one box against its left wall, starting at `x`."""
    walls = corridor(with_features=False)
    return Scene([*walls.boxes, ((x, 0.25, 0.0), (x + 0.4, 0.75, 0.8))])


@pytest.mark.parametrize("pushed", [0.06, 0.08])
def test_a_moved_box_does_not_drag_a_corridor_pose_away_from_good_odometry(pushed):
    # The box is the corridor's only feature along its axis, and since the map was made
    # someone pushed it: ICP follows the box, which the odometry's covariance says is
    # 5-8 sigma away. The map does not fit the scan clearly better there, so the scan
    # keeps the odometry's pose; with the check off, the box drags it.
    rng = np.random.default_rng(17)
    local_map = _map_of(_with_box(2.0), [(0.0, 0.0, 0.0), (0.1, 0.0, 0.0)], rng)
    truth = (0.2, 0.0, 0.0)
    scan = make_scan(_with_box(2.0 + pushed), truth, rng)
    source = prepare_source(scan.points, CONFIG, scan.range_sigma)
    odometry = Prior(se2_to_pose(0.203, -0.002, 0.001),
                     NOISE.odometry_covariance(se2_to_pose(0.1, 0.0, 0.0)))
    checked = register_scan(source, local_map, odometry, 0.2, CONFIG)
    unchecked = register_scan(source, local_map, odometry, 0.2,
                              replace(CONFIG, consistency_level=1.0))
    assert checked.status is RegistrationStatus.INCONSISTENT and not checked.ok
    np.testing.assert_array_equal(checked.pose, odometry.pose)
    assert np.all(np.abs(_error(checked, truth)) < [0.005, 0.005, 0.002])
    assert unchecked.ok and _error(unchecked, truth)[0] < -pushed / 2


def test_a_wheel_slip_the_map_shows_is_still_corrected():
    # Odometry 0.15 m and 3 deg off after a 0.3 m step (7 sigma): the office's walls and
    # furniture fit the scan clearly better at the matched pose, so the match stands.
    rng = np.random.default_rng(18)
    truth = (0.3, -0.2, 0.4)
    result, prior = _register(office(), [(0.0, 0.0, 0.3), (0.15, -0.1, 0.35)], truth,
                              (0.42, -0.11, 0.45), rng, threshold=0.3)
    assert between(prior.pose, result.pose)[:2] @ between(prior.pose, result.pose)[:2] \
        > 5 ** 2 * prior.covariance[0, 0]
    assert result.status is RegistrationStatus.OK
    assert np.all(np.abs(_error(result, truth)) < [0.005, 0.005, 0.002])


def _with_bad_points(scan: Scan) -> Scan:
    bad = np.array([[np.nan, 1.0, 0.5], [np.inf, 0.0, 0.2], [1.0, -np.inf, 0.3],
                    [1e30, 1.0, 0.5], [1.0, 1.0, np.nan]])
    n = len(bad)
    return Scan(points=np.vstack([scan.points, bad]),
                colors=np.vstack([scan.colors, np.zeros((n, 3), np.uint8)]),
                time=np.concatenate([scan.time, [np.nan, np.inf, 0.0, 0.0, 0.0]]),
                heading=np.concatenate([scan.heading, np.zeros(n)]),
                frame_index=np.concatenate([scan.frame_index, np.zeros(n, np.int32)]),
                range_sigma=np.concatenate([scan.range_sigma, [np.nan, np.inf, -1, 0, 0]]),
                index=scan.index, stamp=scan.stamp, odom_start=scan.odom_start,
                odom_end=scan.odom_end)


def _sequence(scene, truth, odometry, rng, **scan_args):
    return [with_odometry(make_scan(scene, p, rng, index=i, stamp=3.0 * i, **scan_args),
                          se2_to_pose(*o), se2_to_pose(*o))
            for i, (p, o) in enumerate(zip(truth, odometry, strict=True))]


def test_nan_and_inf_points_change_nothing():
    rng = np.random.default_rng(16)
    truth = [(0.0, 0.0, 0.0), (0.25, 0.05, 0.05)]
    scans = _sequence(office(), truth, [(0, 0, 0), (0.27, 0.04, 0.06)], rng)
    clean, dirty = ScanOdometry(), ScanOdometry()
    for scan in scans:
        a, b = clean.register(scan), dirty.register(_with_bad_points(scan))
        assert a.status == b.status and b.ok
        np.testing.assert_allclose(a.pose, b.pose, atol=1e-12)
    assert np.all(np.abs(_error(b, truth[1])) < [0.003, 0.003, 0.002])


def test_a_scan_of_ten_points_is_too_few():
    rng = np.random.default_rng(17)
    scans = _sequence(office(), [(0, 0, 0), (0.2, 0, 0)], [(0, 0, 0), (0.21, 0, 0)], rng)
    odometry = ScanOdometry()
    odometry.register(scans[0])
    tiny = scans[1].select(np.arange(10))
    result = odometry.register(tiny)
    assert result.status is RegistrationStatus.TOO_FEW_POINTS and result.num_points <= 10
    np.testing.assert_allclose(pose_to_se2(result.pose), (0.21, 0, 0), atol=1e-12)  # prior
    with pytest.raises(RegistrationError, match="too_few_points"):
        result.raise_for_status()
    assert odometry.register(scans[1]).ok  # the map was not touched by the failure


def test_scans_ten_kilometres_from_the_origin_register_as_at_home():
    rng = np.random.default_rng(18)
    truth = [(0.0, 0.0, 0.0), (0.3, 0.02, 0.03), (0.6, 0.0, 0.05)]
    odometry = [(0.0, 0.0, 0.0), (0.32, 0.0, 0.02), (0.63, -0.01, 0.06)]
    scans = _sequence(office(), truth, odometry, rng)
    far = se2_to_pose(1e4, -1e4, 0.0)  # the same voxel grid, 14 km away
    home, away = ScanOdometry(), ScanOdometry(initial_pose=far)
    for scan in scans:
        shifted = with_odometry(scan, far @ scan.odom_start, far @ scan.odom_end)
        a, b = home.register(scan), away.register(shifted)
        assert a.ok and b.ok
        np.testing.assert_allclose(far @ a.pose, b.pose, rtol=0, atol=1e-8)
    assert np.all(np.abs(_error(a, truth[2])) < [0.003, 0.003, 0.002])


def test_identical_consecutive_scans_do_not_move():
    rng = np.random.default_rng(19)
    (scan,) = _sequence(office(), [(0.5, 0.2, 1.0)], [(0.0, 0.0, 0.0)], rng)
    odometry = ScanOdometry(initial_pose=se2_to_pose(0.5, 0.2, 1.0))
    first = odometry.register(scan)
    second = odometry.register(scan)
    assert first.status is RegistrationStatus.INITIALISED and second.status is RegistrationStatus.OK
    assert second.fitness > 0.9 and not second.degenerate
    motion = pose_to_se2(invert_pose(first.pose) @ second.pose)
    assert np.all(np.abs(motion) < [1e-3, 1e-3, 1e-3])


def test_full_se3_mode_uses_the_floor_for_height_roll_and_pitch():
    rng = np.random.default_rng(20)
    config = RegistrationConfig(planar=False)
    local_map = LocalMap(config.map_voxel_size, config.map_radius, config.map_max_count,
                         config.min_plane_points, config.flatness)
    truth = se2_to_pose(0.2, -0.1, 0.3)
    for i, pose in enumerate([(0.0, 0.0, 0.2), (0.1, 0.0, 0.25)]):
        scan = make_scan(office(), pose, rng)
        cloud = prepare_source(scan.points, config, scan.range_sigma).cloud
        t = se2_to_pose(*pose)
        local_map.insert(cloud @ t[:3, :3].T + t[:3, 3], i + 1)
    scan = make_scan(office(), pose_to_se2(truth), rng)
    source = prepare_source(scan.points, config, scan.range_sigma)
    assert (source.points[:, 2] < 0.05).sum() > 100  # the floor is kept
    guess = truth @ pose_exp(np.array([0.02, -0.01, 0.03, 0.01, -0.015, 0.01]))
    prior = Prior(guess, np.diag(np.square([0.05, 0.05, 0.05, 0.05, 0.05, 0.05])))
    result = register_scan(source, local_map, prior, 0.1, config)
    assert result.status is RegistrationStatus.OK and not result.degenerate
    error = between(truth, result.pose)
    assert np.all(np.abs(error[:3]) < 0.003) and np.all(np.abs(error[3:]) < 0.002)
    assert np.all(np.diag(result.covariance) > 0)  # all six estimated
