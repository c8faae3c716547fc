"""The motion prior: where odometry (or a constant-velocity guess) says the scan was taken.

The prior is both registration's initial guess and a weighted term in its cost, so a
direction the geometry cannot fix (a featureless corridor's axis) follows odometry.
Its covariance grows with the motion, as in the odometry motion model of Thrun,
Burgard and Fox (Probabilistic Robotics, ch. 5): translation noise with the distance
driven and the angle turned, rotation noise likewise, plus a floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanmap.registration.lie import pose_log
from scanmap_driver.errors import RegistrationError


@dataclass(frozen=True, eq=False)
class Prior:
    """pose: 4x4 (map-local) guess. covariance: 6x6 over body-frame (x, y, z, rx, ry, rz)."""

    pose: np.ndarray
    covariance: np.ndarray

    def __post_init__(self) -> None:
        pose = np.asarray(self.pose, dtype=np.float64)
        cov = np.asarray(self.covariance, dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise RegistrationError(f"Prior.pose: expected a finite 4x4 pose, got {pose.shape}")
        if cov.shape != (6, 6) or not np.isfinite(cov).all():
            raise RegistrationError(f"Prior.covariance: expected a finite 6x6 matrix, "
                                    f"got {cov.shape}")
        if np.any(np.linalg.eigvalsh(0.5 * (cov + cov.T)) <= 0):
            raise RegistrationError("Prior.covariance: must be positive definite")
        object.__setattr__(self, "pose", pose)
        object.__setattr__(self, "covariance", 0.5 * (cov + cov.T))

    def information(self, axes: np.ndarray) -> np.ndarray:
        """Inverse covariance over the estimated axes."""
        return np.linalg.inv(self.covariance[np.ix_(axes, axes)])


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Standard deviations of wheel odometry and of the fallbacks without it.

    trans_per_metre, trans_per_radian: translation sigma (m) per metre driven and per
    radian turned; rot_per_metre, rot_per_radian: rotation sigma (rad) likewise;
    trans_floor, rot_floor: minimum sigmas. vertical, tilt: sigma of z (m) and of roll
    and pitch (rad) between scans (SE(3) mode; wheels do not measure them).
    guess_trans, guess_rot: sigmas of a constant-velocity guess (no odometry).
    """

    trans_per_metre: float = 0.05
    trans_per_radian: float = 0.02
    rot_per_metre: float = 0.02
    rot_per_radian: float = 0.05
    trans_floor: float = 0.005
    rot_floor: float = 0.005
    vertical: float = 0.02
    tilt: float = 0.02
    guess_trans: float = 0.1
    guess_rot: float = 0.1

    def odometry_covariance(self, motion: np.ndarray) -> np.ndarray:
        """6x6 covariance of an odometry increment `motion` (4x4)."""
        twist = pose_log(motion)
        distance = float(np.linalg.norm(twist[:2]))
        turn = abs(float(twist[5]))
        trans = self.trans_floor + self.trans_per_metre * distance + self.trans_per_radian * turn
        rot = self.rot_floor + self.rot_per_metre * distance + self.rot_per_radian * turn
        return self._covariance(trans, rot)

    def guess_covariance(self) -> np.ndarray:
        """6x6 covariance of a constant-velocity guess."""
        return self._covariance(self.guess_trans, self.guess_rot)

    def _covariance(self, trans: float, rot: float) -> np.ndarray:
        return np.diag(np.square([trans, trans, self.vertical, self.tilt, self.tilt, rot]))
