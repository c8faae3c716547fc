"""A grid frozen for merging: what `HeightGrid.merge` reads of a submap, in a fraction of
the memory.

A live grid keeps room for K levels in every cell of every tile it allocated and an
index over all the tiles of its extent (1.6 MB at the default 1 km), so that insertion
never moves anything. A submap is written once and then only merged, so it keeps:
- its tiles' index over the tiles it allocated (their bounding box), not the extent;
- per cell its level count and the position of its first level in packed level arrays
  that hold the levels in use only (in the 3-D scanner's office, 11 % of the slots);
- per cell what the merge reads: the observed heights, the last scan id, the last scan
  that saw its floor unlit, where its lowest level was seen from and the scans that
  reached it (1 for a grid that did not count them: a merge then takes one miss).
For the office's submaps of 25 scans: 2.0 MB against 8.0 MB as built
(`bench_loop_closure`'s scans; 1.75 and 7.7 MB before the cells kept where they were
seen from, 2026-12-06).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid.config import GridConfig

# Columns of PackedGrid.cells.
P_SEEN, P_SCAN, P_UNLIT, P_FROM, P_VISITS = range(5)


@dataclass(frozen=True, eq=False)
class PackedGrid:
    """The merge's view of a grid (module docstring). Cell offsets follow the live
    grid's layout (`tile << 2 shift | row << shift | column`) over `tiles`, whose tile
    (0, 0) is the grid's tile `tile_origin` (ty, tx)."""

    config: GridConfig
    tiles: np.ndarray  # (nty, ntx) int32: packed tile number, -1 where none
    tile_origin: np.ndarray  # (2,) int64: (ty, tx) of tiles[0, 0] in the grid's tiles
    nlev: np.ndarray  # (tiles * cells,) uint8
    first: np.ndarray  # (tiles * cells,) int32: each cell's first level in lev_f, lev_n
    cells: np.ndarray  # (tiles * cells, 5) uint64: P_SEEN, P_SCAN, P_UNLIT, P_FROM, P_VISITS
    lev_f: np.ndarray  # (levels in use, N_FLOAT_FIELDS) float32
    lev_n: np.ndarray  # (levels in use, N_INT_FIELDS) uint32
    bounds: tuple[float, float, float, float] | None  # of its tiles, None when empty
    scan_times: tuple[float, ...]  # as HeightGrid's: index 0 is "never"
    stood: np.ndarray  # (scans, 2) where the robot stood
    stamp: float

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays."""
        return sum(a.nbytes for a in (self.tiles, self.nlev, self.first, self.cells,
                                      self.lev_f, self.lev_n, self.stood))

    def cell_origin(self, shift: int) -> np.ndarray:
        """(ix, iy) of the first cell of tiles[0, 0] in the grid's cells."""
        return np.array([self.tile_origin[1] << shift, self.tile_origin[0] << shift], np.int64)


def pack_pools(coords: np.ndarray, lev_f: np.ndarray, lev_n: np.ndarray, nlev: np.ndarray,
               cells: np.ndarray, visits: int | None) -> tuple[np.ndarray, ...]:
    """(tiles, tile_origin, nlev, first, cells, lev_f, lev_n) of a grid's used slots: their
    (ty, tx) `coords` and pools (slot, ...), levels (slot, cells * K, fields); `visits`:
    the cells' column counting scans, or None for one each."""
    count, cells_per_tile = nlev.shape
    k = lev_f.shape[1] // cells_per_tile
    low = coords.min(axis=0) if count else np.zeros(2, np.int64)
    tiles = np.full(tuple(coords.max(axis=0) - low + 1) if count else (0, 0), -1, np.int32)
    tiles[tuple((coords - low).T)] = np.arange(count, dtype=np.int32)
    flat_nlev = nlev.reshape(-1)
    used = np.arange(k) < flat_nlev[:, None].astype(np.int64)  # (cells, K) in cell order
    first = (np.cumsum(flat_nlev, dtype=np.int64) - flat_nlev).astype(np.int32)
    flat_cells = cells.reshape(-1, cells.shape[2])
    packed_cells = np.ones((len(flat_cells), 5), np.uint64)
    packed_cells[:, P_SEEN] = flat_cells[:, gk.SEEN]
    packed_cells[:, P_SCAN] = flat_cells[:, gk.SCAN]
    packed_cells[:, P_UNLIT] = flat_cells[:, gk.UNLIT]
    packed_cells[:, P_FROM] = flat_cells[:, gk.FROM]
    if visits is not None:
        packed_cells[:, P_VISITS] = flat_cells[:, visits]
    return (tiles, low.astype(np.int64), flat_nlev.copy(), first, packed_cells,
            lev_f.reshape(-1, k, lev_f.shape[2])[used],
            lev_n.reshape(-1, k, lev_n.shape[2])[used])
