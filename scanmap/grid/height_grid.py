"""The tiled 2.5D height/occupancy grid: what the robot needs to know about each cell.

A cell (default 5 cm) holds up to K levels - occupied height intervals with clamped
log-odds, hit and pass counts and the mean hit position inside the cell - plus the
heights observed there (a 64-bit mask), its last update time and the last scan whose
laser lines crossed its floor without a return (`scanmap.grid.unlit`). Floor height and
the obstacle layer are derived from these (`scanmap.navigation.floor`).

Memory follows the area seen: the map is cut into square tiles (64 x 64 cells) that
are allocated when a ray first crosses them, inside a configured maximum extent (a
point beyond it is a MapError, never a huge allocation). With `window` set, the grid
keeps only the tiles near the robot (`recenter`), and rays leaving the window are
dropped. Insertion runs in Numba without the GIL; a lock makes each insertion, copy
and window extraction atomic with respect to the others.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid import _merge_kernels as mk
from scanmap.grid import _swept_kernels as sk
from scanmap.grid.config import GridConfig
from scanmap.grid.growing import GrowingArray
from scanmap.grid.packed import PackedGrid, pack_pools
from scanmap_driver.errors import MapError
from scanmap_driver.files import exact_array

if TYPE_CHECKING:
    from scanmap.grid.swept import SweptFrames

POOL_NAMES = ("lev_f", "lev_n", "lev_flag", "nlev", "cells")
SAVED_CELL_FIELDS = 4  # observed mask, scan id, unlit scan id, seen from; not the scratch


@dataclass(frozen=True)
class InsertStats:
    """What one insertion did: rays used, skipped and why, levels cleared, tiles allocated."""

    inserted: int
    nonfinite: int
    outside_window: int
    too_far: int
    cleared: int
    new_tiles: int


@dataclass(frozen=True, eq=False)
class CellLayers:
    """Dense copy of a rectangular window of the grid, row = y, column = x.

    origin: (x, y) of the lower-left corner of cell [0, 0]. levels: (ny, nx, K, 8)
    float32 records (`_kernels.LO` to `MZ`: lo, hi, log-odds, mean hit x and y offset
    from the cell centre, this scan's hit range, mean hit height); counts: (ny, nx, K, 2)
    uint32 (hits, passes); nlev: levels in use; seen: observed height mask; updated: last
    update time (NaN where never updated). stood: (M, 2) x, y where the robot stood (each
    scan's path as `insert` was given it, else the middle of its ray origins) during the
    scans inserted since the grid was made, inside the window: floor the robot stood on.
    unlit: (ny, nx) bool, cells whose floor a laser line crossed without a return
    (`scanmap.grid.unlit`); none if not given. seen_from: (ny, nx, 2) x, y where the
    camera stood when it last saw each cell's lowest level (its last hit there, or the
    ray that looked deepest into the cell below its levels; the centre of that grid
    cell): where a drop-off the cell shows was seen from; NaN where none is known.
    """

    origin: tuple[float, float]
    resolution: float
    z_min: float
    mask_dz: float
    levels: np.ndarray
    counts: np.ndarray
    nlev: np.ndarray
    seen: np.ndarray
    updated: np.ndarray
    stood: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    unlit: np.ndarray | None = None
    seen_from: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.unlit is None:
            object.__setattr__(self, "unlit", np.zeros(self.nlev.shape, bool))
        if self.seen_from is None:
            object.__setattr__(self, "seen_from", np.full((*self.nlev.shape, 2), np.nan))

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx)."""
        return tuple(self.nlev.shape)

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """x (nx,) and y (ny,) of the cell centres."""
        ny, nx = self.shape
        r = self.resolution
        return (self.origin[0] + (np.arange(nx) + 0.5) * r,
                self.origin[1] + (np.arange(ny) + 0.5) * r)

    def occupied_mask(self, z_low: np.ndarray | float, z_high: np.ndarray | float) -> np.ndarray:
        """Cells with a level overlapping the open band (z_low, z_high) (per cell or scalar)."""
        k = np.arange(self.levels.shape[2])
        used = k[None, None, :] < self.nlev[..., None]
        lo, hi = self.levels[..., gk.LO], self.levels[..., gk.HI]
        low = np.asarray(z_low, dtype=np.float64)[..., None] if np.ndim(z_low) else z_low
        high = np.asarray(z_high, dtype=np.float64)[..., None] if np.ndim(z_high) else z_high
        return (used & (hi > low) & (lo < high)).any(axis=2)


def _per_point(name: str, sources: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """`insert`'s ray origins as one contiguous (N, 3) row per point: given so, or one
    (3,) for all."""
    sources = np.asarray(sources, dtype=np.float64)
    if sources.shape == (3,):
        sources = np.broadcast_to(sources, shape)
    if sources.shape != shape:
        raise MapError(f"HeightGrid.insert: {name} must be (3,) or {shape}, "
                       f"got {sources.shape}")
    return np.ascontiguousarray(sources)


def _path(stood: np.ndarray, spacing: float) -> np.ndarray:
    """The finite (x, y) rows of `stood`, each at least `spacing` from the last one kept,
    and the last row."""
    xy = np.asarray(stood, dtype=np.float64).reshape(len(stood), -1)[:, :2]
    xy = xy[np.isfinite(xy).all(axis=1)]
    keep = []
    for i, p in enumerate(xy):
        if not keep or i == len(xy) - 1 or np.hypot(*(p - xy[keep[-1]])) >= spacing:
            keep.append(i)
    return xy[keep]


class HeightGrid:
    """The 2.5D grid. Thread-safe: insert, copy and layers never interleave."""

    def __init__(self, config: GridConfig | None = None, count_visits: bool = False) -> None:
        """count_visits: also count per cell the scans whose rays reached it (what a
        submap's free space weighs in `merge`)."""
        self.config = config or GridConfig()
        self.count_visits = bool(count_visits)
        c = self.config
        n = c.tiles_per_side
        self._tile_index = np.full((n, n), -1, np.int32)
        self._coords = np.zeros((0, 2), np.int64)  # (ty, tx) of each slot, -1 when free
        self._free: list[int] = []
        self._lock = threading.Lock()
        self.stamp = math.nan  # time of the newest insertion
        self._window_origin: tuple[float, float] | None = None
        self._scan_times = GrowingArray(np.array([math.nan]))  # of each scan id; 0 = never
        self._stood = GrowingArray(np.zeros((0, 2)))  # x, y where the robot stood
        self._stood_bins: set[tuple[int, int]] = set()  # `_add_stood`'s bins of them
        cells, levels = c.tile_cells ** 2, c.tile_cells ** 2 * c.levels
        self._lev_f = np.zeros((0, levels, gk.N_FLOAT_FIELDS), np.float32)
        self._lev_n = np.zeros((0, levels, gk.N_INT_FIELDS), np.uint32)
        self._lev_flag = np.zeros((0, levels), np.uint8)
        self._nlev = np.zeros((0, cells), np.uint8)
        self._cell_fields = gk.N_CELL_FIELDS + int(self.count_visits)
        self._cells = np.zeros((0, cells, self._cell_fields), np.uint64)
        self._ray_key = 0  # last ray-bundle key used
        self._fp = np.array([c.resolution, c.corner, c.corner, c.z_min, c.mask_dz, c.merge_gap,
                             c.clear_margin, c.l_hit, c.l_miss, c.l_max, c.protect,
                             c.pass_radius, math.sin(math.radians(c.graze_angle)),
                             c.see_through],
                            np.float64)
        self._shift = c.tile_cells.bit_length() - 1

    # -- tiles -------------------------------------------------------------------------
    @property
    def tile_count(self) -> int:
        """Tiles currently allocated."""
        return int((self._tile_index >= 0).sum())

    @property
    def memory_bytes(self) -> int:
        """Bytes held by the tile pools and the tile index."""
        return int(sum(a.nbytes for a in self._pools()) + self._tile_index.nbytes)

    @property
    def used_bytes(self) -> int:
        """Bytes of the allocated tiles' records (what `copy` and `state` hold)."""
        slots = len(self._coords)  # each slot holds a tile or is free
        return int(sum(a.nbytes for a in self._pools()) * (slots - len(self._free))
                   // max(slots, 1))

    def _pools(self) -> tuple[np.ndarray, ...]:
        return (self._lev_f, self._lev_n, self._lev_flag, self._nlev, self._cells)

    def _set_pools(self, pools: list[np.ndarray]) -> None:
        self._lev_f, self._lev_n, self._lev_flag, self._nlev, self._cells = pools

    def _flat_pools(self) -> tuple[np.ndarray, ...]:
        """The pools as the kernels address them: one record per level or cell."""
        return (self._lev_f.reshape(-1, gk.N_FLOAT_FIELDS),
                self._lev_n.reshape(-1, gk.N_INT_FIELDS), self._lev_flag.reshape(-1),
                self._nlev.reshape(-1), self._cells.reshape(-1, self._cell_fields))

    def _allocate(self, tiles: np.ndarray) -> None:
        """Give each (ty, tx) in `tiles` an empty slot, growing the pools by doubling."""
        need = len(tiles) - len(self._free)
        if need > 0:
            old = len(self._coords)
            new_cap = max(2 * old, old + need, 4)
            pools = []
            for a in self._pools():
                grown = np.zeros((new_cap, *a.shape[1:]), a.dtype)
                grown[:old] = a
                pools.append(grown)
            self._set_pools(pools)
            self._coords = np.vstack([self._coords, np.full((new_cap - old, 2), -1, np.int64)])
            self._free.extend(range(new_cap - 1, old - 1, -1))
        for ty, tx in tiles:
            slot = self._free.pop()
            self._nlev[slot] = 0
            self._cells[slot] = 0
            self._coords[slot] = (ty, tx)
            self._tile_index[ty, tx] = slot

    def _release(self, slot: int) -> None:
        ty, tx = self._coords[slot]
        self._tile_index[ty, tx] = -1
        self._coords[slot] = -1
        self._free.append(slot)

    # -- rolling window ----------------------------------------------------------------
    def _window_bounds(self) -> np.ndarray:
        c = self.config
        lo, hi = c.corner, c.corner + c.tiles_per_side * c.tile_size
        if c.window is None:
            return np.array([lo, lo, hi, hi])
        if self._window_origin is None:
            raise MapError("HeightGrid: a rolling-window grid needs recenter(x, y) before insert")
        x, y = self._window_origin
        return np.array([x, y, x + c.window, y + c.window])

    def recenter(self, x: float, y: float) -> None:
        """Move the rolling window to be centred on (x, y) (snapped to tiles); drop far tiles."""
        c = self.config
        if c.window is None:
            raise MapError("HeightGrid.recenter: this grid has no rolling window (config.window)")
        if not (math.isfinite(x) and math.isfinite(y)):
            raise MapError(f"HeightGrid.recenter: position ({x}, {y}) is not finite")
        half = 0.5 * c.window
        ts = c.tile_size
        left = math.floor((x - half - c.corner) / ts) * ts + c.corner
        bottom = math.floor((y - half - c.corner) / ts) * ts + c.corner
        limit = c.corner + c.tiles_per_side * ts
        if left < c.corner or bottom < c.corner or left + c.window > limit \
                or bottom + c.window > limit:
            raise MapError(f"HeightGrid.recenter: window at ({x:.1f}, {y:.1f}) leaves the "
                           f"configured extent +-{c.extent} m")
        with self._lock:
            self._window_origin = (left, bottom)
            for slot, (ty, tx) in enumerate(self._coords):
                if ty < 0:
                    continue
                tx0, ty0 = c.corner + tx * ts, c.corner + ty * ts
                if tx0 + ts <= left or tx0 >= left + c.window or ty0 + ts <= bottom \
                        or ty0 >= bottom + c.window:
                    self._release(slot)

    # -- insertion ---------------------------------------------------------------------
    def reserve(self, rays: Iterable[tuple[np.ndarray, np.ndarray]]) -> None:
        """Allocate at once every tile these (points (N, 3), origins (N, 3)) in map would
        make `insert` allocate, so that inserting many scans does not grow the pools by
        doubling, each time copying them (half of a rebuild's time). Rays `insert`
        refuses are left to it."""
        c = self.config
        span = c.corner + c.tiles_per_side * c.tile_size
        bounds = np.array([c.corner, c.corner, span, span])
        with self._lock:
            window = self._window_bounds()
            index = self._tile_index.copy()  # collect_missing_tiles marks those it lists
            buffer = np.empty((4096, 2), np.int64)
            tiles = [np.zeros((0, 2), np.int64)]
            for points, origins in rays:
                points = np.ascontiguousarray(points, np.float64)
                origins = np.ascontiguousarray(origins, np.float64)
                cls = gk.classify_points(points, origins, bounds, window, c.max_range)
                count = -1
                while count < 0:
                    count = gk.collect_missing_tiles(points, origins, cls, index,
                                                     c.resolution, c.tile_cells, c.corner,
                                                     c.corner, buffer)
                    tiles.append(buffer[:count].copy() if count >= 0 else buffer.copy())
            self._allocate(np.concatenate(tiles))

    def insert(self, points: np.ndarray, origins: np.ndarray, stamp: float,
               stood: np.ndarray | None = None, unlit: np.ndarray | None = None,
               lasers: np.ndarray | None = None, swept: SweptFrames | None = None
               ) -> InsertStats:
        """Fuse one scan: points (N, 3) in map, ray origins (N, 3) or one (3,), time (s).

        lasers: where the light of each point came from, (N, 3) or one (3,) in map (the
        laser's emitter, `scanmap.grid.rays.laser_origins`): the light's path to a point
        was free too, and clears levels seen briefly that lay on it (see
        `scanmap.grid._kernels`; below the camera, the emitter's rays cross the low heights
        near the robot that the camera's rays pass above), in the tiles the camera's rays
        reached (the emitter sits by the camera: on the reference scanner both rays to a
        point cross the same cells). Rays from an emitter beyond the extent or window are
        left out.

        stood: (M, 2+) x, y where the robot stood during the scan (its path; default the
        middle of the ray origins). unlit: (K, 2+) x, y of floor the scan's laser lines
        crossed without a return (`scanmap.grid.unlit.unlit_floor`), marked in the tiles
        its rays reached (none are allocated for them). swept: the scan's frames
        (`scanmap.grid.swept.swept_frames`): the levels their laser plane swept in view
        without lighting them, seen in fewer than `static_scans` scans, are missed (a
        person who left; counted in `cleared`). Non-finite rays are skipped; a
        point or origin beyond the configured extent raises MapError before anything
        changes.
        """
        points = np.ascontiguousarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise MapError(f"HeightGrid.insert: points must be (N, 3), got {points.shape}")
        origins = _per_point("origins", origins, points.shape)
        lasers = np.zeros((0, 3)) if lasers is None else _per_point("lasers", lasers,
                                                                     points.shape)
        if not math.isfinite(stamp):
            raise MapError(f"HeightGrid.insert: stamp must be finite, got {stamp}")
        c = self.config
        with self._lock:
            window = self._window_bounds()
            span = c.corner + c.tiles_per_side * c.tile_size
            bounds = np.array([c.corner, c.corner, span, span])
            cls = gk.classify_points(points, origins, bounds, window, c.max_range)
            laser_cls = gk.classify_points(points, lasers, bounds, window, c.max_range) \
                if len(lasers) else cls
            outside = cls == gk.POINT_OUTSIDE_EXTENT
            if outside.any():
                i = int(np.argmax(outside))
                raise MapError(
                    f"HeightGrid.insert: {int(outside.sum())} ray(s) leave the configured "
                    f"extent +-{c.extent} m (e.g. point {points[i].tolist()} from origin "
                    f"{origins[i].tolist()}); nothing was inserted")
            new_tiles = 0
            buffer = np.empty((256, 2), np.int64)
            while True:  # the camera's rays' tiles: the laser's clear only in those
                count = gk.collect_missing_tiles(points, origins, cls, self._tile_index,
                                                 c.resolution, c.tile_cells, c.corner,
                                                 c.corner, buffer)
                found = buffer if count < 0 else buffer[:count]
                self._allocate(found)
                new_tiles += len(found)
                if count >= 0:
                    break
            self._scan_times.append(float(stamp))
            ip = np.array([self._shift, c.levels, c.max_misses, len(self._scan_times) - 1,
                           self._ray_key, c.bundle_run, c.static_scans,
                           int(self.count_visits)], np.int64)
            hits, cleared, self._ray_key = gk.insert_scan(points, origins, cls, lasers,
                                                          laser_cls, self._tile_index,
                                                          *self._flat_pools(), self._fp, ip)
            if unlit is not None:  # also when empty: compiled by the warm-up
                *_, cells = self._flat_pools()
                gk.mark_unlit(np.ascontiguousarray(unlit, np.float64), self._tile_index,
                              cells, c.corner, c.corner, c.resolution, self._shift,
                              len(self._scan_times) - 1)
            if swept is not None:  # also without frames: compiled by the warm-up
                cleared += sk.miss_swept_levels(swept.to_head, swept.cameras, swept.emitters,
                                                swept.nearest, swept.optics, swept.box,
                                                self._tile_index, *self._flat_pools()[:4],
                                                self._fp, ip)
            self.stamp = float(stamp) if math.isnan(self.stamp) else max(self.stamp, stamp)
            if stood is not None:
                self._add_stood(_path(stood, 0.5 * c.resolution))
            else:
                box = gk.usable_box(origins, cls)
                if not np.isnan(box[0]):
                    self._add_stood(0.5 * (box[None, :2] + box[None, 2:]))
        def count(kind: int) -> int:  # a tenth of np.bincount's time on the uint8 classes
            return int(np.count_nonzero(cls == kind))

        return InsertStats(inserted=hits, nonfinite=count(gk.POINT_NONFINITE),
                           outside_window=count(gk.POINT_OUTSIDE_WINDOW),
                           too_far=count(gk.POINT_TOO_FAR), cleared=cleared,
                           new_tiles=new_tiles)

    def _add_stood(self, places: np.ndarray) -> None:
        """Keep the places (M, 2) the robot stood but those in a quarter-cell bin already
        holding one: a robot that passes a place again (a patrol) adds nothing there, so
        the places, and the cost of its footprint in each segmentation, grow with the
        area driven, not with the run (a footprint moves by at most a third of a cell)."""
        bin_side = 0.25 * self.config.resolution
        kept = []
        for i, key in enumerate(map(tuple, np.floor(places / bin_side).astype(np.int64)
                                    .tolist())):
            if key not in self._stood_bins:
                self._stood_bins.add(key)
                kept.append(i)
        self._stood.extend(places[kept])

    def packed(self) -> PackedGrid:
        """What `merge` reads of this grid, packed (`scanmap.grid.packed`): a submap
        kept for later merges in a fraction of a live grid's memory."""
        with self._lock:
            used = np.flatnonzero(self._coords[:, 0] >= 0)
            arrays = pack_pools(self._coords[used], self._lev_f[used], self._lev_n[used],
                                self._nlev[used], self._cells[used],
                                gk.VISITS if self.count_visits else None)
            return PackedGrid(self.config, *arrays, bounds=self.bounds(),
                              scan_times=tuple(self._scan_times.array.tolist()),
                              stood=self._stood.array.copy(),
                              stamp=self.stamp)

    def merge(self, submap: HeightGrid | PackedGrid, motion: np.ndarray | None = None) -> int:
        """Merge `submap`, a grid of later scans with the same configuration (or its
        `packed()` form), moved by the planar rigid `motion` (4x4; its x, y and yaw;
        default none), as if its scans had been fused after this grid's (`_merge_kernels`:
        levels it saw through go, levels joined, its scan times appended). For a rebuild
        after loop closure: a submap moved whole costs a pass over its cells instead of
        its rays. Returns the levels removed as seen through."""
        c = self.config
        if c.window is not None or submap.config != c:
            raise MapError("HeightGrid.merge: needs two grids of one configuration "
                           "without a rolling window")
        if isinstance(submap, HeightGrid):
            submap = submap.packed()
        m = np.eye(4) if motion is None else np.asarray(motion, dtype=np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all():
            raise MapError(f"HeightGrid.merge: motion must be a finite 4x4 pose, got {m.shape}")
        if submap.bounds is None:
            return 0
        yaw = math.atan2(m[1, 0], m[0, 0])
        planar = np.array([math.cos(yaw), math.sin(yaw), m[0, 3], m[1, 3]])
        turn = np.array([[planar[0], planar[1]], [-planar[1], planar[0]]])  # rows @ turn
        bounds = submap.bounds
        corners = np.array([[bounds[0], bounds[1]], [bounds[2], bounds[1]],
                            [bounds[0], bounds[3]], [bounds[2], bounds[3]]])
        moved = corners @ turn + planar[2:]
        side = c.tiles_per_side * c.tile_cells
        low = np.floor((moved.min(axis=0) - c.corner) / c.resolution).astype(int) - 1
        high = np.ceil((moved.max(axis=0) - c.corner) / c.resolution).astype(int) + 1
        box = np.array([*np.clip(low, 0, side), *np.clip(high, 0, side)], np.int64)
        src_box = np.round((np.array(bounds) - c.corner) / c.resolution).astype(np.int64)
        src = (submap.tiles, submap.cell_origin(self._shift), submap.nlev, submap.first,
               submap.cells, submap.lev_f)
        with self._lock:
            buffer = np.empty((256, 2), np.int64)
            while True:
                count = mk.tiles_to_merge(*src, self._tile_index, planar, box, src_box,
                                          self._fp, self._shift, buffer)
                self._allocate(buffer if count < 0 else buffer[:count])
                if count >= 0:
                    break
            offset = len(self._scan_times) - 1
            removed = mk.merge_submap(*src, submap.lev_n, self._tile_index,
                                      *self._flat_pools(), planar, box, src_box, self._fp,
                                      self._shift, c.levels, c.static_scans, offset)
            self._scan_times.extend(np.array(submap.scan_times[1:], np.float64))
            if not math.isnan(submap.stamp):
                self.stamp = submap.stamp if math.isnan(self.stamp) \
                    else max(self.stamp, submap.stamp)
            self._add_stood(submap.stood @ turn + planar[2:])
        return int(removed)

    # -- reading -----------------------------------------------------------------------
    def bounds(self) -> tuple[float, float, float, float] | None:
        """(xmin, ymin, xmax, ymax) of the allocated tiles, or None when empty."""
        used = self._coords[self._coords[:, 0] >= 0]
        if not len(used):
            return None
        c = self.config
        lo, hi = used.min(axis=0), used.max(axis=0) + 1
        return (c.corner + lo[1] * c.tile_size, c.corner + lo[0] * c.tile_size,
                c.corner + hi[1] * c.tile_size, c.corner + hi[0] * c.tile_size)

    def layers(self, bounds: tuple[float, float, float, float] | None = None) -> CellLayers:
        """Dense copy of the cells inside bounds (xmin, ymin, xmax, ymax), snapped to cells.

        Defaults to the allocated tiles (or the rolling window); absent tiles are unknown.
        """
        c = self.config
        with self._lock:
            if bounds is None:
                if c.window is not None and self._window_origin is not None:
                    x, y = self._window_origin
                    bounds = (x, y, x + c.window, y + c.window)
                else:
                    bounds = self.bounds() or (0.0, 0.0, c.resolution, c.resolution)
            xmin, ymin, xmax, ymax = map(float, bounds)
            if not (xmax > xmin and ymax > ymin and all(map(math.isfinite, bounds))):
                raise MapError(f"HeightGrid.layers: bad bounds {bounds}")
            ix0 = math.floor((xmin - c.corner) / c.resolution)
            iy0 = math.floor((ymin - c.corner) / c.resolution)
            nx = math.ceil((xmax - c.corner) / c.resolution) - ix0
            ny = math.ceil((ymax - c.corner) / c.resolution) - iy0
            if nx * ny > 50_000_000:
                raise MapError(f"HeightGrid.layers: window of {nx} x {ny} cells is too large")
            k = c.levels
            out_f = np.empty((ny, nx, k, gk.N_FLOAT_FIELDS), np.float32)  # all written
            out_n = np.empty((ny, nx, k, 2), np.uint32)
            out_nlev = np.empty((ny, nx), np.uint8)
            out_seen = np.empty((ny, nx), np.uint64)
            out_scan = np.empty((ny, nx), np.uint64)
            out_unlit = np.empty((ny, nx), bool)
            out_from = np.empty((ny, nx, 2), np.float32)
            lev_f, lev_n, _, nlev, cells = self._flat_pools()
            gk.extract_window(self._tile_index, lev_f, lev_n, nlev, cells, self._shift, k,
                              ix0, iy0, out_f, out_n, out_nlev, out_seen, out_scan, out_unlit,
                              out_from, c.corner, c.resolution)
            out_updated = self._scan_times.array[out_scan]
            stood = self._stood.array
        origin = (round(c.corner + ix0 * c.resolution, 9), round(c.corner + iy0 * c.resolution, 9))
        x, y = stood[:, 0], stood[:, 1]  # by columns: a tenth of the time of by rows
        inside = (x >= xmin) & (x < xmax) & (y >= ymin) & (y < ymax)
        return CellLayers(origin=origin,
                          resolution=c.resolution, z_min=c.z_min, mask_dz=c.mask_dz,
                          levels=out_f, counts=out_n, nlev=out_nlev, seen=out_seen,
                          updated=out_updated, stood=stood[inside], unlit=out_unlit,
                          seen_from=out_from)

    # -- whole-state copy (map files) --------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        """A consistent copy of everything the grid holds, with used tiles only."""
        with self._lock:
            used = np.flatnonzero(self._coords[:, 0] >= 0)
            out = {"tile_coords": self._coords[used].copy(),
                   "scan_times": self._scan_times.array.copy(),
                   "stamp": np.array(self.stamp, np.float64),
                   "stood": self._stood.array.copy()}
            for name, pool in zip(POOL_NAMES, self._pools(), strict=True):
                out[name] = pool[used]
            out["cells"] = out["cells"][..., :SAVED_CELL_FIELDS].copy()  # not the scratch
            if self._window_origin is not None:
                out["window_origin"] = np.array(self._window_origin, np.float64)
        return out

    def copy(self) -> HeightGrid:
        """An independent grid holding exactly what this one holds (its tiles with the
        scratch of ray bundles, the scan times, where the robot stood), without spare
        slots: inserting the same scans into both gives the same grid."""
        out = HeightGrid(self.config, self.count_visits)
        with self._lock:
            used = np.flatnonzero(self._coords[:, 0] >= 0)
            out._set_pools([a[used] for a in self._pools()])
            out._coords = self._coords[used]
            out._tile_index[tuple(out._coords.T)] = np.arange(len(used), dtype=np.int32)
            out.stamp = self.stamp
            out._window_origin = self._window_origin
            out._scan_times = self._scan_times.copy()
            out._stood, out._stood_bins = self._stood.copy(), set(self._stood_bins)
            out._ray_key = self._ray_key
        return out

    @classmethod
    def from_state(cls, config: GridConfig, state: dict[str, np.ndarray],
                   source: str = "map") -> HeightGrid:
        """Rebuild a grid from `state()`; MapError names `source` and the bad array."""
        grid = cls(config)
        coords = np.asarray(state["tile_coords"])
        n = len(coords) if coords.ndim == 2 and coords.shape[1] == 2 else -1
        cells = config.tile_cells ** 2
        levels = cells * config.levels
        expected = dict(zip(POOL_NAMES, [
            ((n, levels, gk.N_FLOAT_FIELDS), np.float32), ((n, levels, gk.N_INT_FIELDS), np.uint32),
            ((n, levels), np.uint8), ((n, cells), np.uint8),
            ((n, cells, SAVED_CELL_FIELDS), np.uint64)],
            strict=True))
        if n < 0 or coords.dtype.kind not in "iu":
            raise MapError(f"{source}: tile_coords must be an (n, 2) integer array, "
                           f"got {coords.dtype} {coords.shape}")
        for name, (shape, dtype) in expected.items():
            a = np.asarray(state[name])
            if a.shape != shape or a.dtype != dtype:
                raise MapError(f"{source}: {name} must be {np.dtype(dtype)} {shape}, "
                               f"got {a.dtype} {a.shape}")
        side = config.tiles_per_side
        if n and (coords.min() < 0 or coords.max() >= side
                  or len(np.unique(coords, axis=0)) != n):
            raise MapError(f"{source}: tile_coords outside 0..{side - 1} or repeated")
        if (np.asarray(state["nlev"]) > config.levels).any():
            raise MapError(f"{source}: nlev exceeds the {config.levels} levels of the "
                           "configuration")
        times = exact_array(np.asarray(state["scan_times"]), f"{source}: scan_times",
                            np.float64, MapError, allow_nan=True)  # NaN: a scan without time
        scan_ids = np.asarray(state["cells"])[..., gk.SCAN:gk.UNLIT + 1]  # and unlit ones
        if times.ndim != 1 or not len(times) or (n and scan_ids.max() >= len(times)):
            raise MapError(f"{source}: scan_times does not cover the scan ids of the cells")
        grid._allocate(coords)  # slot i holds tile coords[i]
        for name, pool in zip(POOL_NAMES, grid._pools(), strict=True):
            saved = np.asarray(state[name])
            pool[:n, ..., :saved.shape[-1]] = saved
        grid._scan_times = GrowingArray(times)
        grid.stamp = float(state["stamp"])
        if "stood" in state:  # absent from maps written before 2026-12-03: none known
            stood = exact_array(np.asarray(state["stood"]), f"{source}: stood", np.float64,
                                MapError)
            if stood.ndim != 2 or stood.shape[1] != 2:
                raise MapError(f"{source}: stood must be (M, 2) x, y, got {stood.shape}")
            grid._add_stood(stood)
        if "window_origin" in state:
            grid._window_origin = tuple(map(float, state["window_origin"]))
        return grid
