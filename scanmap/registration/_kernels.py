"""Numba kernels of scan-to-map ICP: the normal equations and the Gauss-Newton loop.

`normal_equations` builds H and g of the point-to-plane (and point-to-blob) cost in one
pass over the source points (the model is in `icp`'s docstring). `gauss_newton` runs the
whole loop at one correspondence distance in compiled code: per iteration the kernel
takes about 40 us on a 2-D laser scan, the rest of an iteration in Python (the
degeneracy's eigen-analysis, the prior's error, the solve, the pose update) took 330 us.
Its plain reference, built from `lie` and `degeneracy`, is in the tests.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from scanmap.registration.lie import so3_exp, so3_log
from scanmap.registration.voxel_hash import table_find, voxel_key


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


@njit(cache=True, nogil=True)
def _between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """6-vector log(a^-1 b) in a's body frame (`lie.between`)."""
    rotation = np.ascontiguousarray(a[:3, :3].T)
    out = np.empty(6)
    out[:3] = rotation @ (b[:3, 3] - a[:3, 3])
    out[3:] = so3_log(rotation @ np.ascontiguousarray(b[:3, :3]))
    return out


@njit(cache=True, nogil=True)
def _project_degenerate(h: np.ndarray, g: np.ndarray, unit_weight: float, scale: np.ndarray,
                        min_constraint: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, g) without the directions whose scaled information is below `min_constraint`
    well-aligned points (`degeneracy.analyse_degeneracy` and `Degeneracy.project`)."""
    outer = np.outer(scale, scale)
    scaled = h / outer / max(unit_weight, 1e-300)
    values, vectors = np.linalg.eigh(0.5 * (scaled + scaled.T))
    if not (values < min_constraint).any():
        return h, g
    good = np.ascontiguousarray(vectors[:, values >= min_constraint])
    projector = good @ good.T
    return (projector @ (h / outer) @ projector) * outer, (projector @ (g / scale)) * scale


@njit(cache=True, nogil=True)
def gauss_newton(src, src_normals, src_var, table_keys, table_values, means, normals,
                 plane_var, flags, flag, spread_var, blob_flag, inv_voxel, rings_xy, max_dist,
                 var_floor, min_cos, pose, prior_pose, information, axes, rotations, lever,
                 min_constraint, max_iterations, tolerance):
    """Gauss-Newton at a fixed correspondence distance (`icp.align`): (pose, iterations),
    a NaN pose when a step is not finite. Each iteration: the normal equations at the
    pose, over the estimated `axes` (`rotations` marks theirs); the degenerate directions
    projected out; the geometry divided by the residuals' chi-square per degree of
    freedom where above 1; the prior's `information` on the error from `prior_pose`; the
    step solved and applied on the right. Stops when the step's translation and rotation
    are both below `tolerance`; a NaN or inf on the way (which numpy's solve would carry
    into the step) gives the NaN pose at once."""
    dof = axes.shape[0]
    scale = np.ones(dof)
    for a in range(dof):
        if rotations[a]:
            scale[a] = max(lever, 1e-3)
    pose = pose.copy()
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        hessian, gradient, stats = normal_equations(
            src, src_normals, src_var, np.ascontiguousarray(pose[:3, :3]),
            np.ascontiguousarray(pose[:3, 3]), table_keys, table_values, means, normals,
            plane_var, flags, flag, spread_var, blob_flag, inv_voxel, rings_xy, 1, max_dist,
            max_dist / 3.0, var_floor, min_cos)
        h = np.empty((dof, dof))
        g = np.empty(dof)
        for a in range(dof):
            g[a] = gradient[axes[a]]
            for b in range(dof):
                h[a, b] = hessian[axes[a], axes[b]]
        error = _between(prior_pose, pose)[axes]
        if not (np.isfinite(h).all() and np.isfinite(g).all() and np.isfinite(error).all()
                and np.isfinite(information).all()):
            return np.full((4, 4), np.nan), iterations  # LAPACK here refuses NaN and inf
        h, g = _project_degenerate(h, g, stats[3] / max(stats[0], 1.0), scale, min_constraint)
        inliers = int(stats[0])
        noise = max(1.0, stats[2] / (inliers - dof)) if inliers > dof else 1.0
        step = np.linalg.solve(h / noise + information, -(g / noise + information @ error))
        if not np.isfinite(step).all():
            return np.full((4, 4), np.nan), iterations
        delta = np.zeros(6)
        delta[axes] = step
        increment = np.eye(4)
        increment[:3, :3] = so3_exp(delta[3:])
        increment[:3, 3] = delta[:3]
        pose = pose @ increment
        moved = turned = 0.0
        for a in range(dof):
            if rotations[a]:
                turned += step[a] * step[a]
            else:
                moved += step[a] * step[a]
        if math.sqrt(moved) < tolerance and math.sqrt(turned) < tolerance:
            break
    return pose, iterations
