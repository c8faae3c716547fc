"""The 2.5D height/occupancy grid: 5 cm cells in 64x64 tiles allocated where something is
seen, each holding up to three height intervals with clamped log-odds, the camera rays
of a scan that fill and clear it, and the floor its laser lines crossed without a
return. Kernels (Numba, `nogil`) are in `_kernels`. See docs/architecture.md."""

from scanmap.grid.height_grid import CellLayers, GridConfig, HeightGrid, InsertStats
from scanmap.grid.rays import camera_centres, scan_rays
from scanmap.grid.unlit import unlit_floor

__all__ = ["CellLayers", "GridConfig", "HeightGrid", "InsertStats", "camera_centres",
           "scan_rays", "unlit_floor"]
