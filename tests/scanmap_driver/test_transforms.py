"""Rigid transforms: quaternions and SE(2) against closed forms."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.transforms import (
    invert_pose,
    make_pose,
    pose_to_se2,
    quaternion_to_rotation,
    rot_x,
    rot_y,
    rot_z,
    rotation_to_quaternion,
    se2_to_pose,
    wrap_angle,
)

angles = st.floats(-7.0, 7.0)


@given(angles, angles, angles)
def test_quaternion_round_trip(a, b, c):
    rotation = rot_z(a) @ rot_y(b) @ rot_x(c)
    q = rotation_to_quaternion(rotation)
    assert abs(np.linalg.norm(q) - 1) < 1e-12 and q[3] >= 0
    np.testing.assert_allclose(quaternion_to_rotation(q), rotation, atol=1e-12)


@given(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4), angles)
def test_se2_round_trip_and_inverse(x, y, yaw):
    pose = se2_to_pose(x, y, yaw)
    x2, y2, yaw2 = pose_to_se2(pose)
    assert np.allclose([x2, y2], [x, y]) and abs(wrap_angle(yaw2 - yaw)) < 1e-12
    np.testing.assert_allclose(pose @ invert_pose(pose), np.eye(4), atol=1e-9)


def test_rotation_directions():
    np.testing.assert_allclose(rot_z(np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rot_y(np.pi / 2) @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(rot_x(np.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    assert make_pose(np.eye(3), [1, 2, 3])[2, 3] == 3
