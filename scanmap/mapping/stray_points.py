"""Lone points below the floor: a laser peak thrown off the stripe, not a hole.

Where the stripe ends at an occluding edge (a ramp's corner), its last image line can
hold a peak several pixels off the stripe; triangulated, the point lies on the laser
plane tens of cm beyond the surface, and the plane slopes down, so it lands below the
floor (rendered random room 503: one point 27 cm beyond a ramp's corner and 8 cm down).
Fused, it and the rays passing below the floor on their way to it made 17 cells of
drop-off 1.8 m from any hole. A real hole, step down or far wall shows itself along the
stripe: a run of points of the same frame side by side (the columns lie millimetres
apart), so a point below the floor with no other point of its frame near it is dropped
before fusion.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from scanmap_driver.scan import Scan


def lone_low_points(scan: Scan, depth: float, radius: float) -> np.ndarray:
    """(N,) bool: the points of `scan` more than `depth` (m) below base_link's x-y plane
    with no other point of their frame within `radius` (m), in any order of the points."""
    points, frames = scan.points, scan.frame_index
    in_frames = slice(None) if bool((frames[1:] >= frames[:-1]).all()) \
        else np.argsort(frames, kind="stable")  # scans are assembled frame by frame
    lone = np.empty(len(points), bool)
    lone[in_frames] = _lone(points[in_frames], frames[in_frames],
                            points[in_frames, 2] < -depth, radius * radius)
    return lone


@njit(cache=True, nogil=True)
def _lone(points: np.ndarray, frames: np.ndarray, low: np.ndarray,
          radius2: float) -> np.ndarray:
    """`lone_low_points` on points sorted by frame: each low point against the others of
    its frame."""
    n = points.shape[0]
    out = np.zeros(n, np.bool_)
    start = 0
    while start < n:
        end = start
        while end < n and frames[end] == frames[start]:
            end += 1
        for i in range(start, end):
            if not low[i]:
                continue
            alone = True
            for j in range(start, end):
                if j != i:
                    dx = points[j, 0] - points[i, 0]
                    dy = points[j, 1] - points[i, 1]
                    dz = points[j, 2] - points[i, 2]
                    if dx * dx + dy * dy + dz * dz <= radius2:
                        alone = False
                        break
            out[i] = alone
        start = end
    return out
