"""Binary morphology and connected components on cell masks, in Numba on the calling thread.

The segmentation needs a few of scipy.ndimage's operations on small boolean grids:
dilation by the 3 x 3 square (also geodesic: grown only inside a mask, a step at a time,
and only into cells within a range of the seed's), by a disc, square minimum, maximum and span
filters, neighbour counts, and 8-connected components with their bounding boxes. These
kernels give ndimage's results (tested against it) on the calling thread alone, and keep
scipy out of a command's start (importing scipy.ndimage takes 0.2 s, with scipy.special
that it loads). OpenCV's versions, a few microseconds each on a segmentation's window,
hand each call to its thread pool, whose worker then spins on the other core: 1.45 ms of
CPU per segmentation of the corridor (2.5 ms on the main thread), on a robot's computer
the core its planner needs.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from numba import njit


def _bytes(mask: np.ndarray) -> np.ndarray:
    """`mask` (its truth) as a C-contiguous uint8 array of 0 and 1, a view of a contiguous
    bool mask (no copy): the kernels' loops over bytes vectorise."""
    return np.ascontiguousarray(mask, dtype=np.bool_).view(np.uint8)


def dilate(mask: np.ndarray, iterations: int = 1, within: np.ndarray | None = None
           ) -> np.ndarray:
    """`mask` dilated `iterations` times by the 3 x 3 square (nothing beyond the array's
    edge). With `within`, each step changes only cells of `within`; the others keep their
    value in `mask` (ndimage.binary_dilation's `mask`): `geodesic_dilate`."""
    if within is None:
        return _dilate_rows(_bytes(mask), _square(max(iterations, 0))).view(np.bool_)
    return geodesic_dilate(mask, within, max(iterations, 0))


def geodesic_dilate(mask: np.ndarray, within: np.ndarray, steps: int) -> np.ndarray:
    """The cells of `mask`, and those of `within` at most `steps` 8-connected moves from
    it through cells of `within` (`dilate` with `within`): a dilation a step, kept to
    `within` (ten times a breadth-first search's speed where the mask covers most of the
    grid, as the unobserved space of a segmentation window does); it stops early when a
    step adds nothing."""
    return _geodesic(_bytes(mask), _bytes(within), steps).view(np.bool_)


@njit(cache=True, nogil=True)
def _geodesic(mask: np.ndarray, within: np.ndarray, steps: int) -> np.ndarray:
    """`geodesic_dilate` on 0/1 bytes: each step the 3 x 3 maximum of the last, kept to
    `within`. (Here and below, loops run over row slices: an index with an offset, which
    Numba checks for wrapping round, keeps a loop from being vectorised.)"""
    ny, nx = mask.shape
    grown = mask.copy()
    across = np.empty((ny, nx), np.uint8)  # the last step's maximum along each row
    grown_in = np.empty(nx, np.uint8)
    for _ in range(steps):
        for y in range(ny):
            _row_max(grown[y], across[y], 1)
        changed = 0
        for y in range(ny):
            _copy_into(grown_in, across[y])
            if y > 0:
                _or_into(grown_in, across[y - 1])
            if y + 1 < ny:
                _or_into(grown_in, across[y + 1])
            row, inside = grown[y], within[y]
            for x in range(nx):
                value = row[x] | (grown_in[x] & inside[x])
                changed |= value ^ row[x]
                row[x] = value
        if not changed:
            break
    return grown


@njit(cache=True, nogil=True, inline="always")
def _any(values: np.ndarray) -> bool:
    """Whether any of the 0/1 bytes `values` is 1 (a reduction that vectorises, where
    NumPy's `any` in Numba cost 5-8 us a window)."""
    seen = np.uint8(0)
    for x in range(values.shape[0]):
        seen |= values[x]
    return seen != 0


