"""The scene seen by every pixel of a frame, ray cast at a fraction of the cost.

Casting all 307,200 rays of a frame would dominate the render time. Rows are cast every
`step` rows only; between two cast rows of a column that hit the same plane, the rows in
between hit that plane too (faces are convex, and the rays of a column fan between the
two hits), so their distances are computed exactly from the plane in float64. Only the
gaps whose ends disagree (edges, silhouettes) are cast. The result equals a full cast
except for objects thinner than `step` pixels slipping between two cast rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .geometry import NO_HIT, Raycaster, rotate


@dataclass(frozen=True)
class HitMap:
    """Per pixel: plane id (NO_HIT) and distance (inf) from the camera centre (m)."""

    plane: np.ndarray  # (H, W) int32
    t: np.ndarray  # (H, W) float64


@njit(cache=True, nogil=True)
def fill_between_rows(plane: np.ndarray, t: np.ndarray, cast_rows: np.ndarray,
                      planes_head: np.ndarray, centre: np.ndarray,
                      directions: np.ndarray) -> np.ndarray:
    """Fill the rows between cast rows where both ends hit the same plane (in place).

    plane, t: (H, W) with the cast rows filled; planes_head: (P, 4) planes in `head`;
    directions: (H, W, 3) unit rays in `head`. Returns the (H, W) mask of pixels still to
    cast.
    """
    height, width = plane.shape
    todo = np.zeros((height, width), dtype=np.bool_)
    offsets = planes_head[:, 3] - (planes_head[:, 0] * centre[0] + planes_head[:, 1] * centre[1]
                                   + planes_head[:, 2] * centre[2])
    for k in range(cast_rows.shape[0] - 1):
        r0, r1 = cast_rows[k], cast_rows[k + 1]
        for col in range(width):
            p = plane[r0, col]
            same = p == plane[r1, col]
            for row in range(r0 + 1, r1):
                if not same:
                    todo[row, col] = True
                elif p == NO_HIT:
                    plane[row, col] = NO_HIT
                    t[row, col] = np.inf
                else:
                    d = directions[row, col]
                    plane[row, col] = p
                    t[row, col] = offsets[p] / (planes_head[p, 0] * d[0] + planes_head[p, 1] * d[1]
                                                + planes_head[p, 2] * d[2])
    return todo


def cast_rows(height: int, step: int) -> np.ndarray:
    """The rows cast directly: every `step`-th and the last."""
    return np.unique(np.append(np.arange(0, height, step), height - 1))


def hit_map(raycaster: Raycaster, centre: np.ndarray, directions: np.ndarray,
            pose_map_head: np.ndarray, step: int = 4, threads: int = 0) -> HitMap:
    """The scene's plane and distance along a grid of rays (R, W, 3) in `head` from the
    camera `centre`, for the camera at T_map_head: every pixel, or every n-th row of them.
    """
    rows_total, width = directions.shape[:2]
    rotation, shift = pose_map_head[:3, :3], pose_map_head[:3, 3]
    origin = rotation @ centre + shift
    plane = np.empty((rows_total, width), dtype=np.int32)
    t = np.empty((rows_total, width))
    rows = cast_rows(rows_total, step)
    p, d = raycaster.cast(origin, rotate(directions[rows].reshape(-1, 3), rotation), threads)
    plane[rows], t[rows] = p.reshape(-1, width), d.reshape(-1, width)
    planes = raycaster.planes.planes
    planes_head = np.column_stack([rotate(planes[:, :3], rotation.T),
                                   planes[:, 3] - planes[:, :3] @ shift])
    todo = fill_between_rows(plane, t, rows, planes_head, centre, directions)
    if todo.any():
        p, d = raycaster.cast(origin, rotate(directions[todo], rotation), threads)
        plane[todo], t[todo] = p, d
    return HitMap(plane, t)
