"""A voxel hash for Numba kernels: integer voxel coordinates -> slot, in two flat arrays.

Open addressing with linear probing in a power-of-two table: `keys` (int64, EMPTY where
free) and `values` (int64 slot numbers). A voxel's key packs its three integer
coordinates in 21 bits each (offset by 2**20), so keys are non-negative and coordinates
must stay within +-2**20 voxels of the local origin (+-52 km at 5 cm): callers work
relative to a local origin (float precision) and check that bound. Tables are never
deleted from; a map that forgets voxels rebuilds its table (`build_table`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

EMPTY = -1
COORD_LIMIT = 1 << 20  # |voxel coordinate| must stay below this
_BITS = 21
_MASK = (1 << _BITS) - 1


@njit(cache=True, nogil=True)
def voxel_key(ix: int, iy: int, iz: int) -> int:
    """Packed non-negative key of voxel (ix, iy, iz); -1 if a coordinate is out of range."""
    if abs(ix) >= COORD_LIMIT or abs(iy) >= COORD_LIMIT or abs(iz) >= COORD_LIMIT:
        return -1
    return ((ix + COORD_LIMIT) << (2 * _BITS)) | ((iy + COORD_LIMIT) << _BITS) \
        | (iz + COORD_LIMIT)


@njit(cache=True, nogil=True)
def key_coords(key: int) -> tuple[int, int, int]:
    """Voxel coordinates of a packed key (inverse of `voxel_key`)."""
    return ((key >> (2 * _BITS)) & _MASK) - COORD_LIMIT, ((key >> _BITS) & _MASK) - COORD_LIMIT, \
        (key & _MASK) - COORD_LIMIT


@njit(cache=True, nogil=True)
def _home(key: int, mask: int) -> int:
    h = key ^ (key >> 29)
    h = h * 0x5851F42D4C957F2D  # wraps in int64, as intended
    h ^= h >> 32
    return h & mask


@njit(cache=True, nogil=True)
def _probe(keys: np.ndarray, key: int) -> int:
    """Index of `key` in the table, or of the empty slot where it would go."""
    mask = keys.size - 1
    i = _home(key, mask)
    while keys[i] != key and keys[i] != EMPTY:
        i = (i + 1) & mask
    return i


@njit(cache=True, nogil=True)
def table_find(keys: np.ndarray, values: np.ndarray, key: int) -> int:
    """Value stored for `key`, or -1 if absent."""
    i = _probe(keys, key)
    return values[i] if keys[i] == key else -1


@njit(cache=True, nogil=True)
def table_insert(keys: np.ndarray, values: np.ndarray, key: int, value: int) -> int:
    """Store `key` -> `value` unless present; returns the value now stored for `key`.

    The caller keeps the table at most half full, so probing always ends.
    """
    i = _probe(keys, key)
    if keys[i] == EMPTY:
        keys[i] = key
        values[i] = value
    return values[i]


def table_size(entries: int) -> int:
    """Power-of-two table size holding `entries` at most half full."""
    return 1 << max(4, int(2 * max(entries, 1) - 1).bit_length())


def new_table(entries: int) -> tuple[np.ndarray, np.ndarray]:
    """Empty (keys, values) arrays sized for `entries`."""
    size = table_size(entries)
    return np.full(size, EMPTY, dtype=np.int64), np.full(size, -1, dtype=np.int64)


@njit(cache=True, nogil=True)
def fill_table(keys: np.ndarray, values: np.ndarray, voxel_keys: np.ndarray) -> None:
    """Insert voxel_keys[i] -> i for every i (into an empty table)."""
    for i in range(voxel_keys.size):
        table_insert(keys, values, voxel_keys[i], i)


def build_table(voxel_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A table mapping each of `voxel_keys` (unique) to its index."""
    keys, values = new_table(voxel_keys.size)
    fill_table(keys, values, np.ascontiguousarray(voxel_keys, dtype=np.int64))
    return keys, values


@njit(cache=True, nogil=True)
def grown(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A table of twice the size holding the same entries (for kernels that fill up)."""
    new_keys = np.full(2 * keys.size, EMPTY, dtype=np.int64)
    new_values = np.full(2 * keys.size, -1, dtype=np.int64)
    for i in range(keys.size):
        if keys[i] != EMPTY:
            table_insert(new_keys, new_values, keys[i], values[i])
    return new_keys, new_values


def first_per_voxel(points: np.ndarray, voxel: float) -> tuple[np.ndarray, bool]:
    """(indices in order of the first finite point (N, 3) in each voxel of size `voxel`,
    on a grid from the points' lowest corner; False when they span COORD_LIMIT voxels or
    more, and the indices are incomplete)."""
    points = np.ascontiguousarray(points, np.float64)
    return _first_per_voxel(points, float(voxel), *new_table(points.shape[0]))


@njit(cache=True, nogil=True)
def _first_per_voxel(points: np.ndarray, voxel: float, keys: np.ndarray,
                     values: np.ndarray) -> tuple[np.ndarray, bool]:
    """`first_per_voxel` with an empty table (keys, values) sized for the points."""
    n = points.shape[0]
    finite = np.empty(n, np.bool_)
    low = np.full(3, np.inf)
    for i in range(n):
        finite[i] = np.isfinite(points[i, 0]) and np.isfinite(points[i, 1]) \
            and np.isfinite(points[i, 2])
        if finite[i]:
            for k in range(3):
                low[k] = min(low[k], np.floor(points[i, k] / voxel))
    out = np.empty(n, np.int64)
    count = 0
    for i in range(n):
        if not finite[i]:
            continue
        key = voxel_key(int(np.floor(points[i, 0] / voxel) - low[0]),
                        int(np.floor(points[i, 1] / voxel) - low[1]),
                        int(np.floor(points[i, 2] / voxel) - low[2]))
        if key < 0:
            return out[:count], False
        if table_insert(keys, values, key, i) == i:
            out[count] = i
            count += 1
    return out[:count], True
