"""Compile the mapping kernels before the robot moves.

Numba compiles each kernel on its first call (or loads it from its cache), which can take
seconds: long enough for a first live scan's obstacle field to be stale when it is
published. `warm_up` runs the whole per-scan pipeline once on two synthetic scans of a
square room (registration, fusion with clearing, floor segmentation, distance fields,
every obstacle query) in a throwaway mapper, and merges its grid into an empty one (the
submap merge of a rebuild after loop closure).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from scanmap.grid.height_grid import HeightGrid
from scanmap_driver.scan import Scan

FRAMES = 50


def room_scan(shift: float, index: int, half_side: float = 2.0) -> Scan:
    """A 360 deg scan of a square room's walls (0.1-1 m high) and floor, from (shift, 0)."""
    angle = np.linspace(-np.pi, np.pi, 1800, endpoint=False)
    c, s = np.cos(angle), np.sin(angle)
    wall = half_side / np.maximum(np.abs(c), np.abs(s))  # range to the square's wall
    rings = [np.column_stack([wall * c - shift, wall * s, np.full(angle.size, z)])
             for z in np.linspace(0.1, 1.0, 6)]
    rings.append(np.column_stack([0.6 * wall * c, 0.6 * wall * s, np.zeros(angle.size)]))
    points = np.vstack(rings)
    heading = np.arctan2(points[:, 1], points[:, 0])
    frame = np.minimum(((heading + np.pi) / (2 * np.pi) * FRAMES).astype(np.int32), FRAMES - 1)
    n = len(points)
    return Scan(points=points, colors=np.zeros((n, 3), np.uint8), time=frame * 0.04 + index,
                heading=heading, frame_index=frame, range_sigma=np.full(n, 0.005),
                index=index, stamp=float(index))


def warm_up(mapper: Any) -> None:
    """Run the per-scan pipeline twice in `mapper`, a throwaway offline `Mapper` (see the
    module docstring)."""
    for index, shift in enumerate((0.0, 0.05)):
        mapper.add(room_scan(shift, index))
    mapper.obstacles.update(mapper.grid)
    mapper.obstacles.nearest(0.0, 0.0)
    mapper.obstacles.distance(np.zeros((2, 2)))
    mapper.obstacles.travel((0.0, 0.0, 0.0))  # a controller's other queries
    mapper.obstacles.polar(0.0, 0.0, 0.0)
    mapper.obstacles.clearance((0.0, 0.0, 0.0), np.array([[0.2, 0.1], [-0.2, 0.1], [0.0, -0.1]]))
    if mapper.grid.config.window is None:
        HeightGrid(mapper.grid.config).merge(mapper.grid)
