"""What the robot needs from the grid: floor segmentation and obstacle layer (`floor`), the
exact distance field (`distance_field`), the queries a controller polls (`obstacles`) and
Nav2-style costmaps (`costmap`). Kernels (Numba, `nogil`) are in `_kernels` (queries,
distance field) and, for the segmentation, `floor/_*_kernels.py`.
See docs/architecture.md."""

from scanmap.navigation.costmap import (
    INSCRIBED,
    LETHAL,
    costmap_to_occupancy,
    inflate,
    occupancy_grid,
)
from scanmap.navigation.distance_field import distance_transform
from scanmap.navigation.floor import (
    DROP_OFF,
    FREE,
    OBSTACLE,
    UNKNOWN,
    FloorConfig,
    FloorPlane,
    RobotShape,
    Segmentation,
    segment,
)
from scanmap.navigation.obstacles import (
    Clearance,
    Nearest,
    ObstacleMap,
    ObstacleSnapshot,
    PolarScan,
    QueryStatus,
    Travel,
)

__all__ = [
    "DROP_OFF",
    "FREE",
    "INSCRIBED",
    "LETHAL",
    "OBSTACLE",
    "UNKNOWN",
    "Clearance",
    "FloorConfig",
    "FloorPlane",
    "Nearest",
    "ObstacleMap",
    "ObstacleSnapshot",
    "PolarScan",
    "QueryStatus",
    "RobotShape",
    "Segmentation",
    "Travel",
    "costmap_to_occupancy",
    "distance_transform",
    "inflate",
    "occupancy_grid",
    "segment",
]
