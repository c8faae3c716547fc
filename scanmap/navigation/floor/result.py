"""What the segmentation gives: the floor planes and the floor and obstacle layers of a
window."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanmap.navigation.floor.config import RobotShape


@dataclass(frozen=True)
class FloorPlane:
    """A floor plane normal . p = offset (unit normal, z up) and the floor cells it explains."""

    normal: tuple[float, float, float]
    offset: float
    cells: int

    def height_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Plane height at (x, y)."""
        a, b, c = self.normal
        return (self.offset - a * np.asarray(x) - b * np.asarray(y)) / c


@dataclass(frozen=True, eq=False)
class Segmentation:
    """Floor and obstacle layers of a window of the grid (row = y, column = x).

    floor_height: (ny, nx) float32, NaN where unknown. is_floor: open floor: known floor
    (seen there, stood on, or a small gap in it, not within max_gap of floor a laser
    line crossed without a return: `scanmap.grid.unlit`), nothing is in the robot's band, and
    nothing may hang above unseen (not the floor under a table); and the edge of a step
    between two floors (an OBSTACLE). Traversable = is_floor and FREE (the band was
    seen). slope: (ny, nx) float32 floor slope (rad) of the cells
    with observed floor, NaN elsewhere.
    state: UNKNOWN / FREE / OBSTACLE / DROP_OFF per cell. points: (ny, nx, 2) float32, the obstacle
    point of each obstacle cell (mean of its hits in the band), the centre elsewhere.
    band_logodds: (ny, nx) float32, highest log-odds of the band's levels of at least
    `FloorConfig.min_logodds` (NaN where none).
    updated: (ny, nx) float64 last update time.
    """

    origin: tuple[float, float]
    resolution: float
    robot: RobotShape
    floor_height: np.ndarray
    is_floor: np.ndarray
    planes: tuple[FloorPlane, ...]
    state: np.ndarray
    points: np.ndarray
    band_logodds: np.ndarray
    updated: np.ndarray
    slope: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx)."""
        return tuple(self.state.shape)
