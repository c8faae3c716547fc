"""Exact Euclidean distance transform with the nearest feature cell (Felzenszwalb-Huttenlocher).

Two separable passes in Numba: down each column, the nearest feature row; then along
each row, the lower envelope of parabolas (q - x)^2 + g(q)^2 gives the exact squared
distance and which column - hence which cell - attains it. Linear in the cell count,
so a 20 m x 20 m window at 5 cm is recomputed per scan rather than patched.
"""

from __future__ import annotations

import numpy as np

from scanmap.navigation import _kernels as nk


def distance_transform(features: np.ndarray, pad: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Distance in cells (float32, inf where there is no feature at all) from every cell to
    the nearest True cell of `features` (ny, nx), and that cell's flat index (int64, -1),
    counted in the array grown by `pad` cells on every side (a border that spares the
    3 x 3 lookups around it their bounds checks)."""
    features = np.ascontiguousarray(features, dtype=np.bool_)
    if features.ndim != 2:
        raise ValueError(f"distance_transform: expected a 2-D mask, got shape {features.shape}")
    distance = np.empty(features.shape, np.float32)
    nearest = np.empty(features.shape, np.int64)
    if features.size:
        nk.edt_kernel(features, distance, nearest, pad)
    return distance, nearest
