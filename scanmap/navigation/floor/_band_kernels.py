"""Numba kernels of the cells' states: what occupies the robot's band over each cell's
floor, overhanging boards (`classify_band`), the band's heights seen round a cell
(`pooled_bits`), two FREE cells a step apart (`free_steps`), and the height-mask
bit helpers. Called through `_states`.

Every kernel releases the GIL (`nogil`) so queries run beside mapping.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from scanmap.grid import _kernels as gk
from scanmap.navigation._kernels import FREE, OBSTACLE, UNKNOWN


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
