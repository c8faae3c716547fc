"""The overhead view of a point cloud, coloured by height above the floor (paper Figs. 6-7).

Seen from above, each pixel shows its highest point: floor points (within `step` of the
floor) light blue as in the paper, everything higher from blue (low) through green to
red (`max_height` and above). The robot's path is drawn in dark grey, with a 1 m scale
bar and a height legend, so the walls' straightness and the stripes of single frames can
be judged by eye.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

FLOOR_BGR = (230, 216, 173)  # light blue
BACKGROUND = 255
INK = (60, 60, 60)
LOOP_BGR = (40, 40, 220)  # red: the edges of closed loops
_TURBO = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_TURBO)[:, 0]


def height_colours(height: np.ndarray, step: float, max_height: float) -> np.ndarray:
    """(N, 3) BGR colours: light blue within `step` of the floor, else TURBO of height."""
    height = np.asarray(height, dtype=np.float64)
    level = np.clip((height - step) / max(max_height - step, 1e-9), 0.0, 1.0)
    colours = _TURBO[np.rint(255 * level).astype(np.intp)]
    colours[np.abs(height) < step] = FLOOR_BGR
    return colours


def overhead_view(points: np.ndarray, floor_height: float | np.ndarray = 0.0, *,
                  resolution: float = 0.01, max_height: float = 1.0, step: float = 0.03,
                  path: np.ndarray | None = None, loops: np.ndarray | None = None,
                  max_side: int = 4000) -> np.ndarray:
    """BGR image of (N, 3) map points from above (see the module docstring).

    floor_height: of the floor under each point (or one value). path: (K, 2) robot
    positions. loops: (L, 2, 2) the two positions each closed loop joins, drawn in red
    (a line and a ring where it closed). resolution: metres per pixel, coarsened so no
    side exceeds `max_side`.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    height = points[:, 2] - np.broadcast_to(np.asarray(floor_height, np.float64), len(points))
    keep = np.isfinite(points).all(axis=1) & np.isfinite(height)
    points, height = points[keep], height[keep]
    xy = points[:, :2]
    extent = np.vstack([xy, np.zeros((0, 2)) if path is None else np.asarray(path)[:, :2]])
    if not len(extent):
        return np.full((64, 64, 3), BACKGROUND, np.uint8)
    low, high = extent.min(axis=0) - 0.3, extent.max(axis=0) + 0.3
    resolution = max(resolution, float((high - low).max()) / max_side)
    width, rows = (np.ceil((high - low) / resolution).astype(int) + 1).tolist()
    col = ((xy[:, 0] - low[0]) / resolution).astype(np.int64)
    row = rows - 1 - ((xy[:, 1] - low[1]) / resolution).astype(np.int64)
    top = np.full(rows * width, -np.inf)
    np.maximum.at(top, row * width + col, height)
    seen = np.isfinite(top)
    image = np.full((rows * width, 3), BACKGROUND, np.uint8)
    image[seen] = height_colours(top[seen], step, max_height)
    image = image.reshape(rows, width, 3)

    def to_pixel(p: np.ndarray) -> np.ndarray:
        return np.column_stack([(p[:, 0] - low[0]) / resolution,
                                rows - 1 - (p[:, 1] - low[1]) / resolution]).astype(np.int32)

    if path is not None and len(path):
        pixels = to_pixel(np.asarray(path, dtype=np.float64))
        cv2.polylines(image, [pixels.reshape(-1, 1, 2)], False, INK, 1, cv2.LINE_AA)
        for p in pixels:
            cv2.circle(image, tuple(int(v) for v in p), 2, INK, -1, cv2.LINE_AA)
    for a, b in np.asarray(loops if loops is not None else np.zeros((0, 2, 2)), np.float64):
        # The two ends of a loop are near each other (the robot came back): a ring marks
        # where it closed, a line joins the ends.
        start, end = (tuple(map(int, p)) for p in to_pixel(np.array([a, b])))
        cv2.line(image, start, end, LOOP_BGR, 1)
        cv2.circle(image, end, 5, LOOP_BGR, 1)
    _scale_bar(image, resolution)
    _legend(image, step, max_height)
    return image


def _scale_bar(image: np.ndarray, resolution: float) -> None:
    """A 1 m bar (a power of ten below a quarter of a narrower image) at the lower left."""
    quarter = image.shape[1] * resolution / 4
    metres = min(1.0, 10.0 ** math.floor(math.log10(max(quarter, 1e-3))))
    length = round(metres / resolution)
    y = image.shape[0] - 10
    cv2.line(image, (10, y), (10 + length, y), INK, 2)
    cv2.putText(image, f"{metres:g} m", (10, y - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4, INK, 1,
                cv2.LINE_AA)


def _legend(image: np.ndarray, step: float, max_height: float) -> None:
    """A vertical height scale at the upper right: floor, then step .. max_height."""
    rows = min(100, image.shape[0] - 20)
    if rows < 20 or image.shape[1] < 80:
        return
    heights = np.linspace(max_height, 0.0, rows)
    bar = height_colours(heights, step, max_height)
    x = image.shape[1] - 50
    image[10:10 + rows, x:x + 10] = bar[:, None, :]
    for value, y in ((max_height, 10 + 8), (0.0, 10 + rows)):
        cv2.putText(image, f"{value:g} m", (x + 13, y), cv2.FONT_HERSHEY_SIMPLEX, 0.35, INK,
                    1, cv2.LINE_AA)
