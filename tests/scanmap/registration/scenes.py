"""Synthetic scans for registration tests: ray-cast boxes, a floor and round walls.

The rays imitate the scanner's coverage: from the camera height (1 m) over all
azimuths and downward elevations, hits kept within 0.3-4 m horizontal range and below
1 m height, Gaussian noise along the ray growing with range squared (triangulation).
A scan can be taken while moving: each azimuth column (one frame) is cast from the
robot's pose at its time and expressed in base_link at that time, as the scanner does.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from scanmap_driver.scan import Scan
from scanmap_driver.transforms import se2_to_pose

SENSOR_HEIGHT = 1.0
MAX_RANGE = 4.0


@dataclass(frozen=True)
class Scene:
    """Axis-aligned boxes (lo, hi corners), round rooms seen from inside (cx, cy, radius),
    and the floor z = 0 but over pits: open boxes below it (lo, hi corners, hi z = 0)."""

    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]]
    cylinders: list[tuple[float, float, float]] = field(default_factory=list)
    pits: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = \
        field(default_factory=list)

    def shifted(self, dx: float, dy: float) -> Scene:
        """The same scene moved by (dx, dy)."""
        return Scene([((a[0] + dx, a[1] + dy, a[2]), (b[0] + dx, b[1] + dy, b[2]))
                      for a, b in self.boxes],
                     [(cx + dx, cy + dy, r) for cx, cy, r in self.cylinders],
                     [((a[0] + dx, a[1] + dy, a[2]), (b[0] + dx, b[1] + dy, b[2]))
                      for a, b in self.pits])


def _wall(x0, x1, y0, y1, height=1.2):
    return ((x0, y0, 0.0), (x1, y1, height))


def corridor(length: float = 20.0, with_features: bool = True) -> Scene:
    """A 1.5 m wide corridor along x from 0 to `length`: door recesses and boxes if asked."""
    if not with_features:
        return Scene([_wall(-100, 100, 0.75, 0.85), _wall(-100, 100, -0.85, -0.75)])
    boxes = [  # left wall with a door recess at x 13.5-14.5
        _wall(-1.0, 13.5, 0.75, 0.85), _wall(14.5, length + 1.0, 0.75, 0.85),
        _wall(13.5, 14.5, 1.05, 1.15),                       # left recess
        _wall(-1.0, 6.0, -0.85, -0.75), _wall(7.0, length + 1.0, -0.85, -0.75),  # right
        _wall(6.0, 7.0, -1.15, -1.05),                       # its recess
        _wall(-1.2, -1.0, -1.2, 1.2), _wall(length + 1.0, length + 1.2, -1.2, 1.2),  # ends
        ((2.8, 0.35, 0.0), (3.2, 0.75, 0.6)),                # boxes along the walls
        ((9.0, -0.75, 0.0), (9.5, -0.4, 0.8)),
        ((16.3, 0.3, 0.0), (16.9, 0.75, 0.5)),
    ]
    return Scene(boxes)


def square_room(side: float = 4.0) -> Scene:
    """An empty square room centred on the origin (90 deg rotational symmetry)."""
    h = side / 2
    return Scene([_wall(-h - 0.1, h + 0.1, h, h + 0.1), _wall(-h - 0.1, h + 0.1, -h - 0.1, -h),
                  _wall(h, h + 0.1, -h, h), _wall(-h - 0.1, -h, -h, h)])


def office() -> Scene:
    """A 5 m x 4 m room centred on the origin with a cabinet, boxes and a pillar."""
    return Scene([_wall(-2.6, 2.6, 2.0, 2.1), _wall(-2.6, 2.6, -2.1, -2.0),
                  _wall(2.5, 2.6, -2.0, 2.0), _wall(-2.6, -2.5, -2.0, 2.0),
                  ((1.2, 1.4, 0.0), (2.5, 2.0, 0.9)),      # cabinet in a corner
                  ((-1.6, -1.2, 0.0), (-1.0, -0.7, 0.5)),  # boxes
                  ((0.8, -1.5, 0.0), (1.2, -1.1, 0.7)),
                  ((-1.3, 0.8, 0.0), (-1.1, 1.0, 1.2))])   # pillar


def round_room(radius: float = 2.5) -> Scene:
    """A round room centred on the origin: yaw is unobservable."""
    return Scene([], [(0.0, 0.0, radius)])


def _cast(scene: Scene, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Distance along each ray to the first hit (inf if none)."""
    best = np.full(len(directions), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        down = directions[:, 2] < 0
        best[down] = -origins[down, 2] / directions[down, 2]  # the floor
        for lo, hi in scene.pits:  # through the floor's opening to a wall or the bottom
            at = origins + best[:, None] * directions
            inside = down & (at[:, 0] > lo[0]) & (at[:, 0] < hi[0]) & (at[:, 1] > lo[1]) \
                & (at[:, 1] < hi[1])
            t1 = (np.array(lo) - origins) / directions
            t2 = (np.array(hi) - origins) / directions
            best = np.where(inside, np.nanmin(np.maximum(t1, t2), axis=1), best)
        for lo, hi in scene.boxes:
            t1 = (np.array(lo) - origins) / directions
            t2 = (np.array(hi) - origins) / directions
            near = np.nanmax(np.minimum(t1, t2), axis=1)
            far = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (near <= far) & (near > 1e-6)
            best = np.where(hit & (near < best), near, best)
        for cx, cy, radius in scene.cylinders:  # seen from inside
            ox, oy = origins[:, 0] - cx, origins[:, 1] - cy
            a = directions[:, 0] ** 2 + directions[:, 1] ** 2
            b = 2 * (ox * directions[:, 0] + oy * directions[:, 1])
            c = ox ** 2 + oy ** 2 - radius ** 2
            t = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
            best = np.where((t > 0) & (t < best), t, best)
    return best


def make_scan(scene: Scene, pose: np.ndarray, rng: np.random.Generator, *,
              end_pose: np.ndarray | None = None, columns: int = 400, rows: int = 50,
              noise: float = 1.0, index: int = 0, stamp: float = 0.0,
              duration: float = 2.0) -> Scan:
    """A 360 deg scan from planar `pose` (moving linearly to `end_pose` if given)."""
    end_pose = pose if end_pose is None else end_pose
    azimuth = np.linspace(-np.pi, np.pi, columns, endpoint=False)
    elevation = np.deg2rad(np.linspace(-40.0, -1.0, rows))
    az, el = np.meshgrid(azimuth, elevation, indexing="ij")
    s = np.repeat(np.linspace(0.0, 1.0, columns), rows)
    x0, y0, yaw0 = pose
    x1, y1, yaw1 = end_pose
    px, py, pyaw = x0 + s * (x1 - x0), y0 + s * (y1 - y0), yaw0 + s * (yaw1 - yaw0)
    local = np.column_stack([np.cos(el.ravel()) * np.cos(az.ravel()),
                             np.cos(el.ravel()) * np.sin(az.ravel()), np.sin(el.ravel())])
    c, sn = np.cos(pyaw), np.sin(pyaw)
    world_dir = np.column_stack([c * local[:, 0] - sn * local[:, 1],
                                 sn * local[:, 0] + c * local[:, 1], local[:, 2]])
    origins = np.column_stack([px, py, np.full_like(px, SENSOR_HEIGHT)])
    distance = _cast(scene, origins, world_dir)
    sigma = noise * (0.002 + 0.001 * distance ** 2)
    measured = distance + rng.normal(size=distance.size) * sigma
    points = local * measured[:, None] + [0.0, 0.0, SENSOR_HEIGHT]
    horizontal = np.hypot(points[:, 0], points[:, 1])
    keep = np.isfinite(distance) & (horizontal >= 0.3) & (horizontal <= MAX_RANGE) \
        & (points[:, 2] <= 1.0)
    n = int(keep.sum())
    frame = np.repeat(np.arange(columns), rows)[keep]
    return Scan(points=points[keep], colors=np.zeros((n, 3), np.uint8),
                time=stamp + duration * s[keep], heading=az.ravel()[keep], frame_index=frame,
                range_sigma=sigma[keep], index=index, stamp=stamp)


def with_odometry(scan: Scan, odom_start: np.ndarray, odom_end: np.ndarray) -> Scan:
    """The scan carrying odometry poses (4x4) at its start and end."""
    return Scan(points=scan.points, colors=scan.colors, time=scan.time, heading=scan.heading,
                frame_index=scan.frame_index, range_sigma=scan.range_sigma, index=scan.index,
                stamp=scan.stamp, odom_start=odom_start, odom_end=odom_end)


def noisy_odometry(truth: np.ndarray, rng: np.random.Generator, trans_sigma: float = 0.02,
                   rot_sigma: float = 0.01, scale: float = 1.03,
                   yaw_bias: float = 0.01) -> np.ndarray:
    """(N, 3) odometry drifting from (N, 3) planar truth: noisy, scaled, biased increments."""
    odom = [np.array(truth[0], dtype=float)]
    for a, b in itertools.pairwise(truth):
        step = np.linalg.inv(se2_to_pose(*a)) @ se2_to_pose(*b)
        dx, dy = step[0, 3], step[1, 3]
        dyaw = np.arctan2(step[1, 0], step[0, 0])
        dist = np.hypot(dx, dy)
        dx = dx * scale + rng.normal(0, trans_sigma * max(dist, 0.1))
        dy = dy * scale + rng.normal(0, trans_sigma * max(dist, 0.1))
        dyaw = dyaw + yaw_bias * dist + rng.normal(0, rot_sigma * max(dist, 0.1))
        x, y, yaw = odom[-1]
        odom.append(np.array([x + np.cos(yaw) * dx - np.sin(yaw) * dy,
                              y + np.sin(yaw) * dx + np.cos(yaw) * dy, yaw + dyaw]))
    return np.array(odom)
