"""Procedural surface texture: smooth value noise in each surface's own coordinates.

Real walls and floors are not uniformly coloured; a texture fixed to the surface (not to
the image) moves with the scene under motion blur and gives the colour of each scan point
something to show. 2D value noise (random values on a periodic lattice, interpolated with a
smoothstep) at a coarse and a fine scale, in coordinates along two axes of each plane.
"""

from __future__ import annotations

import numpy as np
from numba import njit

COARSE_CELL = 0.23  # m
FINE_CELL = 0.031  # m
COARSE_WEIGHT = 0.65
LATTICE = 256  # lattice period (cells): 8 m for the fine scale, 59 m for the coarse one


def surface_axes(normals: np.ndarray) -> np.ndarray:
    """(P, 2, 3) two unit axes in each plane: (x, y) on floors and tops, along the wall
    and up on walls, so that textures run level."""
    normals = np.asarray(normals, dtype=np.float64)
    horizontal = np.column_stack([-normals[:, 1], normals[:, 0], np.zeros(len(normals))])
    length = np.linalg.norm(horizontal, axis=1)
    flat = length < 0.7  # facing up or down more than sideways
    along = np.where(flat[:, None], [1.0, 0.0, 0.0],
                     horizontal / np.where(length > 0.0, length, 1.0)[:, None])
    other = np.where(flat[:, None], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    return np.stack([along, other], axis=1)


def _lattice_table() -> np.ndarray:
    """Random values in [0, 1) on a periodic 256 x 256 lattice, the same in every run."""
    return np.random.default_rng(20260101).random((LATTICE, LATTICE))


TABLE = _lattice_table()


@njit(cache=True, nogil=True)
def _noise(x: float, y: float) -> float:
    fx, fy = np.floor(x), np.floor(y)
    ix, iy = np.int64(fx), np.int64(fy)
    tx, ty = x - fx, y - fy
    sx, sy = tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty)
    x0, y0 = ix & (LATTICE - 1), iy & (LATTICE - 1)
    x1, y1 = (x0 + 1) & (LATTICE - 1), (y0 + 1) & (LATTICE - 1)
    bottom = (1.0 - sx) * TABLE[x0, y0] + sx * TABLE[x1, y0]
    top = (1.0 - sx) * TABLE[x0, y1] + sx * TABLE[x1, y1]
    return (1.0 - sy) * bottom + sy * top


@njit(cache=True, nogil=True)
def texture_at(a: float, b: float, contrast: float) -> float:
    """Multiplicative brightness factor (within 1 +- contrast) at surface coordinates (m)."""
    n = COARSE_WEIGHT * _noise(a / COARSE_CELL, b / COARSE_CELL) \
        + (1.0 - COARSE_WEIGHT) * _noise(a / FINE_CELL + 17.0, b / FINE_CELL + 31.0)
    return 1.0 + contrast * (2.0 * n - 1.0)


@njit(cache=True, nogil=True)
def texture_factor(points: np.ndarray, plane: np.ndarray, axes: np.ndarray,
                   contrast: float) -> np.ndarray:
    """`texture_at` for (N, 3) `map` points on planes `plane` with `surface_axes` axes."""
    out = np.empty(points.shape[0], dtype=np.float32)
    for i in range(points.shape[0]):
        ax = axes[plane[i]]
        a = ax[0, 0] * points[i, 0] + ax[0, 1] * points[i, 1] + ax[0, 2] * points[i, 2]
        b = ax[1, 0] * points[i, 0] + ax[1, 1] * points[i, 1] + ax[1, 2] * points[i, 2]
        out[i] = texture_at(a, b, contrast)
    return out
