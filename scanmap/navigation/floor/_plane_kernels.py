"""Numba kernels of the floor model's planes and slopes: the floor candidates and their
mean heights, the RANSAC hypotheses and their support, each candidate's slope fitted
over its neighbourhood (`local_slope`), a plane's heights. Called through `_model`.

Every kernel releases the GIL (`nogil`) so queries run beside mapping.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from scanmap.grid import _kernels as gk


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
    window's plane, at 0.3 px of noise, overshot gentle ramps), and a cell whose centre
    lies past the crease takes the slope of the surface beyond it (`_across_crease`,
    from the cells off the best window's plane: the cell's own mean hit, on both
    surfaces, cannot tell its side). Where no window holds it,
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
            best, slope, fits, best_y, best_x = np.inf, -np.inf, 0, y, x
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
                            best, chosen, best_y, best_x = score, fits, yy, xx
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
                if best == np.inf:
                    slope = steepest
                elif gentler <= LEVEL_SLOPE:  # no ramp rises in its window
                    slope = max(slope, gentler)
                else:
                    slope = max(slope, gentler, _across_crease(
                        heights, offsets, plane, radius, max_step, res, tolerance, y, x,
                        best_y, best_x))
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


@njit(cache=True, nogil=True)
def _across_crease(heights: np.ndarray, offsets: np.ndarray, plane: np.ndarray, radius: int,
                   max_step: float, res: float, tolerance: float, y: int, x: int,
                   best_y: int, best_x: int) -> float:
    """The slope of the ramp rising across a crease from the level floor a cell's best
    window lies on (`local_slope`'s, centred on best_y, best_x), where the cell's centre
    lies past that crease; -inf elsewhere. At a steep ramp's foot the cell's mean hit
    lies on both surfaces, a few mm up, and the floor's window explains it about as well
    as the ramp's: the foot cells of a 25 deg ramp were fitted 10-14 deg (random room
    11106 at 0.3 px: 14 cells FREE). The ramp is the candidates within twice `radius`
    (beyond a platform's rim its top's cells lie flat) more than `tolerance` above the
    floor's plane, where they fit a plane within `tolerance` (RMS; fitted once more
    without the cells more than twice its RMS off it, a ramp's side face's, beside it)
    that holds the cell's mean hit within it too and passes above the floor's at the
    cell's centre (a valley's surface is the higher of its two planes);
    its slope so taken is its gradient less two standard deviations, no steeper than its
    noise allows (a gentle ramp's foot stays gentle). The ramp's cells lie uphill of the
    cell, their centroid within 45 deg of its gradient (UPHILL), not beside it: past the
    side of a 27 deg ramp, its plane carried on sideways passed above the floor there
    (random room 1: a floor cell 7 cm beside it 17 deg). Level floor only (LEVEL_SLOPE),
    rising only: the side cells of a ramp (7.7 deg, random room 1; 3.5 deg, mixed room
    12004) claimed by the floor a few cm below them with the cells the side's face
    crosses at in-between heights, a plane that fits them, came out at 15-17 deg."""
    hc = heights[y, x]
    gx, gy = plane[best_y, best_x, 0], plane[best_y, best_x, 1]
    if math.hypot(gx, gy) > math.tan(LEVEL_SLOPE):
        return -np.inf
    # the floor plane's height at the cell's centre, above hc
    base = heights[best_y, best_x] + plane[best_y, best_x, 2] - hc \
        + gx * ((x - best_x) * res - offsets[best_y, best_x, 0]) \
        + gy * ((y - best_y) * res - offsets[best_y, best_x, 1])
    floor = (gx, gy, base)
    ramp, szz = _above_floor(heights, offsets, y, x, 2 * radius, max_step, res, tolerance,
                             floor, (0.0, 0.0, 0.0), np.inf)
    rx, ry, rms, centre = _ramp_fit(ramp, szz, res)
    if rms > tolerance:  # once more without the cells off it: a side face's, beside it
        ramp, szz = _above_floor(heights, offsets, y, x, 2 * radius, max_step, res,
                                 tolerance, floor, (rx, ry, centre), 2.0 * rms)
        rx, ry, rms, centre = _ramp_fit(ramp, szz, res)
    if not rms <= tolerance or centre <= base:  # (True for NaN: no plane)
        return -np.inf
    n = ramp[0]
    ahead = (ramp[1] * rx + ramp[2] * ry) / n  # its cells' centroid along its gradient
    if ahead <= 0.0 or ahead * ahead < UPHILL * (ramp[1] * ramp[1] + ramp[2] * ramp[2]) \
            / (n * n) * (rx * rx + ry * ry) \
            or abs(centre + rx * offsets[y, x, 0] + ry * offsets[y, x, 1]) > tolerance:
        return -np.inf
    spread = math.sqrt(rms * rms * n / (n - 3.0) / _least_spread(ramp))
    return math.atan(max(math.hypot(rx, ry) - 2.0 * spread, 0.0))


@njit(cache=True, nogil=True, inline="always")
def _ramp_fit(sums: tuple, szz: float, res: float) -> tuple[float, float, float, float]:
    """`_across_crease`'s plane fitted to the cells summed in `sums` (`_with_cell`;
    `szz`: their squared heights): its gradient (dz/dx, dz/dy), RMS residual and height
    at the cell's centre; NaN with too few cells or too narrow a spread (`_gradient`)."""
    n = sums[0]
    if n < 6:  # `_gradient` divides by n first
        return np.nan, np.nan, np.nan, np.nan
    gx, gy = _gradient(sums, res)
    if np.isnan(gx):
        return np.nan, np.nan, np.nan, np.nan
    return gx, gy, _plane_rms(sums, szz, gx, gy), (sums[3] - gx * sums[1] - gy * sums[2]) / n


