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

from dataclasses import dataclass

import numpy as np

from scanmap.registration._kernels import gauss_newton, normal_equations
from scanmap.registration.config import RegistrationConfig
from scanmap.registration.degeneracy import Degeneracy, analyse_degeneracy
from scanmap.registration.lie import PLANAR_AXES
from scanmap.registration.local_map import LINE, PLANE, LocalMap
from scanmap.registration.preprocess import Source, blob_flag
from scanmap.registration.prior import Prior

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


def _map_arrays(local_map: LocalMap, threshold: float, config: RegistrationConfig) -> tuple:
    """The kernels' map arguments: the voxel table; means, normals, normal variances,
    flags, the usable flag, the blobs' spread variances and flag (blobs count in planar
    mode on 2-D scans only: on the 3-D scanner's, a voxel that is no wall is floor or a
    table top, which cannot move x, y or yaw); 1 / voxel and the candidate rings in x-y
    (two when `threshold` exceeds a voxel)."""
    n = len(local_map)
    voxel = local_map.voxel_size
    if config.planar:
        surfaces = (local_map.means[:n], local_map.line_normals[:n], local_map.line_var[:n],
                    local_map.flags[:n], LINE, local_map.spread_var[:n], blob_flag(config))
    else:
        surfaces = (local_map.means[:n], local_map.normals[:n], local_map.plane_var[:n],
                    local_map.flags[:n], PLANE, local_map.spread_var[:n], 0)
    return (local_map.table_keys, local_map.table_values, *surfaces, 1.0 / voxel,
            1 if threshold <= voxel else 2)


def evaluate(source: Source, local_map: LocalMap, pose: np.ndarray, threshold: float,
             config: RegistrationConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(H 6x6, g 6, stats) of the cost at `pose` (map-local) with correspondence `threshold`."""
    return normal_equations(source.points, source.normals, source.variance,
                            np.ascontiguousarray(pose[:3, :3]), np.ascontiguousarray(pose[:3, 3]),
                            *_map_arrays(local_map, threshold, config), 1, threshold,
                            threshold / 3.0, config.sigma_floor ** 2,
                            np.cos(config.max_normal_angle))


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
    """Iterate to convergence at a fixed threshold: (pose, iterations); NaN pose if blown
    (`_kernels.gauss_newton`)."""
    pose, iterations = gauss_newton(
        source.points, source.normals, source.variance,
        *_map_arrays(local_map, threshold, config), threshold, config.sigma_floor ** 2,
        np.cos(config.max_normal_angle), np.ascontiguousarray(pose, dtype=np.float64),
        np.ascontiguousarray(prior.pose, dtype=np.float64), prior.information(axes), axes,
        _ROTATIONS[axes], lever, config.min_constraint, config.max_iterations,
        config.tolerance)
    return pose, int(iterations)


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
