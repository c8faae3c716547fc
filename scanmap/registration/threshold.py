"""Adaptive correspondence threshold (after KISS-ICP, Vizzo et al., RA-L 2023).

How far may a point be from its match? As far as the guess is usually wrong. Every
registered scan measures that: the correction from the guess to the result, expressed as
the largest displacement it causes within sensor range (|dt| + 2 r_max sin(|dtheta|/2)).
The threshold is three times the RMS of those deviations, bounded; scans taken while
standing still do not count (they would shrink it to nothing).
"""

from __future__ import annotations

import numpy as np

from scanmap.registration.config import RegistrationConfig
from scanmap.registration.lie import pose_log

_MIN_MOTION = 0.02  # m (or rad times 1 m): below this the robot stood still


class AdaptiveThreshold:
    """Running estimate of the guess error, turned into a correspondence distance."""

    def __init__(self, config: RegistrationConfig) -> None:
        self.config = config
        self.sum_sq = 0.0
        self.count = 0

    @property
    def value(self) -> float:
        """Current correspondence threshold (m)."""
        c = self.config
        if self.count == 0:
            return c.initial_threshold
        return float(np.clip(3.0 * np.sqrt(self.sum_sq / self.count), c.min_threshold,
                             c.max_threshold))

    def update(self, correction: np.ndarray, motion: np.ndarray) -> None:
        """Record a registration's correction (guess to result) for a scan that moved `motion`."""
        step = pose_log(motion)
        if np.linalg.norm(step[:3]) + np.linalg.norm(step[3:]) < _MIN_MOTION:
            return
        fix = pose_log(correction)
        angle = float(np.linalg.norm(fix[3:]))
        deviation = float(np.linalg.norm(fix[:3])) + 2.0 * self.config.max_range \
            * np.sin(min(angle, np.pi) / 2.0)
        self.sum_sq += deviation ** 2
        self.count += 1
