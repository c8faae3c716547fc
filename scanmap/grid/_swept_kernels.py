"""Numba kernel of `scanmap.grid.swept`: miss the levels a scan's laser plane swept in
view without lighting them."""

from __future__ import annotations

import numpy as np
from numba import njit

from scanmap.grid._kernels import (
    FP_MASK_DZ,
    FP_RES,
    FP_X0,
    FP_Y0,
    HI,
    HIT_FLAG,
    IP_LEVELS,
    IP_MAXMISS,
    IP_SCAN,
    IP_SHIFT,
    IP_STATIC,
    LO,
    MX,
    MY,
    MZ,
    SCANS,
    STAMP,
    _beside_seen_in,
    _cell_offset,
    _dda_setup,
    _dda_step,
    _miss,
    _touch,
)
from scanmap.grid.unlit import project_to_image

# Fields of the optics vector (`swept.SweptFrames.optics`).
(O_CAMERA, O_TO_CAMERA, O_INTRINSICS, O_DIST, O_LASER, O_MIN_RANGE, O_REACH, O_WIDTH,
 O_HEIGHT, O_TOLERANCE, O_ABOVE, O_NEAR_Z, O_OUTSHINE, O_BLOCK_Z, O_MISSES, O_DARK_REACH,
 O_DARK_MISSES) = (0, 3, 12, 16, 21, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 37, 38)
N_OPTICS = 39


@njit(cache=True, nogil=True, inline="always")
def _hit_now(lev_n, lev_flag, li, scan) -> bool:
    """Whether this scan hit level record li."""
    return lev_n[li, STAMP] == scan and (lev_flag[li] & HIT_FLAG) != 0


@njit(cache=True, nogil=True, _nrt=False)
def _hit_beside(lev_f, lev_n, lev_flag, nlev, tile_index, ix, iy, z, near_z, shift, levels,
                scan) -> bool:
    """Whether this scan hit a level of cell (ix, iy) or one of its 8 neighbours within
    near_z of height z: a face on the cell's edge puts its hits either side of it."""
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            off = _cell_offset(tile_index, ix + dx, iy + dy, shift)
            if off < 0:
                continue
            for k in range(np.int64(nlev[off])):
                li = off * levels + k
                if _hit_now(lev_n, lev_flag, li, scan) and lev_f[li, LO] - near_z <= z \
                        <= lev_f[li, HI] + near_z:
                    return True
    return False


@njit(cache=True, nogil=True, _nrt=False)
def _blocked(lev_f, lev_n, lev_flag, nlev, tile_index, px, py, pz, qx, qy, qz, fp, shift,
             levels, scan, static_scans, margin) -> bool:
    """Whether a level this scan hit, or a static one, lies on the segment from point p to
    q (map) at its heights (within `margin`), outside the 3 x 3 cells round p's: the
    camera could not see p, or the laser not reach it."""
    res, x0, y0 = fp[FP_RES], fp[FP_X0], fp[FP_Y0]
    gx, gy = (px - x0) / res, (py - y0) / res
    ix, iy, sx, sy, tmx, tmy, tdx, tdy, steps = _dda_setup(gx, gy, (qx - x0) / res,
                                                           (qy - y0) / res)
    home_x, home_y = ix, iy
    t_in = 0.0
    for s in range(steps + 1):
        t_out = 1.0 if s == steps else min(tmx, tmy, 1.0)
        if abs(ix - home_x) > 1 or abs(iy - home_y) > 1:
            off = _cell_offset(tile_index, ix, iy, shift)
            if off >= 0:
                za, zb = pz + (qz - pz) * t_in, pz + (qz - pz) * t_out
                lo, hi = min(za, zb) - margin, max(za, zb) + margin
                for k in range(np.int64(nlev[off])):
                    li = off * levels + k
                    if lev_f[li, HI] >= lo and lev_f[li, LO] <= hi and (
                            _hit_now(lev_n, lev_flag, li, scan)
                            or np.int64(lev_n[li, SCANS]) >= static_scans):
                        return True
        ix, iy, t_in, tmx, tmy = _dda_step(ix, iy, sx, sy, tmx, tmy, tdx, tdy)
    return False


