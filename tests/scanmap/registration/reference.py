"""Plain-numpy references of the registration kernels: slow, obvious, for the tests."""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial.transform import Rotation

from scanmap.registration.degeneracy import analyse_degeneracy
from scanmap.registration.icp import evaluate
from scanmap.registration.lie import between, retract

FACE_NEIGHBOURS = [(0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1),
                   (0, 0, -1)]


def group_by_voxel(points: np.ndarray, voxel: float) -> dict[tuple, np.ndarray]:
    """Indices of `points` grouped by voxel coordinates."""
    cells = np.floor(points / voxel).astype(np.int64)
    groups: dict[tuple, list] = {}
    for i, cell in enumerate(map(tuple, cells)):
        groups.setdefault(cell, []).append(i)
    return {cell: np.array(idx) for cell, idx in groups.items()}


def neighbourhood(groups: dict[tuple, np.ndarray], cell: tuple) -> np.ndarray:
    """Indices of the points in `cell` and its 6 face neighbours."""
    parts = [groups[c] for d in FACE_NEIGHBOURS
             if (c := tuple(np.add(cell, d))) in groups]
    return np.concatenate(parts)


def square_neighbourhood(groups: dict[tuple, np.ndarray], cell: tuple, reach: int) -> np.ndarray:
    """Indices of the points within `reach` voxels of `cell` in x and y, in its z layer."""
    parts = [groups[c] for dx in range(-reach, reach + 1) for dy in range(-reach, reach + 1)
             if (c := (cell[0] + dx, cell[1] + dy, cell[2])) in groups]
    return np.concatenate(parts)


def wall_fit(points: np.ndarray) -> tuple[float, float, np.ndarray, float]:
    """(thin variance, long variance, horizontal unit normal, z variance) of points."""
    cov = np.cov(points.T, bias=True)
    values, vectors = np.linalg.eigh(cov[:2, :2])
    normal = np.array([*vectors[:, 0], 0.0])
    return float(values[0]), float(values[1]), normal, float(cov[2, 2])


def deskew(points: np.ndarray, times: np.ndarray, motion: np.ndarray, t0: float,
           t1: float) -> np.ndarray:
    """Each point moved by the fraction s of `motion` (rotation vector and translation)."""
    s = np.clip((times - t0) / (t1 - t0), 0.0, 1.0)
    rotvec = Rotation.from_matrix(motion[:3, :3]).as_rotvec()
    rotations = Rotation.from_rotvec(s[:, None] * rotvec)
    return rotations.apply(points) + s[:, None] * motion[:3, 3]


def correspondences(source, source_normals, source_var, pose, cells, means, normals,
                    plane_var, usable, voxel, rings_xy, rings_z, max_dist, var_floor, min_cos,
                    blob=None, spread_var=None):
    """Per source point: a list of (matched map index, normal, residual, weight before the
    kernel), empty without a match: one residual for a wall (plane), two for a `blob` (its
    narrowest spread along `normals`, variance `plane_var`; its widest across it,
    `spread_var`).

    cells: (K, 3) integer voxel coordinates of the map entries (means may leave them).
    """
    blob = np.zeros(len(cells), bool) if blob is None else blob
    index = {tuple(c): i for i, c in enumerate(cells)}
    moved = source @ pose[:3, :3].T + pose[:3, 3]
    turned = source_normals @ pose[:3, :3].T
    out = []
    for q, u, var in zip(moved, turned, source_var, strict=True):
        base = np.floor(q / voxel - 0.5).astype(np.int64)
        best, best_d2 = -1, np.inf
        for d in itertools.product(range(1 - rings_xy, rings_xy + 1),
                                   range(1 - rings_xy, rings_xy + 1),
                                   range(1 - rings_z, rings_z + 1)):
            j = index.get(tuple(base + d), -1)
            if j < 0 or not (usable[j] or blob[j]) \
                    or (usable[j] and u.any() and abs(u @ normals[j]) < min_cos):
                continue
            d2 = float(np.sum((q - means[j]) ** 2))
            if d2 < best_d2:
                best, best_d2 = j, d2
        matches = []
        offset = q - means[best] if best >= 0 else None
        if best >= 0 and usable[best]:
            parts = [(normals[best], plane_var[best])]
        elif best >= 0 and np.hypot(*offset[:2]) <= max_dist:
            n = normals[best]
            parts = [(n, plane_var[best]), (np.array([-n[1], n[0], 0.0]), spread_var[best])]
        else:
            parts = []
        for n, part_var in parts:
            r = float(n @ offset)
            if abs(r) <= max_dist:
                matches.append((best, n, r, 1.0 / (var + part_var + var_floor)))
        out.append(matches)
    return out


