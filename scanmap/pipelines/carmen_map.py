"""Occupancy maps of CARMEN laser logs: 2-D scans fused into the 2.5D grid.

A 2-D scan is a 3-D scan whose points share one height: every beam is a horizontal ray
from the laser (at `height`, at the log's corrected pose) to its reading. The floor is
never seen, so the segmentation assumes it at z = 0 and takes a cell as free as soon as
a beam crossed it (the one height the laser sees).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from scanmap.datasets.carmen import CarmenLog
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation.floor import FloorConfig, RobotShape, Segmentation, segment
from scanmap_driver.transforms import se2_to_pose, transform_points

LASER_2D = FloorConfig(detect=False, min_coverage=0.0)


def fuse_carmen(log: CarmenLog, config: GridConfig | None = None, height: float = 0.3,
                ) -> HeightGrid:
    """A grid holding every scan of `log` at its corrected pose.

    Every hit lies at `height` and every ray runs level at it, so no cell ever holds more
    than one level: the grid keeps one (`levels` 1, whatever `config` says), under half
    the memory of the default three. Its tiles are allocated at once before fusing, as a
    rebuild does, so that a building's or a campus's map takes its own size in memory, not
    up to three times it while its pools grow by doubling.
    """
    config = config or GridConfig()
    config = replace(config, max_range=max(config.max_range, log.max_range), levels=1)
    grid = HeightGrid(config)
    rays = [(transform_points(se2_to_pose(*pose), log.scan_points(index, height=height)),
             np.array([*pose[:2], height])) for index, pose in enumerate(log.poses)]
    grid.reserve((points, np.broadcast_to(origin, points.shape)) for points, origin in rays)
    for (points, origin), stamp in zip(rays, log.times, strict=True):
        grid.insert(points, origin, float(stamp))
    return grid


def carmen_segmentation(grid: HeightGrid, robot: RobotShape | None = None) -> Segmentation:
    """Obstacles and free space of a grid fused from 2-D scans (floor assumed at z = 0)."""
    return segment(grid.layers(), robot, LASER_2D, fallback_floor=0.0)


def occupied_cells_per_reading(log: CarmenLog, resolution: float = 0.1) -> float:
    """Cells of a `resolution` grid hit by the log's readings, per reading (0..1].

    The sharpness of the map: readings of one wall at the right poses fall into the few
    cells along it, so a sharp map has few occupied cells per reading; a wrong beam
    layout turns each reading by a different angle and smears the walls over many cells.
    """
    ends = [transform_points(se2_to_pose(*log.poses[i]), log.scan_points(i))[:, :2]
            for i in range(len(log))]
    cells = np.floor(np.vstack(ends) / resolution).astype(np.int64)
    return len(np.unique(cells, axis=0)) / max(len(cells), 1)
