"""Pictures of maps: the occupancy grid as an image to look at and draw on, and PNG files.

An occupancy grid (int8, row 0 at the lowest y, -1 unknown, 0..100) becomes a BGR image
with north up, in the shades of ROS map_server (free 254, occupied 0, unknown 205; cells
between the thresholds mid grey), each cell `scale` pixels wide. `MapImage.pixel`
turns map coordinates into pixel positions so that paths and poses can be drawn on it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import cv2
import numpy as np

from scanmap_driver.errors import MapError
from scanmap_driver.files import atomic_path

FREE_SHADE, OCCUPIED_SHADE, UNKNOWN_SHADE, BETWEEN_SHADE = 254, 0, 205, 150


@dataclass(frozen=True, eq=False)
class MapImage:
    """A BGR image of a map window: cell [0, 0] (lower left) at `origin`, `scale` pixels
    per cell of `resolution` metres, north up."""

    image: np.ndarray
    origin: tuple[float, float]
    resolution: float
    scale: int

    def pixel(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) int32 pixel (column, row) of each map point (x, y)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        per_pixel = self.resolution / self.scale
        col = (xy[:, 0] - self.origin[0]) / per_pixel
        row = self.image.shape[0] - (xy[:, 1] - self.origin[1]) / per_pixel
        return np.column_stack([np.floor(col), np.floor(row)]).astype(np.int32)


def occupancy_image(occupancy: np.ndarray, origin: tuple[float, float], resolution: float,
                    scale: int = 4, occupied_thresh: int = 65, free_thresh: int = 25) -> MapImage:
    """The occupancy grid as a map_server-shaded image, `scale` pixels per cell."""
    occupancy = np.asarray(occupancy)
    if occupancy.ndim != 2 or not occupancy.size:
        raise MapError(f"occupancy_image: expected a non-empty 2-D grid, got {occupancy.shape}")
    if not (isinstance(scale, int) and scale >= 1):
        raise MapError(f"occupancy_image: scale must be a positive integer, got {scale!r}")
    values = occupancy.astype(np.int16)
    shade = np.full(values.shape, BETWEEN_SHADE, np.uint8)
    shade[values < 0] = UNKNOWN_SHADE
    shade[(values >= 0) & (values <= free_thresh)] = FREE_SHADE
    shade[values >= occupied_thresh] = OCCUPIED_SHADE
    grey = np.repeat(np.repeat(shade[::-1], scale, axis=0), scale, axis=1)
    image = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    return MapImage(image, (float(origin[0]), float(origin[1])), float(resolution), scale)


def write_png(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write an image as PNG, atomically."""
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise MapError(f"{path}: OpenCV could not encode the image {image.shape}")
    with atomic_path(path) as tmp:
        tmp.write_bytes(data.tobytes())
