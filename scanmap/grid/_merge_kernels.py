"""Numba kernels that merge a newer grid (a submap) into an older one under a planar
rigid motion: what a rebuild after loop closure does instead of tracing every ray again.

Free space is read backwards: each destination cell the submap covers takes the heights
seen free in every submap cell under its corners (one cell unless the motion turns or
shifts the submap by part of a cell), less the heights levels occupy there. Levels go
forwards: each into the cell its mean hit moves to, so that a turned wall stays where
it was hit. A level whose mean hit crosses into the next cell leaves its own cell
unknown at its heights, never free. Per cell, with the submap the newer observation:
1. A destination level that the submap has no level near (within `merge_gap`), whose
   middle height bin the submap's rays saw free, and that fewer than `static_scans` scans
   hit, takes a miss (`l_miss`) for each scan of the submap whose rays reached the cell,
   and goes when its log-odds reach 0: later scans saw through it (a person who walked
   on). Sequential fusion gives a miss per ray through the level's middle, up to
   `max_misses` a scan; a submap's cell no longer tells its rays apart, so one a scan. A
   level hit in `static_scans` scans or more (a wall, furniture) stays: sequential fusion
   clears it only by rays passing within `pass_radius` of its mean hit, which a submap's
   cells no longer tell apart from rays through the cell's free part.
2. Each submap level joins the destination level within `merge_gap` of it (extents
   joined, log-odds added and clamped, counts added, mean hit weighted by hits) or
   becomes a level of its own; levels it grew into merge, as a hit's growth merges.
3. The observed heights are joined; the last update is the newer one, and so is where
   the cell's lowest level was seen from (`FROM`, moved with the submap).
Scan ids of the submap (its cells' last scan, its levels' stamps) move by `scan_offset`,
so that they follow the destination's. The submap comes packed (`scanmap.grid.packed`):
its cells found through its own tile index (`_src_offset`), its levels from each cell's
`first`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from scanmap.grid._kernels import (
    FP_GAP,
    FP_LMAX,
    FP_LMISS,
    FP_MASK_DZ,
    FP_RES,
    FP_X0,
    FP_Y0,
    FP_ZMIN,
    FROM,
    HI,
    HITS,
    LO,
    LOGODDS,
    MX,
    MY,
    MZ,
    PASSES,
    SCAN,
    SCANS,
    SEEN,
    STAMP,
    UNLIT,
    _cell_offset,
    _level_for,
    _merge_grown,
    _nearest_level,
    _open_level,
    _remove,
    height_mask,
    pack_cell,
    unpack_cell,
)
from scanmap.grid.packed import P_FROM, P_SCAN, P_SEEN, P_UNLIT, P_VISITS

_U32_MAX = 4294967295.0


@njit(cache=True, nogil=True, inline="always")
def _src_offset(src_index, src_origin, ix, iy, shift) -> int:
    """Packed cell offset of the submap's cell (ix, iy) (the grid's cell numbers), or -1
    where it has no tile."""
    return _cell_offset(src_index, ix - src_origin[0], iy - src_origin[1], shift)


@njit(cache=True, nogil=True, inline="always")
def _source_index(motion, ix, iy, fp) -> tuple[int, int]:
    """(ix, iy) of the submap cell under the centre of destination cell (ix, iy); motion:
    cos, sin, tx, ty of the submap's motion into the destination."""
    res, x0, y0 = fp[FP_RES], fp[FP_X0], fp[FP_Y0]
    c, s = motion[0], motion[1]
    dx, dy = x0 + (ix + 0.5) * res - motion[2], y0 + (iy + 0.5) * res - motion[3]
    return (int(np.floor((c * dx + s * dy - x0) / res)),  # R^T (p - t)
            int(np.floor((-s * dx + c * dy - y0) / res)))


@njit(cache=True, nogil=True, inline="always")
def _source_cell(src_index, src_origin, src_nlev, src_cells, motion, ix, iy, fp, shift
                 ) -> int:
    """Offset of the submap cell under destination cell (ix, iy), or -1 where the submap
    holds nothing."""
    sx, sy = _source_index(motion, ix, iy, fp)
    off = _src_offset(src_index, src_origin, sx, sy, shift)
    if off < 0 or (src_nlev[off] == 0 and src_cells[off, P_SEEN] == 0
                   and src_cells[off, P_UNLIT] == 0):
        return -1
    return off


@njit(cache=True, nogil=True, inline="always")
def _hit_cell(src_f, sl, sx, sy, motion, fp) -> tuple[int, int, float, float]:
    """Destination cell (ix, iy) of submap level record sl of cell (sx, sy): where its
    mean hit lands; and the mean hit's offset from that cell's centre."""
    res, x0, y0 = fp[FP_RES], fp[FP_X0], fp[FP_Y0]
    c, s = motion[0], motion[1]
    px, py = x0 + (sx + 0.5) * res + src_f[sl, MX], y0 + (sy + 0.5) * res + src_f[sl, MY]
    qx, qy = c * px - s * py + motion[2], s * px + c * py + motion[3]
    ix, iy = int(np.floor((qx - x0) / res)), int(np.floor((qy - y0) / res))
    return ix, iy, qx - (x0 + (ix + 0.5) * res), qy - (y0 + (iy + 0.5) * res)


