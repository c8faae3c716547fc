"""Place descriptors: a scan-context image of the local map around a scan, and its search.

Scan context (Kim and Kim, IROS 2018): the points within `max_radius` of the robot, seen
from above, binned into `rings` x `sectors` polar cells; a cell holds 1 + its highest
point's height (clipped to `max_height`, as a fraction of it), 0 when empty, so 2-D
scans (one height) give an occupancy image and 3-D scans a height image. A turn of the
robot shifts the image's columns: comparing two images over every circular shift of the
columns (one FFT per ring) gives a distance that does not depend on the heading, and the
best shift is the yaw between them. The ring key (occupied fraction per ring) does not
change at all with a turn: it is what candidates are first looked up by.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlaceDescriptor:
    """image (rings, sectors) float; ring_key (rings,): occupied fraction per ring."""

    image: np.ndarray
    ring_key: np.ndarray

    @property
    def occupied(self) -> int:
        """Number of occupied cells (a descriptor of nearly nothing cannot name a place)."""
        return int(np.count_nonzero(self.image))


def describe(points: np.ndarray, rings: int = 20, sectors: int = 60, max_radius: float = 10.0,
             max_height: float = 2.0) -> PlaceDescriptor:
    """Scan context of (N, 3) points in the robot's frame (see the module docstring)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    radius = np.hypot(points[:, 0], points[:, 1])
    inside = (radius < max_radius) & (radius > 0)
    radius, points = radius[inside], points[inside]
    ring = np.minimum((radius / max_radius * rings).astype(np.int64), rings - 1)
    angle = np.arctan2(points[:, 1], points[:, 0]) % (2 * np.pi)
    sector = np.minimum((angle / (2 * np.pi) * sectors).astype(np.int64), sectors - 1)
    value = 1.0 + np.clip(points[:, 2], 0.0, max_height) / max_height
    image = np.zeros(rings * sectors)
    np.maximum.at(image, ring * sectors + sector, value)
    image = image.reshape(rings, sectors)
    return PlaceDescriptor(image, np.count_nonzero(image, axis=1) / sectors)


def compare(query: PlaceDescriptor, candidate: PlaceDescriptor) -> tuple[float, float]:
    """(distance in [0, 1], yaw of `query` in `candidate`'s frame) over every column shift.

    distance: 1 - mean cosine similarity of the column pairs where both are occupied.
    """
    sectors = query.image.shape[1]
    q = _unit_columns(query.image)
    c = _unit_columns(candidate.image)
    # sim[s] = sum_r sum_j q[r, j] c[r, j + s]: a circular cross-correlation per ring.
    similarity = _circular_correlation(q, c).sum(axis=0)
    both = _circular_correlation((q.any(axis=0))[None].astype(float),
                                 (c.any(axis=0))[None].astype(float))[0]
    score = np.where(both > 0.5, similarity / np.maximum(both, 1.0), 0.0)
    shift = int(np.argmax(score))
    # Query column j sees what candidate column j + shift sees: the query is turned by
    # +shift sectors in the candidate's frame.
    yaw = float(np.angle(np.exp(2j * np.pi * shift / sectors)))
    return float(1.0 - score[shift]), yaw


def _unit_columns(image: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(image, axis=0)
    return np.where(norm > 0, image / np.where(norm > 0, norm, 1.0), 0.0)


def _circular_correlation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per row, out[s] = sum_j a[j] b[(j + s) mod n] (rows of equal length n)."""
    return np.fft.irfft(np.conj(np.fft.rfft(a, axis=1)) * np.fft.rfft(b, axis=1),
                        n=a.shape[1], axis=1)
