"""Surface radiance of the scene and of the encoder disk, in linear sensor units.

The room light is an ambient level (0 dark .. 1 bright) from a broad ceiling source:
surfaces facing up are lit more than walls. Radiance = light x albedo x texture, where 1.0
is the sensor's full scale at the camera's reference exposure and gain. The disk is lit by
a small LED beside it (a dark room still shows the code), its sectors printed white ('1')
and black ('0') with a grey hub inside the code ring.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..encoder_disk import EncoderDisk
from .geometry import NO_HIT
from .texture import texture_at

LIGHT_DIRECTION = np.array([0.25, -0.35, 0.9]) / np.linalg.norm([0.25, -0.35, 0.9])
DIRECT_SHARE = 0.45  # share of the room light that depends on the surface's orientation
WHITE, BLACK, HUB = 0.85, 0.06, 0.45  # albedo of the disk's print and its hub


@njit(cache=True, nogil=True)
def shade_scene(plane: np.ndarray, t: np.ndarray, directions: np.ndarray, centre: np.ndarray,
                rotation: np.ndarray, shift: np.ndarray, normals: np.ndarray, axes: np.ndarray,
                albedo: np.ndarray, light: np.ndarray, level: float,
                contrast: float) -> np.ndarray:
    """(H, W, 3) float32 RGB radiance of the scene hits (0 where nothing is hit).

    directions: (H, W, 3) unit rays in `head`; rotation, shift: T_map_head; normals,
    albedo: per plane (P, 3) in `map` and RGB 0..1; axes: per plane (P, 2, 3) texture
    axes (`texture.surface_axes`); light: unit direction to the light;
    level: ambient level times the scene's radiance scale.
    """
    height, width = plane.shape
    out = np.zeros((height, width, 3), dtype=np.float32)
    # Per plane: the light it gets, seen from either side, and its normal in `head`.
    planes = normals.shape[0]
    lit_front = np.empty(planes)
    lit_back = np.empty(planes)
    normal_head = np.empty((planes, 3))
    for p in range(planes):
        facing = normals[p, 0] * light[0] + normals[p, 1] * light[1] + normals[p, 2] * light[2]
        lit_front[p] = level * (1.0 - DIRECT_SHARE + DIRECT_SHARE * max(facing, 0.0))
        lit_back[p] = level * (1.0 - DIRECT_SHARE + DIRECT_SHARE * max(-facing, 0.0))
        for k in range(3):
            normal_head[p, k] = (rotation[0, k] * normals[p, 0] + rotation[1, k] * normals[p, 1]
                                 + rotation[2, k] * normals[p, 2])
    for row in range(height):
        for col in range(width):
            p = plane[row, col]
            if p == NO_HIT:
                continue
            dx, dy, dz = directions[row, col, 0], directions[row, col, 1], directions[row, col, 2]
            depth = t[row, col]
            hx, hy, hz = centre[0] + depth * dx, centre[1] + depth * dy, centre[2] + depth * dz
            mx = rotation[0, 0] * hx + rotation[0, 1] * hy + rotation[0, 2] * hz + shift[0]
            my = rotation[1, 0] * hx + rotation[1, 1] * hy + rotation[1, 2] * hz + shift[1]
            mz = rotation[2, 0] * hx + rotation[2, 1] * hy + rotation[2, 2] * hz + shift[2]
            # n . ray > 0: the camera sees the plane's back (the inside of a thin face).
            back = normal_head[p, 0] * dx + normal_head[p, 1] * dy + normal_head[p, 2] * dz > 0.0
            a = axes[p, 0, 0] * mx + axes[p, 0, 1] * my + axes[p, 0, 2] * mz
            b = axes[p, 1, 0] * mx + axes[p, 1, 1] * my + axes[p, 1, 2] * mz
            shade = (lit_back[p] if back else lit_front[p]) * texture_at(a, b, contrast)
            out[row, col, 0] = shade * albedo[p, 0]
            out[row, col, 1] = shade * albedo[p, 1]
            out[row, col, 2] = shade * albedo[p, 2]
    return out


def disk_albedo(disk: EncoderDisk, points_base: np.ndarray) -> np.ndarray:
    """Albedo of the disk at (N, 3) `base_link` points on it: the code ring and the hub."""
    radius = np.hypot(points_base[:, 0], points_base[:, 1])
    angle = np.arctan2(points_base[:, 1], points_base[:, 0])
    code = np.where(disk.value_at(angle) == 1, WHITE, BLACK)
    return np.where(radius >= disk.inner_radius, code, HUB)
