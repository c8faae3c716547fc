"""Scan preparation in one pass: filter, de-skew, voxel-downsample.

Kept points: finite, horizontal range within [min_range, max_range], and (planar mode)
off the floor band: above it, or below it (a hole's walls). Each is de-skewed to the
scan's start pose and added to its source voxel's statistics. Each voxel then yields one
source point: the mean of its neighbourhood (itself and its 6 face neighbours), with
that neighbourhood's normal and the variance sum(sigma_i^2) / count^2. The
neighbourhood, not the voxel alone: where a noisy surface lies near a voxel face the
grid splits its noise and biases each voxel's mean, and a voxel cut off an edge can look
flat. A voxel whose neighbourhood is neither a plane (SE(3) mode) nor a wall (planar
mode) - a box corner, a wall meeting a box - is dropped: its mean lies between surfaces,
and matching it to either would bias the pose. So is a voxel within 3 sigma of the range
limits: the limit truncates its noise (only the near side of a wall at 4 m is kept),
which would pull it toward the sensor. The kept full-resolution points go into the local
map once the scan's pose is known.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from scanmap.registration.config import RegistrationConfig
from scanmap.registration.deskew import apply_motion, deskew_twist, motion_at, scan_fraction
from scanmap.registration.planes import BLOB, LINE, PLANE, accumulate, fit_voxel, pool_neighbours
from scanmap.registration.voxel_hash import grown, new_table, table_insert, voxel_key

_LIMIT_SIGMAS = 3.0
_FIRST_TABLE = 4096  # voxels; the kernel doubles the table as it fills


@dataclass(frozen=True, eq=False)
class Source:
    """A prepared scan, in base_link at its start pose (float64).

    points (M, 3): voxel means that registration matches. normals (M, 3): the surface
    normal around each (horizontal in planar mode; zero where too few points tell, and
    on a 2-D scan's blob: a post or a corner, no line).
    variance (M,): their range variance (m^2). cloud (N, 3): every kept point, for the
    map; cloud_variance (N,): theirs.
    """

    points: np.ndarray
    normals: np.ndarray
    variance: np.ndarray
    cloud: np.ndarray
    cloud_variance: np.ndarray

    def __len__(self) -> int:
        return int(self.points.shape[0])


def blob_flag(config: RegistrationConfig) -> int:
    """`planes.BLOB` where `config` matches blobs (2-D scans, planar), else 0."""
    return BLOB if config.scans_2d and config.match_blobs and config.planar else 0


def prepare_source(points: np.ndarray, config: RegistrationConfig,
                   range_sigma: np.ndarray | None = None, times: np.ndarray | None = None,
                   motion: np.ndarray | None = None) -> Source:
    """Filter, de-skew (when `times` and the scan's `motion` t0 -> t1 are given), downsample.

    motion: base_link at the last point's time in base_link at the first's (4x4).
    """
    points = np.ascontiguousarray(points).reshape(-1, 3)
    n = len(points)
    sigma = np.full(n, config.default_range_sigma) if range_sigma is None else \
        np.ascontiguousarray(range_sigma, dtype=np.float64).reshape(-1)
    if times is None or motion is None or n == 0:
        times, t0, t1 = np.zeros(n), 0.0, 0.0
        motion = np.eye(4)
    else:
        times = np.ascontiguousarray(times, dtype=np.float64).reshape(-1)
        finite = times[np.isfinite(times)]
        t0, t1 = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
    twist = deskew_twist(np.asarray(motion, dtype=np.float64), t0, t1)
    inv_span = 1.0 / (t1 - t0) if t1 > t0 else 0.0
    band = config.floor_band if config.planar else 0.0
    keys, values = new_table(min(n, _FIRST_TABLE))
    cloud, cloud_variance, means, normals, variance = _prepare_kernel(
        points, sigma, config.default_range_sigma, times, t0, inv_span, twist,
        config.min_range ** 2, config.max_range ** 2, band, config.voxel_size,
        config.min_plane_points, config.flatness, config.scans_2d,
        LINE if config.planar else PLANE, blob_flag(config), keys, values)
    return Source(means, normals, variance, cloud, cloud_variance)


@njit(cache=True, nogil=True)
def _prepare_kernel(points, sigma, default_sigma, times, t0, inv_span, twist, min_r2, max_r2,
                    band, voxel, min_points, flatness, scans_2d, shape_flag, blobs, keys,
                    values):
    n = points.shape[0]
    inv_voxel = 1.0 / voxel
    cloud = np.empty((n, 3))
    cloud_var = np.empty(n)
    cloud_range = np.empty(n)
    point_slot = np.empty(n, dtype=np.int64)
    cells = np.empty((n, 3), dtype=np.int64)
    kept = 0
    voxels = 0
    last_key = -1
    slot = -1
    last_s = 0.0
    m = motion_at(0.0, twist)
    # Pass 1: filter, de-skew, find each point's voxel.
    for i in range(n):
        x, y, z = float(points[i, 0]), float(points[i, 1]), float(points[i, 2])
        r2 = x * x + y * y
        # NaN fails every comparison: non-finite points drop out here.
        if not (r2 >= min_r2 and r2 <= max_r2 and abs(z) >= band and abs(z) < 1e6):
            continue
        s = scan_fraction(times[i], t0, inv_span)
        if s != last_s:  # points of one frame share a time: one sin/cos per frame
            m = motion_at(s, twist)
            last_s = s
        x, y, z = apply_motion(x, y, z, m)
        sig = sigma[i]
        if not (sig > 0.0 and sig < 1e3):
            sig = default_sigma
        ix, iy, iz = math.floor(x * inv_voxel), math.floor(y * inv_voxel), \
            math.floor(z * inv_voxel)
        if 2 * voxels >= keys.size:
            keys, values = grown(keys, values)
        key = voxel_key(ix, iy, iz)
        if key != last_key:  # neighbours along a laser stripe share voxels: skip the probe
            slot = table_insert(keys, values, key, voxels)
            last_key = key
        if slot == voxels:
            cells[slot, 0], cells[slot, 1], cells[slot, 2] = ix, iy, iz
            voxels += 1
        cloud[kept, 0], cloud[kept, 1], cloud[kept, 2] = x, y, z
        cloud_var[kept] = sig * sig
        cloud_range[kept] = math.sqrt(r2)
        point_slot[kept] = slot
        kept += 1
    # Pass 2: voxel statistics (arrays sized by voxels, not points).
    counts = np.zeros(voxels)
    sums = np.zeros((voxels, 3))
    squares = np.zeros((voxels, 6))
    noise = np.zeros(voxels)
    ranges = np.zeros(voxels)  # summed measured horizontal range
    for i in range(kept):
        slot = point_slot[i]
        accumulate(counts, sums, squares, noise, slot,
                   cloud[i, 0] - (cells[slot, 0] + 0.5) * voxel,
                   cloud[i, 1] - (cells[slot, 1] + 0.5) * voxel,
                   cloud[i, 2] - (cells[slot, 2] + 0.5) * voxel, cloud_var[i])
        ranges[slot] += cloud_range[i]
    # A surface within noise of a range limit is seen only on its near (far) side: the
    # limit truncates its noise and biases it. Its voxels stay out of matching and map.
    at_limit = np.zeros(voxels, dtype=np.bool_)
    for v in range(voxels):
        r = ranges[v] / counts[v]
        margin = _LIMIT_SIGMAS * math.sqrt(noise[v] / counts[v])
        at_limit[v] = r + margin > math.sqrt(max_r2) or r - margin < math.sqrt(min_r2)
    means = np.empty((voxels, 3))
    normals = np.empty((voxels, 3))
    variance = np.empty(voxels)
    plane_normal = np.empty(3)
    wall_normal = np.empty(3)
    pooled_sums = np.empty(3)
    pooled_squares = np.empty(6)
    out = 0
    for v in range(voxels):
        if at_limit[v]:
            continue
        pooled, pooled_noise = pool_neighbours(cells[v, 0], cells[v, 1], cells[v, 2], voxel,
                                               keys, values, counts, sums, squares, noise,
                                               pooled_sums, pooled_squares, 0)
        flags, _, _, _ = fit_voxel(pooled, pooled_sums, pooled_squares, pooled_noise, voxel,
                                   min_points, flatness, scans_2d, plane_normal, wall_normal)
        if pooled < min_points or flags & blobs:  # too sparse to judge, or a 2-D scan's
            plane_normal[:] = 0.0  # blob (a post, a corner): matched without a normal
            wall_normal[:] = 0.0
        elif (flags & shape_flag) == 0:
            continue  # near a corner, an edge or in a blob: its mean is on no surface
        for k in range(3):
            means[out, k] = (cells[v, k] + 0.5) * voxel + pooled_sums[k] / pooled
            normals[out, k] = wall_normal[k] if shape_flag == LINE else plane_normal[k]
        variance[out] = pooled_noise / (pooled * pooled)
        out += 1
    inside = 0
    for i in range(kept):
        if not at_limit[point_slot[i]]:
            cloud[inside] = cloud[i]
            cloud_var[inside] = cloud_var[i]
            inside += 1
    return cloud[:inside], cloud_var[:inside], means[:out], normals[:out], variance[:out]
