"""What registration returns: a pose with its uncertainty and an honest status."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from scanmap_driver.errors import RegistrationError


class RegistrationStatus(enum.Enum):
    """How a registration ended. Only OK and INITIALISED carry a measured pose."""

    OK = "ok"
    INITIALISED = "initialised"  # first scan: it starts the map, at the given pose
    TOO_FEW_POINTS = "too_few_points"
    NO_OVERLAP = "no_overlap"
    DIVERGED = "diverged"
    INCONSISTENT = "inconsistent"  # disagrees with the prior, and the map does not side


@dataclass(frozen=True, eq=False)
class RegistrationResult:
    """Pose of the scan (base_link at the scan's start, in map) and how far to trust it.

    pose: 4x4 float64. On failure it is the prior's pose, not a measurement.
    covariance: 6x6 over body-frame (x, y, z, rx, ry, rz) increments; in planar mode the
      unestimated z, roll, pitch rows and columns are zero; on failure: the prior's.
    fitness: fraction of source points with an inlier correspondence.
    inlier_rmse: RMS point-to-plane distance (m) of the inliers.
    degenerate_directions: (m, 6) unit rows (same parameter order; rotations in rad)
      that the geometry did not constrain and the prior decided.
    iterations: Gauss-Newton iterations run. recovered: a coarse search found the start.
    num_points: source points (after filtering and downsampling).
    """

    pose: np.ndarray
    covariance: np.ndarray
    status: RegistrationStatus
    fitness: float = float("nan")
    inlier_rmse: float = float("nan")
    degenerate_directions: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    iterations: int = 0
    recovered: bool = False
    num_points: int = 0
    message: str = ""

    @property
    def ok(self) -> bool:
        """True when the pose was measured (or the scan started the map)."""
        return self.status in (RegistrationStatus.OK, RegistrationStatus.INITIALISED)

    @property
    def degenerate(self) -> bool:
        """True when some direction came from the prior alone."""
        return len(self.degenerate_directions) > 0

    def raise_for_status(self) -> RegistrationResult:
        """Return self if ok, else raise RegistrationError with the reason."""
        if not self.ok:
            raise RegistrationError(f"registration failed ({self.status.value}): {self.message}")
        return self
