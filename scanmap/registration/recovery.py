"""Coarse (x, y, yaw) search for a start when ICP from the guess finds too few matches.

ICP converges only within about a correspondence threshold of the truth; a guess off by
30 cm and 20 deg (a wheel slip, a bump) needs a search first. This is correlative scan
matching (Olson, ICRA 2009): the map's usable voxels, seen from above, are rasterised
into a likelihood grid (a Gaussian of the distance to the nearest map point), and every
yaw and integer-cell shift within the window scores the scan's points by a sum of grid
lookups. Among near-best candidates the one closest to the guess wins, so symmetric or
degenerate places do not jump. `pose_scores` scores given poses on the same grid.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit

from scanmap.registration.config import RegistrationConfig
from scanmap.registration.local_map import LINE, PLANE, LocalMap
from scanmap.registration.preprocess import Source
from scanmap_driver.transforms import rot_z

_MAX_POINTS = 400
_NEAR_BEST = 0.98


def _points(source: Source, config: RegistrationConfig) -> np.ndarray:
    """At most _MAX_POINTS of the source's points above the floor band, evenly taken."""
    points = source.points[source.points[:, 2] >= config.floor_band]
    if len(points) > _MAX_POINTS:
        points = points[np.linspace(0, len(points) - 1, _MAX_POINTS).astype(np.int64)]
    return points


def _likelihood_grid(local_map: LocalMap, centre: np.ndarray, reach: float,
                     config: RegistrationConfig) -> tuple[np.ndarray, np.ndarray] | None:
    """(grid, its origin) of the usable map voxels within `reach` of `centre`, seen from
    above: a Gaussian (sigma one cell) of the distance to the nearest; None if none."""
    resolution = local_map.voxel_size / 2.0
    n = len(local_map)
    usable = (local_map.flags[:n] & (LINE if config.planar else PLANE)) != 0
    targets = local_map.means[:n][usable, :2]
    targets = targets[np.all(np.abs(targets - centre) <= reach, axis=1)]
    if len(targets) == 0:
        return None
    size = math.ceil(2 * reach / resolution) + 1
    origin = centre - reach
    cells = np.floor((targets - origin) / resolution).astype(np.int64)
    occupied = np.zeros((size, size), dtype=bool)
    occupied[cells[:, 0], cells[:, 1]] = True
    return np.exp(-0.5 * distance_to_occupied(occupied) ** 2), origin


def distance_to_occupied(occupied: np.ndarray) -> np.ndarray:
    """Exact Euclidean distance (cells) from every cell to the nearest occupied one (OpenCV's
    precise mask: Felzenszwalb's algorithm, as scipy's distance_transform_edt)."""
    return cv2.distanceTransform((~occupied).astype(np.uint8), cv2.DIST_L2,
                                 cv2.DIST_MASK_PRECISE).astype(np.float64)


def pose_scores(source: Source, local_map: LocalMap, poses: list[np.ndarray],
                config: RegistrationConfig) -> list[float]:
    """The coarse search's score (mean likelihood in [0, 1]) of the scan at each pose."""
    points = _points(source, config)
    centre = np.mean([pose[:2, 3] for pose in poses], axis=0)
    reach = max(float(np.max(np.abs(pose[:2, 3] - centre))) for pose in poses) \
        + config.max_range + local_map.voxel_size
    grid = _likelihood_grid(local_map, centre, reach, config)
    if grid is None or len(points) == 0:
        return [0.0] * len(poses)
    grid, origin = grid
    resolution = local_map.voxel_size / 2.0
    scores = []
    for pose in poses:
        xy = points @ pose[:3, :3].T[:, :2] + pose[:2, 3] - origin
        cells = np.floor(xy / resolution).astype(np.int64)
        scores.append(float(_shift_scores(grid, cells, 0)[0, 0]))
    return scores


def coarse_search(source: Source, local_map: LocalMap, guess: np.ndarray,
                  config: RegistrationConfig) -> tuple[np.ndarray, float, float]:
    """(best pose, its score, the guess's score); scores are mean likelihoods in [0, 1]."""
    resolution = local_map.voxel_size / 2.0
    points = _points(source, config)
    centre = guess[:2, 3]
    reach = config.search_radius + config.max_range + 2 * resolution
    grid = _likelihood_grid(local_map, centre, reach, config)
    if grid is None or len(points) == 0:
        return guess, 0.0, 0.0
    grid, origin = grid
    shifts = math.ceil(config.search_radius / resolution)
    yaw_step = resolution / max(float(np.sqrt(np.mean(np.sum(points[:, :2] ** 2, axis=1)))),
                                resolution)  # a cell at the points' RMS range
    yaws = np.arange(-config.search_angle, config.search_angle + 0.5 * yaw_step, yaw_step)
    yaws = np.concatenate([[0.0], yaws])  # the guess's own yaw, exactly
    body = points @ guess[:3, :3].T  # rotated like the guess, relative to its position
    offsets = np.arange(-shifts, shifts + 1) * resolution
    far = (offsets[:, None] ** 2 + offsets[None, :] ** 2) / config.search_radius ** 2
    candidates = []  # (score, distance from the guess, yaw, shift x, shift y)
    for yaw in yaws:
        xy = body[:, :2] @ rot_z(yaw)[:2, :2].T + centre - origin
        scores = _shift_scores(grid, np.floor(xy / resolution).astype(np.int64), shifts)
        top = scores.max()
        near = np.where(scores >= _NEAR_BEST * top, far, np.inf)
        a, b = np.unravel_index(np.argmin(near), near.shape)
        distance = near[a, b] + (yaw / config.search_angle) ** 2
        candidates.append((top, distance, yaw, offsets[a], offsets[b], scores[shifts, shifts]))
    best_score = max(c[0] for c in candidates)
    score, _, yaw, dx, dy, _ = min((c for c in candidates if c[0] >= _NEAR_BEST * best_score),
                                   key=lambda c: c[1])
    pose = guess.copy()
    pose[:3, :3] = rot_z(yaw) @ guess[:3, :3]
    pose[:2, 3] += [dx, dy]
    return pose, float(score), float(candidates[0][5])


@njit(cache=True, nogil=True)
def _shift_scores(grid, cells, shifts):
    """Mean grid value of `cells` shifted by every (dx, dy) in [-shifts, shifts]^2."""
    side = 2 * shifts + 1
    out = np.zeros((side, side))
    nx, ny = grid.shape
    for k in range(cells.shape[0]):
        cx, cy = cells[k, 0], cells[k, 1]
        for a in range(side):
            x = cx + a - shifts
            if x < 0 or x >= nx:
                continue
            for b in range(side):
                y = cy + b - shifts
                if 0 <= y < ny:
                    out[a, b] += grid[x, y]
    return out / max(cells.shape[0], 1)
