"""Exact distances to a simulator scene's objects, seen from above: independent truth."""

from __future__ import annotations

import numpy as np

from scanmap_driver.sim.scene import Box


def footprint_distance(scene, xy: np.ndarray, low: float = 0.05, high: float = 1.0
                       ) -> np.ndarray:
    """Exact distance from world points (N, 2) to the footprints of the scene's objects
    that occupy the height band (low, high)."""
    best = np.full(len(xy), np.inf)
    for obj in scene.objects:
        height = obj.size[2] if isinstance(obj, Box) else obj.height
        if not (obj.center[2] + height / 2 > low and obj.center[2] - height / 2 < high):
            continue
        offset = xy - np.array(obj.center[:2])
        if isinstance(obj, Box):
            c, s = np.cos(obj.yaw), np.sin(obj.yaw)
            local = np.abs(offset @ np.array([[c, -s], [s, c]]))
            gap = np.maximum(local - np.array(obj.size[:2]) / 2, 0.0)
            best = np.minimum(best, np.hypot(gap[:, 0], gap[:, 1]))
        else:
            best = np.minimum(best, np.maximum(np.hypot(*offset.T) - obj.radius, 0.0))
    return best
