"""Numba kernels of the navigation layers: floor segmentation, obstacle queries and the
exact Euclidean distance transform. Called through `floor`, `obstacles` and
`distance_field`; every kernel releases the GIL (`nogil`) so queries run beside mapping.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from numba import njit

from scanmap.grid import _kernels as gk

UNKNOWN, FREE, OBSTACLE, DROP_OFF = 0, 1, 2, 3  # cell states of `Segmentation.state`
# Queries farther than this (m) from the map origin, or not finite, are invalid: a pose
# from a diverged filter. It keeps every cell index and squared distance of a query
# exact in int64 and float64.
COORDINATE_LIMIT = 1e6
# How far (cells) an obstacle point may stick out of its cell (float32 rounding of points
# on a cell's edge), and the reach from a cell's centre that covers such a point.
CELL_SLACK = 1e-4
CELL_REACH = 0.7073  # >= sqrt(2) * (0.5 + CELL_SLACK)


@njit(cache=True, nogil=True)
def _nearest_rows(features: np.ndarray, rows: np.ndarray) -> None:
    """rows[y, x] = row of the feature nearest to (y, x) in column x, or -1 if none."""
    ny, nx = features.shape
    for x in range(nx):
        rows[0, x] = 0 if features[0, x] else -1
    for y in range(1, ny):
        for x in range(nx):
            rows[y, x] = y if features[y, x] else rows[y - 1, x]
    for y in range(ny - 2, -1, -1):
        for x in range(nx):
            below = rows[y + 1, x]
            if below >= 0 and (rows[y, x] < 0 or below - y < y - rows[y, x]):
                rows[y, x] = below


@njit(cache=True, nogil=True)
def edt_kernel(features: np.ndarray, distance: np.ndarray, nearest: np.ndarray,
               pad: int) -> None:
    """Distance (cells, inf without features) and flat index of the nearest feature (-1)
    in the array padded by `pad` cells on every side.

    The envelope's breakpoints are kept as exact integer fractions (numerator and
    positive denominator), so the pass needs no division and no rounding.
    """
    ny, nx = features.shape
    width = nx + 2 * pad
    rows = np.empty((ny, nx), np.int32)
    _nearest_rows(features, rows)
    v = np.empty(nx, np.int64)  # columns of the parabolas in the envelope
    z_num = np.empty(nx + 1, np.int64)  # breakpoint k is z_num[k] / z_den[k]
    z_den = np.empty(nx + 1, np.int64)
    f = np.empty(nx, np.int64)  # squared distance down the column
    for y in range(ny):
        k = -1
        for q in range(nx):
            r = rows[y, q]
            if r < 0:
                continue
            f[q] = (y - r) * (y - r)
            if k < 0:
                k = 0
                v[0] = q
                z_num[0], z_den[0] = -1, 0  # -inf
                z_num[1], z_den[1] = 1, 0  # +inf
                continue
            while True:  # drop parabolas the new one hides: s <= z[k]
                c = v[k]
                num = (f[q] + q * q) - (f[c] + c * c)
                den = 2 * (q - c)
                if z_den[k] == 0 or num * z_den[k] > z_num[k] * den:
                    break
                k -= 1
            k += 1
            v[k] = q
            z_num[k], z_den[k] = num, den
            z_num[k + 1], z_den[k + 1] = 1, 0
        if k < 0:
            for q in range(nx):
                distance[y, q] = np.inf
                nearest[y, q] = -1
            continue
        k = 0
        for q in range(nx):
            while z_den[k + 1] != 0 and z_num[k + 1] < q * z_den[k + 1]:
                k += 1
            c = v[k]
            distance[y, q] = np.sqrt((q - c) * (q - c) + f[c])
            nearest[y, q] = (rows[y, c] + pad) * width + c + pad


@njit(cache=True, nogil=True)
def floor_candidates(levels: np.ndarray, nlev: np.ndarray, thickness: float,
                     clearance: float) -> np.ndarray:
    """Height of each cell's lowest level when it can be floor, else NaN: thin, and with
    `clearance` of space above it (not the foot of a wall or box sharing the cell)."""
    ny, nx = nlev.shape
    out = np.full((ny, nx), np.nan, np.float32)
    for y in range(ny):
        for x in range(nx):
            if nlev[y, x] > 0:
                lo, hi = levels[y, x, 0, gk.LO], levels[y, x, 0, gk.HI]
                if hi - lo <= thickness and (nlev[y, x] == 1
                                             or levels[y, x, 1, gk.LO] - hi >= clearance):
                    out[y, x] = 0.5 * (lo + hi)
    return out


@njit(cache=True, nogil=True)
def mean_hit_heights(levels: np.ndarray, nlev: np.ndarray, candidates: np.ndarray,
                     span: float) -> np.ndarray:
    """The height of each floor candidate's mean hit (its lowest level's), to go with the
    mean hit's x and y in `local_slope`: the middle of the level's heights lies up to a
    centimetre off the plane there on a 15 deg ramp whose cells laser lines cross
    unevenly. Only where the lowest levels of the cell and of its 8 neighbours each span
    at most `span` (as much as a surface one may drive on rises across a cell, and the
    noise of its hits): a taller one holds a step's face, whose mean hit tells where
    rays met the face (a chain of such cells down a 6 cm step came out just under 15
    deg), and beside it a cell's mean moves it in or out of a step's reach of the face's
    (cells of a step's edge in or out of the floor, turning a step's drop-off cells
    unknown). The middle also where the mean lies outside the level's heights (trimmed
    since by rays through its top or bottom, or a level not built from hits)."""
    ny, nx = candidates.shape
    out = candidates.copy()
    for y in range(ny):
        for x in range(nx):
            if np.isnan(candidates[y, x]):
                continue
            one_surface = True
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    if nlev[yy, xx] and levels[yy, xx, 0, gk.HI] - levels[yy, xx, 0, gk.LO] > span:
                        one_surface = False
            mean = levels[y, x, 0, gk.MZ]
            if one_surface and levels[y, x, 0, gk.LO] <= mean <= levels[y, x, 0, gk.HI]:
                out[y, x] = mean
    return out


@njit(cache=True, nogil=True)
def faces_below(levels: np.ndarray, candidates: np.ndarray, step: float) -> np.ndarray:
    """Candidates whose level reaches from a floor beside them more than `step` down: a
    face the robot cannot climb crosses the cell (the edge of a step down, its middle
    no floor height), unlike a level as tall standing on the floor (the remnant of a
    person's feet, not yet cleared)."""
    ny, nx = candidates.shape
    out = np.zeros((ny, nx), np.bool_)
    for y in range(ny):
        for x in range(nx):
            if np.isnan(candidates[y, x]):
                continue
            lo = levels[y, x, 0, gk.LO]
            if levels[y, x, 0, gk.HI] - lo <= step:
                continue
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    if candidates[yy, xx] - lo > step:  # False for NaN
                        out[y, x] = True
    return out


@njit(cache=True, nogil=True)
def cell_points(mask: np.ndarray, heights: np.ndarray, xs: np.ndarray,
                ys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows and columns of the cells of `mask`, row by row (as np.nonzero), and their
    points (N, 3): x and y of the cell centres (`xs`, `ys`), the height; one pass where
    numpy's nonzero, gathers and column_stack took four times as long."""
    ny, nx = mask.shape
    count = 0
    for y in range(ny):
        for x in range(nx):
            count += mask[y, x]
    rows, cols = np.empty(count, np.int64), np.empty(count, np.int64)
    points = np.empty((count, 3))
    i = 0
    for y in range(ny):
        for x in range(nx):
            if mask[y, x]:
                rows[i], cols[i] = y, x
                points[i, 0], points[i, 1], points[i, 2] = xs[x], ys[y], heights[y, x]
                i += 1
    return rows, cols, points


@njit(cache=True, nogil=True)
def level_hypotheses(points: np.ndarray, triples: np.ndarray, min_nz: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC's plane hypotheses: for each triple of row indices into `points` (N, 3), the
    unit normal (z >= 0) of the plane through the three and its first point, kept where
    the three span a plane (|cross product| > 1e-9) whose normal's z is at least
    `min_nz` (near-horizontal). As numpy's cross, norm and division compute them (the
    same values), without their per-call cost on a few hundred triples."""
    normals = np.empty((triples.shape[0], 3))
    anchors = np.empty((triples.shape[0], 3))
    kept = 0
    for t in range(triples.shape[0]):
        a, b, c = points[triples[t, 0]], points[triples[t, 1]], points[triples[t, 2]]
        u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        v0, v1, v2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
        norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if not norm > 1e-9:
            continue
        n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
        if n2 < 0.0:
            n0, n1, n2 = -n0, -n1, -n2
        if n2 >= min_nz:
            normals[kept, 0], normals[kept, 1], normals[kept, 2] = n0, n1, n2
            anchors[kept, 0], anchors[kept, 1], anchors[kept, 2] = a[0], a[1], a[2]
            kept += 1
    return normals[:kept], anchors[:kept]


_SUPPORT_BLOCK = 256  # points `_most_supported` counts between its checks


@njit(cache=True, nogil=True)
def _most_supported(coords: np.ndarray, anchors: np.ndarray, normals: np.ndarray,
                    tolerance: float, confidence: float = 1.0) -> int:
    """RANSAC's score: the index of the hypothesis (a point on it and its unit normal)
    with most points within `tolerance` (the first of equals; `plane_support_reference`
    counts them plainly). coords: (3, N) the points' x, y and z as rows, so that the
    inner loop runs over contiguous arrays and vectorises (four times the speed of
    (N, 3) rows). Each hypothesis is counted in blocks and left once the points left
    could not lift it above the best so far: a hypothesis far off a floor that fills
    the window is left after a quarter of the points or so. Below a `confidence` of 1,
    the hypotheses after the first k are not counted once k draws would have drawn
    three points of the best plane so far at that confidence (the RANSAC bound, k =
    log(1 - confidence) / log(1 - share ** 3), the share of the points on it): the
    hypotheses are random draws, so the later ones are no likelier to be better."""
    xs, ys, zs = coords[0], coords[1], coords[2]
    n = xs.shape[0]
    best, best_count, needed = 0, -1, np.inf
    for h in range(normals.shape[0]):
        n0, n1, n2 = normals[h, 0], normals[h, 1], normals[h, 2]
        offset = n0 * anchors[h, 0] + n1 * anchors[h, 1] + n2 * anchors[h, 2]
        count = 0
        for start in range(0, n, _SUPPORT_BLOCK):
            if count + n - start <= best_count:
                break
            end = min(start + _SUPPORT_BLOCK, n)
            # views: the loop over them vectorises (indexed from `start`, it ran 5 x slower)
            bx, by, bz = xs[start:end], ys[start:end], zs[start:end]
            for i in range(bx.shape[0]):
                count += abs(n0 * bx[i] + n1 * by[i] + n2 * bz[i] - offset) <= tolerance
        if count > best_count:
            best, best_count = h, count
            share = best_count / n
            if confidence < 1.0 and share > 0.0:  # draws that find a triple on the best
                # plane at that confidence (fewer, the more of the points it holds)
                needed = 0.0 if share >= 1.0 else math.log1p(-confidence) / math.log1p(
                    -share ** 3)
        if h + 1 >= needed:
            break
    return best


@njit(cache=True, nogil=True)
def best_plane(coords: np.ndarray, sample: np.ndarray, anchors: np.ndarray,
               normals: np.ndarray, tolerance: float, confidence: float, rounds: int
               ) -> tuple[int, np.ndarray, float]:
    """RANSAC's choice, refined: the hypothesis (a point on it and its unit normal) with
    most of the points `sample` (indices into coords (3, N)) within `tolerance`
    (`_most_supported`, drawn to `confidence`), then `rounds` least-squares fits, each on
    every point within tolerance of the plane before (`plane_moments`; the normal is the
    scatter's least eigenvector, z >= 0). Returns (the fewest points a fit had, unit
    normal, offset); in one call, where numpy's gather, eigh and products cost more than
    the arithmetic on a few thousand cells."""
    subset = np.empty((3, sample.shape[0]))
    for r in range(3):
        for j in range(sample.shape[0]):
            subset[r, j] = coords[r, sample[j]]
    best = _most_supported(subset, anchors, normals, tolerance, confidence)
    normal = normals[best].copy()
    offset = np.dot(normal, anchors[best])
    fewest = coords.shape[1]
    for _ in range(rounds):
        count, centre, scatter = plane_moments(coords, normal, offset, tolerance)
        fewest = min(fewest, count)
        if count < 3:
            break
        normal = np.linalg.eigh(scatter)[1][:, 0].copy()
        if normal[2] < 0.0:
            normal = -normal
        offset = np.dot(normal, centre)
    return fewest, normal, offset


@njit(cache=True, nogil=True)
def plane_moments(coords: np.ndarray, normal: np.ndarray, offset: float,
                  tolerance: float) -> tuple[int, np.ndarray, np.ndarray]:
    """(count, mean (3,), centred scatter matrix (3, 3)) of the points within `tolerance`
    of the plane normal . p = offset, never a NaN or inf one (with tolerance inf: every
    finite point). coords: (3, N) as for `_most_supported`. Two passes, the mean first, so
    points 100 km from the origin keep their millimetres; on 50,000 points 0.47 ms of CPU
    against 5.2 for numpy's mask, copy, mean, centring and product."""
    xs, ys, zs = coords[0], coords[1], coords[2]
    n0, n1, n2 = normal[0], normal[1], normal[2]
    count = 0
    sx = sy = sz = 0.0
    for i in range(xs.shape[0]):
        d = n0 * xs[i] + n1 * ys[i] + n2 * zs[i] - offset  # finite iff the point is
        if abs(d) <= tolerance and math.isfinite(d):
            count += 1
            sx += xs[i]
            sy += ys[i]
            sz += zs[i]
    centre = np.array([sx, sy, sz]) / max(count, 1)
    scatter = np.zeros((3, 3))
    for i in range(xs.shape[0]):
        d = n0 * xs[i] + n1 * ys[i] + n2 * zs[i] - offset
        if abs(d) <= tolerance and math.isfinite(d):
            dx, dy, dz = xs[i] - centre[0], ys[i] - centre[1], zs[i] - centre[2]
            scatter[0, 0] += dx * dx
            scatter[0, 1] += dx * dy
            scatter[0, 2] += dx * dz
            scatter[1, 1] += dy * dy
            scatter[1, 2] += dy * dz
            scatter[2, 2] += dz * dz
    scatter[1, 0], scatter[2, 0], scatter[2, 1] = scatter[0, 1], scatter[0, 2], scatter[1, 2]
    return count, centre, scatter


def plane_support_reference(points: np.ndarray, anchors: np.ndarray, normals: np.ndarray,
                            tolerance: float) -> np.ndarray:
    """Per hypothesis, the points (N, 3) within `tolerance` of it, in numpy, for tests."""
    distances = np.abs((points[None] - anchors[:, None]) @ normals[..., None])[..., 0]
    return (distances <= tolerance).sum(axis=1)


@njit(cache=True, nogil=True)
def ring_heights(labels: np.ndarray, count: int, is_floor: np.ndarray,
                 heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest height of the floor cells 8-adjacent to each labelled patch
    (index = label; +inf and -inf without any)."""
    ny, nx = labels.shape
    low = np.full(count + 1, np.inf)
    high = np.full(count + 1, -np.inf)
    for y in range(ny):
        for x in range(nx):
            if not is_floor[y, x]:
                continue
            h = heights[y, x]
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    label = labels[yy, xx]
                    if label > 0:
                        low[label] = min(low[label], h)
                        high[label] = max(high[label], h)
    return low, high


def ring_heights_reference(labels: np.ndarray, count: int, is_floor: np.ndarray,
                           heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`ring_heights` in numpy and scipy, for tests."""
    from scipy import ndimage

    low, high = np.full(count + 1, np.inf), np.full(count + 1, -np.inf)
    for label in range(1, count + 1):
        ring = ndimage.binary_dilation(labels == label, np.ones((3, 3), bool)) & is_floor
        if ring.any():
            low[label], high[label] = heights[ring].min(), heights[ring].max()
    return low, high


@njit(cache=True, nogil=True)
def floor_gaps(labels: np.ndarray, boxes: np.ndarray, small: np.ndarray,
               near_drop: np.ndarray, nlev: np.ndarray, is_floor: np.ndarray,
               heights: np.ndarray, dips: np.ndarray, step: float) -> np.ndarray:
    """Per label, whether its patch is a gap between floor samples: `small` (its box, x y
    w h, lies 2 cells or more inside the grid), no cell of it in `near_drop`, and the cells
    within its box grown by 2 hold floor, no hit off the floor, no cell of `dips` and floor
    heights differing by at most `step` (NaN among them: not a gap).
    `floor_gaps_reference` is the plain version."""
    out = np.zeros(small.shape[0], np.bool_)
    for label in range(1, small.shape[0]):
        if not small[label]:
            continue
        x0, y0, w, h = boxes[label, 0], boxes[label, 1], boxes[label, 2], boxes[label, 3]
        by_drop = False
        for y in range(y0, y0 + h):
            for x in range(x0, x0 + w):
                by_drop |= labels[y, x] == label and near_drop[y, x]
        if by_drop:
            continue
        floor, stray, odd = False, False, False
        low, high = np.float32(np.inf), np.float32(-np.inf)
        for y in range(y0 - 2, y0 + h + 2):
            for x in range(x0 - 2, x0 + w + 2):
                if is_floor[y, x]:
                    floor = True
                    z = heights[y, x]
                    odd |= np.isnan(z)
                    low, high = min(low, z), max(high, z)
                elif nlev[y, x] > 0:
                    stray = True
                odd |= dips[y, x]
        out[label] = floor and not stray and not odd and high - low <= step
    return out


def floor_gaps_reference(labels: np.ndarray, boxes: np.ndarray, small: np.ndarray,
                         near_drop: np.ndarray, nlev: np.ndarray, is_floor: np.ndarray,
                         heights: np.ndarray, dips: np.ndarray, step: float) -> np.ndarray:
    """`floor_gaps` in numpy, for tests."""
    out = np.zeros(small.shape[0], bool)
    for label in np.flatnonzero(small):
        x, y, w, h = map(int, boxes[label])
        if near_drop[y:y + h, x:x + w][labels[y:y + h, x:x + w] == label].any():
            continue
        around = (slice(y - 2, y + h + 2), slice(x - 2, x + w + 2))
        floor = is_floor[around]
        lying = heights[around][floor]
        out[label] = floor.any() and not ((nlev[around] > 0) & ~floor).any() \
            and not dips[around].any() and lying.max() - lying.min() <= step
    return out


@njit(cache=True, nogil=True)
def touching_floor(heights: np.ndarray, is_floor: np.ndarray, cells: np.ndarray,
                   max_step: float) -> np.ndarray:
    """Those of `cells` with a floor 8-neighbour at most max_step from them in height (NaN
    heights never are): one step of the floor's growth."""
    ny, nx = heights.shape
    out = np.zeros((ny, nx), np.bool_)
    for y in range(ny):  # the neighbours of `cells` only: a step's faces are few
        for x in range(nx):
            if not cells[y, x]:
                continue
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    out[y, x] |= (yy != y or xx != x) and is_floor[yy, xx] \
                        and abs(heights[yy, xx] - heights[y, x]) <= max_step
    return out


def touching_floor_reference(heights: np.ndarray, is_floor: np.ndarray, cells: np.ndarray,
                             max_step: float) -> np.ndarray:
    """`touching_floor` in numpy, for tests."""
    ny, nx = heights.shape
    floor = np.pad(np.where(is_floor, heights, np.nan), 1, constant_values=np.nan)
    out = np.zeros((ny, nx), bool)
    with np.errstate(invalid="ignore"):
        for dy in range(3):
            for dx in range(3):
                if dy != 1 or dx != 1:
                    out |= np.abs(floor[dy:dy + ny, dx:dx + nx] - heights) <= max_step
    return out & cells


@njit(cache=True, nogil=True)
def step_edges(levels: np.ndarray, nlev: np.ndarray, heights: np.ndarray,
               is_floor: np.ndarray, step: float, clearance: float,
               tolerance: float) -> np.ndarray:
    """Cells off the floor holding the edge of a step higher than `step` between two
    floors (the raised end or a side of a ramp above the floor beside it): their solid
    (the lowest level and those above it each less than `clearance` above the last: no
    room for the robot between, as where the rays saw a ramp's side face at 5 cm and its
    surface at 18 cm, and nothing between) spans more than the step, its top lies within
    `tolerance` of the floor height (`heights`) of a cell at most two away (a face on the
    boundary of two cells puts its hits in both), and its bottom no more than `tolerance`
    below the lowest floor at most two cells away: the face from the floor below, or
    only its upper part where the rays saw no more of it."""
    ny, nx = nlev.shape
    out = np.zeros((ny, nx), np.bool_)
    for y in range(ny):
        for x in range(nx):
            n = nlev[y, x]
            if n == 0 or is_floor[y, x]:
                continue
            lo, hi = levels[y, x, 0, gk.LO], levels[y, x, 0, gk.HI]
            for k in range(1, n):
                if levels[y, x, k, gk.LO] - hi >= clearance:
                    break
                hi = max(hi, levels[y, x, k, gk.HI])
            if hi - lo <= step:
                continue
            top, lowest = False, np.inf
            for yy in range(max(y - 2, 0), min(y + 3, ny)):
                for xx in range(max(x - 2, 0), min(x + 3, nx)):
                    if is_floor[yy, xx]:
                        top |= abs(heights[yy, xx] - hi) <= tolerance
                        lowest = min(lowest, heights[yy, xx])
            out[y, x] = top and lo >= lowest - tolerance
    return out


@njit(cache=True, nogil=True)
def rim_cells(levels: np.ndarray, nlev: np.ndarray, edges: np.ndarray, is_floor: np.ndarray,
              floor_height: np.ndarray, max_step: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and tops of the `edges` cells with one level whose mean hit lies in
    its upper quarter, a `floor_height` of the 3 x 3 cells round them within `max_step` of
    that top and none more than `max_step` below it (`floor._model._rims`), row by row. In
    float32 as numpy computes it on the float32 arrays (`tests`' reference)."""
    ny, nx = nlev.shape
    step, quarter = np.float32(max_step), np.float32(0.75)
    count = 0
    rows, cols = np.empty(ny * nx, np.int64), np.empty(ny * nx, np.int64)
    tops = np.empty(ny * nx, np.float32)
    for y in range(ny):
        for x in range(nx):
            if not edges[y, x] or nlev[y, x] != 1:
                continue
            lo, hi = levels[y, x, 0, gk.LO], levels[y, x, 0, gk.HI]
            if not levels[y, x, 0, gk.MZ] >= lo + quarter * (hi - lo):
                continue
            near, below = False, False
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    if is_floor[yy, xx]:
                        other = floor_height[yy, xx]
                        near = near or abs(other - hi) <= step
                        below = below or hi - other > step
            if near and not below:
                rows[count], cols[count], tops[count] = y, x, hi
                count += 1
    return rows[:count], cols[:count], tops[:count]


def rim_cells_reference(levels: np.ndarray, nlev: np.ndarray, edges: np.ndarray,
                        is_floor: np.ndarray, floor_height: np.ndarray, max_step: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`rim_cells` in numpy, for tests."""
    rows, cols = np.nonzero(edges & (nlev == 1))
    level = levels[rows, cols, 0]
    lo, hi, mean = level[:, gk.LO], level[:, gk.HI], level[:, gk.MZ]
    upper = mean >= lo + 0.75 * (hi - lo)
    rows, cols, hi = rows[upper], cols[upper], hi[upper]
    padded = np.pad(np.where(is_floor, floor_height, np.nan), 1, constant_values=np.nan)
    near, below = np.zeros(len(rows), bool), np.zeros(len(rows), bool)
    with np.errstate(invalid="ignore"):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                other = padded[rows + 1 + dy, cols + 1 + dx]
                near |= np.abs(other - hi) <= max_step
                below |= hi - other > max_step
    keep = near & ~below
    return rows[keep], cols[keep], hi[keep]


def step_edges_reference(levels: np.ndarray, nlev: np.ndarray, heights: np.ndarray,
                         is_floor: np.ndarray, step: float, clearance: float,
                         tolerance: float) -> np.ndarray:
    """`step_edges` in numpy, for tests."""
    ny, nx = nlev.shape
    lo, hi = levels[:, :, 0, gk.LO], levels[:, :, 0, gk.HI].copy()
    stacked = np.ones((ny, nx), bool)  # every level so far less than clearance above the last
    for k in range(1, levels.shape[2]):
        stacked &= (nlev > k) & (levels[:, :, k, gk.LO] - hi < clearance)
        hi[stacked] = np.maximum(hi, levels[:, :, k, gk.HI])[stacked]
    spans = (nlev > 0) & ~is_floor & (hi - lo > step)
    floor = np.pad(np.where(is_floor, heights, np.nan), 2, constant_values=np.nan)
    top, lowest = np.zeros((ny, nx), bool), np.full((ny, nx), np.inf)
    with np.errstate(invalid="ignore"):
        for dy in range(5):
            for dx in range(5):
                near = floor[dy:dy + ny, dx:dx + nx]
                top |= np.abs(near - hi) <= tolerance
                lowest = np.fmin(lowest, near)
    return spans & top & (lo >= lowest - tolerance)


@njit(cache=True, nogil=True, inline="always")
def _off_floor(known: np.ndarray, hit: np.ndarray, y: int, x: int, unlit: bool) -> bool:
    """Not known floor at (y, x): a hit, or with `unlit` any cell (False outside the
    grid)."""
    ny, nx = known.shape
    return 0 <= y < ny and 0 <= x < nx and not known[y, x] and (unlit or hit[y, x])


@njit(cache=True, nogil=True, inline="always")
def _inner_corner(known: np.ndarray, hit: np.ndarray, y: int, x: int, dy: int, dx: int,
                  unlit: bool) -> bool:
    """Whether both row and column neighbours of (y, x) on one side of the diagonal
    (dy, dx) are off the floor (`_off_floor`)."""
    return (_off_floor(known, hit, y + dy, x, unlit) and _off_floor(known, hit, y, x - dx, unlit)
            ) or (_off_floor(known, hit, y, x + dx, unlit)
                  and _off_floor(known, hit, y - dy, x, unlit))


NO_SAMPLES = np.zeros((0, 0, 2), np.float32)  # `interpolated`: no sample positions known


@njit(cache=True, nogil=True)
def floor_samples(levels: np.ndarray, nlev: np.ndarray, is_floor: np.ndarray,
                  res: float) -> np.ndarray:
    """`interpolated`'s samples (ny, nx, 2): the mean hit of each floor cell's lowest level,
    x and y offsets from the cell's centre in cells (float32, as numpy divides them), NaN
    off the floor. One pass reading the two fields, where numpy's strided slice of the
    levels, division and masked assignment took ten times as long."""
    ny, nx = nlev.shape
    out = np.full((ny, nx, 2), np.nan, np.float32)
    cell = np.float32(res)
    for y in range(ny):
        for x in range(nx):
            if is_floor[y, x] and nlev[y, x] > 0:
                out[y, x, 0] = levels[y, x, 0, gk.MX] / cell
                out[y, x, 1] = levels[y, x, 0, gk.MY] / cell
    return out


@njit(cache=True, nogil=True, _nrt=False)
def _along(samples: np.ndarray, y: int, x: int, ux: float, uy: float, worst: float) -> float:
    """Where the sample of cell (y, x) lies along the unit direction (ux, uy), in cells
    from the cell's centre (`samples` (ny, nx, 2): x and y offsets in cells, NaN where not
    known), or `worst` where not known: anywhere in the cell, its edge."""
    if samples.shape[0] == 0:
        return worst
    sx, sy = samples[y, x, 0], samples[y, x, 1]
    if not (math.isfinite(sx) and math.isfinite(sy)):
        return worst
    return sx * ux + sy * uy


@njit(cache=True, nogil=True)
def interpolated(known: np.ndarray, hit: np.ndarray, heights: np.ndarray, size: int,
                 step: float, unlit_corners: bool, samples: np.ndarray) -> np.ndarray:
    """`known` and the cells without a hit lying between two known cells along a row, a
    column or a diagonal whose samples lie at most `size` + 2 cells apart (metric: a
    diagonal step is sqrt(2) cells), heights within `step`, no other cell with a hit
    between them (`interpolated_reference` is the plain version). A known cell's sample
    is where `samples` (ny, nx, 2: its x and y offset from the cell's centre, in cells)
    puts it, else its edge away from the gap: without samples (NO_SAMPLES), known cells at
    most `size` + 1 cells apart. No argument has a default: Numba's cache would miss an
    omitted array on every run. Not along a diagonal through the inner corner of hits off the
    floor (both of the cell's row and column neighbours on one side of the diagonal), nor
    with `unlit_corners` of any cells not known floor, hit or not: the floor's edge turns
    there (a hole's or a wall's corner; a hole's inside often holds no hit at all), and the
    diagonal between two rim cells runs outside the floor."""
    out = known.copy()
    _interpolate_into(out, known, hit, heights, size, step, unlit_corners, samples)
    return out


@njit(cache=True, nogil=True, _nrt=False)
def _interpolate_into(out: np.ndarray, known: np.ndarray, hit: np.ndarray,
                      heights: np.ndarray, size: int, step: float, unlit_corners: bool,
                      samples: np.ndarray) -> None:
    """`interpolated` into `out`, a copy of `known`. Compiled without Numba's reference
    counting, like `scanmap.grid._kernels`' insertion: the counts of the arrays its
    helpers take were most of its time."""
    ny, nx = known.shape
    widest = size + 2.0  # the opening bridged, sample to sample
    far = widest + (1.0 if samples.shape[0] else -1.0)  # cell to cell
    for y in range(ny):
        for x in range(nx):
            if known[y, x] or hit[y, x]:
                continue
            for d in range(4):
                dy, dx = (0, 1, 1, 1)[d], (1, 0, 1, -1)[d]
                if d >= 2 and _inner_corner(known, hit, y, x, dy, dx, unlit_corners):
                    continue
                length = math.sqrt(dy * dy + dx * dx)
                ka, kb = 0, 0
                ha, hb = np.nan, np.nan
                for k in range(1, int(far) + 1):  # forward: the first cell with a hit
                    yy, xx = y + k * dy, x + k * dx
                    if k * length > far or not (0 <= yy < ny and 0 <= xx < nx):
                        break
                    if known[yy, xx] or hit[yy, xx]:
                        if known[yy, xx]:
                            ka, ha = k, heights[yy, xx]
                        break
                if ka == 0:
                    continue
                for k in range(1, int(far) + 1):  # backward
                    yy, xx = y - k * dy, x - k * dx
                    if (ka + k) * length > far or not (0 <= yy < ny and 0 <= xx < nx):
                        break
                    if known[yy, xx] or hit[yy, xx]:
                        if known[yy, xx]:
                            kb, hb = k, heights[yy, xx]
                        break
                if kb == 0 or not abs(ha - hb) <= step:  # NaN: not within
                    continue
                ux, uy = dx / length, dy / length
                opening = (ka + kb) * length \
                    + _along(samples, y + ka * dy, x + ka * dx, ux, uy, 0.5) \
                    - _along(samples, y - kb * dy, x - kb * dx, ux, uy, -0.5)
                if opening <= widest:
                    out[y, x] = True
                    break


def interpolated_reference(known: np.ndarray, hit: np.ndarray, heights: np.ndarray,
                           size: int, step: float, unlit_corners: bool = False,
                           samples: np.ndarray = NO_SAMPLES) -> np.ndarray:
    """`interpolated` in numpy (shifted copies of the grids), for tests."""
    ny, nx = known.shape
    informative = known | hit
    heights = np.where(known, heights, np.nan)
    if not samples.shape[0]:
        samples = np.full((ny, nx, 2), np.nan, np.float32)
    out = known.copy()
    pad = size + 4
    p_inf, p_known = np.pad(informative, pad), np.pad(known, pad)
    p_h = np.pad(heights, pad, constant_values=np.nan)
    p_s = np.pad(samples, ((pad, pad), (pad, pad), (0, 0)), constant_values=np.nan)
    p_off = np.pad(~known & (hit | unlit_corners), pad)  # off the floor, inside the grid

    def off_floor(oy: int, ox: int) -> np.ndarray:
        return p_off[pad + oy:pad + oy + ny, pad + ox:pad + ox + nx]

    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        corner = np.zeros((ny, nx), bool)
        if dy and dx:  # the inner corner of cells off the floor on one side of the diagonal
            corner = off_floor(dy, 0) & off_floor(0, -dx) | off_floor(0, dx) & off_floor(-dy, 0)
        length = np.hypot(dy, dx)
        ends = []
        for sign in (1, -1):
            found = np.zeros((ny, nx), bool)
            ok = np.zeros((ny, nx), bool)
            distance = np.zeros((ny, nx), np.int64)
            height = np.full((ny, nx), np.nan, heights.dtype)
            along = np.full((ny, nx), 0.5 * sign)  # the cell's edge away from the gap
            for k in range(1, size + 4):
                y0, x0 = pad + sign * k * dy, pad + sign * k * dx
                window = (slice(y0, y0 + ny), slice(x0, x0 + nx))
                new = ~found & p_inf[window]
                ok |= new & p_known[window]
                distance[new] = k
                height[new] = p_h[window][new]
                offset = (p_s[window][..., 0] * dx + p_s[window][..., 1] * dy) / length
                along[new & np.isfinite(offset)] = offset[new & np.isfinite(offset)]
                found |= new
            ends.append((ok, distance, height, along))
        (ok_a, d_a, h_a, s_a), (ok_b, d_b, h_b, s_b) = ends
        opening = (d_a + d_b) * length + s_a - s_b
        with np.errstate(invalid="ignore"):
            out |= ok_a & ok_b & (opening <= size + 2) & (np.abs(h_a - h_b) <= step) & ~hit \
                & ~corner
    return out


# `grow_region`'s jumps: to the 16 cells two away (dy, dx), across the cells between
# (ay, ax) and (by, bx) (half the way, rounded both ways: one cell, or two for a knight's
# move), and their lengths in cells
_JUMPS = np.array([(dy, dx, int(dy / 2), int(dx / 2), dy - int(dy / 2), dx - int(dx / 2))
                   for dy in range(-2, 3) for dx in range(-2, 3) if max(abs(dy), abs(dx)) == 2],
                  np.int64)
_JUMP_LENGTHS = np.hypot(_JUMPS[:, 0], _JUMPS[:, 1])


def _crossed_cells(dy: int, dx: int) -> list[tuple[int, int]]:
    """The cells the segment between the centres of cell (0, 0) and cell (dy, dx)
    passes through, but for those two: where the stretches of it (t from 0 to 1) within
    the cell's rows and within its columns meet, in more than a point or in a corner
    other than one of the end cells' (as a jump two cells on crosses, along a diagonal,
    the cell between, and for a knight's move both cells beside it)."""
    def stretch(d: int, i: int) -> tuple[Fraction, Fraction]:
        if d == 0:
            return (Fraction(0), Fraction(1)) if i == 0 else (Fraction(1), Fraction(0))
        a, b = Fraction(2 * i - 1, 2 * d), Fraction(2 * i + 1, 2 * d)
        return min(a, b), max(a, b)

    cells = []
    for i in range(min(dy, 0), max(dy, 0) + 1):
        for j in range(min(dx, 0), max(dx, 0) + 1):
            (a0, a1), (b0, b1) = stretch(dy, i), stretch(dx, j)
            lo, hi = max(a0, b0, Fraction(0)), min(a1, b1, Fraction(1))
            corner = lo == hi and any(abs(lo * dy - ey) == abs(lo * dx - ex) == Fraction(1, 2)
                                      for ey, ex in ((0, 0), (dy, dx)))
            if lo <= hi and not corner and (i, j) not in ((0, 0), (dy, dx)):
                cells.append((i, j))
    return cells


# `grow_region`'s long jumps along a plane: to the 24 cells three away (dy, dx), across
# the cells the line between their centres crosses (`_LONG_CROSSED[k, :_LONG_COUNTS[k]]`)
_LONG_JUMPS = np.array([(dy, dx) for dy in range(-3, 4) for dx in range(-3, 4)
                        if max(abs(dy), abs(dx)) == 3], np.int64)
_LONG_CROSSED_LISTS = [_crossed_cells(dy, dx) for dy, dx in _LONG_JUMPS]
_LONG_COUNTS = np.array([len(c) for c in _LONG_CROSSED_LISTS], np.int64)
_LONG_LENGTHS = np.hypot(_LONG_JUMPS[:, 0], _LONG_JUMPS[:, 1])
_LONG_CROSSED = np.zeros((len(_LONG_JUMPS), _LONG_COUNTS.max(), 2), np.int64)
for _k, _cells_of_k in enumerate(_LONG_CROSSED_LISTS):
    _LONG_CROSSED[_k, :len(_cells_of_k)] = _cells_of_k


@njit(cache=True, nogil=True)
def grow_region(heights: np.ndarray, seeds: np.ndarray, max_step: float,
                empty: np.ndarray, max_rise: float, candidates: np.ndarray,
                tangents: np.ndarray, tolerance: float, seed_floor: np.ndarray,
                planar: np.ndarray) -> np.ndarray:
    """Cells reachable from the seeds through 8-neighbours whose heights differ <=
    max_step, each step only where every candidate next to its start within max_step of
    it is within max_step of its end too (`_spans_no_step`: a cell at a step's edge, 9
    mm low as it holds some of the face, is within a step of the floor below it, 4.7 cm
    down, but the floor it lies on is not: cell by cell the growth walked down the two,
    step room 11's lower floor FREE), and across the `empty` cells (no hit: a gap
    between the laser's lines) to the cells two away whose heights differ by at most
    `max_rise` per cell of the distance (a floor's slope, not a step's face), where
    every cell between lies in `empty` (its midpoint, or both cells beside a knight's
    move), and each end is within max_step of the cells next to the other that are
    within max_step of it (`_spans_no_step`), those cells read from `candidates`: every
    floor candidate, also those left out of `heights` (too steep, a step's face), as
    they are what shows a step beside a jump's end. And across `empty` cells to the cells
    three away along a plane (`_plane_jump`): where each end's tangent plane (`tangents`,
    ny x nx x 5, `local_slope`: height, x and y in m of its mean hit, and its gradient,
    NaN where it has none) passes within `tolerance` of the other end (a ramp seen from
    afar is cut into islands by gaps two cells wide, and its raised end was an
    obstacle). Jumps are tried only from the few candidates the neighbours alone did not
    reach (a jump is the same from either end), and onwards. Every cell joins only within
    max_step of the anchor of the cell it is reached from: the height of the last cell on
    the growth's way whose own window fits a plane that another window round it agrees
    with (`planar`; one laser line's cells fit none, `local_slope`), a seed's own where
    it fits one, else the seed's `seed_floor` (the floor plane's height there: a seed
    lies up to the plane's tolerance off it, and a ramp's foot anchored at the plane let
    a robot with a 3 cm step climb no ramp). A line that crossed a turned step's face at
    a slant grades from one floor to the other along a chain one cell wide, each window
    round it holding that line alone (step room 1083, 6.9 cm down: 0, -1.5, ..., -6.6 cm
    over ten cells, 8 deg), and the growth
    walked down it onto the lower floor; a ramp's cells fit planes where two lines cross
    their windows. A planar cell too joins only within a step of the anchor it is reached
    from, and then anchors itself: a face cell 2.8 cm down was a seed (an inlier of the
    floor plane, fitting none), the growth jumped from it to a face cell 4.5 cm down and
    on to the floor below, whose cells fit planes (step room 1022, 5.5 cm down, at 0.3
    px). The anchor is that of the first way the breadth-first growth finds."""
    ny, nx = heights.shape
    inside = seeds.copy()
    anchor = np.where(seeds, np.where(planar, heights, seed_floor), np.nan).astype(np.float32)
    queue = np.empty(ny * nx, np.int64)
    tail = 0
    for y in range(ny):
        for x in range(nx):
            if seeds[y, x]:
                queue[tail] = y * nx + x
                tail += 1
    head = tail = _spread(heights, candidates, inside, queue, 0, tail, max_step, empty, max_rise,
                          False, tangents, tolerance, planar, anchor)
    for y in range(ny):
        for x in range(nx):
            if inside[y, x] or np.isnan(heights[y, x]):
                continue
            for k in range(_JUMPS.shape[0]):
                yy, xx = y + _JUMPS[k, 0], x + _JUMPS[k, 1]
                if _can_jump(heights, candidates, empty, max_step, max_rise, y, x, k) \
                        and inside[yy, xx] \
                        and _anchored(heights, planar, anchor, max_step, yy, xx, y, x):
                    inside[y, x] = True
                    break
            for k in range(0 if inside[y, x] else _LONG_JUMPS.shape[0]):
                yy, xx = y + _LONG_JUMPS[k, 0], x + _LONG_JUMPS[k, 1]
                if _plane_jump(heights, candidates, empty, tangents, max_step, max_rise,
                               tolerance, y, x, k) and inside[yy, xx] \
                        and _anchored(heights, planar, anchor, max_step, yy, xx, y, x):
                    inside[y, x] = True
                    break
            if inside[y, x]:
                queue[tail] = y * nx + x
                tail += 1
    _spread(heights, candidates, inside, queue, head, tail, max_step, empty, max_rise, True,
            tangents, tolerance, planar, anchor)
    return inside


@njit(cache=True, nogil=True, inline="always")
def _anchored(heights: np.ndarray, planar: np.ndarray, anchor: np.ndarray, max_step: float,
              y: int, x: int, yy: int, xx: int) -> bool:
    """Whether `grow_region` may go on from the cell (y, x) to (yy, xx) by its anchors
    ((yy, xx) lies within max_step of the anchor of (y, x); a planar cell then anchors
    itself, another takes that anchor); sets the anchor of (yy, xx) if so."""
    if abs(heights[yy, xx] - anchor[y, x]) > max_step:
        return False
    anchor[yy, xx] = heights[yy, xx] if planar[yy, xx] else anchor[y, x]
    return True


@njit(cache=True, nogil=True)
def _spread(heights: np.ndarray, candidates: np.ndarray, inside: np.ndarray, queue: np.ndarray,
            head: int, tail: int, max_step: float, empty: np.ndarray, max_rise: float,
            jumps: bool, tangents: np.ndarray, tolerance: float, planar: np.ndarray,
            anchor: np.ndarray) -> int:
    """`grow_region`'s breadth-first growth from the cells queue[head:tail] (inside),
    with or without jumps; returns the queue's new tail."""
    ny, nx = heights.shape
    while head < tail:
        y, x = queue[head] // nx, queue[head] % nx
        head += 1
        h = heights[y, x]
        for yy in range(max(y - 1, 0), min(y + 2, ny)):
            for xx in range(max(x - 1, 0), min(x + 2, nx)):
                if not inside[yy, xx] and abs(heights[yy, xx] - h) <= max_step \
                        and _spans_no_step(candidates, y, x, heights[yy, xx], max_step) \
                        and _anchored(heights, planar, anchor, max_step, y, x, yy, xx):
                    inside[yy, xx] = True
                    queue[tail] = yy * nx + xx
                    tail += 1
        for k in range(_JUMPS.shape[0] if jumps else 0):
            yy, xx = y + _JUMPS[k, 0], x + _JUMPS[k, 1]
            if _can_jump(heights, candidates, empty, max_step, max_rise, y, x, k) \
                    and not inside[yy, xx] \
                    and _anchored(heights, planar, anchor, max_step, y, x, yy, xx):
                inside[yy, xx] = True
                queue[tail] = yy * nx + xx
                tail += 1
        for k in range(_LONG_JUMPS.shape[0] if jumps else 0):
            yy, xx = y + _LONG_JUMPS[k, 0], x + _LONG_JUMPS[k, 1]
            if _plane_jump(heights, candidates, empty, tangents, max_step, max_rise, tolerance,
                           y, x, k) and not inside[yy, xx] \
                    and _anchored(heights, planar, anchor, max_step, y, x, yy, xx):
                inside[yy, xx] = True
                queue[tail] = yy * nx + xx
                tail += 1
    return tail


@njit(cache=True, nogil=True, inline="always")
def _plane_jump(heights: np.ndarray, candidates: np.ndarray, empty: np.ndarray,
                tangents: np.ndarray, max_step: float, max_rise: float, tolerance: float,
                y: int, x: int, k: int) -> bool:
    """Whether `grow_region` may jump from (y, x) by _LONG_JUMPS[k] (its end may lie
    outside the grid): every cell between `empty`, each end on the other's tangent plane
    within `tolerance` (where it has one: an island beyond a gap may be too small to fit
    a plane), rising no faster than `max_rise` a cell and with no step beside either end
    along the plane (`_no_step_along`). A flat floor's plane does not reach a lower floor
    a step down, nor a ramp's the floor below its raised end."""
    ny, nx = heights.shape
    yy, xx = y + _LONG_JUMPS[k, 0], x + _LONG_JUMPS[k, 1]
    if not (0 <= yy < ny and 0 <= xx < nx) \
            or (np.isnan(tangents[y, x, 3]) and np.isnan(tangents[yy, xx, 3])):
        return False
    for i in range(_LONG_COUNTS[k]):
        if not empty[y + _LONG_CROSSED[k, i, 0], x + _LONG_CROSSED[k, i, 1]]:
            return False
    a, b = tangents[y, x], tangents[yy, xx]
    dx, dy = b[1] - a[1], b[2] - a[2]
    if abs(b[0] - a[0] - a[3] * dx - a[4] * dy) > tolerance \
            or abs(b[0] - a[0] - b[3] * dx - b[4] * dy) > tolerance \
            or not abs(heights[yy, xx] - heights[y, x]) <= max_rise * _LONG_LENGTHS[k]:
        return False
    gx, gy = (a[3], a[4]) if not np.isnan(a[3]) else (b[3], b[4])
    return _no_step_along(candidates, tangents, y, x, b, gx, gy, max_step) \
        and _no_step_along(candidates, tangents, yy, xx, a, gx, gy, max_step)


@njit(cache=True, nogil=True, inline="always")
def _no_step_along(candidates: np.ndarray, tangents: np.ndarray, y: int, x: int,
                   far: np.ndarray, gx: float, gy: float, max_step: float) -> bool:
    """`_spans_no_step` along a plane of gradient (gx, gy): whether every candidate next to
    (y, x) within max_step of it lies within max_step of the plane through the tangent
    point `far` (height, x, y) a jump from (y, x) lands on."""
    ny, nx = candidates.shape
    near = candidates[y, x]
    for yy in range(max(y - 1, 0), min(y + 2, ny)):
        for xx in range(max(x - 1, 0), min(x + 2, nx)):
            h = candidates[yy, xx]
            off = far[0] - h - gx * (far[1] - tangents[yy, xx, 1]) \
                - gy * (far[2] - tangents[yy, xx, 2])
            if abs(h - near) <= max_step and abs(off) > max_step:  # False for NaN
                return False
    return True


@njit(cache=True, nogil=True, inline="always")
def _can_jump(heights: np.ndarray, candidates: np.ndarray, empty: np.ndarray, max_step: float,
              max_rise: float, y: int, x: int, k: int) -> bool:
    """Whether `grow_region` may jump from (y, x) by _JUMPS[k] (inside the grid)."""
    ny, nx = heights.shape
    yy, xx = y + _JUMPS[k, 0], x + _JUMPS[k, 1]
    return 0 <= yy < ny and 0 <= xx < nx and empty[y + _JUMPS[k, 2], x + _JUMPS[k, 3]] \
        and empty[y + _JUMPS[k, 4], x + _JUMPS[k, 5]] \
        and abs(heights[yy, xx] - heights[y, x]) <= max_rise * _JUMP_LENGTHS[k] \
        and _spans_no_step(candidates, y, x, heights[yy, xx], max_step) \
        and _spans_no_step(candidates, yy, xx, heights[y, x], max_step)


@njit(cache=True, nogil=True, inline="always")
def _spans_no_step(heights: np.ndarray, y: int, x: int, far: float, max_step: float
                   ) -> bool:
    """Whether every cell next to (y, x) within max_step of it is within max_step of the
    height `far` a step or jump from (y, x) lands on. A level a step's face leaves in a
    cell (-3 cm beside the floor at 0) is within a step of both floors, and a jump from it
    across a gap between the laser's lines would land on the floor below (-6 cm): the
    jump, not the cells next to each other, would bridge the step (`bridged_steps`); so
    would a step from an edge cell 9 mm low onto a floor 4.7 cm below it."""
    ny, nx = heights.shape
    near = heights[y, x]
    for yy in range(max(y - 1, 0), min(y + 2, ny)):
        for xx in range(max(x - 1, 0), min(x + 2, nx)):
            h = heights[yy, xx]
            if abs(h - near) <= max_step and abs(h - far) > max_step:  # False for NaN
                return False
    return True


@njit(cache=True, nogil=True)
def bridged_steps(heights: np.ndarray, level: np.ndarray, max_step: float, reach: float,
                  varied: np.ndarray) -> np.ndarray:
    """Candidates that bridge a step too high for the robot: within `max_step` of two
    candidates that lie more than max_step apart in height, within `reach` cells of each
    other and on either side of it (inside the circle their distance spans) or both on
    `level` floor (two floors a step apart, wherever they lie round it), and more than a
    tenth of max_step from each (the thin levels a step's face leaves in the cells it
    crosses). Growing the floor cell by cell within max_step would walk down such a
    chain onto the floor below: 0, -2, -6, -8 cm down an 8 cm step, or 0, -1.6, -2.6,
    -3.5, -4.9, -6.1 cm where a turned 6 cm step's face crosses the cells at a slant, its
    two sides three cells apart. `reach` (cells) keeps a ramp within the robot's slope
    clear of it (its heights that far apart differ by less than a step). A cell level
    with one side (a ramp's edge beside its face) is no bridge, nor one at a ramp's side
    beside the floor (the ramp rises along it, the floor lies across), unless both are
    level: where the laser's lines cross a turned step's face sparsely, the floor above
    it and the floor below that lie within reach of each other may both lie to one side
    of a face cell, and two jumps across the gaps beside it joined the two floors (step
    room 1009, 5.7 cm down, at 0.3 px: its lower floor FREE for six scans). Only cells of
    `varied` are looked at: any other has no two candidates more than max_step apart
    round it (`floor._model._bridged_steps`)."""
    ny, nx = heights.shape
    out = np.zeros((ny, nx), np.bool_)
    margin = 0.1 * max_step
    near2 = reach * reach
    cells = int(reach)
    side = 2 * cells + 1
    # (y, x, height, level) of the candidates above the cell and below it, within a step
    above, below = np.empty((side * side, 4)), np.empty((side * side, 4))
    for y in range(ny):
        for x in range(nx):
            hd = heights[y, x]
            if np.isnan(hd) or not varied[y, x]:
                continue
            n_above, n_below = 0, 0
            top, bottom = -np.inf, np.inf
            for yy in range(max(y - cells, 0), min(y + cells + 1, ny)):
                for xx in range(max(x - cells, 0), min(x + cells + 1, nx)):
                    if (yy - y) ** 2 + (xx - x) ** 2 > near2:
                        continue
                    h = heights[yy, xx]
                    if margin < h - hd <= max_step:  # False for NaN
                        above[n_above, 0], above[n_above, 1] = yy, xx
                        above[n_above, 2], above[n_above, 3] = h, level[yy, xx]
                        n_above += 1
                        top = max(top, h)
                    elif margin < hd - h <= max_step:
                        below[n_below, 0], below[n_below, 1] = yy, xx
                        below[n_below, 2], below[n_below, 3] = h, level[yy, xx]
                        n_below += 1
                        bottom = min(bottom, h)
            if top - bottom <= max_step:  # also when either side has none
                continue
            for i in range(n_above):
                for j in range(n_below):
                    if above[i, 2] - below[j, 2] > max_step \
                            and (above[i, 0] - below[j, 0]) ** 2 \
                            + (above[i, 1] - below[j, 1]) ** 2 <= near2 \
                            and ((above[i, 0] - y) * (below[j, 0] - y)
                                 + (above[i, 1] - x) * (below[j, 1] - x) <= 0.0
                                 or (above[i, 3] > 0.0 and below[j, 3] > 0.0)):
                        out[y, x] = True
                        break
                if out[y, x]:
                    break
    return out


@njit(cache=True, nogil=True)
def local_slope(heights: np.ndarray, offsets: np.ndarray, radius: int, max_step: float,
                res: float, plane_noise: float, faces: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Slope (rad) of each candidate cell's floor, from the planes fitted to the
    candidates of the windows that hold it: a window is the square of `radius` cells
    round a candidate, its cells within `max_step` of that centre's height (the other
    side of a step is another surface), each where its hits lie (its cell's centre plus
    `offsets`, ny x nx x 2: the mean hit's x, y offset; a turned ramp's lines cross its
    cells off centre, up to 1.3 cm up or down a 15 deg slope from the centre's height).
    A window whose plane fits within `plane_noise` (RMS, m) lies on one surface, unless
    it holds one of the `faces` (cells whose level is taller than a step: a face the
    robot cannot climb crosses them): a face lit by lines at several heights leaves its
    cells half way down, and with the floors on either side they fitted a 12 deg plane
    where the cells between held no hit (step room 1196, a step 5.8 cm down: its lower
    floor joined the floor through them, 118 cells FREE at the 4th scan; a step, not
    `mean_hit_heights`' drivable surface with its noise, which takes in ramp cells at 0.3
    px, each spoiling 25 windows). Of the
    nine round the cell (centred on it and `radius` cells off in x, y or both: each holds
    it, and at an edge one lies on each side; all 25 gave the same ramp F1 in 1.3 times
    the time) that hold it and pass within twice `plane_noise` of its height, it takes
    the slope of the one that explains it best (least residual variance plus the cell's
    own squared residual): as an edge-preserving (Kuwahara) filter takes a pixel's value
    from the side of an edge it is on, the first rows of a steep ramp take a window on
    the ramp alone (the plane over a window that takes in the floor before it, bent
    within the noise, gave a 16 deg ramp's first 10 cm 11-15 deg), and the floor before
    it a window on the floor. Its slope is then that of the mean gradient of the windows
    that agree with that best one (their gradients within 3 standard deviations of their
    difference, AGREE), each weighted by the inverse of its gradient's variance (the
    plane's residual variance over the spread of its cells across their principal
    line): on a plane all nine agree, and their mean is half as noisy as one (a 14.7 deg
    ramp's inner cells at 0.3 px of laser peak noise: 0.20 -> 0.09 deg standard
    deviation; 5 of 185 came out over max_slope, fresh ramp room 501's F1 0.963), while
    at an edge the windows over both sides disagree with the best by far more than their
    noise and are left out. Where the cell's own window fits no plane (bent by a
    crease or a step's face, or too few cells for one), the cell is no gentler
    than the gentler of the planes fitted at the centres over that whole window and over
    its cells at or above the cell's height: beside a turned step's face, whose cells lie
    at in-between heights, the lower floor's cells each fit a flat window, and the floor
    grew down the face (step room 11: 18 cells of a 6 cm step FREE); both planes rise
    with the face there. At a ramp's side near its low end, where the floor beside lies
    less than a step below, the plane over the whole window tilts towards that floor (a
    14.6 deg ramp's side cells came out at 15-19 deg, not floor), the one over the cells
    at or above it does not; the floor's growth keeps off a step's lower side by itself
    (`grow_region`). At a ramp's foot the whole window's plane is the gentler (half a
    window's plane, at 0.3 px of noise, overshot gentle ramps). Where no window holds it,
    the slope is the steepest of the planes fitted at the centres to the cell's own
    window, to those at or above the cell's height and to those at or below it (taken
    everywhere, the steepest of three noisy fits overshot a 14 deg ramp by 1-2.6 deg, and
    still the foot of a 14.6 deg one). Each fit at the centres (`_plane_slope`): with
    fewer than six cells, or all near one line (the foot of a wall, a laser line's arc),
    the slope along them: a chain of cells each a little lower than the last is steep
    even where no plane fits it; NaN with fewer than three. Returns the slope and each
    candidate's tangent plane, ny x nx x 5 (`grow_region`'s jumps along a plane): its
    height, the x and y (m from the first cell's centre) where its hits lie and, where
    the slope is the agreeing windows' mean (the cell's own window fits a plane) and
    another window round the cell agrees with it, their mean gradient (dz/dx, dz/dy; NaN
    elsewhere: `grow_region` anchors the floor at the cells that have one, and a lone
    window through a line down a step's face and a line on each floor, a 14.7 deg plane
    no window beside agreed with, anchored it half way down, step room 1196's 3rd scan:
    51 cells of the floor below FREE)."""
    ny, nx = heights.shape
    out = np.full((ny, nx), np.nan, np.float32)
    tangent = np.full((ny, nx, 5), np.nan, np.float32)
    # Each window's plane where it fits within plane_noise (its variance; NaN elsewhere):
    # its gradient, its height at the centre's hit above the centre's height and the
    # gradient's variance along the direction its cells spread least
    variances = np.full((ny, nx), np.nan, np.float32)
    plane = np.empty((ny, nx, 4), np.float32)
    none = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for y in range(ny):
        for x in range(nx):
            hc = heights[y, x]
            if np.isnan(hc):
                continue
            at_hits, szz = none, 0.0  # and the sum of their squared heights
            ox, oy = offsets[y, x, 0], offsets[y, x, 1]
            face = False
            for yy in range(max(y - radius, 0), min(y + radius + 1, ny)):
                for xx in range(max(x - radius, 0), min(x + radius + 1, nx)):
                    dz = heights[yy, xx] - hc
                    if abs(dz) <= max_step:  # False for NaN
                        face = face or faces[yy, xx]
                        szz += dz * dz
                        at_hits = _with_cell(at_hits, (xx - x) * res + offsets[yy, xx, 0] - ox,
                                             (yy - y) * res + offsets[yy, xx, 1] - oy, dz, 1.0)
            gx, gy = _gradient(at_hits, res)
            if not np.isnan(gx) and not face:
                rms = _plane_rms(at_hits, szz, gx, gy)
                if rms <= plane_noise:
                    n = at_hits[0]
                    plane[y, x, 0], plane[y, x, 1] = gx, gy
                    plane[y, x, 2] = (at_hits[3] - gx * at_hits[1] - gy * at_hits[2]) / n
                    variances[y, x] = rms * rms * n / (n - 3.0)  # unbiased
                    plane[y, x, 3] = variances[y, x] / _least_spread(at_hits)
    tolerance = 2.0 * plane_noise
    # the fitting windows round a cell: gradient and its variance (`plane[..., 3]`)
    slopes_x, slopes_y, slope_variances = np.empty(9), np.empty(9), np.empty(9)
    chosen = 0
    for y in range(ny):
        for x in range(nx):
            hc = heights[y, x]
            if np.isnan(hc):
                continue
            tangent[y, x, 0] = hc
            tangent[y, x, 1] = x * res + offsets[y, x, 0]
            tangent[y, x, 2] = y * res + offsets[y, x, 1]
            best, slope, fits = np.inf, -np.inf, 0
            for yy in range(y - radius, y + radius + 1, radius):
                for xx in range(x - radius, x + radius + 1, radius):
                    if not (0 <= yy < ny and 0 <= xx < nx):
                        continue
                    variance = variances[yy, xx]
                    if np.isnan(variance) or abs(heights[yy, xx] - hc) > max_step:
                        continue  # no plane, or the cell is not in its window
                    gx, gy = plane[yy, xx, 0], plane[yy, xx, 1]
                    residual = heights[yy, xx] + plane[yy, xx, 2] - hc \
                        + gx * ((x - xx) * res + offsets[y, x, 0] - offsets[yy, xx, 0]) \
                        + gy * ((y - yy) * res + offsets[y, x, 1] - offsets[yy, xx, 1])
                    score = variance + residual * residual
                    if abs(residual) <= tolerance:
                        slopes_x[fits], slopes_y[fits] = gx, gy
                        slope_variances[fits] = plane[yy, xx, 3]
                        if score < best:
                            best, chosen = score, fits
                        fits += 1
            agreeing = 0
            if best < np.inf:  # the best window agrees with itself: weight > 0
                bx, by, bv = slopes_x[chosen], slopes_y[chosen], slope_variances[chosen]
                weight = sx = sy = 0.0
                for i in range(fits):
                    dx, dy = slopes_x[i] - bx, slopes_y[i] - by
                    if dx * dx + dy * dy <= AGREE * (slope_variances[i] + bv):
                        w = 1.0 / (slope_variances[i] + 1e-18)
                        agreeing += 1
                        weight += w
                        sx += w * slopes_x[i]
                        sy += w * slopes_y[i]
                slope = math.atan(math.hypot(sx / weight, sy / weight))
            if best == np.inf or np.isnan(variances[y, x]):  # its own window fits none
                gentler, steepest = _fits_at_centres(heights, radius, max_step, res, y, x)
                slope = steepest if best == np.inf else max(slope, gentler)
            elif agreeing >= 2:
                tangent[y, x, 3], tangent[y, x, 4] = sx / weight, sy / weight
            if slope > -np.inf:  # a fit on either side or over both
                out[y, x] = slope
    return out, tangent


@njit(cache=True, nogil=True, inline="always")
def _fits_at_centres(heights: np.ndarray, radius: int, max_step: float, res: float,
                     y: int, x: int) -> tuple[float, float]:
    """`local_slope`'s planes fitted at the cells' centres to the candidates within
    `radius` and `max_step` of cell (y, x): the gentler of the one over them all and the
    one over those at or above its height, and the steepest of those two and the one
    over those at or below it; -inf without any."""
    ny, nx = heights.shape
    hc = heights[y, x]
    none = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    # Sums over all, over those above (dz > 0) and over those level with it (dz = 0: on
    # both sides); below = all - above (the level ones add nothing to the height sums)
    # (above: weighted 1 or 0, no branch, as the signs of a noisy floor's heights are a
    # coin toss to the branch predictor; level is rare but for the cell)
    every, above, level = none, none, none
    for yy in range(max(y - radius, 0), min(y + radius + 1, ny)):
        for xx in range(max(x - radius, 0), min(x + radius + 1, nx)):
            dz = heights[yy, xx] - hc
            if abs(dz) <= max_step:  # False for NaN
                px, py = (xx - x) * res, (yy - y) * res
                every = _with_cell(every, px, py, dz, 1.0)
                above = _with_cell(above, px, py, dz, 1.0 if dz > 0.0 else 0.0)
                if dz == 0.0:
                    level = _with_cell(level, px, py, dz, 1.0)
    over_all = _plane_slope(every, res)
    rising = _plane_slope(_sum(above, level, 1.0), res)
    return min(over_all, rising), max(over_all, rising,
                                      _plane_slope(_sum(every, above, -1.0), res))


@njit(cache=True, nogil=True, inline="always")
def _with_cell(s: tuple, px: float, py: float, dz: float, weight: float) -> tuple:
    """Plane-fit sums `s` (n, sx, sy, sz, sxx, sxy, syy, sxz, syz: offsets x, y in m from
    the cell, heights z above it) with one more cell if `weight` is 1, the same sums if
    it is 0 (adding a zero: the sums start at +0 and are finite, so never -0)."""
    return (s[0] + weight, s[1] + weight * px, s[2] + weight * py, s[3] + weight * dz,
            s[4] + weight * (px * px), s[5] + weight * (px * py), s[6] + weight * (py * py),
            s[7] + weight * (px * dz), s[8] + weight * (py * dz))


@njit(cache=True, nogil=True, inline="always")
def _sum(a: tuple, b: tuple, sign: float) -> tuple:
    """The sums a + sign * b, term by term."""
    return (a[0] + sign * b[0], a[1] + sign * b[1], a[2] + sign * b[2], a[3] + sign * b[3],
            a[4] + sign * b[4], a[5] + sign * b[5], a[6] + sign * b[6], a[7] + sign * b[7],
            a[8] + sign * b[8])


AGREE = 9.0  # `local_slope`: gradients agree within 3 standard deviations (squared)
PLANE_SPREAD = 0.2  # cells: the least RMS spread of a plane fit's points across their line


@njit(cache=True, nogil=True, inline="always")
def _gradient(s: tuple, res: float) -> tuple[float, float]:
    """Gradient (dz/dx, dz/dy) of the least-squares plane of the cells summed in `s`
    (`_with_cell`); NaN with fewer than six, or lying within PLANE_SPREAD cells (RMS) of
    one line: one laser line's hits along a row of cells tell nothing of the slope across
    it, and a plane through them tilts with their noise (without this, 931 of the 1426
    floor candidates of random room 603's first scan, its lines sparse, came out steep,
    not 59)."""
    n, sx, sy, sz, sxx, sxy, syy, sxz, syz = s
    cxx, cxy, cyy = sxx - sx * sx / n, sxy - sx * sy / n, syy - sy * sy / n
    cxz, cyz = sxz - sx * sz / n, syz - sy * sz / n
    det = cxx * cyy - cxy * cxy
    if n < 6 or not _least_spread(s) > n * (PLANE_SPREAD * res) ** 2:
        return np.nan, np.nan
    return (cyy * cxz - cxy * cyz) / det, (cxx * cyz - cxy * cxz) / det


@njit(cache=True, nogil=True, inline="always")
def _least_spread(s: tuple) -> float:
    """n x the least variance of the positions of the cells summed in `s` (`_with_cell`):
    the scatter across their principal line (m^2)."""
    n, sx, sy, _, sxx, sxy, syy, _, _ = s
    cxx, cxy, cyy = sxx - sx * sx / n, sxy - sx * sy / n, syy - sy * sy / n
    half = 0.5 * (cxx + cyy)
    return half - math.sqrt(max(half * half - (cxx * cyy - cxy * cxy), 0.0))


@njit(cache=True, nogil=True, inline="always")
def _plane_rms(s: tuple, szz: float, gx: float, gy: float) -> float:
    """RMS residual (m) of the cells summed in `s` (`szz`: their squared heights) about
    their least-squares plane, of gradient (gx, gy) (`_gradient`)."""
    n, sx, sy, sz = s[0], s[1], s[2], s[3]
    cxz, cyz = s[7] - sx * sz / n, s[8] - sy * sz / n
    return math.sqrt(max(szz - sz * sz / n - gx * cxz - gy * cyz, 0.0) / n)


@njit(cache=True, nogil=True, inline="always")
def _plane_slope(s: tuple, res: float) -> float:
    """Slope (rad) of the plane `_gradient` fits to the cells summed in `s` (see
    `local_slope`), or along their principal line where it fits none; -inf with fewer
    than three."""
    n, sx, sy, sz, sxx, _, syy, sxz, syz = s
    if n < 3:
        return -np.inf
    gx, gy = _gradient(s, res)
    if not np.isnan(gx):
        return math.atan(math.hypot(gx, gy))
    cxx, cyy = sxx - sx * sx / n, syy - sy * sy / n
    if cxx + cyy > 0.0:  # the least-squares slope along their principal line
        return math.atan(math.hypot(sxz - sx * sz / n, syz - sy * sz / n) / (cxx + cyy))
    return -np.inf


@njit(cache=True, nogil=True)
def below_floor(levels: np.ndarray, nlev: np.ndarray, seen: np.ndarray,
                floor_height: np.ndarray, step: float, z_min: float,
                mask_dz: float, span: float) -> np.ndarray:
    """Cells where the floor is missing: a level lies wholly more than `step` below the
    floor height, or one that spans at most `span` (one surface, as `mean_hit_heights`
    takes it) has its mean hit there, or rays passed (seen free) a bin or more below that.
    A surface's highest hit lies up to three times the noise above it: at 0.3 px of laser
    peak noise the lower floor of a step 5.5 cm down reached within a step of the floor
    above, and most of it was left UNKNOWN. In a cell with hits at the floor's height
    (within a step of it) the heights seen below must reach up to the floor's bin
    unbroken (a far wall's top, hit from the floor down): the observed mask holds each
    hit's own bin, and at 0.3 px a far wall's hit 4-6 m off lands a cell or two past the
    wall, 10-20 cm down among the floor's hits, alone in its bin (ramp rooms at 0.3 px:
    the drop-off's edge 1.1-1.6 cells off the truth in 13 of 24, in 1 without)."""
    ny, nx = nlev.shape
    out = np.zeros((ny, nx), np.bool_)
    for y in range(ny):
        for x in range(nx):
            f = floor_height[y, x]
            if np.isnan(f):
                continue
            limit = f - step
            for k in range(nlev[y, x]):
                lo, hi = levels[y, x, k, gk.LO], levels[y, x, k, gk.HI]
                mean = levels[y, x, k, gk.MZ]
                if hi < limit or (hi - lo <= span and lo <= mean < limit):
                    out[y, x] = True
            bins = math.floor((limit - z_min) / mask_dz) - 1  # bins wholly below limit - dz
            if bins > 0 and not out[y, x]:
                below = seen[y, x] & ((np.uint64(1) << np.uint64(min(bins, 63))) - np.uint64(1))
                if below:  # among floor hits, seen from them down to it (not a noisy hit)
                    between = gk.bins_mask(_highest_bit(below) + 1,
                                           math.floor((f - z_min) / mask_dz) - 1)
                    out[y, x] = seen[y, x] & between == between \
                        or not _floor_hit_in(levels, nlev[y, x], y, x, limit, f + step)
    return out


@njit(cache=True, nogil=True, inline="always")
def _floor_hit_in(levels: np.ndarray, n: int, y: int, x: int, low: float, high: float
                  ) -> bool:
    """Whether a level of cell (y, x) reaches into [low, high] (hits at the floor's
    height)."""
    for k in range(n):
        if levels[y, x, k, gk.HI] >= low and levels[y, x, k, gk.LO] <= high:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _popcount(v: np.uint64) -> int:
    """Set bits of v, by adding neighbouring bit counts in parallel (a dozen operations
    where a loop over the bits of a robot band's mask takes forty)."""
    v = v - ((v >> np.uint64(1)) & np.uint64(0x5555555555555555))
    v = (v & np.uint64(0x3333333333333333)) + ((v >> np.uint64(2)) & np.uint64(0x3333333333333333))
    v = (v + (v >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return int((v * np.uint64(0x0101010101010101)) >> np.uint64(56))


@njit(cache=True, nogil=True, inline="always")
def _widen(mask: np.uint64) -> np.uint64:
    """A surface seen as hits has a thickness nobody measured: widen it by two bins."""
    one = np.uint64(1)
    mask |= (mask << one) | (mask >> one)
    return mask | (mask << one) | (mask >> one)


@njit(cache=True, nogil=True, inline="always")
def _lowest_bit(bits: np.uint64) -> int:
    """Index of the lowest set bit of a non-zero mask: the count of the bits below it (a
    loop over the bits took up to 64 steps; the seen masks start tens of bins up)."""
    return _popcount((bits & (~bits + np.uint64(1))) - np.uint64(1))


@njit(cache=True, nogil=True, inline="always")
def _highest_bit(bits: np.uint64) -> int:
    """Index of the highest set bit of a non-zero mask."""
    high = 63
    while not (bits >> np.uint64(high)) & np.uint64(1):
        high -= 1
    return high


@njit(cache=True, nogil=True)
def lowest_level_below(levels: np.ndarray, nlev: np.ndarray, is_floor: np.ndarray,
                       limit: np.ndarray, field: int) -> np.ndarray:
    """Cells with hits, not floor, whose lowest level's `field` (LO or HI) lies below
    `limit` (False for NaN): `floor._unseen._below_model` and `_reaching_below` in one pass over
    the levels, where numpy's strided read of the field alone took longer."""
    ny, nx = nlev.shape
    out = np.zeros((ny, nx), np.bool_)
    for y in range(ny):
        for x in range(nx):
            out[y, x] = nlev[y, x] > 0 and not is_floor[y, x] \
                and levels[y, x, 0, field] < limit[y, x]
    return out


@njit(cache=True, nogil=True)
def footprint_cells(stood: np.ndarray, xs: np.ndarray, ys: np.ndarray, origin_x: float,
                    origin_y: float, res: float, radius: float, reach: int) -> np.ndarray:
    """Cells (ny, nx: the lengths of the cell centres `ys`, `xs`) whose square lies less
    than `radius` from a place the robot stood (`stood` (M, 2) x, y), searched within
    `reach` cells of the cell holding it (`floor.segmentation._footprint_cells`)."""
    ny, nx = ys.shape[0], xs.shape[0]
    out = np.zeros((ny, nx), np.bool_)
    half = 0.5 * res  # from a cell's centre to its square's nearest point
    for i in range(stood.shape[0]):
        x, y = stood[i, 0], stood[i, 1]
        cx = int(np.floor((x - origin_x) / res))
        cy = int(np.floor((y - origin_y) / res))
        for row in range(max(cy - reach, 0), min(cy + reach + 1, ny)):
            dy = max(abs(ys[row] - y) - half, 0.0)
            for col in range(max(cx - reach, 0), min(cx + reach + 1, nx)):
                dx = max(abs(xs[col] - x) - half, 0.0)
                if dx * dx + dy * dy < radius * radius:
                    out[row, col] = True
    return out


@njit(cache=True, nogil=True)
def observed_span(nlev: np.ndarray, seen: np.ndarray, stood: np.ndarray, origin_x: float,
                  origin_y: float, res: float) -> tuple[int, int, int, int]:
    """First and last row and column of the cells with a level or with heights rays saw,
    or holding a place the robot stood (`stood` (M, 2) x, y; places beyond the window
    left out); (-1, -1, -1, -1) without any (`floor.segmentation._observed_box`, in one pass)."""
    ny, nx = nlev.shape
    top, bottom, left, right = ny, -1, nx, -1
    for y in range(ny):  # each row from both ends to its first observed cell
        first = 0
        while first < nx and nlev[y, first] == 0 and seen[y, first] == 0:
            first += 1
        if first == nx:
            continue
        last = nx - 1
        while nlev[y, last] == 0 and seen[y, last] == 0:
            last -= 1
        top, bottom = min(top, y), y
        left, right = min(left, first), max(right, last)
    for i in range(stood.shape[0]):
        col = np.floor((stood[i, 0] - origin_x) / res)
        row = np.floor((stood[i, 1] - origin_y) / res)
        if 0.0 <= col < nx and 0.0 <= row < ny:  # False for NaN
            top, bottom = min(top, int(row)), max(bottom, int(row))
            left, right = min(left, int(col)), max(right, int(col))
    if bottom < 0:
        return -1, -1, -1, -1
    return top, bottom, left, right


@njit(cache=True, nogil=True)
def plane_heights(normal: tuple[float, float, float], offset: float, xs: np.ndarray,
                  ys: np.ndarray) -> np.ndarray:
    """Height (float32, ny x nx) of the plane normal . p = offset over the cell centres
    `xs` (nx,), `ys` (ny,): `FloorPlane.height_at`'s arithmetic, rounded once to float32,
    without its two float64 temporaries the window's size."""
    a, b, c = normal
    out = np.empty((ys.shape[0], xs.shape[0]), np.float32)
    for y in range(ys.shape[0]):
        for x in range(xs.shape[0]):
            out[y, x] = (offset - a * xs[x] - b * ys[y]) / c
    return out


@njit(cache=True, nogil=True)
def lowest_seen(seen: np.ndarray, z_min: float, mask_dz: float) -> np.ndarray:
    """Bottom height (m) of the lowest height bin rays saw free in each cell; -inf where
    none was (such a cell counts as probed, and cannot be FREE: its band is unseen)."""
    out = np.full(seen.shape, -np.inf)
    for y in range(seen.shape[0]):
        for x in range(seen.shape[1]):
            if seen[y, x]:
                out[y, x] = z_min + mask_dz * _lowest_bit(seen[y, x])
    return out


@njit(cache=True, nogil=True)
def pooled_bits(seen: np.ndarray, reach: int) -> np.ndarray:
    """The height bins seen free in each cell or a cell within `reach` cells of it (the OR
    over the square, nothing beyond the grid's edge)."""
    ny, nx = seen.shape
    rows = np.zeros((ny, nx), np.uint64)
    for y in range(ny):  # the OR along each row, then along each column of that
        for x in range(nx):
            bits = np.uint64(0)
            for xx in range(max(x - reach, 0), min(x + reach + 1, nx)):
                bits |= seen[y, xx]
            rows[y, x] = bits
    out = np.zeros((ny, nx), np.uint64)
    for y in range(ny):
        for yy in range(max(y - reach, 0), min(y + reach + 1, ny)):
            for x in range(nx):
                out[y, x] |= rows[yy, x]
    return out


@njit(cache=True, nogil=True, inline="always")
def _above_lowest_seen(seen: np.uint64) -> np.uint64:
    """Heights above the lowest height seen: where a board that has free space seen under
    it can continue unseen (under a table top), unlike heights below everything a cell
    saw (the shadow behind a box, seen only over it)."""
    if seen == 0:
        return np.uint64(0)
    low = _lowest_bit(seen)
    return ~((np.uint64(2) << np.uint64(low)) - np.uint64(1)) if low < 63 else np.uint64(0)


@njit(cache=True, nogil=True, inline="always")
def _below(bits: np.uint64, margin: int) -> np.uint64:
    """The heights more than `margin` bins below the lowest height in `bits` (non-zero)."""
    low = _lowest_bit(bits)
    return (np.uint64(1) << np.uint64(low - margin)) - np.uint64(1) if low > margin \
        else np.uint64(0)


@njit(cache=True, nogil=True)
def _plates(boards: np.ndarray, occupied: np.ndarray, blank: np.ndarray) -> np.ndarray:
    """The boards (their heights, widened) that overhang: they continue sideways at the
    same heights in at least two of the 8 neighbouring cells (a neighbour's board holds
    this one's middle height: a table top's rim does; a stray piece of a wall face, or a
    sloping line of hits that only touches the next cell's heights at an edge, does not),
    not all on one side of it (a sheet of stray hits sloping along a wall's face: its
    cells along the face lie at other heights, only those towards the wall at its own), and
    no neighbour holds anything more than two bins below them (the side of a box under its
    top, the rest of a wall under a piece of it that rays grazing the face left apart),
    nor lies in `blank` (nothing seen there, nothing hit: the inside of a wall whose face
    lies a few mm inside the board's cell; behind a table's rim, rays pass under its top)."""
    ny, nx = boards.shape
    out = np.zeros((ny, nx), np.uint64)
    for y in range(ny):
        for x in range(nx):
            if not boards[y, x]:
                continue
            below = _below(boards[y, x], 2)
            middle = np.uint64(1) << np.uint64((_lowest_bit(boards[y, x])
                                                + _highest_bit(boards[y, x])) // 2)
            count, sx, sy = 0, 0, 0  # the neighbours at its middle height, their offsets' sum
            supported = False
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    if (yy != y or xx != x) and boards[yy, xx] & middle:
                        count += 1
                        sx += xx - x
                        sy += yy - y
                    supported |= occupied[yy, xx] & below != 0 or blank[yy, xx]
            if count >= 2 and not supported and sx * sx + sy * sy < count * count:
                out[y, x] = _widen(boards[y, x])
    return out


@njit(cache=True, nogil=True)
def _spread_overhangs(hanging: np.ndarray, gaps: np.ndarray, state: np.ndarray,
                      reach: int) -> np.ndarray:
    """Heights of overhanging obstacles carried up to `reach` cells into the cells around
    them (8-neighbours) with gaps at those heights in what they saw: the top of a table
    seen only at its rim covers the cells inside the rim."""
    ny, nx = hanging.shape
    spread = hanging.copy()
    size = ny * nx * 4
    queue = np.empty(size, np.int64)
    depth = np.empty(size, np.int64)
    head, tail = 0, 0
    for y in range(ny):
        for x in range(nx):
            if hanging[y, x] and tail < size:
                queue[tail], depth[tail] = y * nx + x, 0
                tail += 1
    while head < tail:
        i, d = queue[head % size], depth[head % size]
        head += 1
        if d >= reach:
            continue
        y, x = i // nx, i % nx
        for yy in range(max(y - 1, 0), min(y + 2, ny)):
            for xx in range(max(x - 1, 0), min(x + 2, nx)):
                if state[yy, xx] == OBSTACLE:
                    continue
                add = spread[y, x] & gaps[yy, xx] & ~spread[yy, xx]
                if add and tail - head < size:
                    spread[yy, xx] |= add
                    queue[tail % size], depth[tail % size] = yy * nx + xx, d + 1
                    tail += 1
    return spread


@njit(cache=True, nogil=True, inline="always")
def _rim_of_floor(is_floor: np.ndarray, floor_height: np.ndarray, y: int, x: int, z: float,
                  step: float) -> bool:
    """Whether a cell of `is_floor` beside (y, x) has its floor within `step` of height
    `z`: a level there is that floor's rim, not a board (ramp room 8006: a ramp's raised
    end, 24 cm up, hit in the cell past it whose floor rays saw under it, overhung the
    ramp's upper half, whose bands start below 24 cm: 30 of its cells not floor)."""
    ny, nx = is_floor.shape
    for yy in range(max(y - 1, 0), min(y + 2, ny)):
        for xx in range(max(x - 1, 0), min(x + 2, nx)):
            if is_floor[yy, xx] and abs(floor_height[yy, xx] - z) <= step:
                return True
    return False


@njit(cache=True, nogil=True)
def classify_band(levels: np.ndarray, nlev: np.ndarray, seen: np.ndarray,
                  counted: np.ndarray, floor_height: np.ndarray, is_floor: np.ndarray,
                  step: float,
                  height: float, z_min: float,
                  mask_dz: float, coverage: float,
                  reach: int, thin: float, origin_x: float, origin_y: float, res: float,
                  state: np.ndarray, points: np.ndarray, band_logodds: np.ndarray,
                  covered: np.ndarray, min_logodds: float = 0.0) -> None:
    """UNKNOWN / FREE / OBSTACLE per cell, obstacle points and the band's highest log-odds;
    `covered`: cells that may lie under an overhanging obstacle (see below).

    Heights no ray saw anywhere in the window (above the camera) are left out: nothing
    can be known there. A cell without anything in its band is FREE when rays saw at
    least `coverage` of the band's height bins free (the bins in `counted`: its own
    `seen`, or on known floor its neighbours' too; itself at least one), and none of the
    heights it has not seen is suspect: within two bins of an obstacle in a neighbouring
    cell, or of an overhanging board within `reach` cells through cells that have not
    seen those heights either but saw lower ones. A board is the lowest level in its
    cell, at most `thin` thick, with free space seen under it at least a bin below its
    lowest hit (a ray that ends on a box's top marks only the heights above the hit), and
    not within `step` of the floor of a cell of `is_floor` beside it (that floor's rim: a
    ramp's raised end seen in the cell past it, the floor there seen under it), and
    `_plates` decides whether it overhangs. A cell under a table top that rays reached
    only under the top is thus not FREE, however much of the band they saw there.
    A band level with log-odds below `min_logodds` does not make its cell an OBSTACLE
    but keeps it from being FREE (UNKNOWN: as likely gone as there); for its neighbours
    it counts as any other (their unseen heights beside it stay suspect).
    """
    ny, nx = nlev.shape
    occupied = np.zeros((ny, nx), np.uint64)  # band heights held by obstacles, per cell
    hanging = np.zeros((ny, nx), np.uint64)  # the same, of obstacles clear of the floor
    unseen = np.zeros((ny, nx), np.uint64)
    doubtful = np.zeros((ny, nx), np.bool_)  # a band level with log-odds below min_logodds
    observable = np.uint64(0)  # heights some ray saw somewhere (not above the camera)
    for y in range(ny):
        for x in range(nx):
            observable |= seen[y, x]
    for y in range(ny):
        for x in range(nx):
            cx, cy = origin_x + (x + 0.5) * res, origin_y + (y + 0.5) * res
            points[y, x, 0], points[y, x, 1] = cx, cy
            band_logodds[y, x] = np.nan
            f = floor_height[y, x]
            state[y, x] = UNKNOWN
            if np.isnan(f):
                continue
            low, high = f + step, f + height
            band = gk.height_mask(low, high - 1e-6, z_min, mask_dz) & observable
            unseen[y, x] = band & ~seen[y, x]
            weight, sx, sy = 0.0, 0.0, 0.0
            for k in range(nlev[y, x]):
                lo, hi = levels[y, x, k, gk.LO], levels[y, x, k, gk.HI]
                if hi > low and lo < high:
                    bits = gk.height_mask(max(lo, low), min(hi, high), z_min, mask_dz)
                    if lo > low and hi - lo <= thin and occupied[y, x] == 0 \
                            and seen[y, x] & gk.height_mask(low, lo - mask_dz, z_min, mask_dz) \
                            and not _rim_of_floor(is_floor, floor_height, y, x, lo, step):
                        hanging[y, x] |= bits  # a board with free space under it
                    occupied[y, x] |= bits  # for the neighbours, doubtful or not
                    if levels[y, x, k, gk.LOGODDS] < min_logodds:
                        doubtful[y, x] = True
                        continue
                    w = 1.0 + levels[y, x, k, gk.LOGODDS]
                    weight += w
                    sx += w * levels[y, x, k, gk.MX]
                    sy += w * levels[y, x, k, gk.MY]
                    lo_k = levels[y, x, k, gk.LOGODDS]
                    if np.isnan(band_logodds[y, x]) or lo_k > band_logodds[y, x]:
                        band_logodds[y, x] = lo_k
            if weight > 0.0:
                state[y, x] = OBSTACLE
                points[y, x, 0], points[y, x, 1] = cx + sx / weight, cy + sy / weight
    gaps = np.empty((ny, nx), np.uint64)
    for y in range(ny):
        for x in range(nx):
            gaps[y, x] = unseen[y, x] & _above_lowest_seen(seen[y, x])
    overhang = _spread_overhangs(_plates(hanging, occupied, (seen == 0) & (nlev == 0)), gaps,
                                 state, reach)
    widened = np.empty((ny, nx), np.uint64)  # each cell's obstacles widened, once per cell
    for y in range(ny):
        for x in range(nx):
            widened[y, x] = _widen(occupied[y, x])
    beside = pooled_bits(widened, 1)  # over the 3 x 3 square, by rows then columns
    for y in range(ny):
        for x in range(nx):
            f = floor_height[y, x]
            if state[y, x] == OBSTACLE or np.isnan(f):
                continue
            band = gk.height_mask(f + step, f + height - 1e-6, z_min, mask_dz) & observable
            suspect = overhang[y, x] | beside[y, x]
            covered[y, x] = unseen[y, x] & overhang[y, x] != 0
            if _popcount(band & counted[y, x]) >= max(coverage * _popcount(band), 1.0) \
                    and band & seen[y, x] != 0 and unseen[y, x] & suspect == 0 \
                    and not doubtful[y, x]:
                state[y, x] = FREE


@njit(cache=True, nogil=True)
def cell_boxes(state, points, geo) -> tuple[np.ndarray, np.ndarray]:
    """What distances are measured to, one record per cell of the window grown by a border
    of one cell (flat, row-major: cell (y, x) is record (y + 1) * (nx + 2) + x + 1), +inf
    on the border and where there is nothing (a query's distance to it is infinite):
    boxes (x lo, y lo, x hi, y hi) of the cells not known free (an obstacle cell's
    measured point, an unknown cell's square), and the obstacle cells' points (boxes of
    one point: x, y, x, y). Every box lies in its cell, give or take CELL_SLACK cells (the
    searches rely on it): an obstacle point beyond is moved to the nearest point there, a
    NaN one (comparisons with NaN would hide it from every query) to the cell's centre."""
    ny, nx = state.shape
    width = nx + 2
    boxes = np.full(((ny + 2) * width, 4), np.inf)
    obstacle_points = np.full(((ny + 2) * width, 4), np.inf)
    for y in range(ny):
        for x in range(nx):
            b = (y + 1) * width + x + 1
            if state[y, x] == OBSTACLE:
                lo, hi = -CELL_SLACK * geo[2], (1.0 + CELL_SLACK) * geo[2]
                x0, y0 = geo[0] + x * geo[2], geo[1] + y * geo[2]
                px, py = float(points[y, x, 0]), float(points[y, x, 1])
                px = x0 + 0.5 * geo[2] if np.isnan(px) else _clamp(px, x0 + lo, x0 + hi)
                py = y0 + 0.5 * geo[2] if np.isnan(py) else _clamp(py, y0 + lo, y0 + hi)
                boxes[b, 0] = boxes[b, 2] = obstacle_points[b, 0] = obstacle_points[b, 2] = px
                boxes[b, 1] = boxes[b, 3] = obstacle_points[b, 1] = obstacle_points[b, 3] = py
            elif state[y, x] == UNKNOWN:
                boxes[b, 0] = geo[0] + x * geo[2]
                boxes[b, 1] = geo[1] + y * geo[2]
                boxes[b, 2] = boxes[b, 0] + geo[2]
                boxes[b, 3] = boxes[b, 1] + geo[2]
    return boxes, obstacle_points


@njit(cache=True, nogil=True, inline="always")
def _clamp(q: float, lo: float, hi: float) -> float:
    return min(max(q, lo), hi)


@njit(cache=True, nogil=True, inline="always")
def _box_d2(qx, qy, boxes, j):
    """Squared distance from (qx, qy) to box record j (inf for an empty record)."""
    px = _clamp(qx, boxes[j, 0], boxes[j, 2]) - qx
    py = _clamp(qy, boxes[j, 1], boxes[j, 3]) - qy
    return px * px + py * py


@njit(cache=True, nogil=True, inline="always")
def _scan_row(qx, qy, boxes, first, x_lo, x_hi, best, arg):
    """`best, arg` updated with the records first + x_lo ... first + x_hi."""
    for j in range(first + x_lo, first + x_hi + 1):
        d2 = _box_d2(qx, qy, boxes, j)
        if d2 < best:
            best, arg = d2, j
    return best, arg


@njit(cache=True, nogil=True)
def _nearest_record(qx, qy, boxes, nearest, ix, iy, geo, best):
    """Squared distance from (qx, qy) to the nearest box of `cell_boxes` if below `best`,
    and its record (else best, -1): exact, by a search bounded on both sides.

    Every box lies in its cell, so a box nearer than sqrt(best) is in a cell whose centre
    is within sqrt(best) + CELL_REACH of the query; and no cell whose centre is
    nearer the centre of cell (ix, iy) than the field's nearest cell (`nearest`) holds
    one. The rows of the ring between are scanned; the outer bound shrinks with best.
    """
    ox, oy, res, nx = geo[0], geo[1], geo[2], int(geo[3])
    ny = int(geo[4])
    width = nx + 2
    k = nearest[iy, ix]
    if k < 0:
        return best, -1
    arg = -1
    d2 = _box_d2(qx, qy, boxes, k)
    if d2 < best:
        best, arg = d2, k
    inner = (k // width - 1 - iy) ** 2 + (k % width - 1 - ix) ** 2  # cells squared
    gx, gy = (qx - ox) / res - 0.5, (qy - oy) / res - 0.5  # query, cell-centre units
    reach = math.sqrt(best) / res + CELL_REACH
    for y in range(max(math.ceil(gy - reach), 0), min(math.floor(gy + reach), ny - 1) + 1):
        reach = math.sqrt(best) / res + CELL_REACH
        rest = reach * reach - (y - gy) * (y - gy)
        if rest < 0.0:
            continue
        w = math.sqrt(rest)
        x_lo, x_hi = max(math.ceil(gx - w), 0), min(math.floor(gx + w), nx - 1)
        hole = inner - (y - iy) * (y - iy)  # cells with (x - ix)^2 < hole are free
        if hole > 0:
            skip = math.ceil(math.sqrt(hole)) - 1
            best, arg = _scan_row(qx, qy, boxes, (y + 1) * width + 1, x_lo,
                                  min(x_hi, ix - skip - 1), best, arg)
            x_lo = max(x_lo, ix + skip + 1)
        best, arg = _scan_row(qx, qy, boxes, (y + 1) * width + 1, x_lo, x_hi, best, arg)
    return best, arg


@njit(cache=True, nogil=True, inline="always")
def _window_edge(qx, qy, ox, oy, xmax, ymax):
    """Distance from (qx, qy), inside the window [ox, xmax) x [oy, ymax), to its edge."""
    return min(qx - ox, xmax - qx, qy - oy, ymax - qy)


@njit(cache=True, nogil=True, inline="always")
def _cell_of(qx, qy, ox, oy, inv, nx, ny):
    """(column, row) of the window cell holding (qx, qy), or of the window's cell nearest
    it, and whether the window holds it. inv: 1 / resolution."""
    gx, gy = (qx - ox) * inv, (qy - oy) * inv
    inside = 0.0 <= gx < nx and 0.0 <= gy < ny  # False for NaN
    ix = min(max(int(min(max(gx, 0.0), nx - 1.0)), 0), nx - 1)
    iy = min(max(int(min(max(gy, 0.0), ny - 1.0)), 0), ny - 1)
    return ix, iy, inside


@njit(cache=True, nogil=True)
def query_one(qx, qy, state, nearest_blocked, nearest_obstacle, boxes, points, geo):
    """(clearance, kind of what limits it, obstacle distance, obstacle x, obstacle y).

    The obstacle distance is to the nearest measured obstacle point; the clearance is the
    distance to the nearest thing not known free (0 in or beyond the window's unknown or
    occupied cells, the window's edge counting as unknown). Both are exact
    (`_nearest_record`); the query's cell is the window's cell nearest it.
    """
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    ix, iy, inside = _cell_of(qx, qy, ox, oy, 1.0 / res, nx, ny)
    px, py = qx, qy
    d2, j = _nearest_record(qx, qy, points, nearest_obstacle, ix, iy, geo, np.inf)
    if j >= 0:
        px, py = points[j, 0], points[j, 1]
    d = math.sqrt(d2)
    if not inside:
        return 0.0, UNKNOWN, d, px, py
    if state[iy, ix] != FREE:
        return 0.0, np.int64(state[iy, ix]), d, px, py
    edge = _window_edge(qx, qy, ox, oy, ox + nx * res, oy + ny * res)
    best, kind = edge * edge, UNKNOWN
    c2, j = _nearest_record(qx, qy, boxes, nearest_blocked, ix, iy, geo, best)
    if j >= 0:
        best, kind = c2, np.int64(state[j // (nx + 2) - 1, j % (nx + 2) - 1])
    clearance = math.sqrt(best)
    if d <= clearance:
        clearance, kind = d, OBSTACLE
    return clearance, kind, d, px, py


@njit(cache=True, nogil=True)
def query_points(xy, state, nearest_blocked, nearest_obstacle, boxes, points, geo,
                 unknown_blocks, out):
    """Clearance (unknown_blocks) or obstacle distance of each (x, y) row, as `query_one`;
    0 for a row beyond COORDINATE_LIMIT or not finite (it does not change the other rows).
    The boxes of the clearance hold the obstacle points, so one search serves it."""
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    inv, xmax, ymax = 1.0 / res, ox + nx * res, oy + ny * res
    for i in range(xy.shape[0]):
        qx, qy = xy[i, 0], xy[i, 1]
        if not (-COORDINATE_LIMIT <= qx <= COORDINATE_LIMIT
                and -COORDINATE_LIMIT <= qy <= COORDINATE_LIMIT):  # False for NaN
            out[i] = 0.0
            continue
        ix, iy, inside = _cell_of(qx, qy, ox, oy, inv, nx, ny)
        if not unknown_blocks:
            out[i] = math.sqrt(_nearest_record(qx, qy, points, nearest_obstacle, ix, iy, geo,
                                               np.inf)[0])
        elif inside and state[iy, ix] == FREE:
            edge = _window_edge(qx, qy, ox, oy, xmax, ymax)
            out[i] = math.sqrt(_nearest_record(qx, qy, boxes, nearest_blocked, ix, iy, geo,
                                               edge * edge)[0])
        else:
            out[i] = 0.0


@njit(cache=True, nogil=True, inline="always")
def _exit(qx, qy, a, ox, oy, xmax, ymax):
    """Distance from (qx, qy), inside the window [ox, xmax) x [oy, ymax), to its edge along
    the direction a (rad)."""
    dx, dy = math.cos(a), math.sin(a)
    t = np.inf
    if dx > 0:
        t = (xmax - qx) / dx
    elif dx < 0:
        t = (ox - qx) / dx
    if dy > 0:
        t = min(t, (ymax - qy) / dy)
    elif dy < 0:
        t = min(t, (oy - qy) / dy)
    return t


@njit(cache=True, nogil=True)
def polar_kernel(qx, qy, yaw, max_range, state, boxes, geo, ranges, kinds):
    """Per angular bin, the range of the nearest non-free cell within max_range.

    Every blocked cell is spread over the bins its square subtends, so nothing thin is
    missed between bins; the window's edge counts as unknown, at its nearest point in the
    bin's sector (seen from inside, the edge is nearest at the sector's two rays or at the
    foot of a side's perpendicular). Outside the window every range is 0, unknown.
    """
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    xmax, ymax = ox + nx * res, oy + ny * res
    bins = ranges.shape[0]
    width = 2.0 * math.pi / bins
    if not (ox <= qx < xmax and oy <= qy < ymax):
        ranges[:] = 0.0
        kinds[:] = UNKNOWN
        return
    start = yaw - math.pi  # bin b spans start + [b, b + 1] * width
    t0 = _exit(qx, qy, start, ox, oy, xmax, ymax)
    for b in range(bins):
        t1 = _exit(qx, qy, start + (b + 1) * width, ox, oy, xmax, ymax)
        ranges[b] = min(t0, t1)
        t0 = t1
    for side in range(4):  # sides with outward normals 0, pi / 2, pi, -pi / 2
        foot = (xmax - qx, ymax - qy, qx - ox, qy - oy)[side]
        b = math.floor(((side * 0.5 * math.pi - start) % (2.0 * math.pi)) / width)
        ranges[b % bins] = min(ranges[b % bins], foot)
    for b in range(bins):
        kinds[b] = FREE
        if ranges[b] <= max_range:
            kinds[b] = UNKNOWN
        else:
            ranges[b] = np.inf
    half_diag = res * math.sqrt(0.5)
    x_lo = max(int((qx - max_range - half_diag - ox) / res), 0)
    x_hi = min(int((qx + max_range + half_diag - ox) / res) + 1, nx)
    y_lo = max(int((qy - max_range - half_diag - oy) / res), 0)
    y_hi = min(int((qy + max_range + half_diag - oy) / res) + 1, ny)
    # Square rings of cells around the query's cell, nearest first: a cell of ring k lies
    # at least (k - 1 - CELL_SLACK) cells away, so once every bin holds a nearer range
    # the rings beyond cannot change the answer.
    cx = min(max(int((qx - ox) / res), 0), nx - 1)
    cy = min(max(int((qy - oy) / res), 0), ny - 1)
    rings = max(cx - x_lo, x_hi - 1 - cx, cy - y_lo, y_hi - 1 - cy)
    for k in range(rings + 1):
        if k >= 2 and ranges.max() < (k - 1 - CELL_SLACK) * res:
            break
        for y in range(max(cy - k, y_lo), min(cy + k + 1, y_hi)):
            on_edge_row = y == cy - k or y == cy + k
            step = 1 if on_edge_row else max(2 * k, 1)
            for x in range(cx - k, cx + k + 1, step):
                if x_lo <= x < x_hi:
                    _spread_cell(x, y, qx, qy, yaw, max_range, state, boxes, geo, ranges,
                                 kinds)


@njit(cache=True, nogil=True, inline="always")
def _spread_cell(x, y, qx, qy, yaw, max_range, state, boxes, geo, ranges, kinds):
    """Lower the ranges of the bins cell (y, x) subtends to its distance, if it is blocked
    and within max_range (the inner step of `polar_kernel`)."""
    if state[y, x] == FREE:
        return
    ox, oy, res, nx = geo[0], geo[1], geo[2], int(geo[3])
    b = (y + 1) * (nx + 2) + x + 1
    r = math.hypot(_clamp(qx, boxes[b, 0], boxes[b, 2]) - qx,
                   _clamp(qy, boxes[b, 1], boxes[b, 3]) - qy)
    if r > max_range:
        return
    bins = ranges.shape[0]
    width = 2.0 * math.pi / bins
    half_diag = res * math.sqrt(0.5)
    cx, cy = ox + (x + 0.5) * res - qx, oy + (y + 0.5) * res - qy
    rc = math.hypot(cx, cy)
    spread = math.pi if rc <= half_diag else math.asin(half_diag / rc)
    centre = math.atan2(cy, cx) - yaw + math.pi
    b0 = math.floor((centre - spread) / width)
    b1 = math.floor((centre + spread) / width)
    for b in range(b0, b1 + 1):
        bb = b % bins
        if r < ranges[bb]:
            ranges[bb] = r
            kinds[bb] = state[y, x]


_SQUARE_X, _SQUARE_Y = (0.0, 1.0, 1.0, 0.0), (0.0, 0.0, 1.0, 1.0)  # corners, in cells


@njit(cache=True, nogil=True, inline="always")
def _edge_contact(u0, v0, u1, v1, radius):
    """Least forward travel t at which a disc of `radius` centred at the origin, moving
    along +u, meets the segment (u0, v0)-(u1, v1): t = u - sqrt(r^2 - v^2) over the
    segment's points with |v| <= r (inf if none). t is convex along the segment, so its
    least is at an end, where the segment crosses |v| = r, or where dt/ds = 0."""
    r2 = radius * radius
    best = np.inf
    for u, v in ((u0, v0), (u1, v1)):
        if abs(v) <= radius:
            best = min(best, u - math.sqrt(r2 - v * v))
    du, dv = u1 - u0, v1 - v0
    if dv != 0.0:
        for bound in (-radius, radius):
            if (v0 - bound) * (v1 - bound) < 0.0:
                best = min(best, u0 + (bound - v0) / dv * du)
        k = -du / dv  # dt/ds = 0 where v / sqrt(r^2 - v^2) = -du / dv
        v = radius * k / math.sqrt(1.0 + k * k)
        s = (v - v0) / dv
        if 0.0 < s < 1.0 and abs(v) < radius:
            best = min(best, u0 + s * du - math.sqrt(r2 - v * v))
    return best


@njit(cache=True, nogil=True)
def travel_kernel(qx, qy, yaw, radius, max_distance, state, geo):
    """(distance, kind): how far a disc of `radius` at (qx, qy) moves along `yaw` before
    it meets a cell square not FREE (cells beyond the window count as UNKNOWN), capped at
    max_distance (kind FREE then); 0 if it overlaps one already."""
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    if not (ox <= qx < ox + nx * res and oy <= qy < oy + ny * res):
        return 0.0, np.int64(UNKNOWN)  # in the unknown space round the window
    c, s = math.cos(yaw), math.sin(yaw)
    reach = max_distance + radius + res
    # Beyond the ring of cells round the window nothing is met first: moving out of the
    # window, the disc meets that ring (unknown) before anything farther
    x_lo = max(math.floor((qx - reach - ox) / res), -1)
    x_hi = min(math.floor((qx + reach - ox) / res), nx)
    y_lo = max(math.floor((qy - reach - oy) / res), -1)
    y_hi = min(math.floor((qy + reach - oy) / res), ny)
    half_diag = res * math.sqrt(0.5)
    best, kind = max_distance, np.int64(FREE)
    for iy in range(y_lo, y_hi + 1):
        for ix in range(x_lo, x_hi + 1):
            inside = 0 <= ix < nx and 0 <= iy < ny
            cell = np.int64(state[iy, ix]) if inside else np.int64(UNKNOWN)
            if cell == FREE:
                continue
            x0, y0 = ox + ix * res, oy + iy * res
            du = (x0 + 0.5 * res - qx) * c + (y0 + 0.5 * res - qy) * s
            dv = -(x0 + 0.5 * res - qx) * s + (y0 + 0.5 * res - qy) * c
            if abs(dv) > radius + half_diag or not -radius - half_diag < du < \
                    best + radius + half_diag:
                continue  # off the swept band, behind, or beyond the best contact
            nearest_x = min(max(qx, x0), x0 + res) - qx
            nearest_y = min(max(qy, y0), y0 + res) - qy
            if nearest_x * nearest_x + nearest_y * nearest_y < radius * radius:
                return 0.0, cell  # the disc overlaps it already
            t = np.inf
            for corner in range(4):  # the edges (x0, y0) -> (x0 + res, y0) -> ...
                ax, ay = x0 + res * _SQUARE_X[corner], y0 + res * _SQUARE_Y[corner]
                bx = x0 + res * _SQUARE_X[(corner + 1) % 4]
                by = y0 + res * _SQUARE_Y[(corner + 1) % 4]
                t = min(t, _edge_contact((ax - qx) * c + (ay - qy) * s,
                                         -(ax - qx) * s + (ay - qy) * c,
                                         (bx - qx) * c + (by - qy) * s,
                                         -(bx - qx) * s + (by - qy) * c, radius))
            if 0.0 <= t < best:  # t < 0: behind the disc, never met moving forward
                best, kind = t, cell
    return best, kind


@njit(cache=True, nogil=True)
def polygon_margin(polygon, radius, state, points, geo):
    """Least signed distance (negative inside) from the polygon (K, 2) in map to what is
    not known free within `radius` of it: obstacle points (records of `cell_boxes`),
    unknown cells (their square, bounded by its circumcircle) and the window's edge; and
    the kind of that thing. The caller passes a finite polygon and radius."""
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    xmin, xmax = polygon[:, 0].min() - radius, polygon[:, 0].max() + radius
    ymin, ymax = polygon[:, 1].min() - radius, polygon[:, 1].max() + radius
    best, kind = radius, FREE
    half_diag = res * math.sqrt(0.5)
    k = polygon.shape[0]
    for i in range(k):  # the edge is nearest at a vertex
        px, py = polygon[i, 0], polygon[i, 1]
        edge = min(px - ox, ox + nx * res - px, py - oy, oy + ny * res - py)
        if edge < best:
            best, kind = edge, UNKNOWN
    for y in range(max(int((ymin - oy) / res), 0), min(int((ymax - oy) / res) + 1, ny)):
        for x in range(max(int((xmin - ox) / res), 0), min(int((xmax - ox) / res) + 1, nx)):
            if state[y, x] == FREE:
                continue
            if state[y, x] == OBSTACLE:
                b = (y + 1) * (nx + 2) + x + 1
                px, py, reach = points[b, 0], points[b, 1], 0.0
            else:  # unknown: its square, bounded by the circle around it
                px, py, reach = ox + (x + 0.5) * res, oy + (y + 0.5) * res, half_diag
            d = np.inf
            inside = False
            for i in range(k):
                ax, ay = polygon[i, 0], polygon[i, 1]
                bx, by = polygon[(i + 1) % k, 0], polygon[(i + 1) % k, 1]
                d = min(d, gk.segment_distance(px, py, ax, ay, bx, by))
                if (ay > py) != (by > py) and px < ax + (py - ay) * (bx - ax) / (by - ay):
                    inside = not inside
            d = -d - reach if inside else d - reach
            if d < best:
                best, kind = d, state[y, x]
    return best, kind


@njit(cache=True, nogil=True)
def free_steps(free: np.ndarray, height: np.ndarray, step: float, stood: np.ndarray
               ) -> np.ndarray:
    """One cell of each pair of `free` cells side by side (8 neighbours) whose `height`s
    lie more than `step` apart: the lower, or the upper where the robot stood on the lower
    (`stood` cells are never taken). One pass for each side, not eighteen shifted copies
    of the window (a third of a millisecond on 160 x 160 cells)."""
    ny, nx = free.shape
    upper = np.zeros((ny, nx), np.bool_)
    lower = np.zeros((ny, nx), np.bool_)
    for y in range(ny):
        for x in range(nx):
            h = height[y, x]
            if not free[y, x] or np.isnan(h):
                continue
            least, most = h, h  # of the free neighbours' heights (NaN compares False)
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    if free[yy, xx]:
                        least = min(least, height[yy, xx])
                        most = max(most, height[yy, xx])
            upper[y, x] = h - least > step
            lower[y, x] = most - h > step
    out = np.zeros((ny, nx), np.bool_)
    for y in range(ny):
        for x in range(nx):
            if stood[y, x]:
                continue
            out[y, x] = lower[y, x]
            if upper[y, x] and not lower[y, x]:
                for yy in range(max(y - 1, 0), min(y + 2, ny)):
                    for xx in range(max(x - 1, 0), min(x + 2, nx)):
                        out[y, x] |= lower[yy, xx] and stood[yy, xx]
    return out
