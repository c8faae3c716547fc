"""`_growth_kernels.grow_region` for the tests, by default without tangent planes (no jumps
along a plane, `_plane_jump`) and with every cell planar (no anchors)."""

from __future__ import annotations

import numpy as np

from scanmap.navigation.floor import _growth_kernels


def grow_region(heights: np.ndarray, seeds: np.ndarray, max_step: float, empty: np.ndarray,
                max_rise: float, candidates: np.ndarray, tangents: np.ndarray | None = None,
                tolerance: float = 0.0, planar: np.ndarray | None = None,
                seed_floor: np.ndarray | None = None) -> np.ndarray:
    """The floor grown from `seeds` (see `_growth_kernels.grow_region`; a seed anchors its own
    height unless `seed_floor` gives the floor plane's)."""
    if tangents is None:
        tangents = np.full(heights.shape + (5,), np.nan, np.float32)
    if planar is None:
        planar = np.ones(heights.shape, bool)
    return _growth_kernels.grow_region(heights, seeds, max_step, empty, max_rise, candidates,
                                       tangents, tolerance,
                                       heights if seed_floor is None else seed_floor, planar)
