"""Registration: each scan's pose from ICP against a local map, honest about what it knows.

Entry points: `ScanOdometry` registers a sequence of scans (odometry prior, de-skew,
local map, recovery); `register_scan` registers one prepared scan (`prepare_source`)
against a `LocalMap` with a `Prior`. Results are `RegistrationResult`s with a pose,
covariance, fitness, inlier RMSE, degenerate directions and a `RegistrationStatus`.

The floor: it constrains only z, roll and pitch. Planar mode (the default: the floor is
flat, the pose is x, y, yaw) drops points within `floor_band` of the floor before anything
else (those below it stay: the walls of a hole or a step down fix x and y as a wall
does, where a corridor's own walls leave its axis to odometry), and matches only walls
(neighbourhoods that are a line seen from above and that rise), so neither the floor
nor a table top can pull x, y or yaw. SE(3) mode keeps the floor: it
is what fixes z, roll and pitch there.
"""

from scanmap.registration.config import RegistrationConfig
from scanmap.registration.degeneracy import Degeneracy, analyse_degeneracy
from scanmap.registration.deskew import deskew_points
from scanmap.registration.local_map import LocalMap
from scanmap.registration.matcher import register_scan
from scanmap.registration.odometry import ScanOdometry
from scanmap.registration.preprocess import Source, prepare_source
from scanmap.registration.prior import OdometryNoiseConfig, Prior
from scanmap.registration.result import RegistrationResult, RegistrationStatus

__all__ = [
    "Degeneracy",
    "LocalMap",
    "OdometryNoiseConfig",
    "Prior",
    "RegistrationConfig",
    "RegistrationResult",
    "RegistrationStatus",
    "ScanOdometry",
    "Source",
    "analyse_degeneracy",
    "deskew_points",
    "prepare_source",
    "register_scan",
]