@njit(cache=True, nogil=True, inline="always")
def _moved_cell(packed, motion, fp) -> np.uint64:
    """`pack_cell` of the centre of the submap cell `packed` (a `FROM` field) moved by
    `motion` into the destination."""
    res, x0, y0 = fp[FP_RES], fp[FP_X0], fp[FP_Y0]
    c, s = motion[0], motion[1]
    px, py = unpack_cell(packed, x0, y0, res)
    return pack_cell(c * px - s * py + motion[2], s * px + c * py + motion[3], x0, y0, res)


@njit(cache=True, nogil=True, inline="always")
def _list_tile(dst_index, ix, iy, shift, out, count) -> int:
    """Add the tile of destination cell (ix, iy) to `out` unless allocated or listed
    (or outside the grid); the new count, or -1 when `out` is full."""
    ty, tx = iy >> shift, ix >> shift
    if ix < 0 or iy < 0 or ty >= dst_index.shape[0] or tx >= dst_index.shape[1] \
            or dst_index[ty, tx] != -1:
        return count
    if count == out.shape[0]:
        return -1
    dst_index[ty, tx] = -2
    out[count, 0], out[count, 1] = ty, tx
    return count + 1


@njit(cache=True, nogil=True)
def tiles_to_merge(src_index, src_origin, src_nlev, src_first, src_cells, src_f, dst_index,
                   motion, box, src_box, fp, shift, out) -> int:
    """The destination tiles (ty, tx) not allocated yet that the merge writes (cells of
    `box` over submap cells that hold something, and the cells the submap's levels land
    in, from its cells in `src_box`; boxes are ix0, iy0, ix1, iy1), into `out`; their
    count, or -1 when `out` filled up (grow it and call again: `dst_index` marks those
    listed)."""
    count = 0
    for iy in range(box[1], box[3]):
        for ix in range(box[0], box[2]):
            if _source_cell(src_index, src_origin, src_nlev, src_cells, motion, ix, iy, fp,
                            shift) >= 0:
                count = _list_tile(dst_index, ix, iy, shift, out, count)
                if count < 0:
                    return -1
    for sy in range(src_box[1], src_box[3]):
        for sx in range(src_box[0], src_box[2]):
            so = _src_offset(src_index, src_origin, sx, sy, shift)
            if so < 0:
                continue
            for m in range(np.int64(src_nlev[so])):
                ix, iy, _, _ = _hit_cell(src_f, src_first[so] + m, sx, sy, motion, fp)
                count = _list_tile(dst_index, ix, iy, shift, out, count)
                if count < 0:
                    return -1
    return count


