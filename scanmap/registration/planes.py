"""Closed-form eigen-analysis of small symmetric matrices, for plane and line fits in kernels.

A voxel's points give a 3x3 covariance: the eigenvector of its smallest eigenvalue is the
surface normal, and the ratio of the two smallest eigenvalues says how planar the points
are. In planar registration only the xy covariance (2x2) matters: a vertical wall seen
from above is a line. LAPACK costs microseconds per call; these closed forms cost tens
of nanoseconds, and a scan refreshes thousands of voxels.
"""

from __future__ import annotations

import math

from numba import njit

from scanmap.registration.voxel_hash import table_find, voxel_key


@njit(cache=True, nogil=True)
def eigen_sym2(a: float, b: float, c: float) -> tuple[float, float, float, float]:
    """Eigen of [[a, b], [b, c]]: (small, large, nx, ny), (nx, ny) the unit vector of small."""
    half_trace = 0.5 * (a + c)
    root = math.sqrt(0.25 * (a - c) * (a - c) + b * b)
    small, large = half_trace - root, half_trace + root
    # Two candidate vectors in the null space of (M - small I); take the better conditioned.
    x1, y1 = b, small - a
    x2, y2 = small - c, b
    n1, n2 = x1 * x1 + y1 * y1, x2 * x2 + y2 * y2
    if n1 >= n2 and n1 > 0.0:
        s = 1.0 / math.sqrt(n1)
        return small, large, x1 * s, y1 * s
    if n2 > 0.0:
        s = 1.0 / math.sqrt(n2)
        return small, large, x2 * s, y2 * s
    return small, large, 1.0, 0.0  # isotropic: any direction


@njit(cache=True, nogil=True)
def eigen_sym3(xx: float, xy: float, xz: float, yy: float, yz: float,
               zz: float) -> tuple[float, float, float, float, float, float]:
    """Eigen of a symmetric 3x3: (l0 <= l1 <= l2, nx, ny, nz) with n the unit vector of l0.

    Trigonometric solution for the eigenvalues (Smith 1961), then the normal as the
    longest cross product of two rows of (M - l0 I).
    """
    off = xy * xy + xz * xz + yz * yz
    q = (xx + yy + zz) / 3.0
    dx, dy, dz = xx - q, yy - q, zz - q
    p2 = dx * dx + dy * dy + dz * dz + 2.0 * off
    if p2 <= 0.0:
        return q, q, q, 0.0, 0.0, 1.0  # isotropic (or zero): any direction
    p = math.sqrt(p2 / 6.0)
    inv = 1.0 / p
    bxx, byy, bzz = dx * inv, dy * inv, dz * inv
    bxy, bxz, byz = xy * inv, xz * inv, yz * inv
    r = 0.5 * (bxx * (byy * bzz - byz * byz) - bxy * (bxy * bzz - byz * bxz)
               + bxz * (bxy * byz - byy * bxz))
    r = min(1.0, max(-1.0, r))
    phi = math.acos(r) / 3.0
    l2 = q + 2.0 * p * math.cos(phi)
    l0 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    l1 = 3.0 * q - l0 - l2
    # Rows of M - l0 I; the normal is orthogonal to all of them.
    r0x, r0y, r0z = xx - l0, xy, xz
    r1x, r1y, r1z = xy, yy - l0, yz
    r2x, r2y, r2z = xz, yz, zz - l0
    best, nx, ny, nz = 0.0, 0.0, 0.0, 1.0
    for ax, ay, az, bx, by, bz in ((r0x, r0y, r0z, r1x, r1y, r1z),
                                   (r0x, r0y, r0z, r2x, r2y, r2z),
                                   (r1x, r1y, r1z, r2x, r2y, r2z)):
        cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        norm = cx * cx + cy * cy + cz * cz
        if norm > best:
            best, nx, ny, nz = norm, cx, cy, cz
    if best > 0.0:
        s = 1.0 / math.sqrt(best)
        nx, ny, nz = nx * s, ny * s, nz * s
    return l0, l1, l2, nx, ny, nz


