"""The ground-truth 2D raster of a scene: obstacle, floor, drop-off or outside, per cell.

For a robot that drives over things lower than `low` (its step height) and under things
higher than `high` (its height), a cell is an obstacle if any object occupies space between
the two heights over any part of the cell (exact rectangle and disc overlap tests, no
sampling). The floor height and slope of each cell are those at its centre (the floor
z = 0 or a floor region's surface). The robot drives from its scan poses into the open
neighbouring cells (4-connected) whose floor differs by at most `low` and whose slope is
at most `max_slope`: those are floor. Of the cells it cannot enter, those whose floor lies
more than `low` below that of the nearest floor cell are a drop-off where they touch the
floor (with the rest of their lowered area: a hole, a stairwell, the far side of a step
down); those that touch the floor otherwise (a step up, a ramp too steep) are obstacles;
and the rest (behind walls, inside closed objects, on a platform) are outside. Glass and
mirrors are obstacles like any object. Mapping is scored against it.

File (`.npz`, no pickle): `classes` (rows along y from `origin`, columns along x; uint8:
0 outside, 1 floor, 2 obstacle, 3 drop-off), `floor_height` and `slope` (float32, m and
rad), `origin` (x, y of the lower-left corner, m), `resolution` (m), `band` (low, high,
m), `max_slope` (rad), `format_version` (2; version 1 files, without drop-offs and floor
heights, read as a flat floor).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import MapError
from ..files import load_npz, save_npz
from .scene import Box, Cylinder, Scene

OUTSIDE, FLOOR, OBSTACLE, DROP_OFF = 0, 1, 2, 3
FORMAT_VERSION = 2
MAX_SLOPE = math.radians(15.0)  # the steepest floor the robot drives on (FloorConfig's)


@dataclass(frozen=True)
class TruthRaster:
    """Cell classes of a scene; `classes[row, col]` covers x in origin.x + col * resolution
    + [0, resolution), y likewise with row."""

    classes: np.ndarray
    origin: np.ndarray
    resolution: float
    band: tuple[float, float]
    floor_height: np.ndarray | None = None  # (rows, cols) float32, m
    slope: np.ndarray | None = None  # (rows, cols) float32, rad
    max_slope: float = MAX_SLOPE

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) integer (row, col) of `map` points (may lie outside the raster)."""
        index = np.floor((np.asarray(xy)[:, :2] - self.origin) / self.resolution)
        return index[:, ::-1].astype(np.int64)

    def class_at(self, xy: np.ndarray) -> np.ndarray:
        """(N,) uint8 class of the cell holding each `map` point; OUTSIDE beyond the
        raster."""
        cells = self.cell_of(xy)
        rows, cols = self.classes.shape
        inside = (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) \
            & (cells[:, 1] < cols)
        out = np.full(len(cells), OUTSIDE, np.uint8)
        out[inside] = self.classes[cells[inside, 0], cells[inside, 1]]
        return out

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the raster as `.npz` (atomically)."""
        flat = np.zeros(self.classes.shape, np.float32)
        save_npz(path, format_version=np.array(FORMAT_VERSION), classes=self.classes,
                 origin=self.origin, resolution=np.array(self.resolution),
                 band=np.array(self.band), max_slope=np.array(self.max_slope),
                 floor_height=flat if self.floor_height is None else self.floor_height,
                 slope=flat if self.slope is None else self.slope)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> TruthRaster:
        """Read a raster written by `save`."""
        arrays = load_npz(path, MapError,
                          required=("format_version", "classes", "origin", "resolution", "band"))
        version = int(arrays["format_version"])
        if version not in (1, FORMAT_VERSION):
            raise MapError(f"{path}: format_version {version} is not 1 or {FORMAT_VERSION}")
        band = (float(arrays["band"][0]), float(arrays["band"][1]))
        if version == 1:
            return cls(arrays["classes"], arrays["origin"], float(arrays["resolution"]), band)
        extra = load_npz(path, MapError, required=("floor_height", "slope", "max_slope"))
        return cls(arrays["classes"], arrays["origin"], float(arrays["resolution"]), band,
                   extra["floor_height"], extra["slope"], float(extra["max_slope"]))


def truth_raster(scene: Scene, resolution: float = 0.05, low: float = 0.05,
                 high: float = 1.0, margin: float = 0.5,
                 max_slope: float = MAX_SLOPE) -> TruthRaster:
    """The raster of `scene` for a robot's height band [low, high] (m) that drives on
    slopes up to `max_slope` (rad). People are left out (use `scene.at_scan(i)`)."""
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
    height, slope = scene.floor_at(*np.meshgrid(centres_x, centres_y))
    inside = np.floor((scene.scan_poses[:, :2] - origin) / resolution).astype(int)
    floor = _drivable(height, ~obstacle & (slope <= max_slope), inside[:, 1], inside[:, 0], low)
    classes = np.where(floor, FLOOR, OUTSIDE).astype(np.uint8)
    from scipy import ndimage  # building truth only: reading a raster needs no scipy

    touching = ndimage.binary_dilation(floor, ndimage.generate_binary_structure(2, 1)) \
        & ~floor & ~obstacle
    _, (near_y, near_x) = ndimage.distance_transform_edt(~floor, return_indices=True)
    lowered = ~floor & ~obstacle & (height < height[near_y, near_x] - low)
    labels, _ = ndimage.label(lowered)
    drop = np.isin(labels, np.unique(labels[touching & lowered])) & lowered
    classes[touching & ~lowered] = OBSTACLE
    classes[obstacle] = OBSTACLE
    classes[drop] = DROP_OFF
    return TruthRaster(classes, origin, float(resolution), (float(low), float(high)),
                       height.astype(np.float32), slope.astype(np.float32), float(max_slope))


def _drivable(height: np.ndarray, open_: np.ndarray, rows: np.ndarray, cols: np.ndarray,
              step: float) -> np.ndarray:
    """Open cells reachable from the cells (rows, cols) through 4-neighbours whose floor
    heights differ by at most `step` (breadth first)."""
    ny, nx = height.shape
    reached = np.zeros((ny, nx), bool)
    queue = [(r, c) for r, c in zip(rows, cols, strict=True) if open_[r, c]]
    for r, c in queue:
        reached[r, c] = True
    while queue:
        r, c = queue.pop()
        for rr, cc in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
            if (0 <= rr < ny and 0 <= cc < nx and open_[rr, cc] and not reached[rr, cc]
                    and abs(height[rr, cc] - height[r, c]) <= step):
                reached[rr, cc] = True
                queue.append((rr, cc))
    return reached


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
