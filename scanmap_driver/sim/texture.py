"""Procedural surface texture: smooth 3D value noise evaluated at the surface point.

Real walls and floors are not uniformly coloured; a texture fixed to the surface (not to
the image) moves with the scene under motion blur and gives the colour of each scan point
something to show. Value noise on a hashed integer lattice, trilinearly interpolated with
a smoothstep, at a coarse and a fine scale.
"""

from __future__ import annotations

import numpy as np
from numba import njit

COARSE_CELL = 0.23  # m
FINE_CELL = 0.031  # m
COARSE_WEIGHT = 0.65


MASK = 0xFFFFFFFF


@njit(cache=True, nogil=True)
def _lattice(ix: np.int64, iy: np.int64, iz: np.int64) -> float:
    """A hash of the lattice point in [0, 1) (32-bit integer mixing in uint64)."""
    mask = np.uint64(MASK)
    h = ((np.uint64(ix & MASK) * np.uint64(73856093))
         ^ (np.uint64(iy & MASK) * np.uint64(19349663))
         ^ (np.uint64(iz & MASK) * np.uint64(83492791))) & mask
    h ^= h >> np.uint64(16)
    h = (h * np.uint64(0x7FEB352D)) & mask
    h ^= h >> np.uint64(15)
    h = (h * np.uint64(0x846CA68B)) & mask
    h ^= h >> np.uint64(16)
    return h / 4294967296.0


@njit(cache=True, nogil=True)
def _noise(x: float, y: float, z: float) -> float:
    fx, fy, fz = np.floor(x), np.floor(y), np.floor(z)
    ix, iy, iz = np.int64(fx), np.int64(fy), np.int64(fz)
    tx, ty, tz = x - fx, y - fy, z - fz
    sx, sy, sz = tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty), tz * tz * (3.0 - 2.0 * tz)
    total = 0.0
    for dz in range(2):
        wz = sz if dz else 1.0 - sz
        for dy in range(2):
            wy = sy if dy else 1.0 - sy
            for dx in range(2):
                wx = sx if dx else 1.0 - sx
                total += wx * wy * wz * _lattice(ix + dx, iy + dy, iz + dz)
    return total


@njit(cache=True, nogil=True)
def texture_factor(points: np.ndarray, contrast: float) -> np.ndarray:
    """Multiplicative brightness factor (mean 1, within 1 +- contrast) at (N, 3) points."""
    out = np.empty(points.shape[0], dtype=np.float32)
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        n = COARSE_WEIGHT * _noise(x / COARSE_CELL, y / COARSE_CELL, z / COARSE_CELL) \
            + (1.0 - COARSE_WEIGHT) * _noise(x / FINE_CELL + 17.0, y / FINE_CELL + 31.0,
                                             z / FINE_CELL + 7.0)
        out[i] = 1.0 + contrast * (2.0 * n - 1.0)
    return out
