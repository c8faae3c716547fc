"""Wheel odometry: exact without noise, drifting with distance with it; the robot's paths."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap_driver.sim.odometry import arc_poses, dense_arc, dense_drive, odometry_path
from scanmap_driver.sim.scene import SimOdometryNoise
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose

QUIET = SimOdometryNoise(0.0, 0.0, 0.0, 0.0, 0.0)


def _relative(path, start):
    base = invert_pose(se2_to_pose(*start))
    return np.array([pose_to_se2(base @ se2_to_pose(*p)) for p in path])


@settings(max_examples=30, deadline=None)
@given(x=st.floats(-5, 5), y=st.floats(-5, 5), yaw=st.floats(-3, 3),
       gx=st.floats(-5, 5), gy=st.floats(-5, 5), gyaw=st.floats(-3, 3))
def test_noiseless_odometry_is_the_true_path_seen_from_the_start(x, y, yaw, gx, gy, gyaw):
    path = dense_drive(np.array([x, y, yaw]), np.array([gx, gy, gyaw]))
    odom = odometry_path(path, QUIET, np.random.default_rng(0))
    want = _relative(path, path[0])
    np.testing.assert_allclose(odom[:, :2], want[:, :2], atol=1e-9)
    np.testing.assert_allclose(np.cos(odom[:, 2] - want[:, 2]), 1.0, atol=1e-12)
    np.testing.assert_allclose(path[-1, :2], [gx, gy], atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(speed=st.floats(-0.5, 0.5), rate=st.floats(-1, 1), t=st.floats(0.1, 3))
def test_arc_is_the_integrated_twist(speed, rate, t):
    start = np.array([1.0, -2.0, 0.4])
    end = arc_poses(start, speed, rate, np.array([t]))[0]
    # integrate the unicycle numerically
    n = 20000
    dt = t / n
    x, y, yaw = start
    for _ in range(n):
        x += speed * math.cos(yaw + 0.5 * rate * dt) * dt
        y += speed * math.sin(yaw + 0.5 * rate * dt) * dt
        yaw += rate * dt
    np.testing.assert_allclose(end, [x, y, yaw], atol=1e-7)
    dense = dense_arc(start, speed, rate, t)
    np.testing.assert_allclose(dense[-1], end, atol=1e-12)


def test_drift_grows_with_distance():
    path = dense_drive(np.zeros(3), np.array([20.0, 0.0, 0.0]))
    noise = SimOdometryNoise(distance_sigma=0.01, heading_sigma=0.01, turn_sigma=0.0,
                          distance_bias=0.0, heading_bias=0.0)
    errors_at = {5.0: [], 20.0: []}
    for seed in range(200):
        odom = odometry_path(path, noise, np.random.default_rng(seed))
        for distance, errs in errors_at.items():
            i = np.searchsorted(path[:, 0], distance)
            errs.append(odom[i, 2])
    # heading error is a random walk: sigma * sqrt(distance)
    assert np.std(errors_at[5.0]) == pytest.approx(0.01 * math.sqrt(5), rel=0.2)
    assert np.std(errors_at[20.0]) == pytest.approx(0.01 * math.sqrt(20), rel=0.2)


def test_biases_are_systematic():
    path = dense_drive(np.zeros(3), np.array([10.0, 0.0, 0.0]))
    noise = SimOdometryNoise(0.0, 0.0, 0.0, distance_bias=0.02, heading_bias=0.0)
    odom = odometry_path(path, noise, np.random.default_rng(0))
    assert odom[-1, 0] == pytest.approx(10.2, abs=1e-9)
