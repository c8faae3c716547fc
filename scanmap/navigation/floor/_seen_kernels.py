"""Numba kernels of what the cells saw and where from: floor below the floor model
(`below_floor`), the lowest heights seen, openings between floor samples
(`interpolated`, `floor_gaps`, `ring_heights`), the cells the robot stood on and the
span observed. Called through `_drop_offs`, `_unseen` and `segmentation`.

Every kernel releases the GIL (`nogil`) so queries run beside mapping.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from scanmap.grid import _kernels as gk
from scanmap.navigation.floor._band_kernels import _highest_bit, _lowest_bit


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
def lowest_seen(seen: np.ndarray, z_min: float, mask_dz: float) -> np.ndarray:
    """Bottom height (m) of the lowest height bin rays saw free in each cell; -inf where
    none was (such a cell counts as probed, and cannot be FREE: its band is unseen)."""
    out = np.full(seen.shape, -np.inf)
    for y in range(seen.shape[0]):
        for x in range(seen.shape[1]):
            if seen[y, x]:
                out[y, x] = z_min + mask_dz * _lowest_bit(seen[y, x])
    return out
