"""The local map registration matches against: voxels holding running point statistics.

Each voxel (edge `voxel_size`) accumulates the count, sum and sum of squares of the
points that fell in it (relative to the voxel centre, so float64 keeps full precision).
Its plane is fitted to the statistics of the voxel and its 6 face neighbours: the mean
of one voxel is biased wherever a noisy surface lies near a voxel face (the grid splits
the noise between two voxels), and a single voxel cannot tell a surface from a sliver
cut off an edge. The fit gives the 3-D normal (SE(3) mode) and, for near-vertical
planes, the horizontal wall normal (planar mode, where the floor or a table top cannot
move x, y or yaw).

Growing and forgetting: after each scan a voxel's count is capped at `max_count` by
scaling its statistics down, so new scans weigh as much as old ones and the map follows
a changed scene. `forget_far` drops voxels farther than `radius` from the robot, so the map's size
and the cost per scan stay flat on long runs. Coordinates are relative to the map's
local origin: the caller subtracts it (see `ScanOdometry`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from scanmap.registration.planes import BLOB, LINE, PLANE, accumulate, fit_voxel, pool_shape
from scanmap.registration.voxel_hash import (
    COORD_LIMIT,
    fill_table,
    key_coords,
    new_table,
    table_insert,
    voxel_key,
)
from scanmap_driver.errors import MapError

__all__ = ["BLOB", "LINE", "PLANE", "LocalMap"]


class LocalMap:
    """Voxel statistics with planes, a hash for lookups, growth and forgetting."""

    def __init__(self, voxel_size: float = 0.1, radius: float = 6.0, max_count: int = 30,
                 min_points: int = 4, flatness: float = 0.1, scans_2d: bool = False) -> None:
        if not voxel_size > 0 or not radius > 0 or max_count < 2 or min_points < 3:
            raise MapError(f"LocalMap: invalid settings voxel_size={voxel_size}, "
                           f"radius={radius}, max_count={max_count}, min_points={min_points}")
        self.voxel_size = float(voxel_size)
        self.radius = float(radius)
        self.max_count = float(max_count)
        self.min_points = float(min_points)
        self.flatness = float(flatness)
        self.scans_2d = bool(scans_2d)
        self.size = 0
        self._allocate(1024)

    def _allocate(self, capacity: int) -> None:
        old = self.size
        arrays = {"voxel_keys": (np.int64, ()), "counts": (np.float64, ()),
                  "noise": (np.float64, ()),
                  "sums": (np.float64, (3,)), "squares": (np.float64, (6,)),
                  "means": (np.float64, (3,)), "normals": (np.float64, (3,)),
                  "line_normals": (np.float64, (3,)), "flags": (np.int64, ()),
                  "plane_var": (np.float64, ()), "line_var": (np.float64, ()),
                  "spread_var": (np.float64, ()),
                  "last_seen": (np.int64, ())}
        for name, (dtype, tail) in arrays.items():
            fresh = np.zeros((capacity, *tail), dtype=dtype)
            if old:
                fresh[:old] = getattr(self, name)[:old]
            setattr(self, name, fresh)
        self.table_keys, self.table_values = new_table(capacity)
        fill_table(self.table_keys, self.table_values, self.voxel_keys[:old])

    def __len__(self) -> int:
        return self.size

    def insert(self, points: np.ndarray, scan_id: int, variance: np.ndarray | float = 1e-4,
               pose: np.ndarray | None = None) -> None:
        """Add (N, 3) points with their range variance (m^2) and refresh the planes they
        touch. Points are map-local, or moved there by the 4x4 `pose`; non-finite ones are
        skipped. `scan_id` must differ from the previous call's."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
        variance = np.ascontiguousarray(np.broadcast_to(variance, len(points)),
                                        dtype=np.float64)
        if self.size + len(points) > self.table_keys.size // 2:
            self._allocate(max(2 * self.voxel_keys.shape[0], self.size + len(points)))
        touched = np.empty(len(points), dtype=np.int64)
        self.size, n_touched, outside = _insert_points(
            points, variance, np.ascontiguousarray(pose[:3, :3]),
            np.ascontiguousarray(pose[:3, 3]), 1.0 / self.voxel_size, self.voxel_size,
            int(scan_id), self.size,
            self.table_keys, self.table_values, self.voxel_keys, self.counts, self.sums,
            self.squares, self.noise, self.last_seen, touched)
        _refresh_planes(touched[:n_touched], self.voxel_size, self.max_count, self.min_points,
                        self.flatness, self.scans_2d, self.table_keys, self.table_values,
                        self.voxel_keys, self.counts,
                        self.sums, self.squares, self.noise, self.means, self.normals,
                        self.line_normals, self.flags, self.plane_var, self.line_var,
                        self.spread_var)
        if outside:
            raise MapError(f"LocalMap.insert: {outside} points lie beyond "
                           f"{COORD_LIMIT * self.voxel_size:.0f} m of the local origin")

    def forget_far(self, centre: np.ndarray) -> None:
        """Drop voxels whose mean lies farther than `radius` (horizontally) from `centre`."""
        n = self.size
        offset = self.means[:n, :2] - np.asarray(centre, dtype=np.float64)[:2]
        keep = np.flatnonzero(np.einsum("ij,ij->i", offset, offset) <= self.radius ** 2)
        if keep.size == n:
            return
        for name in ("voxel_keys", "counts", "noise", "sums", "squares", "means", "normals",
                     "line_normals", "flags", "plane_var", "line_var", "spread_var",
                     "last_seen"):
            array = getattr(self, name)
            array[:keep.size] = array[keep]
        self.size = int(keep.size)
        self.table_keys.fill(-1)
        fill_table(self.table_keys, self.table_values, self.voxel_keys[:self.size])