@njit(cache=True, nogil=True)
def merge_submap(src_index, src_origin, src_nlev, src_first, src_cells, src_f, src_n,
                 dst_index, lev_f, lev_n, lev_flag, nlev, cells, motion, box, src_box, fp,
                 shift, levels, static_scans, scan_offset) -> int:
    """Merge the submap into the destination (see the module docstring): its free space
    over destination cells `box` (inverse mapping), then its levels each into the cell
    its mean hit lands in (so a turned wall stays where it was hit); returns the
    destination levels removed as seen through."""
    gap, l_max = fp[FP_GAP], fp[FP_LMAX]
    z_min, dz = fp[FP_ZMIN], fp[FP_MASK_DZ]
    offset = np.uint32(scan_offset)
    removed = 0
    for iy in range(box[1], box[3]):
        for ix in range(box[0], box[2]):
            so = _source_cell(src_index, src_origin, src_nlev, src_cells, motion, ix, iy, fp,
                              shift)
            if so < 0:
                continue
            do = _cell_offset(dst_index, ix, iy, shift)
            dbase = do * levels
            # The submap cells under the cell's corners: a turned submap's cells overlap
            # several, and the cell is seen free only where all of them were.
            seen, occupied = ~np.uint64(0), np.uint64(0)
            for corner in range(4):
                qx = ix + (0.05 if corner & 1 else 0.95) - 0.5
                qy = iy + (0.05 if corner & 2 else 0.95) - 0.5
                cx, cy = _source_index(motion, qx, qy, fp)
                co = _src_offset(src_index, src_origin, cx, cy, shift)
                if co < 0:
                    seen = np.uint64(0)
                    continue
                seen &= src_cells[co, P_SEEN]
                for m in range(src_first[co], src_first[co] + np.int64(src_nlev[co])):
                    occupied |= height_mask(src_f[m, LO], src_f[m, HI], z_min, dz)
            free = seen & ~occupied
            # a miss for each scan that reached the cell (one where the submap did not
            # count them)
            visits = float(src_cells[so, P_VISITS])
            for k in range(np.int64(nlev[do]) - 1, -1, -1):  # 1. seen through
                li = dbase + k
                lo, hi = lev_f[li, LO], lev_f[li, HI]
                mid = 0.5 * (lo + hi)
                if np.int64(lev_n[li, SCANS]) >= static_scans \
                        or not free & height_mask(mid, mid, z_min, dz) \
                        or occupied & height_mask(lo - gap, hi + gap, z_min, dz):
                    continue  # static, not seen through, or the submap has a level near
                lev_n[li, PASSES] = np.uint32(min(float(lev_n[li, PASSES]) + 1.0, _U32_MAX))
                lev_f[li, LOGODDS] -= fp[FP_LMISS] * visits
                if lev_f[li, LOGODDS] <= 0.0:
                    _remove(lev_f, lev_n, lev_flag, nlev, do, k, levels)
                    removed += 1
            # 3. observed heights, last update. Heights a level occupies there are not
            # taken as seen: the level may land in the next cell (its mean hit moved across
            # the cell's edge), and this one must then stay unknown, not become free.
            cells[do, SEEN] |= free
            if src_cells[so, P_SCAN] > 0:
                cells[do, SCAN] = max(cells[do, SCAN], src_cells[so, P_SCAN] + np.uint64(offset))
            if src_cells[so, P_UNLIT] > 0:
                cells[do, UNLIT] = max(cells[do, UNLIT],
                                       src_cells[so, P_UNLIT] + np.uint64(offset))
            if src_cells[so, P_FROM] > 0:
                cells[do, FROM] = _moved_cell(src_cells[so, P_FROM], motion, fp)
    for sy in range(src_box[1], src_box[3]):  # 2. the submap's levels
        for sx in range(src_box[0], src_box[2]):
            so = _src_offset(src_index, src_origin, sx, sy, shift)
            if so < 0:
                continue
            for sl in range(src_first[so], src_first[so] + np.int64(src_nlev[so])):
                ix, iy, mx, my = _hit_cell(src_f, sl, sx, sy, motion, fp)
                do = _cell_offset(dst_index, ix, iy, shift)
                if do >= 0:
                    _join_level(lev_f, lev_n, lev_flag, nlev, do, src_f[sl], src_n[sl], mx,
                                my, offset, gap, l_max, levels)
    return removed


@njit(cache=True, nogil=True)
def _join_level(lev_f, lev_n, lev_flag, nlev, off, rec_f, rec_n, mx, my, offset, gap, l_max,
                levels) -> None:
    """Add one submap level (records rec_f, rec_n; mean hit at (mx, my) from the cell's
    centre) to destination cell off."""
    n = np.int64(nlev[off])
    base = off * levels
    lo, hi = rec_f[LO], rec_f[HI]
    k = _level_for(lev_f, base, n, lo, hi, gap)
    stamp = rec_n[STAMP] + offset if rec_n[STAMP] > 0 else np.uint32(0)
    if k < 0 and n < levels:  # a level of its own, in height order
        k = _open_level(lev_f, lev_n, lev_flag, nlev, off, lo, levels)
        li = base + k
        lev_f[li] = rec_f
        lev_f[li, MX], lev_f[li, MY] = mx, my
        lev_n[li] = rec_n
        lev_n[li, STAMP] = stamp
        lev_flag[li] = 0
    else:
        if k < 0:  # all K slots taken: the nearest level takes it (fills the gap)
            k = _nearest_level(lev_f, base, n, lo, hi)
        li = base + k
        ha, hb = float(lev_n[li, HITS]), float(rec_n[HITS])
        w = hb / max(ha + hb, 1.0)
        lev_f[li, MX] += (mx - lev_f[li, MX]) * w
        lev_f[li, MY] += (my - lev_f[li, MY]) * w
        lev_f[li, MZ] += (rec_f[MZ] - lev_f[li, MZ]) * w
        lev_f[li, LO] = min(lev_f[li, LO], lo)
        lev_f[li, HI] = max(lev_f[li, HI], hi)
        lev_f[li, LOGODDS] = min(lev_f[li, LOGODDS] + rec_f[LOGODDS], l_max)
        lev_n[li, HITS] = np.uint32(min(ha + hb, _U32_MAX))
        lev_n[li, PASSES] = np.uint32(min(float(lev_n[li, PASSES]) + float(rec_n[PASSES]),
                                          _U32_MAX))
        lev_n[li, SCANS] = np.uint32(min(float(lev_n[li, SCANS]) + float(rec_n[SCANS]),
                                         _U32_MAX))
        lev_n[li, STAMP] = max(lev_n[li, STAMP], stamp)
        lev_flag[li] = 0
    _merge_grown(lev_f, lev_n, lev_flag, nlev, off, k, gap, levels)