@njit(cache=True, nogil=True, inline="always")
def _copy_into(out: np.ndarray, values: np.ndarray) -> None:
    """out = values (one row; a loop: Numba's slice assignment costs a row's time again)."""
    for x in range(out.shape[0]):
        out[x] = values[x]


@njit(cache=True, nogil=True, inline="always")
def _or_into(out: np.ndarray, values: np.ndarray) -> None:
    """out |= values (one row)."""
    for x in range(out.shape[0]):
        out[x] |= values[x]


@njit(cache=True, nogil=True, inline="always")
def _row_max(values: np.ndarray, out: np.ndarray, reach: int) -> None:
    """out: the maximum of `values` (one row of 0/1 bytes) within `reach` columns."""
    nx = values.shape[0]
    _copy_into(out, values)
    for shift in range(1, min(reach, nx - 1) + 1):
        _or_into(out[:nx - shift], values[shift:])
        _or_into(out[shift:], values[:nx - shift])


class Viewpoints(NamedTuple):
    """Places a seed of `dilate_in_range` seen from no cell may have been seen from:
    `cells` (K, 2) their rows and columns, those `nearest` to `farthest` cells off the
    seed; from such a place p a cell c lies in the bounds of seed s when share[s] * |p s|
    - 1 <= |p c| <= |p s| + `above` (`share`, per cell: how much nearer than the seed its
    rim's shadow may reach). `own` (ny, nx, 2), where known, the row and column a seed
    was seen from (NaN where not): that place alone then, at any distance."""

    cells: np.ndarray
    nearest: float
    farthest: float
    share: np.ndarray
    above: float
    own: np.ndarray | None = None


def dilate_in_range(seeds: np.ndarray, within: np.ndarray, ranges: np.ndarray,
                    low: np.ndarray, high: np.ndarray, steps: int,
                    viewed_from: np.ndarray | None = None,
                    lateral: float | tuple[float, float] = math.inf,
                    elsewhere: Viewpoints | None = None,
                    sources: np.ndarray | None = None) -> np.ndarray:
    """`geodesic_dilate` of `seeds` through the cells of `within` whose value in `ranges`
    lies in the bounds (`low`, `high`) of the seed they came from (the widest, where two
    seeds reach a cell at the same depth): a drop-off's spread kept to the ranges from
    the scanner that the cells showing it lie at. With `viewed_from` (per cell, the flat
    index of the cell it was seen from, -1 for none), also within `lateral` cells of the
    line of sight through the seed they came from (the first to reach them): between the
    scanner's lines, not along a far wall seen aslant; a pair (right, left) bounds each
    side apart (`_off_sight`'s sign). A seed seen from no cell but with places of
    `elsewhere` in reach instead keeps to its range bounds and lateral cells from one of
    them (any), or from its `own` place where known; with none in reach, to `low` and
    `high` alone. `sources`, if given ((ny, nx) int64), receives the flat index of the
    seed each cell came from (-1 where none reached it)."""
    if viewed_from is None:
        viewed_from = np.full(seeds.shape, -1, np.int64)
    if elsewhere is None:
        elsewhere = Viewpoints(np.zeros((0, 2)), 0.0, 0.0, np.ones(seeds.shape), 0.0)
    own = elsewhere.own if elsewhere.own is not None else np.full((*seeds.shape, 2), np.nan)
    if sources is None:
        sources = np.empty(seeds.shape, np.int64)
    right, left = lateral if isinstance(lateral, tuple) else (lateral, lateral)
    return _breadth_first(np.ascontiguousarray(seeds, dtype=np.bool_),
                          np.ascontiguousarray(within, dtype=np.bool_), steps, ranges, low,
                          high, np.ascontiguousarray(viewed_from, dtype=np.int64),
                          float(right), float(left),
                          np.ascontiguousarray(elsewhere.cells, dtype=np.float64),
                          np.ascontiguousarray(elsewhere.share, dtype=np.float64),
                          np.array([elsewhere.nearest, elsewhere.farthest, elsewhere.above]),
                          np.ascontiguousarray(own, dtype=np.float64).reshape(-1, 2),
                          sources.reshape(-1))


