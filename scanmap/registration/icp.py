"""Scan-to-map ICP: point-to-plane Gauss-Newton with a robust kernel and a weighted prior.

Each source point (a voxel mean in base_link) is moved by the current pose and matched
to the nearest usable map voxel among the 2x2x2 voxels whose centres surround it (4x4x2
when the correspondence threshold exceeds a voxel): usable means a plane in SE(3) mode,
a wall in planar mode (the floor and table tops cannot move x, y or yaw). The
candidate's normal must agree with the source point's own, where known (within
max_normal_angle): near a door jamb, a wall point's nearest usable voxel may be the
jamb's. The residual is the signed distance to that voxel's plane (its horizontal trace
in planar mode), r = n . (R p + t - mu); its Jacobian for a body-frame increment
(rho, phi) is [R^T n, p x R^T n].

2-D laser scans also match blobs (`planes.BLOB`: points that are no line, a post, a
corner, clutter) point-to-distribution, as NDT does: two residuals, along the blob's
narrowest and its widest spread, each over that spread's variance. Matching walls only,
a scan of an open hall whose walls are few or far took yaw from odometry in the
directions its lines left free; over seven start scans of each of the seven CARMEN logs
the 1 m relative error fell on six of them (Acapulco 66.9 -> 62.5 mm, Edmonton
61.9 -> 56.9, Intel 43.1 -> 39.8, FHW 56.7 -> 54.5, Freiburg 37.4 -> 36.7, Belgioioso
31.2 -> 30.7) and stayed on ACES (49.3 -> 49.3). A point matched to a blob counts once
as an inlier (fitness) and twice as a residual.

Weights: Geman-McClure, w = (k^2 / (k^2 + r^2))^2 with k a third of the threshold, over
the point's variance (range sigma of the mean + plane thickness + model floor), so a
close, sharp point counts more than a far, noisy one. One kernel pass builds H and g for
all six parameters; planar mode keeps x, y, yaw. Degenerate directions are projected out
(`degeneracy`), the geometry's information is divided by the residuals' chi-square per
degree of freedom where it exceeds 1 (a scan noisier than modelled, as a real 2-D laser
log's, weighs less against the prior), the prior's information is added, and the step
is solved.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from scanmap.registration.config import RegistrationConfig
from scanmap.registration.degeneracy import Degeneracy, analyse_degeneracy
from scanmap.registration.lie import PLANAR_AXES, between, retract
from scanmap.registration.local_map import LINE, PLANE, LocalMap
from scanmap.registration.preprocess import Source, blob_flag
from scanmap.registration.prior import Prior
from scanmap.registration.voxel_hash import table_find, voxel_key

ALL_AXES = np.arange(6)
_ROTATIONS = np.array([False, False, False, True, True, True])


@dataclass(frozen=True, eq=False)
class Alignment:
    """Outcome of Gauss-Newton from one start: pose (map-local), statistics, degeneracy."""

    pose: np.ndarray
    covariance: np.ndarray  # 6x6, zero outside the estimated axes
    inliers: int
    inlier_rmse: float
    degeneracy: Degeneracy
    iterations: int
    finite: bool


@njit(cache=True, nogil=True)
def normal_equations(src, src_normals, src_var, rotation, translation, table_keys,
                     table_values, means, normals, plane_var, flags, flag, spread_var,
                     blob_flag, inv_voxel, rings_xy, rings_z, max_dist, kappa, var_floor,
                     min_cos):
    """H (6x6), g (6) and [residuals, sum r^2, sum w r^2, sum w, inlier points] of the
    point-to-plane cost (two residuals for a point matched to a blob)."""
    hessian = np.zeros((6, 6))
    gradient = np.zeros(6)
    stats = np.zeros(5)
    jac = np.zeros(6)
    k2 = kappa * kappa
    for i in range(src.shape[0]):
        px, py, pz = src[i, 0], src[i, 1], src[i, 2]
        qx = rotation[0, 0] * px + rotation[0, 1] * py + rotation[0, 2] * pz + translation[0]
        qy = rotation[1, 0] * px + rotation[1, 1] * py + rotation[1, 2] * pz + translation[1]
        qz = rotation[2, 0] * px + rotation[2, 1] * py + rotation[2, 2] * pz + translation[2]
        sx, sy, sz = src_normals[i, 0], src_normals[i, 1], src_normals[i, 2]
        ux = rotation[0, 0] * sx + rotation[0, 1] * sy + rotation[0, 2] * sz
        uy = rotation[1, 0] * sx + rotation[1, 1] * sy + rotation[1, 2] * sz
        uz = rotation[2, 0] * sx + rotation[2, 1] * sy + rotation[2, 2] * sz
        known = sx != 0.0 or sy != 0.0 or sz != 0.0
        # The 2r cells per axis whose centres bracket the point (2x2x2 for r = 1).
        ix = math.floor(qx * inv_voxel - 0.5)
        iy = math.floor(qy * inv_voxel - 0.5)
        iz = math.floor(qz * inv_voxel - 0.5)
        best = -1
        best_d2 = np.inf
        for dx in range(1 - rings_xy, rings_xy + 1):
            for dy in range(1 - rings_xy, rings_xy + 1):
                for dz in range(1 - rings_z, rings_z + 1):
                    key = voxel_key(ix + dx, iy + dy, iz + dz)
                    if key < 0:
                        continue
                    j = table_find(table_keys, table_values, key)
                    if j < 0 or (flags[j] & (flag | blob_flag)) == 0:
                        continue
                    if known and flags[j] & flag and abs(
                            ux * normals[j, 0] + uy * normals[j, 1] + uz * normals[j, 2]) \
                            < min_cos:
                        continue  # another surface: a wall's point never matches a jamb
                    ex, ey, ez = qx - means[j, 0], qy - means[j, 1], qz - means[j, 2]
                    d2 = ex * ex + ey * ey + ez * ez
                    if d2 < best_d2:
                        best_d2 = d2
                        best = j
        if best < 0:
            continue
        ex, ey, ez = qx - means[best, 0], qy - means[best, 1], qz - means[best, 2]
        # A wall's point: its distance to the wall. A blob's: its offsets along the blob's
        # narrowest and widest spread, each weighed by the spread's variance in it.
        parts = 1 if flags[best] & flag else 2
        if parts == 2 and ex * ex + ey * ey > max_dist * max_dist:
            continue
        matched = False
        for part in range(parts):
            nx, ny, nz = normals[best, 0], normals[best, 1], normals[best, 2]
            var = plane_var[best]
            if part == 1:
                nx, ny, var = -ny, nx, spread_var[best]
            r = nx * ex + ny * ey + nz * ez
            if abs(r) > max_dist:
                continue
            # m = R^T n (normal in base_link); J = [m, p x m].
            mx = rotation[0, 0] * nx + rotation[1, 0] * ny + rotation[2, 0] * nz
            my = rotation[0, 1] * nx + rotation[1, 1] * ny + rotation[2, 1] * nz
            mz = rotation[0, 2] * nx + rotation[1, 2] * ny + rotation[2, 2] * nz
            jac[0], jac[1], jac[2] = mx, my, mz
            jac[3] = py * mz - pz * my
            jac[4] = pz * mx - px * mz
            jac[5] = px * my - py * mx
            robust = k2 / (k2 + r * r)
            w = robust * robust / (src_var[i] + var + var_floor)
            for a in range(6):
                wa = w * jac[a]
                gradient[a] += wa * r
                for b in range(a, 6):
                    hessian[a, b] += wa * jac[b]
            stats[0] += 1.0
            stats[1] += r * r
            stats[2] += w * r * r
            stats[3] += w
            matched = True
        if matched:
            stats[4] += 1.0
    for a in range(6):
        for b in range(a):
            hessian[a, b] = hessian[b, a]
    return hessian, gradient, stats


def _map_arrays(local_map: LocalMap, config: RegistrationConfig) -> tuple:
    """Means, normals, normal variances, flags, the usable flag and the blob flag (blobs
    count in planar mode on 2-D scans only: on the 3-D scanner's, a voxel that is no wall
    is floor or a table top, which cannot move x, y or yaw)."""
    n = len(local_map)
    if config.planar:
        return (local_map.means[:n], local_map.line_normals[:n], local_map.line_var[:n],
                local_map.flags[:n], LINE, blob_flag(config))
    return (local_map.means[:n], local_map.normals[:n], local_map.plane_var[:n],
            local_map.flags[:n], PLANE, 0)


def evaluate(source: Source, local_map: LocalMap, pose: np.ndarray, threshold: float,
             config: RegistrationConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(H 6x6, g 6, stats) of the cost at `pose` (map-local) with correspondence `threshold`."""
    means, normals, var, flags, flag, blobs = _map_arrays(local_map, config)
    voxel = local_map.voxel_size
    rings = 1 if threshold <= voxel else 2
    return normal_equations(source.points, source.normals, source.variance,
                            np.ascontiguousarray(pose[:3, :3]), np.ascontiguousarray(pose[:3, 3]),
                            local_map.table_keys, local_map.table_values, means, normals, var,
                            flags, flag, local_map.spread_var[:len(local_map)], blobs,
                            1.0 / voxel, rings, 1, threshold, threshold / 3.0,
                            config.sigma_floor ** 2, np.cos(config.max_normal_angle))