def normal_equations(source, source_normals, source_var, pose, cells, means, normals,
                     plane_var, usable, voxel, rings_xy, rings_z, max_dist, kappa, var_floor,
                     min_cos, blob=None, spread_var=None):
    """H, g, stats as the kernel computes them, point by point."""
    matches = correspondences(source, source_normals, source_var, pose, cells, means, normals,
                              plane_var, usable, voxel, rings_xy, rings_z, max_dist,
                              var_floor, min_cos, blob, spread_var)
    hessian, gradient, stats = np.zeros((6, 6)), np.zeros(6), np.zeros(5)
    for p, point_matches in zip(source, matches, strict=True):
        for _, n, r, w in point_matches:
            m = pose[:3, :3].T @ n
            jac = np.concatenate([m, np.cross(p, m)])
            w *= (kappa ** 2 / (kappa ** 2 + r ** 2)) ** 2
            hessian += w * np.outer(jac, jac)
            gradient += w * jac * r
            stats += [1.0, r * r, w * r * r, w, 0.0]
        stats[4] += bool(point_matches)
    return hessian, gradient, stats


def shift_scores(grid: np.ndarray, cells: np.ndarray, shifts: int) -> np.ndarray:
    """Mean grid value of the cells shifted by every offset in [-shifts, shifts]^2."""
    side = 2 * shifts + 1
    out = np.zeros((side, side))
    for a, b in itertools.product(range(side), range(side)):
        moved = cells + [a - shifts, b - shifts]
        inside = np.all((moved >= 0) & (moved < grid.shape), axis=1)
        out[a, b] = grid[moved[inside, 0], moved[inside, 1]].sum()
    return out / max(len(cells), 1)


def gauss_newton(source, local_map, pose, prior, threshold, config, axes, lever):
    """(pose, iterations) of `icp._gauss_newton`, step by step in numpy: the normal
    equations over `axes`, the degenerate directions projected out, the noise scale, the
    prior, the solve, the update on the right; NaN pose when a step is not finite."""
    rotations = np.isin(axes, [3, 4, 5])
    information = prior.information(axes)
    for iterations in range(1, config.max_iterations + 1):
        hessian, gradient, stats = evaluate(source, local_map, pose, threshold, config)
        h = hessian[np.ix_(axes, axes)]
        degeneracy = analyse_degeneracy(h, stats[3] / max(stats[0], 1.0), lever, rotations,
                                        config.min_constraint)
        h, g = degeneracy.project(h, gradient[axes])
        inliers = int(stats[0])
        noise = max(1.0, stats[2] / (inliers - len(axes))) if inliers > len(axes) else 1.0
        error = between(prior.pose, pose)[axes]
        step = np.linalg.solve(h / noise + information, -(g / noise + information @ error))
        if not np.isfinite(step).all():
            return np.full((4, 4), np.nan), iterations
        delta = np.zeros(6)
        delta[axes] = step
        pose = retract(pose, delta)
        if np.linalg.norm(step[~rotations]) < config.tolerance \
                and np.linalg.norm(step[rotations]) < config.tolerance:
            break
    return pose, iterations
