"""Analytic distance from points to a scene's surfaces: the independent truth for the tests.

Exact boxes and exact (round) cylinders and the floor, written from the scene format
alone; the simulator's meshes are not used.
"""

from __future__ import annotations

import numpy as np

from scanmap_driver.sim.scene import Box, Scene


def surface_distance(scene: Scene, points: np.ndarray) -> np.ndarray:
    """|distance| from each (N, 3) `map` point to the nearest scene surface (m)."""
    points = np.asarray(points, dtype=np.float64)
    best = np.abs(points[:, 2])  # the floor
    for obj in scene.objects:
        rel = points - np.array(obj.center)
        if isinstance(obj, Box):
            c, s = np.cos(obj.yaw), np.sin(obj.yaw)
            local = np.column_stack([c * rel[:, 0] + s * rel[:, 1],
                                     -s * rel[:, 0] + c * rel[:, 1], rel[:, 2]])
            half = 0.5 * np.array(obj.size)
        else:
            radial = np.hypot(rel[:, 0], rel[:, 1])
            local = np.column_stack([radial, np.zeros_like(radial), rel[:, 2]])
            half = np.array([obj.radius, np.inf, 0.5 * obj.height])
        q = np.abs(local) - half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        best = np.minimum(best, np.abs(outside + inside))
    return best
