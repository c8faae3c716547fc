"""Numba kernels of the obstacle queries and the exact Euclidean distance transform, and
the cell states every navigation kernel shares (the floor segmentation's kernels are
`floor/_*_kernels.py`). Called through `obstacles` and `distance_field`; every kernel
releases the GIL (`nogil`) so queries run beside mapping.
"""

from __future__ import annotations

import math

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