@njit(cache=True, nogil=True, inline="always")
def _off_sight(seed: int, viewed_from: int, y: int, x: int, nx: int) -> float:
    """Signed distance (cells) of cell (y, x) from the line through `seed` and the cell it
    was seen from, positive to the left looking from that cell (0 without one)."""
    if viewed_from < 0 or viewed_from == seed:
        return 0.0
    sy, sx = seed // nx, seed % nx
    py, px = viewed_from // nx, viewed_from % nx
    dy, dx = sy - py, sx - px
    return (dx * (y - py) - dy * (x - px)) / math.sqrt(dy * dy + dx * dx)


@njit(cache=True, nogil=True, inline="always")
def _seen_from_one(places: np.ndarray, share: float, bounds: np.ndarray, seed: int, y: int,
                   x: int, nx: int, right: float, left: float) -> int:
    """For a seed seen from no cell: 1 when cell (y, x) lies in its bounds and lateral
    cells from one of the `places` in reach of it (`Viewpoints`: its `share`; bounds holds
    nearest, farthest, above), 0 when from none, -1 when none is in reach."""
    nearest, farthest, above = bounds[0], bounds[1], bounds[2]
    sy, sx = seed // nx, seed % nx
    found = -1
    for k in range(places.shape[0]):
        py, px = places[k, 0], places[k, 1]
        dy, dx, ey, ex = sy - py, sx - px, y - py, x - px
        reach = math.sqrt(dy * dy + dx * dx)
        if not (nearest <= reach <= farthest and reach > 0.0):
            continue
        found = 0
        there = math.sqrt(ey * ey + ex * ex)
        side = (dx * ey - dy * ex) / reach
        if share * reach - 1.0 <= there <= reach + above and -right <= side <= left:
            return 1
    return found


@njit(cache=True, nogil=True)
def _breadth_first(seeds: np.ndarray, within: np.ndarray, steps: int, ranges: np.ndarray,
                   low: np.ndarray, high: np.ndarray, viewed_from: np.ndarray,
                   right: float, left: float, places: np.ndarray, share: np.ndarray,
                   bounds: np.ndarray, own: np.ndarray, source: np.ndarray) -> np.ndarray:
    """`dilate_in_range`: one pass from a queue of the seeds, each cell carrying the bounds
    and the sight line of the seed it came from (`source`, flat, -1 for none)."""
    ny, nx = seeds.shape
    out = seeds.copy()
    queue = np.empty(ny * nx, np.int64)
    depth = np.zeros(ny * nx, np.int32)
    lows, highs = np.empty(ny * nx, np.float32), np.empty(ny * nx, np.float32)
    source[:] = -1
    anywhere = np.array([0.0, np.inf, bounds[2]])  # a seed's own place: at any distance
    tail = 0
    for y in range(ny):
        for x in range(nx):
            if seeds[y, x]:
                cell = y * nx + x
                queue[tail] = cell
                tail += 1
                lows[cell], highs[cell] = low[y, x], high[y, x]
                source[cell] = cell
    head = 0
    while head < tail:
        cell = queue[head]
        head += 1
        d = depth[cell]
        if d >= steps:
            continue
        y, x = cell // nx, cell % nx
        lo, hi, seed = lows[cell], highs[cell], source[cell]
        sight = viewed_from.flat[seed]
        known = own[seed, 0] == own[seed, 0]  # its own place: that one alone
        candidates, reach = (own[seed:seed + 1], anywhere) if known else (places, bounds)
        for yy in range(max(y - 1, 0), min(y + 2, ny)):
            for xx in range(max(x - 1, 0), min(x + 2, nx)):
                if not within[yy, xx]:
                    continue
                placed = _seen_from_one(candidates, share.flat[seed], reach, seed, yy, xx,
                                        nx, right, left) if sight < 0 else -1
                if placed == 0:
                    continue
                if placed < 0 and not (lo <= ranges[yy, xx] <= hi and -right <= _off_sight(
                        seed, sight, yy, xx, nx) <= left):
                    continue
                n = yy * nx + xx
                if not out[yy, xx]:
                    out[yy, xx] = True
                    depth[n] = d + 1
                    queue[tail] = n
                    tail += 1
                    lows[n], highs[n], source[n] = lo, hi, seed
                elif depth[n] == d + 1 and not seeds[yy, xx]:  # not popped yet
                    lows[n], highs[n] = min(lows[n], lo), max(highs[n], hi)
    return out


