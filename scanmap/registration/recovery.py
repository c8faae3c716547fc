"""Coarse (x, y, yaw) search for a start when ICP from the guess finds too few matches.

ICP converges only within about a correspondence threshold of the truth; a guess off by
30 cm and 20 deg (a wheel slip, a bump) needs a search first. This is correlative scan
matching (Olson, ICRA 2009): the map's usable voxels, seen from above, are rasterised
into a likelihood grid (a Gaussian of the distance to the nearest map point), and every
yaw and integer-cell shift within the window scores the scan's points by a sum of grid
lookups. Among near-best candidates the one closest to the guess wins, so symmetric or
degenerate places do not jump. `pose_scores` scores given poses on the same grid.

Cost: the grid covers only the box the scan's points can fall in (a 2-D laser sees a
half disc), and a branch and bound over blocks of shifts (Olson's multi-resolution
bound: a block scores at most the mean of the grid's maxima over as many cells) scores
only what can reach _NEAR_BEST of the best; the choice is the exhaustive search's. On
the CARMEN logs about 6 ms a search instead of 20.
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
_MARGIN = 10  # cells of map beyond the lookups' box: exp(-50) and less is nothing
_BLOCK = 4  # shifts per side of a block the branch and bound bounds at once


def _points(source: Source, config: RegistrationConfig) -> np.ndarray:
    """At most _MAX_POINTS of the source's points off the floor band, evenly taken."""
    points = source.points[np.abs(source.points[:, 2]) >= config.floor_band]
    if len(points) > _MAX_POINTS:
        points = points[np.linspace(0, len(points) - 1, _MAX_POINTS).astype(np.int64)]
    return points


def _likelihood_grid(local_map: LocalMap, low: np.ndarray, high: np.ndarray,
                     anchor: np.ndarray, config: RegistrationConfig
                     ) -> tuple[np.ndarray, np.ndarray] | None:
    """(grid, its origin) over the x-y box [low, high] (m) that the lookups fall in, from
    the usable map voxels seen from above: a Gaussian (sigma one cell) of the distance to
    the nearest, voxels up to _MARGIN cells beyond the box included; None if none.
    Its cells are aligned on `anchor` (the guess): the box does not move the lattice."""
    resolution = local_map.voxel_size / 2.0
    n = len(local_map)
    usable = (local_map.flags[:n] & (LINE if config.planar else PLANE)) != 0
    origin = anchor - resolution * np.ceil((anchor - low) / resolution + _MARGIN)
    size = np.ceil((np.asarray(high) - origin) / resolution).astype(np.int64) + _MARGIN + 1
    cells = np.floor((local_map.means[:n][usable, :2] - origin) / resolution).astype(np.int64)
    cells = cells[np.all((cells >= 0) & (cells < size), axis=1)]
    if len(cells) == 0:
        return None
    occupied = np.zeros(tuple(size), dtype=bool)
    occupied[cells[:, 0], cells[:, 1]] = True
    likelihood = distance_to_occupied(occupied).astype(np.float64)
    np.square(likelihood, out=likelihood)  # in place: a grid is some 150,000 cells
    likelihood *= -0.5
    return np.exp(likelihood, out=likelihood), origin


def distance_to_occupied(occupied: np.ndarray) -> np.ndarray:
    """Exact Euclidean distance (cells, float32) from every cell to the nearest occupied one
    (OpenCV's precise mask: Felzenszwalb's algorithm, as scipy's distance_transform_edt)."""
    return cv2.distanceTransform((~occupied).astype(np.uint8), cv2.DIST_L2,
                                 cv2.DIST_MASK_PRECISE)


def pose_scores(source: Source, local_map: LocalMap, poses: list[np.ndarray],
                config: RegistrationConfig) -> list[float]:
    """The coarse search's score (mean likelihood in [0, 1]) of the scan at each pose."""
    points = _points(source, config)
    if len(points) == 0:
        return [0.0] * len(poses)
    placed = [points @ pose[:3, :3].T[:, :2] + pose[:2, 3] for pose in poses]
    grid = _likelihood_grid(local_map, np.min([xy.min(axis=0) for xy in placed], axis=0),
                            np.max([xy.max(axis=0) for xy in placed], axis=0),
                            np.mean([pose[:2, 3] for pose in poses], axis=0), config)
    if grid is None:
        return [0.0] * len(poses)
    grid, origin = grid
    resolution = local_map.voxel_size / 2.0
    return [float(_shift_scores(grid, np.floor((xy - origin) / resolution).astype(np.int64),
                                0)[0, 0]) for xy in placed]


def coarse_search(source: Source, local_map: LocalMap, guess: np.ndarray,
                  config: RegistrationConfig) -> tuple[np.ndarray, float, float]:
    """(best pose, its score, the guess's score); scores are mean likelihoods in [0, 1].

    Branch and bound over the shifts (Olson's multi-resolution search): a block of
    _BLOCK x _BLOCK shifts is bounded by the grid's maximum over as many cells, yaws are
    tried best bound first, and what cannot reach _NEAR_BEST of the best is never
    scored. The result is the exhaustive search's (`exhaustive=True`, kept to test it)."""
    return _search(source, local_map, guess, config, exhaustive=False)