def align(source: Source, local_map: LocalMap, start: np.ndarray, prior: Prior,
          threshold: float, config: RegistrationConfig) -> Alignment:
    """Gauss-Newton from `start` (map-local 4x4) to the pose minimising geometry + prior.

    Two stages: with the correspondence `threshold` (as wrong as the guess may be), then
    with a fine one (three times the first stage's inlier RMS, at least min_threshold),
    so that distant wrong matches, tolerated while the pose was uncertain, no longer pull
    on it. Fitness counts inliers at `threshold`.
    """
    axes = PLANAR_AXES if config.planar else ALL_AXES
    lever = float(np.sqrt(np.mean(np.sum(source.points[:, :2] ** 2, axis=1)))) \
        if len(source) else 1.0
    pose, iterations = _gauss_newton(source, local_map, start, prior, threshold, config, axes,
                                     lever)
    fine = threshold
    stats = np.zeros(5)
    if np.isfinite(pose).all():
        _, _, stats = evaluate(source, local_map, pose, threshold, config)
        if stats[0] > 0:
            fine = float(np.clip(3.0 * np.sqrt(stats[1] / stats[0]), config.min_threshold,
                                 threshold))
        if fine < threshold:
            pose, more = _gauss_newton(source, local_map, pose, prior, fine, config, axes, lever)
            iterations += more
    finite = bool(np.isfinite(pose).all())
    if not finite:
        pose = prior.pose.copy()  # reported as diverged; keep the numbers finite
    hessian, gradient, fine_stats = evaluate(source, local_map, pose, fine, config)
    h = hessian[np.ix_(axes, axes)]
    degeneracy = _degeneracy(h, fine_stats, lever, axes, config)
    h, _ = degeneracy.project(h, gradient[axes])
    if finite and fine < threshold:
        _, _, stats = evaluate(source, local_map, pose, threshold, config)
    return _alignment(pose, h, prior.information(axes), fine_stats, int(stats[4]), degeneracy,
                      iterations, finite, axes)


