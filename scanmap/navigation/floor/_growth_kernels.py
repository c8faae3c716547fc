"""Numba kernels of the floor's growth from the dominant plane's inliers (`grow_region`:
its jumps across the gaps between the laser's lines), the in-between levels of a
step's face (`bridged_steps`, `touching_floor`) and the step's edges between two
floors and their rims. Called through `_model`.

Every kernel releases the GIL (`nogil`) so queries run beside mapping.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from numba import njit

from scanmap.grid import _kernels as gk


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
                  varied: np.ndarray, spans: np.ndarray, hit_heights: np.ndarray,
                  hits_at: np.ndarray, res: float, run: float, max_gradient: float,
                  ramp_span: float) -> np.ndarray:
    """Candidates that bridge a step too high for the robot: within `max_step` of two
    candidates that lie more than max_step apart in height, within `reach` cells of each
    other and on either side of it (inside the circle their distance spans) or both on
    `level` floor (two floors a step apart, wherever they lie round it), and more than a
    tenth of max_step from each (the thin levels a step's face leaves in the cells it
    crosses). Growing the floor cell by cell within max_step would walk down such a
    chain onto the floor below: 0, -2, -6, -8 cm down an 8 cm step, or 0, -1.6, -2.6,
    -3.5, -4.9, -6.1 cm where a turned 6 cm step's face crosses the cells at a slant, its
    two sides three cells apart. `reach` (cells) keeps a ramp within the robot's slope
    clear of it (its heights that far apart differ by less than a step) as far as `run`
    (cells: a ramp at the robot's slope rises nine tenths of a step across it). Two
    sides farther apart (`reach` is two cells at least) do not count round a cell of a
    ramp: one whose level `spans` at most `ramp_span` (m: as much as a ramp at the
    robot's slope rises across a cell's diagonal; a step's face spans the step), where
    the slope between their mean hits (`hit_heights`, where `hits_at` puts them: m from
    the cells' centres) is no steeper than `max_gradient`. A robot with a 3 cm step and
    20 deg took every inner cell of a 17.2 deg ramp for a bridge, its cells two apart
    3.1 cm apart (ramp room 11203: 250 of its 274 cells not floor; `heights`, the
    middles of the cells' levels, stray up to a centimetre from the ramp's plane, and a
    bound on them left 70); a step down 3.4 cm has its sides two cells apart on a 19 deg
    slope, and by the slope alone its face cells joined the floor, which then lay within
    a step of the floor below: at 0.3 px of laser peak noise half its drop-off cells
    UNKNOWN (none FREE). A cell level with one side (a ramp's edge beside its face) is no
    bridge, nor one at a ramp's side beside the floor (the ramp rises along it, the
    floor lies across), unless both are level: where the laser's lines cross a turned
    step's face sparsely, the floor above it and the floor below that lie within reach
    of each other may both lie to one side of a face cell, and two jumps across the gaps
    beside it joined the two floors (step room 1009, 5.7 cm down, at 0.3 px: its lower
    floor FREE for six scans). Only cells of `varied` are looked at: any other has no two
    candidates more than max_step apart round it (`floor._model._bridged_steps`)."""
    ny, nx = heights.shape
    out = np.zeros((ny, nx), np.bool_)
    margin = 0.1 * max_step
    near2, run2 = reach * reach, run * run
    cells = int(reach)
    side = 2 * cells + 1
    # (y, x, height, level, and the mean hit's x, y (m) and height) of the candidates
    # above the cell and below it, within a step
    above, below = np.empty((side * side, 7)), np.empty((side * side, 7))
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
                        _note(above, n_above, yy, xx, h, level, hit_heights, hits_at, res)
                        n_above += 1
                        top = max(top, h)
                    elif margin < hd - h <= max_step:
                        _note(below, n_below, yy, xx, h, level, hit_heights, hits_at, res)
                        n_below += 1
                        bottom = min(bottom, h)
            if top - bottom <= max_step:  # also when either side has none
                continue
            for i in range(n_above):
                for j in range(n_below):
                    apart2 = (above[i, 0] - below[j, 0]) ** 2 + (above[i, 1] - below[j, 1]) ** 2
                    if above[i, 2] - below[j, 2] > max_step and apart2 <= near2 \
                            and (((above[i, 0] - y) * (below[j, 0] - y)
                                  + (above[i, 1] - x) * (below[j, 1] - x) <= 0.0
                                  and (apart2 <= run2 or spans[y, x] > ramp_span
                                       or _steeper(above, i, below, j, max_gradient)))
                                 or (above[i, 3] > 0.0 and below[j, 3] > 0.0)):
                        out[y, x] = True
                        break
                if out[y, x]:
                    break
    return out


@njit(cache=True, nogil=True, inline="always")
def _note(found: np.ndarray, n: int, y: int, x: int, height: float, level: np.ndarray,
          hit_heights: np.ndarray, hits_at: np.ndarray, res: float) -> None:
    """Row n of `bridged_steps`' candidates `found`: cell (y, x), its height, whether it
    is level, and where its mean hit lies (x, y in m, and its height)."""
    found[n, 0], found[n, 1], found[n, 2], found[n, 3] = y, x, height, level[y, x]
    found[n, 4] = x * res + hits_at[y, x, 0]
    found[n, 5] = y * res + hits_at[y, x, 1]
    found[n, 6] = hit_heights[y, x]


@njit(cache=True, nogil=True, inline="always")
def _steeper(above: np.ndarray, i: int, below: np.ndarray, j: int, gradient: float) -> bool:
    """Whether the mean hits of candidates above[i] and below[j] (`_note`) lie on a slope
    steeper than `gradient` (dz / dx): a step's face between them, not a ramp."""
    rise = above[i, 6] - below[j, 6]
    dx, dy = above[i, 4] - below[j, 4], above[i, 5] - below[j, 5]
    return rise > 0.0 and rise * rise > gradient * gradient * (dx * dx + dy * dy)
