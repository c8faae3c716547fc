"""The ground-truth 2D raster of a scene: obstacle, floor or outside, per cell.

For a robot that drives over things lower than `low` (its step height) and under things
higher than `high` (its height), a cell is an obstacle if any object occupies space between
the two heights over any part of the cell (exact rectangle and disc overlap tests, no
sampling); the open cells that the robot can reach from its scan poses (4-connected) are
floor, and the rest (behind walls, inside closed objects) are outside. Mapping is scored
against it.

File (`.npz`, no pickle): `classes` (rows along y from `origin`, columns along x; uint8:
0 outside, 1 floor, 2 obstacle), `origin` (x, y of the lower-left corner, m),
`resolution` (m), `band` (low, high, m), `format_version`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import MapError
from ..files import load_npz, save_npz
from .scene import Box, Cylinder, Scene

OUTSIDE, FLOOR, OBSTACLE = 0, 1, 2
FORMAT_VERSION = 1


@dataclass(frozen=True)
class TruthRaster:
    """Cell classes of a scene; `classes[row, col]` covers x in origin.x + col * resolution
    + [0, resolution), y likewise with row."""

    classes: np.ndarray
    origin: np.ndarray
    resolution: float
    band: tuple[float, float]

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) integer (row, col) of `map` points (may lie outside the raster)."""
        index = np.floor((np.asarray(xy)[:, :2] - self.origin) / self.resolution)
        return index[:, ::-1].astype(np.int64)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the raster as `.npz` (atomically)."""
        save_npz(path, format_version=np.array(FORMAT_VERSION), classes=self.classes,
                 origin=self.origin, resolution=np.array(self.resolution),
                 band=np.array(self.band))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> TruthRaster:
        """Read a raster written by `save`."""
        arrays = load_npz(path, MapError,
                          required=("format_version", "classes", "origin", "resolution", "band"))
        if int(arrays["format_version"]) != FORMAT_VERSION:
            raise MapError(f"{path}: format_version {int(arrays['format_version'])} is not "
                           f"{FORMAT_VERSION}")
        return cls(arrays["classes"], arrays["origin"], float(arrays["resolution"]),
                   (float(arrays["band"][0]), float(arrays["band"][1])))


def truth_raster(scene: Scene, resolution: float = 0.05, low: float = 0.05,
                 high: float = 1.0, margin: float = 0.5) -> TruthRaster:
    """The raster of `scene` for a robot's height band [low, high] (m)."""
    if not (resolution > 0.0 and 0.0 <= low < high):
        raise ValueError(f"expected resolution > 0 and 0 <= low < high, got {resolution}, "
                         f"{low}, {high}")
    lower, upper = scene.bounds()
    origin = np.floor((lower - margin) / resolution) * resolution
    cols, rows = (np.ceil((upper + margin - origin) / resolution)).astype(int)
    centres_x = origin[0] + (np.arange(cols) + 0.5) * resolution
    centres_y = origin[1] + (np.arange(rows) + 0.5) * resolution
    obstacle = np.zeros((rows, cols), dtype=bool)
    half = 0.5 * resolution
    for obj in scene.objects:
        height = obj.size[2] if isinstance(obj, Box) else obj.height
        if not (obj.center[2] + 0.5 * height > low and obj.center[2] - 0.5 * height < high):
            continue
        reach = (math.hypot(obj.size[0], obj.size[1]) / 2 if isinstance(obj, Box)
                 else obj.radius)
        c0, c1 = np.searchsorted(centres_x, [obj.center[0] - reach - half,
                                             obj.center[0] + reach + half])
        r0, r1 = np.searchsorted(centres_y, [obj.center[1] - reach - half,
                                             obj.center[1] + reach + half])
        x, y = np.meshgrid(centres_x[c0:c1], centres_y[r0:r1])
        overlap = (_box_overlaps(obj, x, y, half) if isinstance(obj, Box)
                   else _disc_overlaps(obj, x, y, half))
        obstacle[r0:r1, c0:c1] |= overlap
    labels, _ = ndimage.label(~obstacle)
    inside = np.floor((scene.scan_poses[:, :2] - origin) / resolution).astype(int)
    reached = labels[inside[:, 1], inside[:, 0]]
    classes = np.where(np.isin(labels, reached[reached > 0]), FLOOR, OUTSIDE).astype(np.uint8)
    classes[obstacle] = OBSTACLE
    return TruthRaster(classes, origin, float(resolution), (float(low), float(high)))


def _disc_overlaps(cylinder: Cylinder, x: np.ndarray, y: np.ndarray, half: float) -> np.ndarray:
    """Cells (centres x, y, half size) that the cylinder's disc overlaps."""
    dx = np.maximum(np.abs(x - cylinder.center[0]) - half, 0.0)
    dy = np.maximum(np.abs(y - cylinder.center[1]) - half, 0.0)
    return dx * dx + dy * dy < cylinder.radius ** 2


def _box_overlaps(box: Box, x: np.ndarray, y: np.ndarray, half: float) -> np.ndarray:
    """Cells that the box's (turned) rectangle overlaps: separating-axis test."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    hx, hy = 0.5 * box.size[0], 0.5 * box.size[1]
    dx, dy = x - box.center[0], y - box.center[1]
    # Cell axes (x and y): the box's extent along them is hx|c| + hy|s| (and hx|s| + hy|c|).
    apart = (np.abs(dx) >= half + hx * abs(c) + hy * abs(s)) \
        | (np.abs(dy) >= half + hx * abs(s) + hy * abs(c))
    # Box axes: the cell's extent along them is half (|c| + |s|).
    cell = half * (abs(c) + abs(s))
    apart |= np.abs(c * dx + s * dy) >= hx + cell
    apart |= np.abs(-s * dx + c * dy) >= hy + cell
    return ~apart
