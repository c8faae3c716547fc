"""The small parts of registration against closed forms: degeneracy, prior, threshold,
odometry calibration, settings, the local map's bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap.registration import (
    LocalMap,
    OdometryNoiseConfig,
    Prior,
    RegistrationConfig,
    RegistrationStatus,
    ScanOdometry,
    analyse_degeneracy,
)
from scanmap.registration.calibration import OdometryCalibration
from scanmap.registration.lie import (
    between,
    pose_exp,
    pose_log,
    retract,
    so3_exp,
    so3_log,
    transport,
)
from scanmap.registration.threshold import AdaptiveThreshold
from scanmap_driver.errors import MapError, RegistrationError
from scanmap_driver.transforms import pose_to_se2, se2_to_pose

ROTATIONS = np.array([False, False, True])  # planar (x, y, yaw)


def test_an_unconstrained_axis_is_degenerate_and_projected_out():
    hessian = np.diag([1e-4, 500.0, 300.0 * 4.0])  # x unseen; yaw seen at 2 m
    result = analyse_degeneracy(hessian, unit_weight=1.0, lever_arm=2.0,
                                rotation_mask=ROTATIONS, min_constraint=3.0)
    np.testing.assert_allclose(result.eigenvalues, [1e-4, 300.0, 500.0])
    np.testing.assert_allclose(np.abs(result.degenerate_directions), [[1.0, 0.0, 0.0]])
    h, g = result.project(hessian, np.array([5.0, 1.0, 2.0]))
    np.testing.assert_allclose(h, np.diag([0.0, 500.0, 1200.0]), atol=1e-12)
    np.testing.assert_allclose(g, [0.0, 1.0, 2.0], atol=1e-12)


def test_degeneracy_counts_rotation_at_the_lever_arm():
    # A yaw information of 8 at a 2 m lever arm equals 2 points aligned with the rotation.
    hessian = np.diag([100.0, 100.0, 8.0])
    weak = analyse_degeneracy(hessian, 1.0, 2.0, ROTATIONS, min_constraint=3.0)
    assert weak.degenerate.tolist() == [True, False, False]
    np.testing.assert_allclose(np.abs(weak.degenerate_directions), [[0.0, 0.0, 1.0]])
    strong = analyse_degeneracy(hessian, 1.0, 1.0, ROTATIONS, min_constraint=3.0)
    assert not strong.degenerate.any()
    h, _ = strong.project(hessian, np.ones(3))
    np.testing.assert_array_equal(h, hessian)


def test_a_degenerate_mixed_direction_is_found_in_scaled_units():
    direction = np.array([0.6, 0.0, 0.8 / 3.0])  # metres and radians at a 3 m lever arm
    basis = np.linalg.qr(np.column_stack([direction * [1, 1, 3], [0, 1, 0], [1, 0, 0]]))[0]
    scaled = basis @ np.diag([0.0, 50.0, 80.0]) @ basis.T
    hessian = scaled * np.outer([1, 1, 3], [1, 1, 3])
    result = analyse_degeneracy(hessian, 1.0, 3.0, ROTATIONS, min_constraint=1.0)
    (found,) = result.degenerate_directions
    assert abs(found @ direction) / np.linalg.norm(direction) == pytest.approx(1.0)


def test_odometry_noise_grows_with_motion():
    noise = OdometryNoiseConfig()
    still = noise.odometry_covariance(np.eye(4))
    moved = noise.odometry_covariance(se2_to_pose(1.0, 0.0, 0.5))
    assert still[0, 0] == pytest.approx(noise.trans_floor ** 2)
    expected = noise.trans_floor + noise.trans_per_metre + 0.5 * noise.trans_per_radian
    assert moved[0, 0] == pytest.approx(expected ** 2)
    assert moved[5, 5] > still[5, 5]


@pytest.mark.parametrize("pose, covariance, fragment", [
    (np.eye(3), np.eye(6), "4x4"),
    (np.full((4, 4), np.nan), np.eye(6), "finite"),
    (np.eye(4), np.eye(5), "6x6"),
    (np.eye(4), -np.eye(6), "positive definite"),
])
def test_bad_priors_are_refused(pose, covariance, fragment):
    with pytest.raises(RegistrationError, match=fragment):
        Prior(pose, covariance)


@pytest.mark.parametrize("changes, fragment", [
    ({"voxel_size": -0.1}, "voxel_size"),
    ({"max_range": 0.2}, "min_range"),
    ({"min_threshold": 0.5, "max_threshold": 0.1}, "min_threshold"),
    ({"map_radius": "far"}, "map_radius"),
    ({"consistency_level": 1.5}, "consistency_level"),
])
def test_bad_settings_are_refused_by_name(changes, fragment):
    with pytest.raises(RegistrationError, match=fragment):
        RegistrationConfig(**changes)


def test_adaptive_threshold_is_three_rms_deviations():
    config = RegistrationConfig()
    threshold = AdaptiveThreshold(config)
    assert threshold.value == config.initial_threshold
    threshold.update(se2_to_pose(0.02, 0.0, 0.0), se2_to_pose(0.3, 0.0, 0.0))
    threshold.update(se2_to_pose(0.0, 0.0, 0.004), se2_to_pose(0.3, 0.0, 0.0))
    threshold.update(se2_to_pose(0.5, 0.0, 0.0), np.eye(4))  # standing still: ignored
    rotation = 2 * config.max_range * np.sin(0.002)  # at the edge of the range
    assert threshold.value == pytest.approx(3 * np.sqrt((0.02 ** 2 + rotation ** 2) / 2))
    for _ in range(10):
        threshold.update(se2_to_pose(1.0, 0.0, 0.0), se2_to_pose(0.3, 0.0, 0.0))
    assert threshold.value == config.max_threshold


def test_odometry_calibration_recovers_scale_turn_and_drift():
    calibration = OdometryCalibration()
    rng = np.random.default_rng(6)
    for _ in range(20):
        x, y, turn = rng.uniform(0.1, 0.4), rng.uniform(-0.05, 0.05), rng.uniform(-0.5, 0.5)
        odometry = se2_to_pose(x, y, turn)
        truth = se2_to_pose(0.95 * x, 0.95 * y, 1.1 * turn + 0.02 * np.hypot(x, y))
        calibration.update(odometry, truth)
    assert calibration.scale == pytest.approx(0.95)
    assert calibration.heading_model() == pytest.approx((0.1, 0.02))
    step = se2_to_pose(0.3, 0.0, 0.2)
    np.testing.assert_allclose(pose_to_se2(calibration.correct(step)),
                               (0.285, 0.0, 0.22 + 0.006), atol=1e-12)


def test_odometry_calibration_waits_for_evidence():
    calibration = OdometryCalibration()
    calibration.update(se2_to_pose(0.3, 0, 0), se2_to_pose(0.2, 0, 0.1))
    assert calibration.scale == 1.0 and calibration.heading_model() == (0.0, 0.0)


def test_lie_helpers_invert_each_other():
    rng = np.random.default_rng(7)
    for _ in range(20):
        delta = rng.normal(0, 1, 6)
        delta[3:] *= 3.0 / max(np.linalg.norm(delta[3:]), 1.0)  # angle below pi
        np.testing.assert_allclose(pose_log(pose_exp(delta)), delta, atol=1e-9)
    near_pi = so3_exp(np.array([0.0, np.pi - 1e-6, 0.0]))
    np.testing.assert_allclose(so3_exp(so3_log(near_pi)), near_pi, atol=1e-9)
    a = pose_exp(rng.normal(0, 1, 6))
    b = retract(a, np.array([0.1, -0.2, 0.05, 0.01, 0.02, -0.3]))
    np.testing.assert_allclose(between(a, b), [0.1, -0.2, 0.05, 0.01, 0.02, -0.3], atol=1e-9)


def test_local_map_forgets_far_voxels_and_keeps_lookups_right():
    local_map = LocalMap(voxel_size=0.1, radius=2.0)
    xs = np.arange(0.0, 6.0, 0.01)
    wall = np.column_stack([xs, np.full_like(xs, 0.55), np.tile([0.15, 0.25], 300)])
    local_map.insert(wall, 1)
    before = len(local_map)
    local_map.forget_far(np.array([5.0, 0.0, 0.0]))
    assert 0 < len(local_map) < before
    n = len(local_map)
    assert np.all(np.hypot(local_map.means[:n, 0] - 5.0, local_map.means[:n, 1]) <= 2.0)
    local_map.insert(wall, 2)  # the same points again: forgotten voxels return
    assert len(local_map) == before


def test_local_map_caps_the_weight_of_the_past():
    local_map = LocalMap(voxel_size=0.1, max_count=10)
    old = np.column_stack([np.linspace(0.01, 0.09, 40), np.full(40, 0.05), np.full(40, 0.05)])
    local_map.insert(old, 1)
    assert local_map.counts[0] == 10
    local_map.insert(old + [0, 0.02, 0], 2)  # the wall moved 2 cm
    # 10 old points' worth against 40 new: the mean moves 80 % of the way.
    assert local_map.means[0, 1] == pytest.approx(0.05 + 0.8 * 0.02)


def test_local_map_refuses_points_beyond_its_reach():
    local_map = LocalMap(voxel_size=0.1)
    with pytest.raises(MapError, match="local origin"):
        local_map.insert(np.array([[2e5, 0.0, 0.0]]), 1)


def test_noise_scale_is_the_chi_square_per_degree_of_freedom_above_one():
    from scanmap.registration.icp import _noise_scale

    rng = np.random.default_rng(0)
    residuals = rng.normal(0.0, 0.02, 5000)  # twice the modelled 1 cm sigma
    stats = np.array([residuals.size, 0.0, np.sum(residuals ** 2 / 0.01 ** 2), 0.0])
    assert _noise_scale(stats, 3) == pytest.approx(4.0, rel=0.05)
    quiet = stats * [1, 0, 1 / 16, 0]  # half the modelled sigma
    assert _noise_scale(quiet, 3) == 1.0  # quieter than modelled: never more weight
    assert _noise_scale(np.array([3.0, 0.0, 1e6, 0.0]), 3) == 1.0  # no degree of freedom left


def test_transport_moves_a_perturbation_to_the_pose_a_step_ahead():
    """exp(d) step = step exp(J d): the sampled J d have the covariance transport gives."""
    rng = np.random.default_rng(1)
    step = pose_exp(np.array([0.8, -0.3, 0.05, 0.02, -0.01, 0.5]))
    covariance = np.diag(rng.uniform(1e-8, 1e-6, 6))
    samples = rng.multivariate_normal(np.zeros(6), covariance, 4000)
    moved = np.array([between(step, pose_exp(d) @ step) for d in samples])
    np.testing.assert_allclose(np.cov(moved.T), transport(covariance, step), atol=2e-8,
                               rtol=0.1)


def test_a_pose_the_map_did_not_fix_carries_its_uncertainty_to_the_next_prior():
    noise = OdometryNoiseConfig()
    registration = ScanOdometry(noise=noise)
    wall = np.column_stack([np.full(400, 2.0), np.linspace(-2, 2, 400), np.linspace(0.1, 1, 400)])
    registration.register_points(wall, stamp=0.0, odometry=np.eye(4))
    steps = [se2_to_pose(0.3, 0.0, 0.1), se2_to_pose(0.3, 0.05, -0.2)]
    odometry = np.eye(4)
    results = []
    for k, step in enumerate(steps, start=1):
        odometry = odometry @ step
        results.append(registration.register_points(wall[:3], stamp=float(k),
                                                    odometry=odometry))
    assert [r.status for r in results] == [RegistrationStatus.TOO_FEW_POINTS] * 2
    first, second = (r.covariance for r in results)
    np.testing.assert_allclose(first, noise.odometry_covariance(steps[0]))
    np.testing.assert_allclose(second, noise.odometry_covariance(steps[1])
                               + transport(first, steps[1]), atol=1e-15)
