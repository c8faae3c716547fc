"""Wheel odometry with realistic errors, integrated along the robot's true path.

A differential-drive robot's odometry drifts: each metre driven adds a random distance
error and a random heading error (growing with the square root of the distance), the
wheel calibration adds systematic distance and heading biases, and each turn is off by a
few percent. The result is a pose in the `odom` frame, which starts at the robot's first
true pose.
"""

from __future__ import annotations

import math

import numpy as np

from ..transforms import wrap_angle
from .scene import SimOdometryNoise

PATH_STEP = 0.02  # m (and rad): spacing of the dense true path the odometry integrates


def dense_arc(pose: np.ndarray, speed: float, yaw_rate: float, duration: float) -> np.ndarray:
    """(M, 3) poses of a constant body twist from `pose` over `duration`, first row = pose."""
    travel = max(abs(speed), abs(yaw_rate)) * duration
    t = np.linspace(0.0, duration, max(2, math.ceil(travel / PATH_STEP) + 1))
    return arc_poses(pose, speed, yaw_rate, t)


def arc_poses(pose: np.ndarray, speed: float, yaw_rate: float, t: np.ndarray) -> np.ndarray:
    """(N, 3) poses after driving the body twist (speed, yaw_rate) for times t from `pose`."""
    x, y, yaw = pose
    t = np.asarray(t, dtype=np.float64)
    heading = yaw + yaw_rate * t
    if abs(yaw_rate) < 1e-12:
        dx, dy = speed * t * math.cos(yaw), speed * t * math.sin(yaw)
    else:
        radius = speed / yaw_rate
        dx = radius * (np.sin(heading) - math.sin(yaw))
        dy = radius * (math.cos(yaw) - np.cos(heading))
    return np.column_stack([x + dx, y + dy, heading])


def dense_drive(start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """(M, 3) poses of turning toward `goal`, driving straight to it, and turning to its yaw."""
    start = np.asarray(start, dtype=np.float64)
    goal = np.asarray(goal, dtype=np.float64)
    delta = goal[:2] - start[:2]
    distance = float(np.hypot(*delta))
    legs = [start[None, :]]
    yaw = start[2]
    if distance > 1e-9:
        bearing = math.atan2(delta[1], delta[0])
        legs.append(_turn(start[:2], yaw, bearing))
        yaw = yaw + float(wrap_angle(bearing - yaw))
        n = max(2, math.ceil(distance / PATH_STEP) + 1)
        s = np.linspace(0.0, 1.0, n)[1:, None]
        legs.append(np.column_stack([start[:2] + s * delta, np.full(n - 1, yaw)]))
    legs.append(_turn(goal[:2], yaw, goal[2]))
    return np.vstack(legs)


def _turn(xy: np.ndarray, yaw: float, goal_yaw: float) -> np.ndarray:
    """Poses turning on the spot from yaw to goal_yaw (the short way), without the start."""
    delta = float(wrap_angle(goal_yaw - yaw))
    n = max(2, math.ceil(abs(delta) / PATH_STEP) + 1)
    yaws = yaw + np.linspace(0.0, delta, n)[1:]
    return np.column_stack([np.broadcast_to(xy, (n - 1, 2)), yaws])


def odometry_path(path: np.ndarray, noise: SimOdometryNoise,
                  rng: np.random.Generator) -> np.ndarray:
    """Noisy odometry (M, 3) in `odom` along a dense true path (M, 3) in `map`.

    The first odometry pose is (0, 0, 0): `odom` is where the robot started.
    """
    path = np.asarray(path, dtype=np.float64)
    step = np.diff(path, axis=0)
    cos, sin = np.cos(path[:-1, 2]), np.sin(path[:-1, 2])
    local_x = cos * step[:, 0] + sin * step[:, 1]
    local_y = -sin * step[:, 0] + cos * step[:, 1]
    length = np.hypot(local_x, local_y)
    direction = np.arctan2(local_y, local_x)
    turn = wrap_angle(step[:, 2])
    n = length.shape[0]
    noisy_length = (length * (1.0 + noise.distance_bias)
                    + noise.distance_sigma * np.sqrt(length) * rng.standard_normal(n))
    noisy_turn = (turn * (1.0 + noise.turn_sigma * rng.standard_normal(n))
                  + noise.heading_bias * length
                  + noise.heading_sigma * np.sqrt(length) * rng.standard_normal(n))
    yaw = np.concatenate([[0.0], np.cumsum(noisy_turn)])
    mid = yaw[:-1] + direction
    x = np.concatenate([[0.0], np.cumsum(noisy_length * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(noisy_length * np.sin(mid))])
    return np.column_stack([x, y, yaw])