def _degeneracy(h: np.ndarray, stats: np.ndarray, lever: float, axes: np.ndarray,
                config: RegistrationConfig) -> Degeneracy:
    return analyse_degeneracy(h, stats[3] / max(stats[0], 1.0), lever, _ROTATIONS[axes],
                              config.min_constraint)


def _gauss_newton(source: Source, local_map: LocalMap, pose: np.ndarray, prior: Prior,
                  threshold: float, config: RegistrationConfig, axes: np.ndarray,
                  lever: float) -> tuple[np.ndarray, int]:
    """Iterate to convergence at a fixed threshold: (pose, iterations); NaN pose if blown."""
    rotations = _ROTATIONS[axes]
    information = prior.information(axes)
    for iterations in range(1, config.max_iterations + 1):
        hessian, gradient, stats = evaluate(source, local_map, pose, threshold, config)
        h = hessian[np.ix_(axes, axes)]
        h, g = _degeneracy(h, stats, lever, axes, config).project(h, gradient[axes])
        scale = _noise_scale(stats, len(axes))
        h, g = h / scale, g / scale
        error = between(prior.pose, pose)[axes]
        step = np.linalg.solve(h + information, -(g + information @ error))
        if not np.isfinite(step).all():
            return np.full((4, 4), np.nan), iterations
        delta = np.zeros(6)
        delta[axes] = step
        pose = retract(pose, delta)
        if np.linalg.norm(step[~rotations]) < config.tolerance \
                and np.linalg.norm(step[rotations]) < config.tolerance:
            break
    return pose, iterations


def _noise_scale(stats: np.ndarray, dof: int) -> float:
    """How much larger the residuals are than their modelled sigmas (chi-square per degree
    of freedom, at least 1): the geometry's information is divided by it, so a scan
    noisier than modelled weighs less against the prior."""
    inliers = int(stats[0])
    return max(1.0, stats[2] / (inliers - dof)) if inliers > dof else 1.0


def _alignment(pose, h, information, stats, inliers, degeneracy, iterations, finite,
               axes) -> Alignment:
    fine_inliers = int(stats[0])
    covariance = np.zeros((6, 6))
    covariance[np.ix_(axes, axes)] = np.linalg.inv(h / _noise_scale(stats, len(axes))
                                                   + information)
    return Alignment(pose=pose, covariance=covariance, inliers=inliers,
                     inlier_rmse=float(np.sqrt(stats[1] / fine_inliers)) if fine_inliers
                     else float("nan"),
                     degeneracy=degeneracy, iterations=iterations, finite=finite)
