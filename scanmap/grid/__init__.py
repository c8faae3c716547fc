"""The 2.5D height/occupancy grid: 5 cm cells in 64x64 tiles allocated where something is
seen, each holding up to three height intervals with clamped log-odds, the camera rays
of a scan that fill and clear it, the floor its laser lines crossed without a return,
and the levels its laser plane swept in view without lighting them. Kernels (Numba,
`nogil`) are in `_kernels`. See docs/architecture.md."""

from scanmap.grid.height_grid import CellLayers, GridConfig, HeightGrid, InsertStats
from scanmap.grid.rays import camera_centres, scan_rays
from scanmap.grid.swept import SweptFrames, swept_frames
from scanmap.grid.unlit import unlit_floor

__all__ = ["CellLayers", "GridConfig", "HeightGrid", "InsertStats", "SweptFrames",
           "camera_centres", "scan_rays", "swept_frames", "unlit_floor"]