PLANE = 1  # the voxel's points are a plane in 3-D (normal valid)
LINE = 2   # the voxel is a wall: its horizontal line normal is valid
BLOB = 4   # 2-D scans, no line (a post, a leg, a corner): its 2-D spread is valid
_NOISE_SIGMAS = 3.0
_THICKNESS_FLOOR = 0.002  # m: surfaces are not perfect planes


@njit(cache=True, nogil=True)
def accumulate(counts, sums, squares, noise, slot, x, y, z, variance):
    """Add a point (relative to its voxel's centre, range `variance`) to voxel `slot`."""
    counts[slot] += 1.0
    noise[slot] += variance
    sums[slot, 0] += x
    sums[slot, 1] += y
    sums[slot, 2] += z
    squares[slot, 0] += x * x
    squares[slot, 1] += x * y
    squares[slot, 2] += x * z
    squares[slot, 3] += y * y
    squares[slot, 4] += y * z
    squares[slot, 5] += z * z


@njit(cache=True, nogil=True)
def fit_voxel(n, sums, squares, noise, voxel, min_points, flatness, scans_2d, normal,
              line_normal):
    """Shape of a set of points (a voxel or a neighbourhood): (flags, plane var, wall var,
    spread var).

    A shape needs `min_points`, a spread of at least a fifth of the voxel, and a
    thickness its points' range noise explains (at most 3 sigma, `noise` being their
    summed variance, plus a 2 mm floor) and at most `flatness` times the spread's: a
    corner or a blob is thicker.
    PLANE: the 3-D points are a plane; its unit normal goes into `normal`.
    LINE (a wall): seen from above, the points are a line, and they rise (z spread of at
    least a fifth of the voxel), so that neither the floor nor a table top qualifies; the
    horizontal unit normal goes into `line_normal`. A wall needs no second direction in
    3-D: one laser stripe across it (the reference scanner's stripes are 7 deg apart,
    12 cm at 1 m) already fixes its trace. 2-D laser scans (`scans_2d`: all points at one
    height) have no height to test: there a straight footprint is a wall.
    BLOB (2-D scans only): any other shape. Every return of a horizontal 2-D scan lies on
    something upright, so points that are no line are still a fixed place in the plane (a
    post, a table leg, a corner, clutter): `line_normal` and the wall variance then hold
    the direction and variance of its narrowest spread, the spread variance that of its
    widest, for a point-to-distribution match.
    """
    flags = 0
    plane_var = 0.0
    line_var = 0.0
    spread_var = 0.0
    if n < min_points:
        return flags, plane_var, line_var, spread_var
    mx, my, mz = sums[0] / n, sums[1] / n, sums[2] / n
    xx = squares[0] / n - mx * mx
    xy = squares[1] / n - mx * my
    yy = squares[3] / n - my * my
    zz = squares[5] / n - mz * mz
    min_spread = (0.2 * voxel) ** 2 / 12.0
    max_thickness = _NOISE_SIGMAS ** 2 * noise / n + _THICKNESS_FLOOR ** 2
    small, large, lx, ly = eigen_sym2(xx, xy, yy)
    if small <= min(flatness * large, max_thickness) and large >= min_spread \
            and (scans_2d or zz >= min_spread):
        flags |= LINE
    elif scans_2d:
        flags |= BLOB
        spread_var = max(large, 0.0)
    if flags:
        line_normal[0], line_normal[1], line_normal[2] = lx, ly, 0.0
        line_var = max(small, 0.0)
    if scans_2d:
        return flags, plane_var, line_var, spread_var
    xz = squares[2] / n - mx * mz
    yz = squares[4] / n - my * mz
    l0, l1, _, nx, ny, nz = eigen_sym3(xx, xy, xz, yy, yz, zz)
    if l0 <= min(flatness * l1, max_thickness) and l1 >= min_spread:
        flags |= PLANE
        normal[0], normal[1], normal[2] = nx, ny, nz
        plane_var = max(l0, 0.0)
    return flags, plane_var, line_var, spread_var