@njit(cache=True, nogil=True)
def _insert_points(points, variance, rotation, translation, inv_voxel, voxel, scan_id, size,
                   table_keys, table_values, voxel_keys, counts, sums, squares, noise,
                   last_seen, touched):
    n_touched = 0
    outside = 0
    limit = (COORD_LIMIT - 1) * voxel
    last_key = -1
    slot = -1
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        px = rotation[0, 0] * x + rotation[0, 1] * y + rotation[0, 2] * z + translation[0]
        py = rotation[1, 0] * x + rotation[1, 1] * y + rotation[1, 2] * z + translation[1]
        pz = rotation[2, 0] * x + rotation[2, 1] * y + rotation[2, 2] * z + translation[2]
        if not (abs(px) < limit and abs(py) < limit and abs(pz) < limit):
            if math.isfinite(px) and math.isfinite(py) and math.isfinite(pz):
                outside += 1
            continue
        ix = math.floor(px * inv_voxel)
        iy = math.floor(py * inv_voxel)
        iz = math.floor(pz * inv_voxel)
        key = voxel_key(ix, iy, iz)
        if key != last_key:  # neighbours along a laser stripe share voxels: skip the probe
            slot = table_insert(table_keys, table_values, key, size)
            last_key = key
        if slot == size:
            voxel_keys[slot] = key
            counts[slot] = 0.0
            noise[slot] = 0.0
            sums[slot, :] = 0.0
            squares[slot, :] = 0.0
            last_seen[slot] = scan_id - 1
            size += 1
        if last_seen[slot] != scan_id:
            last_seen[slot] = scan_id
            touched[n_touched] = slot
            n_touched += 1
        accumulate(counts, sums, squares, noise, slot, px - (ix + 0.5) * voxel,
                   py - (iy + 0.5) * voxel, pz - (iz + 0.5) * voxel, variance[i])
    return size, n_touched, outside


@njit(cache=True, nogil=True)
def _refresh_planes(touched, voxel, max_count, min_points, flatness, scans_2d, table_keys,
                    table_values, voxel_keys, counts, sums, squares, noise, means, normals,
                    line_normals, flags, plane_var, line_var, spread_var):
    for slot in touched:
        if counts[slot] > max_count:  # forget some of the past, keep the statistics' shape
            scale = max_count / counts[slot]
            counts[slot] = max_count
            noise[slot] *= scale
            sums[slot, :] *= scale
            squares[slot, :] *= scale
    pooled_sums = np.empty(3)
    pooled_squares = np.empty(6)
    for slot in touched:
        ix, iy, iz = key_coords(voxel_keys[slot])
        n, pooled_noise = pool_shape(ix, iy, iz, voxel, table_keys, table_values, counts,
                                     sums, squares, noise, min_points, scans_2d, pooled_sums,
                                     pooled_squares)
        means[slot, 0] = (ix + 0.5) * voxel + pooled_sums[0] / n
        means[slot, 1] = (iy + 0.5) * voxel + pooled_sums[1] / n
        means[slot, 2] = (iz + 0.5) * voxel + pooled_sums[2] / n
        flags[slot], plane_var[slot], line_var[slot], spread_var[slot] = fit_voxel(
            n, pooled_sums, pooled_squares, pooled_noise, voxel, min_points, flatness, scans_2d,
            normals[slot], line_normals[slot])
