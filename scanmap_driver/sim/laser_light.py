"""How the laser stripe looks: a Gaussian profile across the line, its brightness and speckle.

Each stripe point (one per image column and lit surface) is drawn down its column as a
Gaussian of width `sigma` (the optics, widened by defocus at short range since the lens is
focused far away), swept from the row where the stripe was when the shutter opened to
where it was when it closed (the laser co-rotates with the camera, so it only moves where
the surface's depth along the line changes). Its peak is the laser's irradiance on the
surface (falling with the square of the distance and with the incidence angle) times the
surface's red albedo, and it is modulated by speckle: a gamma-distributed factor per pixel
with mean 1. The value drawn is radiance in the red channel; the sensor's green and blue
pick up a little of it (`camera_effects`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

WINDOW = 48  # rows drawn per stripe point at most


def stripe_sigma(base_sigma: float, defocus_px: np.ndarray) -> np.ndarray:
    """Gaussian width (px) across the stripe: the optics and a defocus blur circle of
    diameter `defocus_px` (a uniform disc of diameter D has a standard deviation of D / 4)."""
    return np.sqrt(base_sigma ** 2 + (0.25 * np.asarray(defocus_px)) ** 2)


def defocus_diameter(depth: np.ndarray, focal_px: float, aperture: float,
                     focus_distance: float) -> np.ndarray:
    """Blur circle diameter (px) of points at `depth` (m) for a lens of `aperture` (m)
    focused at `focus_distance` (m): thin-lens geometry, f * A * |1/Z - 1/Z_f|."""
    return focal_px * aperture * np.abs(1.0 / np.asarray(depth) - 1.0 / focus_distance)


def speckle(rng: np.random.Generator, points: int, contrast: float) -> np.ndarray:
    """(points, WINDOW) gamma factors with mean 1 and standard deviation `contrast`."""
    if contrast <= 0.0:
        return np.ones((points, WINDOW), dtype=np.float32)
    shape = 1.0 / contrast ** 2
    return rng.gamma(shape, 1.0 / shape, (points, WINDOW)).astype(np.float32)


@njit(cache=True, nogil=True)
def draw_stripes(layer: np.ndarray, column: np.ndarray, v_open: np.ndarray,
                 v_close: np.ndarray, peak: np.ndarray, sigma: np.ndarray,
                 grain: np.ndarray) -> None:
    """Add each stripe point's swept Gaussian to its column of `layer` (H, W), in place.

    The profile is the Gaussian averaged over the centre moving uniformly from v_open to
    v_close: exp(-(r - v)^2 / 2 sigma^2) for a still stripe, and
    sigma sqrt(2 pi) / L * (Phi((r - a) / sigma) - Phi((r - b) / sigma)) for a sweep of
    length L from a to b. grain: (M, WINDOW) speckle factors.
    """
    height = layer.shape[0]
    root2 = math.sqrt(2.0)
    for i in range(column.shape[0]):
        a, b = min(v_open[i], v_close[i]), max(v_open[i], v_close[i])
        s = sigma[i]
        first = max(math.floor(a - 4.0 * s), 0)
        last = min(math.ceil(b + 4.0 * s), height - 1, first + grain.shape[1] - 1)
        length = b - a
        for row in range(first, last + 1):
            if length < 1e-3:
                shape = math.exp(-0.5 * ((row - 0.5 * (a + b)) / s) ** 2)
            else:
                shape = (s * math.sqrt(2.0 * math.pi) / length * 0.5
                         * (math.erf((row - a) / (root2 * s)) - math.erf((row - b) / (root2 * s))))
            layer[row, column[i]] += peak[i] * shape * grain[i, row - first]