def within_distance(mask: np.ndarray, distance: float) -> np.ndarray:
    """Cells whose centre lies within `distance` cells of the centre of a cell of `mask`:
    `distance_transform(mask)[0] <= distance` as that float32 field compares, by one
    dilation with the disc of the offsets within it (a fifth of the transform's time for
    a disc of radius 3)."""
    return _dilate_rows(_bytes(mask), _disc(float(distance))).view(np.bool_)


@functools.lru_cache(maxsize=16)
def _disc(distance: float) -> np.ndarray:
    """Half-widths of the disc of the offsets (dy, dx) whose length, rounded to float32 as
    the distance field stores it, is at most `distance` in float32 (as numpy compares the
    field with it): for each dy from -reach to reach, the largest |dx| in it."""
    limit = np.float32(distance)
    reach = max(math.floor(limit), 0)  # beyond, every length exceeds the limit
    dy, dx = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    inside = np.sqrt(dy * dy + dx * dx).astype(np.float32) <= limit
    return np.where(inside, np.abs(dx), -1).max(axis=1).astype(np.int32)


@functools.lru_cache(maxsize=16)
def _square(reach: int) -> np.ndarray:
    """Half-widths (`_disc`'s form) of the square of side 2 reach + 1."""
    return np.full(2 * reach + 1, reach, np.int32)


@njit(cache=True, nogil=True)
def _dilate_rows(mask: np.ndarray, half_widths: np.ndarray) -> np.ndarray:
    """`mask` (0/1 bytes) dilated by the shape of `half_widths` (`_disc`): 1 where row
    y + dy holds a cell of `mask` within half_widths[dy + reach] columns (none where it
    is -1). Each row's maximum within a half-width is the last one's widened by a column
    each side; the rows are then joined a block at a time (the rows are contiguous)."""
    ny, nx = mask.shape
    out = np.zeros((ny, nx), np.uint8)
    if not _any(mask.reshape(-1)):  # often: no drop-off, no dip in the window
        return out
    reach = (len(half_widths) - 1) // 2
    across = np.empty((max(half_widths.max(), 0) + 1, ny, nx), np.uint8)  # by half-width
    _copy_into(across[0].reshape(-1), mask.reshape(-1))
    for width in range(1, across.shape[0]):
        for y in range(ny):
            row, source = across[width, y], mask[y]
            _copy_into(row, across[width - 1, y])
            if width < nx:
                _or_into(row[:nx - width], source[width:])
                _or_into(row[width:], source[:nx - width])
    flat, rows = out.reshape(-1), across.reshape(across.shape[0], -1)
    for k in range(len(half_widths)):
        dy, width = k - reach, half_widths[k]
        first, last = max(0, -dy), min(ny, ny - dy)  # the rows y with y + dy inside
        if width >= 0 and first < last:
            _or_into(flat[first * nx:last * nx], rows[width, (first + dy) * nx:(last + dy) * nx])
    return out