@njit(cache=True, nogil=True, _nrt=False)
def _unlit_sweeps(lev_f, lev_n, lev_flag, nlev, tile_index, px, py, pz, to_head, cameras,
                  emitters, nearest, optics, fp, shift, levels, scan, static_scans) -> int:
    """The misses owed by the scan's frames that swept point p (map) with the laser plane,
    in view, unshadowed and unhidden, without their image column returning anything as
    near: O_MISSES a frame, O_DARK_MISSES where the column and those beside it returned
    nothing at all and p lies farther than optics' dark reach (the stripe may have faded
    there)."""
    lx, ly, lz = optics[O_LASER], optics[O_LASER + 1], optics[O_LASER + 2]
    nx, ny, nz = optics[O_LASER + 3], optics[O_LASER + 4], optics[O_LASER + 5]
    cx, cy, cz = optics[O_CAMERA], optics[O_CAMERA + 1], optics[O_CAMERA + 2]
    width = nearest.shape[1]
    misses = 0
    for f in range(to_head.shape[0]):
        m = to_head[f]
        hx = m[0, 0] * px + m[0, 1] * py + m[0, 2] * pz + m[0, 3]
        hy = m[1, 0] * px + m[1, 1] * py + m[1, 2] * pz + m[1, 3]
        hz = m[2, 0] * px + m[2, 1] * py + m[2, 2] * pz + m[2, 3]
        if abs((hx - lx) * nx + (hy - ly) * ny + (hz - lz) * nz) > optics[O_TOLERANCE]:
            continue
        reach = np.hypot(hx, hy)
        if not optics[O_MIN_RANGE] <= reach <= optics[O_REACH]:
            continue
        u, v, ok = project_to_image(hx - cx, hy - cy, hz - cz,
                                    optics[O_TO_CAMERA:O_TO_CAMERA + 9],
                                    optics[O_INTRINSICS:O_INTRINSICS + 4],
                                    optics[O_DIST:O_DIST + 5])
        if not (ok and 0.0 <= u < optics[O_WIDTH] and 0.0 <= v < optics[O_HEIGHT]):
            continue
        distance = np.sqrt((hx - cx) ** 2 + (hy - cy) ** 2 + (hz - cz) ** 2)
        column = int(np.rint(u))
        outshone, dark = False, True  # dark: nothing returned on the line or beside it
        for w in range(max(column - 1, 0), min(column + 2, width)):
            outshone |= nearest[f, w] <= distance + optics[O_OUTSHINE]
            dark &= not nearest[f, w] < np.inf
        if outshone:
            continue
        margin = optics[O_BLOCK_Z]
        if _blocked(lev_f, lev_n, lev_flag, nlev, tile_index, px, py, pz, cameras[f, 0],
                    cameras[f, 1], cameras[f, 2], fp, shift, levels, scan, static_scans,
                    margin) \
                or _blocked(lev_f, lev_n, lev_flag, nlev, tile_index, px, py, pz,
                            emitters[f, 0], emitters[f, 1], emitters[f, 2], fp, shift,
                            levels, scan, static_scans, margin):
            continue
        faded = dark and reach > optics[O_DARK_REACH]
        misses += int(optics[O_DARK_MISSES] if faded else optics[O_MISSES])
    return misses


@njit(cache=True, nogil=True, _nrt=False)
def miss_swept_levels(to_head, cameras, emitters, nearest, optics, box, tile_index, lev_f,
                      lev_n, lev_flag, nlev, fp, ip) -> int:
    """Miss the levels in the cells of box (x0, y0, x1, y1, map) that the scan's frames
    swept unlit (`swept`): not static nor beside a static level at their heights (a
    face's rim or end, `_beside_seen_in`), not hit by this scan in or beside their cell,
    mean hit above optics' `above`; the misses `_unlit_sweeps` counts, within the grid's
    `max_misses` a scan. Returns the levels removed."""
    res, x0, y0 = fp[FP_RES], fp[FP_X0], fp[FP_Y0]
    shift, levels, max_miss = ip[IP_SHIFT], ip[IP_LEVELS], ip[IP_MAXMISS]
    scan, static_scans = np.uint32(ip[IP_SCAN]), ip[IP_STATIC]
    ix0 = max(int(np.floor((box[0] - x0) / res)), 0)
    iy0 = max(int(np.floor((box[1] - y0) / res)), 0)
    ix1 = min(int(np.floor((box[2] - x0) / res)), (tile_index.shape[1] << shift) - 1)
    iy1 = min(int(np.floor((box[3] - y0) / res)), (tile_index.shape[0] << shift) - 1)
    removed = 0
    for iy in range(iy0, iy1 + 1):
        for ix in range(ix0, ix1 + 1):
            off = _cell_offset(tile_index, ix, iy, shift)
            if off < 0:
                continue
            k = 0
            while k < np.int64(nlev[off]):
                li = off * levels + k
                k += 1
                pz = lev_f[li, MZ]
                if np.int64(lev_n[li, SCANS]) >= static_scans or pz < optics[O_ABOVE] \
                        or _hit_now(lev_n, lev_flag, li, scan) \
                        or _hit_beside(lev_f, lev_n, lev_flag, nlev, tile_index, ix, iy, pz,
                                       optics[O_NEAR_Z], shift, levels, scan) \
                        or _beside_seen_in(lev_f, lev_n, nlev, tile_index, ix, iy,
                                           lev_f[li, LO], lev_f[li, HI], fp[FP_MASK_DZ], shift,
                                           levels, static_scans):
                    continue
                px = x0 + (ix + 0.5) * res + lev_f[li, MX]
                py = y0 + (iy + 0.5) * res + lev_f[li, MY]
                misses = _unlit_sweeps(lev_f, lev_n, lev_flag, nlev, tile_index, px, py, pz,
                                       to_head, cameras, emitters, nearest, optics, fp, shift,
                                       levels, scan, static_scans)
                if misses:
                    _touch(lev_n, lev_flag, li, scan)
                for _ in range(misses):
                    if _miss(lev_f, lev_n, lev_flag, nlev, off, k - 1, fp, levels, max_miss):
                        removed += 1
                        k -= 1  # the next level moved into this one's place
                        break
    return removed
