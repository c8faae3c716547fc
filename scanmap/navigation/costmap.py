"""Costmaps for planners, in Nav2's conventions, and OccupancyGrid-style int8 arrays.

Costs (nav2_costmap_2d): 254 LETHAL on obstacle and drop-off cells, 253 INSCRIBED within the robot's
inscribed radius, then (253 - 1) * exp(-cost_scaling_factor * (d - inscribed)) out to
the inflation radius (d: distance between cell centres in metres), 0 FREE, and 255
NO_INFORMATION on unknown cells (kept unless inflated to INSCRIBED or more, Nav2's
default `inflate_unknown: false`). `costmap_to_occupancy` is Nav2's costmap publisher
table (0 -> 0, 1..252 -> 1..98, 253 -> 99, 254 -> 100, 255 -> -1).
"""

from __future__ import annotations

import math

import numpy as np

from scanmap.navigation.distance_field import distance_transform
from scanmap.navigation.floor import DROP_OFF, FREE, OBSTACLE, UNKNOWN, Segmentation
from scanmap_driver.errors import MapError

FREE_SPACE, INSCRIBED, LETHAL, NO_INFORMATION = 0, 253, 254, 255


def inflate(seg: Segmentation, inscribed_radius: float | None = None,
            inflation_radius: float = 0.55, cost_scaling_factor: float = 3.0) -> np.ndarray:
    """(ny, nx) uint8 Nav2 costs of the segmentation's cells (inscribed radius defaults to
    the robot's footprint radius)."""
    inscribed = seg.robot.radius if inscribed_radius is None else float(inscribed_radius)
    for name, value in (("inscribed_radius", inscribed), ("inflation_radius", inflation_radius),
                        ("cost_scaling_factor", cost_scaling_factor)):
        if not (math.isfinite(value) and value >= 0):
            raise MapError(f"inflate: {name} must be a finite number >= 0, got {value}")
    distance, _ = distance_transform((seg.state == OBSTACLE) | (seg.state == DROP_OFF))
    d = distance.astype(np.float64) * seg.resolution
    decay = (INSCRIBED - 1) * np.exp(-cost_scaling_factor * (d - inscribed))
    inflated = np.where(d <= inscribed, INSCRIBED, decay.astype(np.int64))
    inflated = np.where(d <= inflation_radius, inflated, FREE_SPACE)
    inflated[d == 0] = LETHAL
    costs = np.where(seg.state == UNKNOWN, NO_INFORMATION, FREE_SPACE)
    unknown = seg.state == UNKNOWN
    costs = np.where(unknown & (inflated >= INSCRIBED), inflated, costs)
    costs = np.where(~unknown, np.maximum(costs, inflated), costs)
    return costs.astype(np.uint8)


def costmap_to_occupancy(costs: np.ndarray) -> np.ndarray:
    """Nav2's translation of costs (integers 0..255) to OccupancyGrid values (int8). Other
    values raise MapError: a cast would wrap them (256 to FREE_SPACE, NaN to anything)."""
    costs = np.asarray(costs)
    if not np.issubdtype(costs.dtype, np.integer) or (
            costs.size and (costs.min() < 0 or costs.max() > NO_INFORMATION)):
        raise MapError(f"costmap_to_occupancy: costs must be integers 0..255, got "
                       f"{costs.dtype} values")
    table = np.empty(256, np.int8)
    table[0] = 0
    table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
    table[253], table[254], table[255] = 99, 100, -1
    return table[costs]


def occupancy_grid(seg: Segmentation) -> np.ndarray:
    """(ny, nx) int8 occupancy in percent: -1 unknown, 0 free, and for obstacle cells the
    probability of their most certain level in the robot band (sigmoid of log-odds; 100
    when the log-odds are NaN: an obstacle cell is never written less than occupied
    for want of a number); 100 for drop-off cells (nothing to stand on)."""
    out = np.full(seg.shape, -1, np.int8)
    out[seg.state == FREE] = 0
    out[seg.state == DROP_OFF] = 100
    obstacle = seg.state == OBSTACLE
    p = 1.0 / (1.0 + np.exp(-seg.band_logodds[obstacle].astype(np.float64)))
    out[obstacle] = np.clip(np.rint(100.0 * np.nan_to_num(p, nan=1.0)), 0, 100).astype(np.int8)
    return out
