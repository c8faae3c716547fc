"""The laser plane from three measured points, as the paper calibrates it.

The laser line is projected onto a wall; the positions of two lit points on the wall
are measured relative to the laser aperture, all in `head` coordinates (m). The
aperture and the two wall points span the plane; the aperture is kept as the plane's
origin.

Three points define a plane only if they form a real triangle. Nearly collinear
points define it badly (the normal's error grows as the triangle flattens), so the
triangle's flatness, 2 * area / longest side^2 (0 for collinear points, 0.87 for an
equilateral triangle), must reach `tolerance`, and no two points may be closer than
`tolerance` times the longest side.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations

import numpy as np

from ..errors import CalibrationError
from ..scanner_model import LaserPlane

DEFAULT_TOLERANCE = 1e-3


def laser_plane_from_points(aperture: Sequence[float], wall_a: Sequence[float],
                            wall_b: Sequence[float], *,
                            tolerance: float = DEFAULT_TOLERANCE) -> LaserPlane:
    """The plane through the laser aperture and two lit wall points (`head` frame, m).

    The normal is oriented upward (+z in `head`; for a vertical plane +x, then +y), so
    the same three points give the same plane whatever their order.
    Raises CalibrationError for non-finite, coincident or collinear points.
    """
    named = {name: _point(name, value) for name, value in
             (("aperture", aperture), ("wall_a", wall_a), ("wall_b", wall_b))}
    sides = {(p, q): float(np.linalg.norm(named[p] - named[q]))
             for p, q in combinations(named, 2)}
    longest = max(sides.values())
    for (p, q), length in sides.items():
        if length <= tolerance * longest or longest == 0.0:
            raise CalibrationError(
                f"laser plane: {p} and {q} coincide ({length:.3g} m apart, the points span "
                f"{longest:.3g} m); measure two distinct points of the line on the wall")
    origin = named["aperture"]
    normal = np.cross(named["wall_a"] - origin, named["wall_b"] - origin)
    flatness = float(np.linalg.norm(normal)) / longest**2
    if flatness < tolerance:
        raise CalibrationError(
            f"laser plane: aperture, wall_a and wall_b are collinear (flatness {flatness:.3g} "
            f"< tolerance {tolerance:g}); measure wall points farther apart along the line")
    return LaserPlane.from_point_normal(origin, _upward(normal))


def _point(name: str, value: Sequence[float]) -> np.ndarray:
    try:
        point = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        point = np.full(1, np.nan)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise CalibrationError(f"laser plane: {name}: expected 3 finite coordinates (m), "
                               f"got {value!r}")
    return point


def _upward(normal: np.ndarray) -> np.ndarray:
    """`normal` or its opposite: the first clearly non-zero of z, x, y made positive."""
    unit = normal / np.linalg.norm(normal)
    axis = next(a for a in (2, 0, 1) if abs(unit[a]) > 1e-12)
    return normal if unit[axis] > 0 else -normal
