"""Numba kernels of the 2.5D grid: tile discovery, scan insertion, window extraction.

Each cell holds up to K height intervals ("levels"): occupied space seen as hits, kept
sorted by height and separated by more than `merge_gap`. A cell therefore holds one
surface until observations show more (the floor and, above a gap, a table top).

Insertion is one scan at a time, in three passes:
1. Hits: each point extends the level it falls in (within `merge_gap`) or starts one,
   and adds `l_hit` log-odds to it once per scan. The level remembers the height range
   of this scan's hits on it.
2. Rays, traced from the hit back to the sensor origin, cell by cell (Amanatides-Woo in
   x, y). In each cell the ray spans heights [za, zb]; it marks them seen free (the
   cell's observed mask), and it clears (subtracts `l_miss` from) a level only if it
   passed through it: the span crosses the height bin (`mask_dz`) of the level's middle,
   or lies inside the level. A ray under a table top or over a low box leaves them
   alone; a ray through the bin of a thin level (a person's arm seen once, a few mm
   thick) passes it, as a voxel map counts it, even where it misses its exact height.
   A level hit in this scan elsewhere and crossed inside is split around the ray
   instead (see _pass_cell). A ray that only enters a level from above or below, without
   reaching its middle bin, trims it to where the ray entered, unless this scan hit the
   level within `protect` of the ray: a person's foot merged with the floor into one
   level is cut down as later rays pass through its heights one part at a time, though
   the floor under it is hit in every scan. A level hit in `static_scans` scans or
   more (a wall, furniture), or beside such a level at its heights in a neighbouring
   cell (the face's end or rim, seen in fewer scans), is passed only by rays within
   `pass_radius` of its mean hit: where a face cuts a cell, rays through the cell's free
   part would otherwise wear it away. Nor is a static level (or one hit in half as many
   scans, a sliver of the same face) passed by a ray that runs along its face, within
   `graze_angle` of the face's direction read from the mean hits of the neighbouring
   cells' static levels: seen from nearly in its plane, a face's cells are crossed
   through their free part close to the mean hit, which lies on the face (a cabinet's
   end face lost three cells so in a room with people). Nor is a static level passed by
   a ray with every static level round it on one side of its line, those within half
   `pass_radius` of it on neither (`_past_corner`): it passed a corner, as at a turned
   cabinet's, whose two faces' mean hit lies within `pass_radius` of both. Guards
   against eroding surfaces at grazing incidence: the last `clear_margin` metres before
   the hit clear nothing; a level hit in this scan within `protect` metres of the ray's
   heights is not cleared ("occupied wins", as in OctoMap, but per height, so a level
   wrongly spanning a gap still loses the passes through the gap); a level loses at
   most `max_misses` per scan. A level whose log-odds fall to 0 (p = 0.5) is removed:
   the space is free, and a new hit there is occupied at once.
   The laser's rays, from its emitter to the points it lit, are traced too when given:
   the light's path was free as well, and from the emitter (0.5 m below the camera on
   the reference scanner) they cross the low heights near the robot that the camera's
   rays pass above (on `people`, 962 of 1445 cell-scans still an obstacle three scans
   after a person left lay in cells whose band later camera rays had crossed only in
   part, 50-95 % of its bins, most holding a thin level hit once). Nearly level, they
   run along faces at their heights for metres, so they pass only a level seen in
   fewer than `static_scans` scans, only within `pass_radius` of its mean hit, and not
   along a face (`_grazes_static` within LASER_GRAZE_SIN of the ray's direction, read
   from the neighbouring cells' levels of any age): through the free part of the cells
   a face cuts they eroded walls (people rooms 3 and 5: 29 cell-scans, the static ones;
   room 22: 127, a cabinet's side seen in one scan, then passed at 13 deg). Nor do
   they mark the heights they cross seen: the segmentation reads that mask as what the
   camera's rays showed (floor they passed just above unlit, space below the floor by
   a hole), and the laser's, reaching the floor at a third of the camera's slope, left
   drop-offs reaching up to 2.9 cells past their edge for a scan (ramp rooms 1-24).
   Where the emitter lies over or under the camera centre (the reference scanner's), a
   laser's ray crosses the camera ray's cells at the same points of its way: both are
   traced in one walk (`_joint`), the laser's clearing ending where the camera ray's
   bundle does (on a 20,000-point corridor scan the laser's rays took 1.05 ms of the
   insertion's 2.9 traced alone, 0.35-0.4 ms so).
   Rays from one origin (one camera frame) converge there and share their last cells:
   the cell remembers the heights the current origin's rays marked (VKEY, VMASK), and a
   ray stops after `bundle_run` cells in a row that a sibling ray already updated with
   the same heights (as Voxblox's "fast" integrator does) instead of repeating them.
3. Consolidation: a level a hit started merges with its neighbours unless a ray was
   seen passing between them: a cell holds one surface until
   observations show more.

The insertion kernel and its helpers allocate nothing, and are compiled without Numba's
reference counting (`_nrt=False`; `insert_scan` allocates their scratch): the atomic
counts Numba adds for each array a helper takes, which its pruning pass leaves in
branching code, took a third of an insertion (perf on the corridor: NRT_incref and
NRT_decref 35 % of its samples). An allocation among them fails to compile.

Log-odds are clamped at `l_max`, so an object seen for thousands of scans still clears
within ceil(l_max / (max_misses * l_miss)) scans once it has gone.

Memory layout (flat, for speed): cell `off = (slot << 2s) | (row << s) | col` with
s = log2(tile_cells); `cells[off] = (seen-free height mask, last scan id, last unlit
scan id, where its lowest level was seen from, bundle key, bundle mask[, scans whose rays
reached it])`, where bit b of a mask covers
z_min + [b, b+1) * mask_dz; `nlev[off]` levels in use; level k of the cell is record
`off * K + k` of lev_f (lo, hi, log-odds, mean hit x, y offset from the cell centre,
this scan's hit range, mean hit height), lev_n (hits, passes, scan stamp, scans that hit
it) and lev_flag.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Fields of the float level record lev_f[li, :].
# SLO, SHI: height range of the hits in scan `stamp` (valid while HIT_FLAG is set).
# MX, MY, MZ: the mean hit (a running mean, `_MEAN_WINDOW`), x and y from the cell's
# centre and its height: a plane through the cells' mean hits fits a slope where the
# mid-range height, taken with the mean hit's x and y, is off by up to a centimetre on
# a cell that laser lines cross unevenly.
LO, HI, LOGODDS, MX, MY, SLO, SHI, MZ = range(8)
N_FLOAT_FIELDS = 8
# Fields of the integer level record lev_n[li, :]; SCANS counts the scans that hit it.
HITS, PASSES, STAMP, SCANS = 0, 1, 2, 3
N_INT_FIELDS = 4
LASER_GRAZE_SIN = math.sin(math.radians(30.0))  # the laser's rays along a face (module)
HIT_FLAG = 0x80  # lev_flag bit: hit in scan `stamp`; the low bits count its misses
# Fields of cells[off]: observed-height mask, last scan id, last scan whose laser line
# crossed the cell's floor unlit (`scanmap.grid.unlit`; 0 never), the cell the camera
# stood over at the last hit on the cell's lowest level (`pack_cell`; 0 none: where a
# drop-off it shows was seen from), and the ray-bundle scratch; a grid that counts
# visits (a submap) has a seventh, the scans whose rays reached the cell (not saved:
# how strongly a submap saw it free).
SEEN, SCAN, UNLIT, FROM, VKEY, VMASK, VISITS = range(7)
N_CELL_FIELDS = 6

# Point classes of classify_points.
POINT_OK, POINT_NONFINITE, POINT_OUTSIDE_WINDOW, POINT_OUTSIDE_EXTENT, POINT_TOO_FAR = range(5)

# Indices into the float parameter vector `fp` of the insertion kernel.
(FP_RES, FP_X0, FP_Y0, FP_ZMIN, FP_MASK_DZ, FP_GAP, FP_MARGIN, FP_LHIT, FP_LMISS, FP_LMAX,
 FP_PROTECT, FP_PASS_RADIUS, FP_GRAZE_SIN, FP_SEE_THROUGH) = range(14)
# Indices into the integer parameter vector `ip`.
IP_SHIFT, IP_LEVELS, IP_MAXMISS, IP_SCAN, IP_KEY, IP_RUN, IP_STATIC, IP_VISITS = range(8)

_U32_MAX = np.uint32(0xFFFFFFFF)
JOINT_XY = 1e-6  # m: an emitter this near the camera's x, y shares its rays' walk
_MEAN_WINDOW = 1024.0  # hit-centroid running mean forgets beyond this many hits


@njit(cache=True, nogil=True)
def classify_points(points: np.ndarray, origins: np.ndarray, bounds: np.ndarray,
                    window: np.ndarray, max_range: float) -> np.ndarray:
    """POINT_* class of each ray: bounds and window are (xmin, ymin, xmax, ymax) in metres.

    The rays are copied by columns first and classed without a branch: the loop then
    vectorises, where the rows' interleaved x, y, z kept it scalar (82 -> 43 us for
    20,000 rays)."""
    n = points.shape[0]
    p, o = columns(points), columns(origins)
    out = np.empty(n, np.uint8)
    reach = max_range * max_range
    for i in range(n):
        px, py, pz, ox, oy, oz = p[0, i], p[1, i], p[2, i], o[0, i], o[1, i], o[2, i]
        finite = _finite(px) & _finite(py) & _finite(pz) & _finite(ox) & _finite(oy) \
            & _finite(oz)
        inside = _in_box(px, py, bounds) & _in_box(ox, oy, bounds)
        in_window = _in_box(px, py, window) & _in_box(ox, oy, window)
        far = (px - ox) ** 2 + (py - oy) ** 2 + (pz - oz) ** 2 > reach
        out[i] = POINT_NONFINITE if not finite else POINT_OUTSIDE_EXTENT if not inside \
            else POINT_OUTSIDE_WINDOW if not in_window else POINT_TOO_FAR if far \
            else POINT_OK
    return out


@njit(cache=True, nogil=True, inline="always")
def columns(rows: np.ndarray) -> np.ndarray:
    """(3, N) float64 copy of (N, 3) rows: a loop over the columns vectorises, where over
    the rows their interleaved x, y, z are gathered lane by lane."""
    out = np.empty((3, rows.shape[0]))
    for i in range(rows.shape[0]):
        out[0, i], out[1, i], out[2, i] = rows[i, 0], rows[i, 1], rows[i, 2]
    return out


@njit(cache=True, nogil=True, inline="always")
def _finite(value: float) -> bool:
    """Neither NaN nor infinite, without a branch (x - x is NaN for both)."""
    return value - value == 0.0


@njit(cache=True, nogil=True, inline="always")
def _in_box(x: float, y: float, box: np.ndarray) -> bool:
    """xmin <= x < xmax and ymin <= y < ymax for box (xmin, ymin, xmax, ymax), without a
    branch."""
    return (box[0] <= x) & (x < box[2]) & (box[1] <= y) & (y < box[3])


@njit(cache=True, nogil=True)
def usable_box(xy: np.ndarray, cls: np.ndarray) -> np.ndarray:
    """(xmin, ymin, xmax, ymax) of the rows of xy (N, 2+) with cls == POINT_OK (NaN if none)."""
    box = np.array([np.inf, np.inf, -np.inf, -np.inf])
    for i in range(xy.shape[0]):
        if cls[i] == POINT_OK:
            box[0], box[1] = min(box[0], xy[i, 0]), min(box[1], xy[i, 1])
            box[2], box[3] = max(box[2], xy[i, 0]), max(box[3], xy[i, 1])
    if box[0] > box[2]:
        box[:] = np.nan
    return box


@njit(cache=True, nogil=True, inline="always")
def _dda_setup(gx0: float, gy0: float, gx1: float, gy1: float):
    """Amanatides-Woo set-up in cell units: start cell, steps, next crossings, deltas, count."""
    ix, iy = int(np.floor(gx0)), int(np.floor(gy0))
    ex, ey = int(np.floor(gx1)), int(np.floor(gy1))
    dx, dy = gx1 - gx0, gy1 - gy0
    sx = 1 if dx > 0 else -1
    sy = 1 if dy > 0 else -1
    if dx != 0.0:
        tdx = abs(1.0 / dx)
        tmx = ((ix + 1 - gx0) if dx > 0 else (gx0 - ix)) * tdx
    else:
        tdx, tmx = np.inf, np.inf
    if dy != 0.0:
        tdy = abs(1.0 / dy)
        tmy = ((iy + 1 - gy0) if dy > 0 else (gy0 - iy)) * tdy
    else:
        tdy, tmy = np.inf, np.inf
    return ix, iy, sx, sy, tmx, tmy, tdx, tdy, abs(ex - ix) + abs(ey - iy)


@njit(cache=True, nogil=True, inline="always")
def _dda_step(ix: int, iy: int, sx: int, sy: int, tmx: float, tmy: float, tdx: float,
              tdy: float):
    """One Amanatides-Woo step into the next cell: (ix, iy, t where it is entered, tmx,
    tmy)."""
    if tmx < tmy:
        return ix + sx, iy, tmx, tmx + tdx, tmy
    return ix, iy + sy, tmy, tmx, tmy + tdy


@njit(cache=True, nogil=True)
def _request_tile(tile_index, ty, tx, out, count) -> int:
    """Mark tile (ty, tx) requested (-2) and list it if it has no slot; -1 when out is full."""
    if tile_index[ty, tx] != -1:
        return count
    if count == out.shape[0]:
        return -1
    tile_index[ty, tx] = -2
    out[count, 0] = ty
    out[count, 1] = tx
    return count + 1


@njit(cache=True, nogil=True, inline="always")
def _corner_tiles_listed(tile_index, gx0, gy0, gx1, gy1) -> bool:
    """Whether a ray from tile coordinates (gx0, gy0) to (gx1, gy1) spans at most 2 x 2
    tiles, all with a slot or already listed: it crosses no other tile (a segment stays
    within its bounding box), so it needs no walk."""
    xa, xb = int(np.floor(min(gx0, gx1))), int(np.floor(max(gx0, gx1)))
    ya, yb = int(np.floor(min(gy0, gy1))), int(np.floor(max(gy0, gy1)))
    return xb - xa <= 1 and yb - ya <= 1 and tile_index[ya, xa] != -1 \
        and tile_index[ya, xb] != -1 and tile_index[yb, xa] != -1 and tile_index[yb, xb] != -1


@njit(cache=True, nogil=True, error_model="numpy")
def collect_missing_tiles(points: np.ndarray, origins: np.ndarray, cls: np.ndarray,
                          tile_index: np.ndarray, res: float, tile_cells: int, x0: float,
                          y0: float, out: np.ndarray) -> int:
    """Tiles crossed by valid rays that have no slot: marks them -2 and lists (ty, tx) in out.

    Tile coordinates are cell coordinates divided by the (power of 2) tile size, exactly
    as the insertion kernel computes them. Returns the count listed, or -1 when `out`
    filled up (allocate, then call again).
    """
    count = 0
    per_tile = 1.0 / tile_cells  # a power of two: multiplying by it divides exactly
    for i in range(points.shape[0]):
        if cls[i] != POINT_OK:
            continue
        gx0, gy0 = (origins[i, 0] - x0) / res * per_tile, (origins[i, 1] - y0) / res * per_tile
        gx1, gy1 = (points[i, 0] - x0) / res * per_tile, (points[i, 1] - y0) / res * per_tile
        if _corner_tiles_listed(tile_index, gx0, gy0, gx1, gy1):
            continue  # the common case once the map is built
        count = _request_tile(tile_index, int(np.floor(gy1)), int(np.floor(gx1)), out, count)
        ix, iy, sx, sy, tmx, tmy, tdx, tdy, steps = _dda_setup(gx0, gy0, gx1, gy1)
        for _ in range(steps + 1):
            if count < 0:
                return -1
            count = _request_tile(tile_index, iy, ix, out, count)
            ix, iy, _, tmx, tmy = _dda_step(ix, iy, sx, sy, tmx, tmy, tdx, tdy)
        if count < 0:
            return -1
    return count


@njit(cache=True, nogil=True, inline="always")
def height_mask(za: float, zb: float, z_min: float, dz: float) -> np.uint64:
    """Bits of the observed-height mask covering [za, zb] (za <= zb), clipped to 64 bins."""
    return bins_mask(int(np.floor((za - z_min) / dz)), int(np.floor((zb - z_min) / dz)))


@njit(cache=True, nogil=True, inline="always")
def bins_mask(b0: int, b1: int) -> np.uint64:
    """Bits b0 to b1 (b0 <= b1) of the observed-height mask, each clipped to 0-63."""
    b0 = min(max(b0, 0), 63)
    b1 = min(max(b1, 0), 63)
    one = np.uint64(1)
    high = np.uint64(0xFFFFFFFFFFFFFFFF) if b1 == 63 else (one << np.uint64(b1 + 1)) - one
    return high & ~((one << np.uint64(b0)) - one)


@njit(cache=True, nogil=True, inline="always")
def _touch(lev_n, lev_flag, li, scan) -> None:
    """Start the per-scan bookkeeping of level record li when this scan first touches it."""
    if lev_n[li, STAMP] != scan:
        lev_n[li, STAMP] = scan
        lev_flag[li] = 0


@njit(cache=True, nogil=True, inline="always")
def _copy_level(lev_f, lev_n, lev_flag, dst, src) -> None:
    """Copy level record src over record dst, field by field: assigning a whole row may
    need a temporary copy, an allocation the kernels compiled without reference counting
    cannot make."""
    for f in range(N_FLOAT_FIELDS):
        lev_f[dst, f] = lev_f[src, f]
    for f in range(N_INT_FIELDS):
        lev_n[dst, f] = lev_n[src, f]
    lev_flag[dst] = lev_flag[src]


@njit(cache=True, nogil=True, _nrt=False)
def _remove(lev_f, lev_n, lev_flag, nlev, off, k, levels) -> None:
    """Delete level k of cell off, keeping the others sorted and packed."""
    n = np.int64(nlev[off])
    base = off * levels
    for j in range(base + k, base + n - 1):
        _copy_level(lev_f, lev_n, lev_flag, j, j + 1)
    nlev[off] = n - 1


@njit(cache=True, nogil=True, _nrt=False)
def _merge_down(lev_f, lev_n, lev_flag, nlev, off, k, levels) -> None:
    """Merge level k+1 of cell off into its level k and close the slot it leaves."""
    ia = off * levels + k
    ib = ia + 1
    ha, hb = float(lev_n[ia, HITS]), float(lev_n[ib, HITS])
    w = hb / max(ha + hb, 1.0)
    lev_f[ia, MX] += (lev_f[ib, MX] - lev_f[ia, MX]) * w
    lev_f[ia, MY] += (lev_f[ib, MY] - lev_f[ia, MY]) * w
    lev_f[ia, MZ] += (lev_f[ib, MZ] - lev_f[ia, MZ]) * w
    lev_f[ia, LO] = min(lev_f[ia, LO], lev_f[ib, LO])
    lev_f[ia, HI] = max(lev_f[ia, HI], lev_f[ib, HI])
    lev_f[ia, LOGODDS] = max(lev_f[ia, LOGODDS], lev_f[ib, LOGODDS])
    lev_n[ia, HITS] = np.uint32(min(ha + hb, 4294967295.0))
    lev_n[ia, PASSES] = np.uint32(min(float(lev_n[ia, PASSES]) + float(lev_n[ib, PASSES]),
                                      4294967295.0))
    lev_n[ia, SCANS] = max(lev_n[ia, SCANS], lev_n[ib, SCANS])
    if lev_n[ib, STAMP] > lev_n[ia, STAMP]:
        lev_n[ia, STAMP] = lev_n[ib, STAMP]
        lev_flag[ia] = lev_flag[ib]
        lev_f[ia, SLO], lev_f[ia, SHI] = lev_f[ib, SLO], lev_f[ib, SHI]
    elif lev_n[ib, STAMP] == lev_n[ia, STAMP]:
        fa, fb = np.int64(lev_flag[ia]), np.int64(lev_flag[ib])
        lev_flag[ia] = ((fa | fb) & HIT_FLAG) | max(fa & 0x7F, fb & 0x7F)
        if fa & HIT_FLAG and fb & HIT_FLAG:
            lev_f[ia, SLO] = min(lev_f[ia, SLO], lev_f[ib, SLO])
            lev_f[ia, SHI] = max(lev_f[ia, SHI], lev_f[ib, SHI])
        elif fb & HIT_FLAG:
            lev_f[ia, SLO], lev_f[ia, SHI] = lev_f[ib, SLO], lev_f[ib, SHI]
    _remove(lev_f, lev_n, lev_flag, nlev, off, k + 1, levels)


@njit(cache=True, nogil=True, inline="always")
def _level_for(lev_f, base, n, lo, hi, gap) -> int:
    """The first of the n levels from record base within `gap` of heights [lo, hi], or
    -1."""
    for j in range(n):
        if lev_f[base + j, LO] - gap <= hi and lo <= lev_f[base + j, HI] + gap:
            return j
    return -1


@njit(cache=True, nogil=True, inline="always")
def _nearest_level(lev_f, base, n, lo, hi) -> int:
    """The one of the n levels from record base nearest to heights [lo, hi]."""
    best, k = np.inf, 0
    for j in range(n):
        d = max(lev_f[base + j, LO] - hi, lo - lev_f[base + j, HI])
        if d < best:
            best, k = d, j
    return k


@njit(cache=True, nogil=True, inline="always")
def _open_level(lev_f, lev_n, lev_flag, nlev, off, z, levels) -> int:
    """Make room in cell off for a new level at height z, in height order; returns its
    index (the caller fills the record)."""
    n = np.int64(nlev[off])
    base = off * levels
    k = 0
    while k < n and lev_f[base + k, LO] < z:
        k += 1
    for j in range(base + n, base + k, -1):
        _copy_level(lev_f, lev_n, lev_flag, j, j - 1)
    nlev[off] = n + 1
    return k


@njit(cache=True, nogil=True, inline="always")
def _merge_grown(lev_f, lev_n, lev_flag, nlev, off, k, gap, levels) -> None:
    """Merge level k of cell off, which just grew, with its neighbours within `gap`."""
    base = off * levels
    while k + 1 < np.int64(nlev[off]) and lev_f[base + k + 1, LO] - gap <= lev_f[base + k, HI]:
        _merge_down(lev_f, lev_n, lev_flag, nlev, off, k, levels)
    while k > 0 and lev_f[base + k - 1, HI] + gap >= lev_f[base + k, LO]:
        _merge_down(lev_f, lev_n, lev_flag, nlev, off, k - 1, levels)
        k -= 1


@njit(cache=True, nogil=True, inline="always")
def pack_cell(x: float, y: float, x0: float, y0: float, res: float) -> np.uint64:
    """The grid cell holding (x, y) as one number for `cells[off, FROM]`: (row << 32 |
    column) + 1 of the grid whose corner is (x0, y0); 0 (none) off the grid or NaN."""
    gx, gy = (x - x0) / res, (y - y0) / res
    if not (0.0 <= gx < 4294967295.0 and 0.0 <= gy < 4294967295.0):
        return np.uint64(0)
    return (np.uint64(int(gy)) << np.uint64(32) | np.uint64(int(gx))) + np.uint64(1)


@njit(cache=True, nogil=True, inline="always")
def unpack_cell(packed: np.uint64, x0: float, y0: float, res: float) -> tuple[float, float]:
    """x, y of the centre of the grid cell `pack_cell` packed (not 0)."""
    cell = packed - np.uint64(1)
    return (x0 + (float(cell & np.uint64(0xFFFFFFFF)) + 0.5) * res,
            y0 + (float(cell >> np.uint64(32)) + 0.5) * res)


@njit(cache=True, nogil=True, inline="always")
def _add_hit(lev_f, lev_n, lev_flag, nlev, off, z, ox, oy, fp, levels, scan) -> bool:
    """Record a hit at height z and offset (ox, oy) from the centre of cell off; True when
    it started a new level."""
    gap = fp[FP_GAP]
    n = np.int64(nlev[off])
    base = off * levels
    k = _level_for(lev_f, base, n, z, z, gap)
    fresh = k < 0 and n < levels
    if fresh:
        k = _open_level(lev_f, lev_n, lev_flag, nlev, off, z, levels)
        li = base + k
        lev_f[li, LO] = z
        lev_f[li, HI] = z
        lev_f[li, LOGODDS] = 0.0
        lev_f[li, MX] = ox
        lev_f[li, MY] = oy
        lev_f[li, MZ] = z
        lev_n[li, HITS] = 0
        lev_n[li, PASSES] = 0
        lev_n[li, STAMP] = scan
        lev_n[li, SCANS] = 0
        lev_flag[li] = 0
    elif k < 0:  # all K slots taken: the nearest level absorbs the hit (fills the gap)
        k = _nearest_level(lev_f, base, n, z, z)
    li = base + k
    grew = fresh or z < lev_f[li, LO] or z > lev_f[li, HI]
    lev_f[li, LO] = min(lev_f[li, LO], z)
    lev_f[li, HI] = max(lev_f[li, HI], z)
    hits = min(float(lev_n[li, HITS]) + 1.0, 4294967295.0)
    lev_n[li, HITS] = np.uint32(hits)
    w = 1.0 / min(hits, _MEAN_WINDOW)
    lev_f[li, MX] += (ox - lev_f[li, MX]) * w
    lev_f[li, MY] += (oy - lev_f[li, MY]) * w
    lev_f[li, MZ] += (z - lev_f[li, MZ]) * w
    _touch(lev_n, lev_flag, li, scan)
    if not lev_flag[li] & HIT_FLAG:
        lev_flag[li] |= HIT_FLAG
        lev_n[li, SCANS] = min(lev_n[li, SCANS] + np.uint32(1), _U32_MAX)
        lev_f[li, LOGODDS] = min(lev_f[li, LOGODDS] + fp[FP_LHIT], fp[FP_LMAX])
        lev_f[li, SLO] = z
        lev_f[li, SHI] = z
    else:
        lev_f[li, SLO] = min(lev_f[li, SLO], z)
        lev_f[li, SHI] = max(lev_f[li, SHI], z)
    if grew:  # only growth merges: the gap a ray opened by splitting a level stays open
        _merge_grown(lev_f, lev_n, lev_flag, nlev, off, k, gap, levels)
    return fresh


@njit(cache=True, nogil=True, _nrt=False)
def _closed_gap(lev_f, base, k, free_mask, z_min, dz) -> bool:
    """No height bin strictly between levels k and k+1 has been seen free."""
    b0 = int(np.floor((lev_f[base + k, HI] - z_min) / dz)) + 1
    b1 = int(np.floor((lev_f[base + k + 1, LO] - z_min) / dz)) - 1
    if b1 < b0:
        return True
    gap = height_mask(z_min + (b0 + 0.5) * dz, z_min + (b1 + 0.5) * dz, z_min, dz)
    return free_mask & gap == 0


@njit(cache=True, nogil=True, _nrt=False)
def _consolidate(lev_f, lev_n, lev_flag, nlev, off, z, free_mask, z_min, dz, levels) -> None:
    """Merge the level holding height z with its neighbours unless a ray was seen passing
    between them.

    A cell holds one surface until observations show more: sparse hits up a wall face
    become one level, while the floor and a table top, with rays seen passing between
    them (a height bin strictly between them seen free), stay two.
    """
    base = off * levels
    k = 0
    while k < np.int64(nlev[off]) and lev_f[base + k, HI] < z:
        k += 1
    if k == np.int64(nlev[off]):
        return
    if k + 1 < np.int64(nlev[off]) and _closed_gap(lev_f, base, k, free_mask, z_min, dz):
        _merge_down(lev_f, lev_n, lev_flag, nlev, off, k, levels)
    if k > 0 and _closed_gap(lev_f, base, k - 1, free_mask, z_min, dz):
        _merge_down(lev_f, lev_n, lev_flag, nlev, off, k - 1, levels)


@njit(cache=True, nogil=True, inline="always")
def _crosses(lo: float, hi: float, za: float, zb: float, bits: np.uint64, z_min: float,
             dz: float) -> bool:
    """A ray spanning heights [za, zb] (height bins `bits`) in a cell passed through the
    level [lo, hi]: through the height bin of its middle, or wholly inside it.

    The middle counts in height bins, as the observed mask and the ray bundles do: a thin
    level (a person's sleeve seen once) is the bin it lies in, and every ray through that
    bin passes it, as in a voxel map.
    """
    mid = 0.5 * (lo + hi)
    return bits & height_mask(mid, mid, z_min, dz) != 0 or (za >= lo and zb <= hi)


@njit(cache=True, nogil=True, inline="always")
def _enters(lo: float, hi: float, za: float, zb: float) -> bool:
    """A ray spanning heights [za, zb] in a cell reached into the level [lo, hi]."""
    return za < hi and zb > lo


@njit(cache=True, nogil=True, inline="always")
def _touches_any(lev_f, n, base, za, zb, bits, z_min, dz) -> bool:
    """Whether the ray passed through, or into, any of the n levels starting at record
    base (see _pass_cell)."""
    for li in range(base, base + n):
        lo, hi = lev_f[li, LO], lev_f[li, HI]
        if _enters(lo, hi, za, zb) or _crosses(lo, hi, za, zb, bits, z_min, dz):
            return True
    return False


@njit(cache=True, nogil=True, _nrt=False)
def _miss(lev_f, lev_n, lev_flag, nlev, off, k, fp, levels, max_miss) -> int:
    """One pass through level k of cell off: a miss, unless it had `max_misses` this scan.

    Returns 1 when the level falls to p = 0.5 and is removed.
    """
    li = off * levels + k
    flag = np.int64(lev_flag[li])
    if (flag & 0x7F) >= max_miss:
        return 0
    lev_flag[li] = flag + 1
    lev_f[li, LOGODDS] -= fp[FP_LMISS]
    if lev_f[li, LOGODDS] > 0.0:
        return 0
    _remove(lev_f, lev_n, lev_flag, nlev, off, k, levels)
    return 1


@njit(cache=True, nogil=True, _nrt=False)
def _split(lev_f, lev_n, lev_flag, nlev, off, k, za, zb, levels) -> None:
    """Split level k of cell off around the free span [za, zb] into two levels."""
    base = off * levels
    li = base + k
    for j in range(base + np.int64(nlev[off]), li, -1):  # level k itself too
        _copy_level(lev_f, lev_n, lev_flag, j, j - 1)
    lev_f[li, HI] = za
    lev_f[li, SHI] = min(lev_f[li, SHI], za)
    lev_f[li + 1, LO] = zb
    lev_f[li + 1, SLO] = max(lev_f[li + 1, SLO], zb)
    nlev[off] += 1


@njit(cache=True, nogil=True, _nrt=False)
def segment_distance(px: float, py: float, ax: float, ay: float, bx: float,
                     by: float) -> float:
    """Distance from point (px, py) to the segment (ax, ay)-(bx, by)."""
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 == 0.0 else min(max(((px - ax) * ex + (py - ay) * ey) / length2, 0.0), 1.0)
    return np.hypot(px - ax - t * ex, py - ay - t * ey)


@njit(cache=True, nogil=True, inline="always")
def _beside_static(lev_f, lev_n, nlev, tile_index, li, ix, iy, za, zb, path, fp, shift,
                   levels, static_scans) -> bool:
    """A level of a static surface and a ray that crossed its cell (ix, iy) only beside
    it: farther than `pass_radius` from the level's mean hit. Static: the level was hit
    in `static_scans` scans or more (a wall, furniture), or a neighbouring cell holds such
    a level at its heights (the face's end or rim, seen in fewer scans: a cabinet's end
    face seen only while the robot came towards it, its corner where a turned face cuts
    the cell near its edge). Where a face cuts a cell, rays through the cell's free part
    must not clear the face; a level seen briefly away from any static one (a person)
    clears from any pass. Nor does a ray near a static level's mean hit clear it where it
    passes a corner (`_past_corner`, the ray spanning heights [za, zb]): at a turned
    cabinet's corner the mean hit of the two faces' hits lies within `pass_radius` of
    both, and rays past the corner cleared it (people room 19002: a corner cut 1-2 cm
    into its cell FREE at one scan, with or without people)."""
    static = np.int64(lev_n[li, SCANS]) >= static_scans
    if segment_distance(lev_f[li, MX], lev_f[li, MY], path[0], path[1], path[2],
                        path[3]) <= fp[FP_PASS_RADIUS]:
        return static and _past_corner(lev_f, lev_n, nlev, tile_index, li, ix, iy, za, zb,
                                       path, fp, shift, levels, static_scans)
    return static or _beside_seen_in(
        lev_f, lev_n, nlev, tile_index, ix, iy, lev_f[li, LO], lev_f[li, HI], fp[FP_MASK_DZ],
        shift, levels, static_scans)


@njit(cache=True, nogil=True, inline="always")
def _cell_offset(tile_index, ix, iy, shift) -> int:
    """Flat cell offset of cell (ix, iy), or -1 outside the allocated tiles."""
    ty, tx = iy >> shift, ix >> shift
    if ix < 0 or iy < 0 or ty >= tile_index.shape[0] or tx >= tile_index.shape[1]:
        return -1
    slot = tile_index[ty, tx]
    if slot < 0:
        return -1
    mask = (1 << shift) - 1
    return (np.int64(slot) << (2 * shift)) | ((iy & mask) << shift) | (ix & mask)


_NEIGHBOURS = np.array([(dx, dy) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dx or dy],
                       np.int64)  # (dx, dy) of the 8 cells round a cell


@njit(cache=True, nogil=True, _nrt=False)
def _grazes_static(lev_f, lev_n, nlev, tile_index, li, ix, iy, za, zb, path, fp, shift,
                   levels, static_scans, graze) -> bool:
    """A ray (x-y direction path[4:6]) that runs along a static face through level record
    li of cell (ix, iy): one mean hit cannot tell a ray beside a face from one through it,
    so the face is read from the neighbouring cells (see _pass_cell).

    Their static levels (hit in `static_scans` scans or more) that reach the ray's heights
    [za, zb] (within a height bin) give one mean hit a cell; it takes two or more. The ray
    runs along the face when one of them lies, from the level's own mean hit, within
    the angle whose sine is `graze` of the ray's direction (ahead or behind, at least half
    a cell away) and the others all lie on one side of the ray's line: a face crossed
    steeply has its cells on both sides of the ray, a blob (a floor, a box's top at the
    ray's heights) all around it, while beside a corner (a cabinet's) the other face lies
    on one side only. One static neighbour alone (a person's outline) is too little to
    tell a face.
    """
    if graze <= 0.0:
        return False
    found, along, left, right = _static_sides(lev_f, lev_n, nlev, tile_index, ix, iy, za, zb,
                                              lev_f[li, MX], lev_f[li, MY], path, fp, shift,
                                              levels, static_scans, graze, 0.0)
    return found >= 2 and along and not (left and right)


@njit(cache=True, nogil=True, _nrt=False)
def _past_corner(lev_f, lev_n, nlev, tile_index, li, ix, iy, za, zb, path, fp, shift, levels,
                 static_scans) -> bool:
    """Whether a ray (its x-y segment in the cell path[0:4], direction path[4:6]) through
    level record li of cell (ix, iy) passes a static surface's corner or edge beside it:
    two or more of the neighbouring cells hold a static level at the ray's heights
    (`_static_sides`), all on one side of the ray's own line. A ray that crossed where a
    static surface stands would have it on both sides; one past its corner has all of it
    on one side. The sides are taken from the ray's own line, not a parallel through the
    level's mean hit, and a neighbour's mean hit within half `pass_radius` of it lies on
    neither: the mean hits are known to about that, and the rays past a turned cabinet's
    corner, within millimetres of it, had the mean hit of the corner's own cell on their
    far side (people room 20001: a corner cut 4 mm into its cell FREE, without people)."""
    found, _, left, right = _static_sides(lev_f, lev_n, nlev, tile_index, ix, iy, za, zb,
                                          path[0], path[1], path, fp, shift, levels,
                                          static_scans, 0.0, 0.5 * fp[FP_PASS_RADIUS])
    return found >= 2 and left != right


@njit(cache=True, nogil=True, _nrt=False)
def _static_sides(lev_f, lev_n, nlev, tile_index, ix, iy, za, zb, mx, my, path, fp, shift,
                  levels, static_scans, graze, margin) -> tuple[int, bool, bool, bool]:
    """Of the 8 cells round cell (ix, iy), those holding a static level (hit in
    `static_scans` scans or more) that reaches the heights [za, zb] (within a height bin),
    one mean hit a cell: how many, whether one lies, from the point (mx, my) (relative to
    the cell's centre), within the angle whose sine is `graze` of the ray's x-y direction
    path[4:6] (ahead or behind, at least half a cell away), and whether one lies left
    and one right of the line through (mx, my) in that direction (the others, more than
    `margin` off it)."""
    res, tol = fp[FP_RES], fp[FP_MASK_DZ]
    dx, dy = path[4], path[5]
    length = np.hypot(dx, dy)
    if length == 0.0:
        return 0, False, False, False
    ux, uy = dx / length, dy / length
    near2 = 0.25 * res * res
    along, left, right, found = False, False, False, 0
    for n in range(8):
        nx, ny = _NEIGHBOURS[n, 0], _NEIGHBOURS[n, 1]
        joff = _cell_offset(tile_index, ix + nx, iy + ny, shift)
        for lj in range(joff * levels, joff * levels + (np.int64(nlev[joff]) if joff >= 0 else 0)):
            if np.int64(lev_n[lj, SCANS]) >= static_scans \
                    and lev_f[lj, LO] - tol <= zb and za <= lev_f[lj, HI] + tol:
                found += 1
                px, py = nx * res + lev_f[lj, MX] - mx, ny * res + lev_f[lj, MY] - my
                d2 = px * px + py * py
                cross = ux * py - uy * px
                if cross * cross <= graze * graze * d2:
                    along = along or d2 >= near2
                elif cross > margin:
                    left = True
                elif cross < -margin:
                    right = True
                break
    return found, along, left, right


@njit(cache=True, nogil=True, _nrt=False)
def _beside_seen_in(lev_f, lev_n, nlev, tile_index, ix, iy, lo, hi, tol, shift, levels,
                    scans) -> bool:
    """Whether one of the 8 cells round cell (ix, iy) holds a level hit in `scans` scans or
    more that reaches the heights [lo, hi] (within `tol`): the level of (ix, iy) at those
    heights may be part of the same surface, seen in fewer scans there (a face's end or
    rim, hit at a grazing angle), not what a person left (see _pass_cell)."""
    for n in range(8):
        joff = _cell_offset(tile_index, ix + _NEIGHBOURS[n, 0], iy + _NEIGHBOURS[n, 1], shift)
        for lj in range(joff * levels, joff * levels + (np.int64(nlev[joff]) if joff >= 0 else 0)):
            if np.int64(lev_n[lj, SCANS]) >= scans and lev_f[lj, LO] - tol <= hi \
                    and lo <= lev_f[lj, HI] + tol:
                return True
    return False


@njit(cache=True, nogil=True, _nrt=False)
def _pass_cell(lev_f, lev_n, lev_flag, nlev, tile_index, off, ix, iy, za, zb, bits, path, fp,
               shift, levels, max_miss, static_scans, scan, through, from_laser) -> int:
    """A ray spanning heights [za, zb] crossed cell off: clear the levels it passed through.

    A level not hit in this scan takes a miss; one the ray only entered, from above or
    below, without passing its middle (`_crosses`), is trimmed to the ray's nearer end
    (also when hit in this scan, but not within `protect` of that end): that part of it
    is free, the rest keeps its confidence. A level hit in this scan, but
    not within `protect` of these heights, and crossed strictly inside, wrongly spans
    free space (a floor merged with a table top before the gap was seen; the floor where
    a person stood): it is split around the span, and the part without this scan's hits
    takes the miss, or is cut off when thinner than two height bins. `path` is the ray's
    x-y segment in the cell, relative to its centre (see _beside_static), and its x-y
    direction. A level not hit in this scan is also left alone by a ray that runs along
    the static face it lies on (_grazes_static: cell (ix, iy)'s neighbours, found through
    `tile_index`, give the face's direction), when it was hit in at least half
    `static_scans` scans: a face that cuts a cell off its centre is hit there in fewer
    scans than in its neighbours, and the level is split by rays through the free part.
    A level hit in one scan only, not hit in this one, is removed outright by a ray that
    went on `see_through` beyond the cell (`through`), unless a neighbouring cell holds a
    level at its heights hit in two scans or more (_beside_seen_in).
    Returns the levels removed.
    """
    cleared = 0
    base = off * levels
    protect = fp[FP_PROTECT]
    split_margin = 0.5 * fp[FP_MASK_DZ]
    min_part = 2.0 * fp[FP_MASK_DZ]
    for k in range(np.int64(nlev[off]) - 1, -1, -1):
        li = base + k
        lo, hi = lev_f[li, LO], lev_f[li, HI]
        crossed = _crosses(lo, hi, za, zb, bits, fp[FP_ZMIN], fp[FP_MASK_DZ])
        if not crossed and not _enters(lo, hi, za, zb):
            continue
        _touch(lev_n, lev_flag, li, scan)
        if from_laser and (np.int64(lev_n[li, SCANS]) >= static_scans or segment_distance(
                lev_f[li, MX], lev_f[li, MY], path[0], path[1], path[2], path[3])
                > fp[FP_PASS_RADIUS] or _grazes_static(
                    lev_f, lev_n, nlev, tile_index, li, ix, iy, za, zb, path, fp, shift,
                    levels, 1, LASER_GRAZE_SIN)):
            continue  # a laser ray: only near the mean hit of a level seen briefly
        hit_now = lev_flag[li] & HIT_FLAG
        if not hit_now and _beside_static(lev_f, lev_n, nlev, tile_index, li, ix, iy, za, zb,
                                          path, fp, shift, levels, static_scans):
            continue
        if not hit_now and 2 * np.int64(lev_n[li, SCANS]) >= static_scans \
                and _grazes_static(lev_f, lev_n, nlev, tile_index, li, ix, iy, za, zb, path,
                                   fp, shift, levels, static_scans, fp[FP_GRAZE_SIN]):
            continue
        if not crossed:  # into the level's top or bottom, not through its middle
            # The part the ray passed through is free: trim it off, unless this scan hit
            # the level within `protect` of it.
            if za > 0.5 * (lo + hi):
                if not hit_now or za > lev_f[li, SHI] + protect:
                    lev_f[li, HI] = za
            elif not hit_now or zb < lev_f[li, SLO] - protect:
                lev_f[li, LO] = zb
            continue
        lev_n[li, PASSES] = min(lev_n[li, PASSES] + np.uint32(1), _U32_MAX)
        if not hit_now:
            if through and lev_n[li, SCANS] <= 1 and not _beside_seen_in(
                    lev_f, lev_n, nlev, tile_index, ix, iy, lo, hi, fp[FP_MASK_DZ], shift,
                    levels, 2):
                _remove(lev_f, lev_n, lev_flag, nlev, off, k, levels)  # one look through
                cleared += 1  # outweighs one scan's hits
            else:
                cleared += _miss(lev_f, lev_n, lev_flag, nlev, off, k, fp, levels, max_miss)
            continue
        if zb >= lev_f[li, SLO] - protect and za <= lev_f[li, SHI] + protect:
            continue  # hit near these heights in this scan: occupied wins
        hits_below, hits_above = lev_f[li, SLO] <= za, lev_f[li, SHI] >= zb
        inside = lo + split_margin < za and zb + split_margin < hi
        if not hits_above and hi - zb < min_part:
            lev_f[li, HI] = max(za, lev_f[li, SHI])  # cut off the unsupported top
        elif not hits_below and za - lo < min_part:
            lev_f[li, LO] = min(zb, lev_f[li, SLO])
        elif inside and np.int64(nlev[off]) < levels:
            _split(lev_f, lev_n, lev_flag, nlev, off, k, za, zb, levels)
            if not hits_above:
                cleared += _miss(lev_f, lev_n, lev_flag, nlev, off, k + 1, fp, levels,
                                 max_miss)
            if not hits_below:
                cleared += _miss(lev_f, lev_n, lev_flag, nlev, off, k, fp, levels, max_miss)
        else:
            cleared += _miss(lev_f, lev_n, lev_flag, nlev, off, k, fp, levels, max_miss)
    return cleared


@njit(cache=True, nogil=True)
def insert_scan(points: np.ndarray, origins: np.ndarray, cls: np.ndarray,
                lasers: np.ndarray, laser_cls: np.ndarray, tile_index: np.ndarray,
                lev_f: np.ndarray, lev_n: np.ndarray, lev_flag: np.ndarray, nlev: np.ndarray,
                cells: np.ndarray, fp: np.ndarray, ip: np.ndarray) -> tuple[int, int, int]:
    """Insert one scan: the hits and camera rays from `origins` with cls == POINT_OK and,
    where `lasers` holds a row per point (else none), the laser's rays from its emitter
    with laser_cls == POINT_OK; returns (hits, cleared, last ray key)."""
    n = points.shape[0]
    return _insert_scan(points, origins, cls, lasers, laser_cls, tile_index, lev_f, lev_n,
                        lev_flag, nlev, cells, fp, ip, np.empty(n, np.int64),
                        np.empty(n, np.float64), np.empty(6, np.float64))


@njit(cache=True, nogil=True, _nrt=False)
def _insert_scan(points, origins, cls, lasers, laser_cls, tile_index, lev_f, lev_n, lev_flag,
                 nlev, cells, fp, ip, fresh, fresh_z, path) -> tuple[int, int, int]:
    """`insert_scan` with its scratch: (N,) cells where a hit started a level and the
    height it started at, and (6,) a ray's x-y segment in a cell, from the cell's centre,
    and its x-y direction (see _beside_static)."""
    res, x0, y0 = fp[FP_RES], fp[FP_X0], fp[FP_Y0]
    z_min, mdz = fp[FP_ZMIN], fp[FP_MASK_DZ]
    shift, levels = ip[IP_SHIFT], ip[IP_LEVELS]
    count_visits = ip[IP_VISITS] != 0
    mask = (1 << shift) - 1
    scan = np.uint32(ip[IP_SCAN])
    scan64 = np.uint64(ip[IP_SCAN])
    n_hits = 0
    n_fresh = 0
    for i in range(points.shape[0]):  # pass 1: hits
        if cls[i] != POINT_OK:
            continue
        gx, gy = (points[i, 0] - x0) / res, (points[i, 1] - y0) / res
        ix, iy = int(np.floor(gx)), int(np.floor(gy))
        off = (np.int64(tile_index[iy >> shift, ix >> shift]) << (2 * shift)) \
            | ((iy & mask) << shift) | (ix & mask)
        z = points[i, 2]
        if _add_hit(lev_f, lev_n, lev_flag, nlev, off, z, (gx - ix - 0.5) * res,
                    (gy - iy - 0.5) * res, fp, levels, scan):
            fresh[n_fresh] = off
            fresh_z[n_fresh] = z
            n_fresh += 1
        if np.float32(z) <= lev_f[off * levels, HI]:  # on its lowest level: seen from there
            cells[off, FROM] = pack_cell(origins[i, 0], origins[i, 1], x0, y0, res)
        if count_visits and cells[off, SCAN] != scan64:
            cells[off, VISITS] += np.uint64(1)
        cells[off, SCAN] = scan64
        n_hits += 1
    key = np.uint64(ip[IP_KEY])
    n_cleared, key = _trace_rays(points, origins, cls, lasers, laser_cls, tile_index, lev_f,
                                 lev_n, lev_flag, nlev, cells, fp, ip, key, path,
                                 False)  # pass 2
    if lasers.shape[0] == points.shape[0]:
        cleared, key = _trace_rays(points, origins, cls, lasers, laser_cls, tile_index, lev_f,
                                   lev_n, lev_flag, nlev, cells, fp, ip, key, path, True)
        n_cleared += cleared
    for i in range(n_fresh):  # pass 3: merge new levels unless their gap was seen free
        off = fresh[i]
        _consolidate(lev_f, lev_n, lev_flag, nlev, off, fresh_z[i], cells[off, SEEN], z_min,
                     mdz, levels)
    return n_hits, n_cleared, np.int64(key)


@njit(cache=True, nogil=True, inline="always")
def _deepest_look(seen, bits, lev_f, nlev, off, levels, z_low) -> bool:
    """Whether a camera ray crossing cell off at height bins `bits`, down to z_low, looked
    as deep into it as any before (its lowest bin at or below the lowest the cell's `seen`
    mask holds) and below its every level: where a drop-off the cell shows was seen from
    (`FROM`), as a hit on its lowest level tells in `_insert_scan`."""
    lowest_seen = seen & (~seen + np.uint64(1))
    return (seen == 0 or bits & (~bits + np.uint64(1)) <= lowest_seen) \
        and (nlev[off] == 0 or z_low < lev_f[off * levels, LO])


@njit(cache=True, nogil=True, inline="always")
def _joint(origins, cls, lasers, laser_cls, i) -> bool:
    """Whether the camera's and the laser's rays to point i are both traced and cross the
    same cells: the emitter lies over or under the camera centre (within JOINT_XY), as on
    the reference scanner, so one walk serves both."""
    return lasers.shape[0] == origins.shape[0] and cls[i] == POINT_OK \
        and laser_cls[i] == POINT_OK and abs(lasers[i, 0] - origins[i, 0]) <= JOINT_XY \
        and abs(lasers[i, 1] - origins[i, 1]) <= JOINT_XY


@njit(cache=True, nogil=True, _nrt=False)
def _trace_rays(points, origins, cls, lasers, laser_cls, tile_index, lev_f, lev_n, lev_flag,
                nlev, cells, fp, ip, key, path, from_laser) -> tuple[int, np.uint64]:
    """Pass 2 of `_insert_scan`: the rays to the points, each traced from the hit back to
    its origin; returns the levels cleared and the last bundle key. Without `from_laser`
    the camera's, from `origins`, and in the same walk the laser's where they cross the
    same cells (`_joint`: its emitter's x, y are the camera's, so the walk's cells and
    its parameter t are the laser ray's too; it goes as far as the camera's ray, whose
    bundle ends both). With `from_laser`, the laser's other rays, from `lasers` (see the
    module)."""
    res, x0, y0 = fp[FP_RES], fp[FP_X0], fp[FP_Y0]
    z_min, mdz = fp[FP_ZMIN], fp[FP_MASK_DZ]
    shift, levels = ip[IP_SHIFT], ip[IP_LEVELS]
    bundle_run = ip[IP_RUN]
    # multiplied by, not divided: a ray's set-up held twelve divisions (about 0.25 ms of a
    # 20,000-point scan's 3.6). Where a point lies on a cell's edge its cell may round
    # otherwise than pass 1's; the ray's cells are then checked against the tiles as
    # rounding off them is (`tile_base`)
    per_res, per_dz = 1.0 / res, 1.0 / mdz
    count_visits = ip[IP_VISITS] != 0
    mask = (1 << shift) - 1
    scan64 = np.uint64(ip[IP_SCAN])
    n_cleared = 0
    group = (-1, -1, -1)
    for i in range(points.shape[0]):
        joint = _joint(origins, cls, lasers, laser_cls, i)
        if from_laser:
            if laser_cls[i] != POINT_OK or joint:
                continue
            ox, oy, oz = lasers[i, 0], lasers[i, 1], lasers[i, 2]
        else:
            if cls[i] != POINT_OK:
                continue
            ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        origin_cell = (int(np.floor(ox * per_res)), int(np.floor(oy * per_res)),
                       int(np.floor(oz * per_res)))
        if origin_cell != group:
            group = origin_cell
            key += np.uint64(1)
        pz = points[i, 2]
        dxr, dyr, dzr = ox - points[i, 0], oy - points[i, 1], oz - pz
        length = np.sqrt(dxr * dxr + dyr * dyr + dzr * dzr)
        t_margin = fp[FP_MARGIN] / length if length > 0.0 else 2.0
        dz_laser, length_laser, t_margin_laser = 0.0, 0.0, 2.0  # the laser's ray, if joint
        if joint:
            dz_laser = lasers[i, 2] - pz
            length_laser = np.sqrt(dxr * dxr + dyr * dyr + dz_laser * dz_laser)
            if length_laser > 0.0:
                t_margin_laser = fp[FP_MARGIN] / length_laser
        path[4], path[5] = dxr, dyr
        seen_from = pack_cell(ox, oy, x0, y0, res)
        ix, iy, sx, sy, tmx, tmy, tdx, tdy, steps = _dda_setup(
            (points[i, 0] - x0) * per_res, (points[i, 1] - y0) * per_res,
            (ox - x0) * per_res, (oy - y0) * per_res)
        # the ray's height bin at t: bin_at + bin_rate * t, one multiply a cell, where
        # height_mask's two divisions were the loop's longest wait (insertion 8 % faster)
        bin_at, bin_rate = (pz - z_min) * per_dz, dzr * per_dz
        t_in, b_in = 0.0, int(np.floor(bin_at))
        run = 0
        tile_x, tile_y, tile_base = -1, -1, np.int64(-1)
        for s in range(steps + 1):
            if ix >> shift != tile_x or iy >> shift != tile_y:
                tile_x, tile_y = ix >> shift, iy >> shift
                tile_base = np.int64(tile_index[tile_y, tile_x]) << (2 * shift)
            t_out = 1.0 if s == steps else min(tmx, tmy, 1.0)
            b_out = int(np.floor(bin_at + bin_rate * t_out))
            if tile_base >= 0:  # always, unless rounding stepped off the ray's tiles
                off = tile_base | ((iy & mask) << shift) | (ix & mask)
                bits = bins_mask(min(b_in, b_out), max(b_in, b_out))
                if bundle_run > 0 and cells[off, VKEY] == key \
                        and cells[off, VMASK] & bits == bits:
                    run += 1  # a ray of the same origin already did this cell's update
                    if run == bundle_run:
                        break
                else:
                    run = 0
                    if cells[off, VKEY] != key:
                        cells[off, VKEY] = key
                        cells[off, VMASK] = 0
                    cells[off, VMASK] |= bits
                    if not from_laser:
                        if _deepest_look(cells[off, SEEN], bits, lev_f, nlev, off, levels,
                                         pz + dzr * (t_in if dzr > 0.0 else t_out)):
                            cells[off, FROM] = seen_from
                        cells[off, SEEN] |= bits
                    if count_visits and cells[off, SCAN] != scan64:
                        cells[off, VISITS] += np.uint64(1)
                    cells[off, SCAN] = scan64
                    n_cleared += _clear_in_cell(points, i, lev_f, lev_n, lev_flag, nlev,
                                                tile_index, off, ix, iy, t_in, t_out, t_margin,
                                                dzr, length, path, fp, ip, from_laser)
                if joint:
                    n_cleared += _clear_in_cell(points, i, lev_f, lev_n, lev_flag, nlev,
                                                tile_index, off, ix, iy, t_in, t_out,
                                                t_margin_laser, dz_laser, length_laser, path,
                                                fp, ip, True)
            b_in = b_out
            ix, iy, t_in, tmx, tmy = _dda_step(ix, iy, sx, sy, tmx, tmy, tdx, tdy)
    return n_cleared, key


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _clear_in_cell(points, i, lev_f, lev_n, lev_flag, nlev, tile_index, off, ix, iy, t_in,
                   t_out, t_margin, dzr, length, path, fp, ip, from_laser) -> int:
    """The levels of cell `off` that the ray from point i, rising dzr over its length, passed
    between t_in and t_out (past its last `clear_margin`, t_margin), cleared by
    `_pass_cell`; path[4:6] holds the ray's x-y direction. Returns the levels removed."""
    if nlev[off] == 0 or t_out <= t_margin:
        return 0
    res, z_min, mdz = fp[FP_RES], fp[FP_ZMIN], fp[FP_MASK_DZ]
    levels = ip[IP_LEVELS]
    pz = points[i, 2]
    t_clear = max(t_in, t_margin)
    za, zb = pz + dzr * t_clear, pz + dzr * t_out
    za, zb = min(za, zb), max(za, zb)
    clear = height_mask(za, zb, z_min, mdz)
    if not _touches_any(lev_f, nlev[off], off * levels, za, zb, clear, z_min, mdz):
        return 0
    cx, cy = fp[FP_X0] + (ix + 0.5) * res, fp[FP_Y0] + (iy + 0.5) * res
    path[0] = points[i, 0] + path[4] * t_clear - cx
    path[1] = points[i, 1] + path[5] * t_clear - cy
    path[2] = points[i, 0] + path[4] * t_out - cx
    path[3] = points[i, 1] + path[5] * t_out - cy
    return _pass_cell(lev_f, lev_n, lev_flag, nlev, tile_index, off, ix, iy, za, zb, clear,
                      path, fp, ip[IP_SHIFT], levels, ip[IP_MAXMISS], ip[IP_STATIC],
                      np.uint32(ip[IP_SCAN]), t_in * length >= fp[FP_SEE_THROUGH],
                      from_laser)


@njit(cache=True, nogil=True)
def mark_unlit(points: np.ndarray, tile_index: np.ndarray, cells: np.ndarray, x0: float,
               y0: float, res: float, shift: int, scan: int) -> int:
    """Stamp `scan` as the cells' last unlit scan at the (x, y) of points (M, 2+) in
    allocated tiles (a cell no ray of the scan reached is not marked); returns how many."""
    marked = 0
    for i in range(points.shape[0]):
        gx, gy = (points[i, 0] - x0) / res, (points[i, 1] - y0) / res
        if not (0.0 <= gx < float(tile_index.shape[1] << shift)
                and 0.0 <= gy < float(tile_index.shape[0] << shift)):
            continue  # beyond the grid, or NaN
        off = _cell_offset(tile_index, int(np.floor(gx)), int(np.floor(gy)), shift)
        if off >= 0:
            cells[off, UNLIT] = np.uint64(scan)
            marked += 1
    return marked


@njit(cache=True, nogil=True)
def extract_window(tile_index: np.ndarray, lev_f: np.ndarray, lev_n: np.ndarray,
                   nlev: np.ndarray, cells: np.ndarray, shift: int, levels: int, ix0: int,
                   iy0: int, out_f: np.ndarray, out_n: np.ndarray, out_nlev: np.ndarray,
                   out_seen: np.ndarray, out_scan: np.ndarray, out_unlit: np.ndarray,
                   out_from: np.ndarray, corner: float, res: float) -> None:
    """Copy cells [iy0, iy0+ny) x [ix0, ix0+nx) into dense arrays, every entry written (the
    arrays may come uninitialised: one pass over them instead of zeroing first): absent
    tiles and unused levels are zeros. out_from (ny, nx, 2): x, y of the centre of the cell
    each cell's lowest level was seen from (`FROM`), of the grid whose corner is (corner,
    corner); NaN without."""
    ny, nx = out_nlev.shape
    for y in range(ny):
        for x in range(nx):
            off = _cell_offset(tile_index, ix0 + x, iy0 + y, shift)
            n = nlev[off] if off >= 0 else 0
            out_nlev[y, x] = n
            out_seen[y, x] = cells[off, SEEN] if off >= 0 else np.uint64(0)
            out_scan[y, x] = cells[off, SCAN] if off >= 0 else np.uint64(0)
            out_unlit[y, x] = off >= 0 and cells[off, UNLIT] != 0
            out_from[y, x, 0], out_from[y, x, 1] = np.nan, np.nan
            if off >= 0 and cells[off, FROM] > 0:
                out_from[y, x, 0], out_from[y, x, 1] = unpack_cell(cells[off, FROM], corner,
                                                                   corner, res)
            for k in range(levels):  # by elements: slices cost a view each
                for f in range(N_FLOAT_FIELDS):
                    out_f[y, x, k, f] = lev_f[off * levels + k, f] if k < n else 0.0
                out_n[y, x, k, HITS] = lev_n[off * levels + k, HITS] if k < n else 0
                out_n[y, x, k, PASSES] = lev_n[off * levels + k, PASSES] if k < n else 0


@njit(cache=True, nogil=True)
def frame_rays(points: np.ndarray, headings: np.ndarray, frames: np.ndarray,
               poses: np.ndarray, head: np.ndarray, camera: np.ndarray,
               out_points: np.ndarray, out_origins: np.ndarray) -> None:
    """Points (N, 3) in base_link and their camera centres (the camera at `camera` in the
    head mount, turned by each heading about z, then by the 4x4 `head` pose) carried to
    map by the pose of each point's frame (poses (F, 4, 4)). A frame's points share its
    heading: the camera centre is turned and carried again only when the heading or the
    frame changes (a point's own work is then its pose's three rows: 103 -> 38 us for
    20,000 points). An empty `out_points` ((0, 3)) leaves the points out: only their
    origins are wanted."""
    with_points = out_points.shape[0] == points.shape[0]
    last_heading, last_frame = np.nan, -1
    bx = by = bz = 0.0
    origin = (0.0, 0.0, 0.0)
    zero = (0.0, 0.0, 0.0, 0.0)
    row_x, row_y, row_z = zero, zero, zero  # the frame's pose, read once a frame
    for i in range(points.shape[0]):
        f = frames[i]
        if headings[i] != last_heading or f != last_frame:
            if headings[i] != last_heading:
                last_heading = headings[i]
                c, s = np.cos(headings[i]), np.sin(headings[i])
                mx = c * camera[0] - s * camera[1]
                my = s * camera[0] + c * camera[1]
                mz = camera[2]
                bx = head[0, 0] * mx + head[0, 1] * my + head[0, 2] * mz + head[0, 3]
                by = head[1, 0] * mx + head[1, 1] * my + head[1, 2] * mz + head[1, 3]
                bz = head[2, 0] * mx + head[2, 1] * my + head[2, 2] * mz + head[2, 3]
            last_frame = f
            row_x = (poses[f, 0, 0], poses[f, 0, 1], poses[f, 0, 2], poses[f, 0, 3])
            row_y = (poses[f, 1, 0], poses[f, 1, 1], poses[f, 1, 2], poses[f, 1, 3])
            row_z = (poses[f, 2, 0], poses[f, 2, 1], poses[f, 2, 2], poses[f, 2, 3])
            origin = (_affine(row_x, bx, by, bz), _affine(row_y, bx, by, bz),
                      _affine(row_z, bx, by, bz))
        out_origins[i, 0], out_origins[i, 1], out_origins[i, 2] = origin
        if with_points:
            px, py = np.float64(points[i, 0]), np.float64(points[i, 1])
            pz = np.float64(points[i, 2])
            out_points[i, 0] = _affine(row_x, px, py, pz)
            out_points[i, 1] = _affine(row_y, px, py, pz)
            out_points[i, 2] = _affine(row_z, px, py, pz)


@njit(cache=True, nogil=True, inline="always")
def _affine(row: tuple[float, float, float, float], x: float, y: float, z: float) -> float:
    """One row of a 4x4 rigid transform applied to (x, y, z, 1)."""
    return row[0] * x + row[1] * y + row[2] * z + row[3]