SPARSE_REACH = 2  # voxels: a sparse 2-D neighbourhood is widened to this half-width


@njit(cache=True, nogil=True)
def pool_shape(ix, iy, iz, voxel, keys, values, counts, sums, squares, noise, min_points,
               scans_2d, pooled_sums, pooled_squares):
    """Statistics of the neighbourhood that judges voxel (ix, iy, iz)'s shape.

    Its 6 face neighbours; in a 2-D scan where they hold fewer than `min_points`, the
    (2 SPARSE_REACH + 1)^2 square around it in the scan plane. A 2-D laser's beams are
    1 deg apart, 10 cm at 6 m: beyond that each 10 cm voxel holds one point of a wall
    per scan, and a wall seen once or twice would otherwise have no line to match. The
    widened square is 0.5 m of wall, still straight; a corner inside it fails the
    flatness test as before.
    """
    n, pooled_noise = pool_neighbours(ix, iy, iz, voxel, keys, values, counts, sums,
                                      squares, noise, pooled_sums, pooled_squares, 0)
    if scans_2d and n < min_points:
        n, pooled_noise = pool_neighbours(ix, iy, iz, voxel, keys, values, counts, sums,
                                          squares, noise, pooled_sums, pooled_squares,
                                          SPARSE_REACH)
    return n, pooled_noise


@njit(cache=True, nogil=True)
def pool_neighbours(ix, iy, iz, voxel, keys, values, counts, sums, squares, noise,
                    pooled_sums, pooled_squares, reach):
    """Statistics of voxel (ix, iy, iz) and its neighbours, relative to its centre.

    reach 0: its 6 face neighbours; reach r > 0: the voxels within r in x and y in its
    own z layer (a 2-D scan's plane). Returns (count, summed noise variance); writes
    sums (3) and squares (6) into the pooled arrays.
    A voxel's own points cannot tell a real surface from a sliver cut off an edge by the
    grid; its neighbourhood can: around an edge it is no plane.
    """
    n = 0.0
    pooled_noise = 0.0
    pooled_sums[:] = 0.0
    pooled_squares[:] = 0.0
    side = max(reach, 1)
    for dx in range(-side, side + 1):
        for dy in range(-side, side + 1):
            for dz in range(-1, 2):
                if (reach == 0 and abs(dx) + abs(dy) + abs(dz) > 1) or (reach > 0 and dz != 0):
                    continue
                key = voxel_key(ix + dx, iy + dy, iz + dz)
                if key < 0:
                    continue
                j = table_find(keys, values, key)
                if j < 0:
                    continue
                c = counts[j]
                ox, oy, oz = dx * voxel, dy * voxel, dz * voxel
                sx, sy, sz = sums[j, 0], sums[j, 1], sums[j, 2]
                n += c
                pooled_noise += noise[j]
                pooled_sums[0] += sx + c * ox
                pooled_sums[1] += sy + c * oy
                pooled_sums[2] += sz + c * oz
                pooled_squares[0] += squares[j, 0] + 2.0 * sx * ox + c * ox * ox
                pooled_squares[1] += squares[j, 1] + sx * oy + ox * sy + c * ox * oy
                pooled_squares[2] += squares[j, 2] + sx * oz + ox * sz + c * ox * oz
                pooled_squares[3] += squares[j, 3] + 2.0 * sy * oy + c * oy * oy
                pooled_squares[4] += squares[j, 4] + sy * oz + oy * sz + c * oy * oz
                pooled_squares[5] += squares[j, 5] + 2.0 * sz * oz + c * oz * oz
    return n, pooled_noise