def _search(source: Source, local_map: LocalMap, guess: np.ndarray,
            config: RegistrationConfig, exhaustive: bool) -> tuple[np.ndarray, float, float]:
    resolution = local_map.voxel_size / 2.0
    points = _points(source, config)
    if len(points) == 0:
        return guess, 0.0, 0.0
    shifts = math.ceil(config.search_radius / resolution)
    yaw_step = resolution / max(float(np.sqrt(np.mean(np.sum(points[:, :2] ** 2, axis=1)))),
                                resolution)  # a cell at the points' RMS range
    yaws = np.arange(-config.search_angle, config.search_angle + 0.5 * yaw_step, yaw_step)
    yaws = np.concatenate([[0.0], yaws])  # the guess's own yaw, exactly
    body = points @ guess[:3, :3].T  # rotated like the guess, relative to its position
    cos, sin = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    placed = np.stack([cos * body[:, 0] - sin * body[:, 1] + guess[0, 3],
                       sin * body[:, 0] + cos * body[:, 1] + guess[1, 3]], axis=-1)
    reach = (shifts + 1) * resolution
    grid = _likelihood_grid(local_map, placed.min(axis=(0, 1)) - reach,
                            placed.max(axis=(0, 1)) + reach, guess[:2, 3], config)
    if grid is None:
        return guess, 0.0, 0.0
    grid, origin = grid
    cells = np.floor((placed - origin) / resolution).astype(np.int64)  # (yaws, points, 2)
    pooled = cv2.dilate(grid, np.ones((_BLOCK, _BLOCK), np.uint8), anchor=(0, 0),
                        borderType=cv2.BORDER_CONSTANT, borderValue=0.0)
    bounds = _block_bounds(pooled, cells, shifts, _BLOCK)
    most = bounds.max(axis=(1, 2))
    offsets = np.arange(-shifts, shifts + 1) * resolution
    far = (offsets[:, None] ** 2 + offsets[None, :] ** 2) / config.search_radius ** 2
    candidates = []  # (yaw index, score, distance from the guess, shift x, shift y)
    best = 0.0
    for i in np.argsort(-most, kind="stable"):
        if exhaustive:
            scores = _shift_scores(grid, cells[i], shifts)
        elif most[i] < _NEAR_BEST * best:
            break  # the rest are bounded lower still
        else:
            # A yaw counts only if its best is within _NEAR_BEST of the best, and then its
            # shifts within _NEAR_BEST of its own best do: below the square, nothing does.
            scores = _pruned_scores(grid, cells[i], shifts, _BLOCK, bounds[i],
                                    _NEAR_BEST ** 2 * best)
        top = scores.max()
        if top == -np.inf:
            continue
        best = max(best, top)
        near = np.where(scores >= _NEAR_BEST * top, far, np.inf)
        a, b = np.unravel_index(np.argmin(near), near.shape)
        distance = near[a, b] + (yaws[i] / config.search_angle) ** 2
        candidates.append((i, top, distance, offsets[a], offsets[b]))
    i, score, _, dx, dy = min((c for c in sorted(candidates) if c[1] >= _NEAR_BEST * best),
                              key=lambda c: c[2])
    pose = guess.copy()
    pose[:3, :3] = rot_z(yaws[i]) @ guess[:3, :3]
    pose[:2, 3] += [dx, dy]
    return pose, float(score), float(_shift_scores(grid, cells[0], 0)[0, 0])


@njit(cache=True, nogil=True)
def _block_bounds(pooled, cells, shifts, block):
    """Per yaw of cells (yaws, points, 2) and block of block x block shifts (from
    -shifts), a bound on the block's mean grid value: the mean of `pooled` (the grid's
    maximum over block x block cells from each)."""
    side = 2 * shifts + 1
    blocks = (side + block - 1) // block
    out = np.zeros((cells.shape[0], blocks, blocks))
    nx, ny = pooled.shape
    for i in range(cells.shape[0]):
        for k in range(cells.shape[1]):
            for p in range(blocks):
                x = cells[i, k, 0] + p * block - shifts
                if x <= -block or x >= nx:
                    continue
                x = max(x, 0)
                for q in range(blocks):
                    y = cells[i, k, 1] + q * block - shifts
                    if -block < y < ny:
                        out[i, p, q] += pooled[x, max(y, 0)]
    return out / max(cells.shape[1], 1)


@njit(cache=True, nogil=True)
def _pruned_scores(grid, cells, shifts, block, bounds, floor):
    """`_shift_scores` where it can matter, -inf elsewhere: blocks in order of their bound,
    until a bound is below `floor` or _NEAR_BEST of the best score found; so every shift
    within _NEAR_BEST of this yaw's best is scored, exactly as `_shift_scores` does."""
    side = 2 * shifts + 1
    blocks = bounds.shape[0]
    out = np.full((side, side), -np.inf)
    nx, ny = grid.shape
    top = -np.inf
    flat = bounds.ravel()
    for o in np.argsort(-flat):
        if flat[o] < floor or flat[o] < _NEAR_BEST * top:
            break
        a0, b0 = (o // blocks) * block, (o % blocks) * block
        a1, b1 = min(a0 + block, side), min(b0 + block, side)
        sums = np.zeros((a1 - a0, b1 - b0))
        for k in range(cells.shape[0]):
            for a in range(a0, a1):
                x = cells[k, 0] + a - shifts
                if x < 0 or x >= nx:
                    continue
                for b in range(b0, b1):
                    y = cells[k, 1] + b - shifts
                    if 0 <= y < ny:
                        sums[a - a0, b - b0] += grid[x, y]
        sums /= max(cells.shape[0], 1)
        out[a0:a1, b0:b1] = sums
        top = max(top, sums.max())
    return out


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
