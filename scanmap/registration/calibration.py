"""Online calibration of wheel odometry's systematic errors, from registered motion.

Wheel odometry is biased: a wheel radius off by 1 % makes every metre 1 % long, unequal
wheels turn the robot a little per metre, a wrong wheel base scales every turn. Where
the geometry constrains every direction, registration measures the true motion;
comparing it with odometry's gives the distance scale (least squares, registered .
odometry / |odometry|^2) and the heading error as a turn scale plus a drift per metre
(least squares in those two unknowns). Where the geometry cannot (a featureless
corridor), the corrected odometry is what the prior carries, so the bias does not pile
up along the corridor.
"""

from __future__ import annotations

import numpy as np

from scanmap_driver.transforms import pose_to_se2, se2_to_pose, wrap_angle

_MIN_TRAVEL = 2.0  # m of constrained travel before corrections apply
_MAX_SCALE_ERROR = 0.1
_MAX_DRIFT = 0.05  # rad per m
_MAX_TURN_ERROR = 0.2


class OdometryCalibration:
    """Running least-squares estimates of odometry's distance scale and heading errors."""

    def __init__(self) -> None:
        self.scale_num = 0.0
        self.scale_den = 0.0
        self.heading_normal = np.zeros((2, 2))  # unknowns: turn scale error, drift per metre
        self.heading_rhs = np.zeros(2)
        self.travel = 0.0

    @property
    def scale(self) -> float:
        """Registered distance per odometry distance (1 until enough travel)."""
        if self.travel < _MIN_TRAVEL or self.scale_den <= 0:
            return 1.0
        return float(np.clip(self.scale_num / self.scale_den, 1 - _MAX_SCALE_ERROR,
                             1 + _MAX_SCALE_ERROR))

    def heading_model(self) -> tuple[float, float]:
        """(turn scale error, drift rad/m): heading error = a * odometry turn + b * distance."""
        if self.travel < _MIN_TRAVEL or np.linalg.det(self.heading_normal) <= 1e-12:
            return 0.0, 0.0
        a, b = np.linalg.solve(self.heading_normal, self.heading_rhs)
        return float(np.clip(a, -_MAX_TURN_ERROR, _MAX_TURN_ERROR)), \
            float(np.clip(b, -_MAX_DRIFT, _MAX_DRIFT))

    def update(self, odometry_step: np.ndarray, registered_step: np.ndarray) -> None:
        """Add one fully constrained scan-to-scan motion (4x4 each, planar parts used)."""
        ox, oy, oyaw = pose_to_se2(odometry_step)
        rx, ry, ryaw = pose_to_se2(registered_step)
        distance = float(np.hypot(ox, oy))
        self.scale_num += rx * ox + ry * oy
        self.scale_den += ox * ox + oy * oy
        row = np.array([oyaw, distance])
        self.heading_normal += np.outer(row, row)
        self.heading_rhs += row * float(wrap_angle(ryaw - oyaw))
        self.travel += distance

    def correct(self, odometry_step: np.ndarray) -> np.ndarray:
        """The planar odometry step with the estimated scale and drift removed."""
        x, y, yaw = pose_to_se2(odometry_step)
        scale = self.scale
        turn_error, drift = self.heading_model()
        return se2_to_pose(scale * x, scale * y,
                           yaw * (1.0 + turn_error) + drift * float(np.hypot(x, y)))