@njit(cache=True, nogil=True, inline="always")
def _above_floor(heights: np.ndarray, offsets: np.ndarray, y: int, x: int, reach: int,
                 max_step: float, res: float, tolerance: float, floor: tuple,
                 ramp: tuple, within: float) -> tuple[tuple, float]:
    """`_across_crease`'s plane-fit sums (`_with_cell`) and squared heights of the
    candidates within `reach` cells and `max_step` above cell (y, x) that lie more than
    `tolerance` above the floor's plane and within `within` of the ramp's (each
    (gx, gy, height at the cell's centre above its own))."""
    ny, nx = heights.shape
    hc = heights[y, x]
    sums, szz = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0.0
    for yy in range(max(y - reach, 0), min(y + reach + 1, ny)):
        for xx in range(max(x - reach, 0), min(x + reach + 1, nx)):
            dz = heights[yy, xx] - hc
            px, py = (xx - x) * res + offsets[yy, xx, 0], (yy - y) * res + offsets[yy, xx, 1]
            if dz <= max_step and dz - floor[2] - floor[0] * px - floor[1] * py > tolerance \
                    and abs(dz - ramp[2] - ramp[0] * px - ramp[1] * py) <= within:
                sums = _with_cell(sums, px, py, dz, 1.0)  # (False for NaN)
                szz += dz * dz
    return sums, szz


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


# `_across_crease`: a ramp's cells lie uphill of a cell when their centroid lies within
# 45 deg of its gradient (the cosine's square)
UPHILL = 0.5


# A floor candidate this gentle (`local_slope`) lies on level floor, for
# `bridged_steps`: two level floors more than a step apart are a step's two sides, not
# a ramp (a floor's cells at 0.3 px of laser peak noise: 1.5 deg at the 90th percentile;
# the cells a step's face crosses, 4-17 deg); and for `_across_crease`, the one side of
# a crease a cell's best window lies on, and a window no ramp rises in (its plane at the
# centres this gentle: not looked at; looking costs the slope 0.04 ms on the corridor's
# window, 0.5 ms before, and looking at every cell without a plane of its own 0.07-0.12)
LEVEL_SLOPE = math.radians(5.0)


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