def max_filter(mask: np.ndarray, size: int) -> np.ndarray:
    """True where any cell of the `size` x `size` square centred there is (odd size)."""
    return _dilate_rows(_bytes(mask), _square(size // 2)).view(np.bool_)


def neighbours(mask: np.ndarray) -> np.ndarray:
    """How many of each cell's 8 neighbours are in `mask` (uint8; none beyond the edge)."""
    return _neighbours(_bytes(mask))


@njit(cache=True, nogil=True)
def _neighbours(mask: np.ndarray) -> np.ndarray:
    """`neighbours`: the sums along each row of three, then along each column."""
    ny, nx = mask.shape
    across = np.empty((ny, nx), np.uint8)  # each cell and its two beside it in the row
    for y in range(ny):
        _copy_into(across[y], mask[y])
        _add_into(across[y, :nx - 1], mask[y, 1:])
        _add_into(across[y, 1:], mask[y, :nx - 1])
    count = np.empty((ny, nx), np.uint8)
    for y in range(ny):
        row = count[y]
        _copy_into(row, across[y])
        for x in range(nx):
            row[x] -= mask[y, x]
        if y > 0:
            _add_into(row, across[y - 1])
        if y + 1 < ny:
            _add_into(row, across[y + 1])
    return count


@njit(cache=True, nogil=True, inline="always")
def _add_into(out: np.ndarray, values: np.ndarray) -> None:
    """out += values (one row)."""
    for x in range(out.shape[0]):
        out[x] += values[x]


def min_filter(values: np.ndarray, size: int) -> np.ndarray:
    """The least value (float32) in the `size` x `size` square centred on each cell (odd
    size; cells beyond the edge do not count; no NaN)."""
    return _min_filter(np.ascontiguousarray(values, dtype=np.float32), size // 2)


@njit(cache=True, nogil=True)
def _min_filter(values: np.ndarray, reach: int) -> np.ndarray:
    """`min_filter`: the least along each row within `reach`, then along each column."""
    ny, nx = values.shape
    across = values.copy()
    for y in range(ny):
        row, source = across[y], values[y]
        for shift in range(1, min(reach, nx - 1) + 1):
            _min_into(row[:nx - shift], source[shift:])
            _min_into(row[shift:], source[:nx - shift])
    out = across.copy()
    for y in range(ny):
        for yy in range(max(y - reach, 0), min(y + reach + 1, ny)):
            if yy != y:
                _min_into(out[y], across[yy])
    return out


@njit(cache=True, nogil=True, inline="always")
def _min_into(out: np.ndarray, values: np.ndarray) -> None:
    """out = min(out, values) (one row)."""
    for x in range(out.shape[0]):
        out[x] = min(out[x], values[x])


def span_filter(values: np.ndarray, size: int) -> np.ndarray:
    """How far apart (float32) the highest and the lowest value not NaN in the `size` x
    `size` square centred on each cell lie (odd size; -inf where all are NaN)."""
    return _span_filter(np.ascontiguousarray(values, dtype=np.float32), size // 2)


@njit(cache=True, nogil=True)
def _span_filter(values: np.ndarray, reach: int) -> np.ndarray:
    """`span_filter`: `_min_filter` of the values and of their negatives, NaN left out."""
    ny, nx = values.shape
    low, high = np.empty((ny, nx), np.float32), np.empty((ny, nx), np.float32)
    for y in range(ny):
        for x in range(nx):
            value = values[y, x]
            low[y, x] = np.inf if np.isnan(value) else value
            high[y, x] = np.inf if np.isnan(value) else -value
    low, high = _min_filter(low, reach), _min_filter(high, reach)
    for y in range(ny):
        for x in range(nx):
            low[y, x] = -high[y, x] - low[y, x]
    return low


def _components(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """8-connected labels (int32, 0 off the mask, numbered in the order of each
    component's first cell row by row, as ndimage.label numbers them) and per-label
    statistics (rows x, y, width, height, cell count; row 0 zero)."""
    return _label(_bytes(mask))


@njit(cache=True, nogil=True, inline="always")
def _root(parent: np.ndarray, k: int) -> int:
    """The root of provisional label `k` (halving the path on the way)."""
    while parent[k] != k:
        parent[k] = parent[parent[k]]
        k = parent[k]
    return k


@njit(cache=True, nogil=True)
def _label(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`_components` by the runs of each row: a run joins (union-find, each root the least
    of its component) the runs of the row above that touch it, diagonally too; the
    components are then numbered by their first runs, and their runs painted and
    counted. A window's masks are mostly long runs (the unobserved space, the floor):
    a run's work, not a cell's."""
    ny, nx = mask.shape
    most = ny * ((nx + 1) // 2) + 1  # runs at most, with the unused 0
    run_y, run_start, run_end = (np.empty(most, np.int32), np.empty(most, np.int32),
                                 np.empty(most, np.int32))
    parent = np.empty(most, np.int32)
    made = 0
    above = above_end = 1  # the row above's runs: made + 1 .. of the last row
    for y in range(ny):
        row = mask[y]
        first = made + 1
        touching = above  # the first run above that may touch this row's next run
        x = 0
        while x < nx:
            if not row[x]:
                x += 1
                continue
            start = x
            while x < nx and row[x]:
                x += 1
            made += 1
            run_y[made], run_start[made], run_end[made] = y, start, x
            parent[made] = own = made
            while touching < above_end and run_end[touching] < start:
                touching += 1
            k = touching
            while k < above_end and run_start[k] <= x:  # touches [start - 1, x]
                root = _root(parent, k)
                if root < own:
                    parent[own] = root
                    own = root
                elif root > own:
                    parent[root] = own
                k += 1
        above, above_end = first, made + 1
    final = np.zeros(made + 1, np.int32)
    count = 0
    for k in range(1, made + 1):  # a root precedes the runs joined to it
        root = _root(parent, k)
        if root == k:
            count += 1
            final[k] = count
        else:
            final[k] = final[root]
    labels = np.zeros((ny, nx), np.int32)
    stats = np.zeros((count + 1, 5), np.int32)  # x, y, right, bottom, cells; then widths
    for k in range(1, made + 1):
        label, y, start, end = final[k], run_y[k], run_start[k], run_end[k]
        labels[y, start:end] = label
        if stats[label, 4] == 0:
            stats[label, 0], stats[label, 1], stats[label, 2] = start, y, end
        else:
            stats[label, 0] = min(stats[label, 0], start)
            stats[label, 2] = max(stats[label, 2], end)
        stats[label, 3] = y + 1
        stats[label, 4] += end - start
    for label in range(1, count + 1):
        stats[label, 2] -= stats[label, 0]
        stats[label, 3] -= stats[label, 1]
    return labels, stats


def component_boxes(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """8-connected components of `mask`: labels (int32, 0 off the mask, 1..count) and
    each label's bounding box as a row (x, y, width, height) (row 0, the background: zeros)."""
    labels, stats = _components(mask)
    return labels, stats[:, :4]


def large_components(mask: np.ndarray, min_cells: int) -> np.ndarray:
    """`mask` without its 8-connected components of fewer than `min_cells` cells."""
    labels, stats = _components(mask)
    keep = stats[:, 4] >= min_cells
    keep[0] = False
    return keep.take(labels)


def box_slices(box: np.ndarray) -> tuple[slice, slice]:
    """(rows, columns) slices of a `component_boxes` box (x, y, width, height)."""
    x, y, w, h = map(int, box)
    return slice(y, y + h), slice(x, x + w)


def small_patches(mask: np.ndarray, size: int, margin: int = 1
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Components of `mask`: labels, each label's box (x, y, width, height) and whether it
    is at most `size` cells on each side and at least `margin` cells from the window's
    edge (False for label 0, off the mask)."""
    ny, nx = mask.shape
    labels, boxes = component_boxes(mask)
    x, y, w, h = boxes.T
    ok = (w <= size) & (h <= size) & (x >= margin) & (y >= margin) \
        & (x + w <= nx - margin) & (y + h <= ny - margin)
    ok[0] = False
    return labels, boxes, ok
