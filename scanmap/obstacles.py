"""Obstacle queries for a controller: distance, nearest obstacle, virtual range scan, clearance.

A query never calls unknown space free. Two distance fields are kept: one over the
obstacle cells, one over every cell not known FREE (obstacles, unknown cells, and
beyond the window). Distances are to measured surface points (the mean of the hits in
a cell), refined over the 3 x 3 cells around the field's nearest cell. `distance()` and
a Nearest's `clearance` are radii of known free space - what a controller may rely on;
`obstacle_distance()` ignores unknown space, for planners and evaluation. Status:

* OK - the nearest thing not known free is an obstacle: clearance = obstacle distance.
* UNKNOWN - unknown space is nearer than any obstacle (or the query is in it): the
  clearance is how far the space is known free, 0 inside unknown space.
* STALE - the newest data are older than `max_age`; FAULTED - the sensor is faulted.
  Both report no clearance at all: distance and clearance 0, collision.

Snapshots are immutable. The mapper builds a new one per scan (`ObstacleMap.update`)
and swaps it in with one reference assignment, so a controller thread polling
`nearest()` always reads one consistent map without locking.
"""

from __future__ import annotations

import enum
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from scanmap_driver.errors import MapError

from .distance_field import distance_transform
from .floor import FREE, OBSTACLE, UNKNOWN, FloorParams, RobotShape, Segmentation, segment
from .grid import HeightGrid


class Status(enum.IntEnum):
    """How far an answer can be trusted (see the module docstring)."""

    OK = 0
    UNKNOWN = 1
    STALE = 2
    FAULTED = 3


@dataclass(frozen=True)
class Nearest:
    """The nearest obstacle: distance (m, inf when none), bearing in map (rad) and point
    (measured surface); clearance: radius (m) of known free space around the query (equal
    to distance when status is OK, smaller when unknown space is nearer); data age (s)."""

    distance: float
    bearing: float
    point: tuple[float, float]
    clearance: float
    age: float
    status: Status


@dataclass(frozen=True, eq=False)
class PolarScan:
    """A virtual 360 deg range scan: ranges (m, inf when free up to max_range) per bin
    centred at angles (rad, robot frame), what ends each bin (OBSTACLE/UNKNOWN/FREE)."""

    angles: np.ndarray
    ranges: np.ndarray
    kinds: np.ndarray
    age: float
    status: Status


@dataclass(frozen=True)
class Clearance:
    """Whether the footprint touches non-free space, and the margin (m) to it."""

    collision: bool
    margin: float
    age: float
    status: Status


@njit(cache=True, nogil=True)
def cell_boxes(state, points, geo, unknown_blocks) -> np.ndarray:
    """(ny, nx, 4) boxes (x lo, y lo, x hi, y hi) to measure distances to, branch-free: an
    obstacle cell's measured point, an unknown cell's square (with `unknown_blocks`), and
    +inf elsewhere (clamping a query into it gives an infinite distance)."""
    ny, nx = state.shape
    boxes = np.full((ny, nx, 4), np.inf)
    for y in range(ny):
        for x in range(nx):
            if state[y, x] == OBSTACLE:
                boxes[y, x, 0] = boxes[y, x, 2] = points[y, x, 0]
                boxes[y, x, 1] = boxes[y, x, 3] = points[y, x, 1]
            elif state[y, x] == UNKNOWN and unknown_blocks:
                boxes[y, x, 0] = geo[0] + x * geo[2]
                boxes[y, x, 1] = geo[1] + y * geo[2]
                boxes[y, x, 2] = boxes[y, x, 0] + geo[2]
                boxes[y, x, 3] = boxes[y, x, 1] + geo[2]
    return boxes


@njit(cache=True, nogil=True, inline="always")
def _clamp(q: float, lo: float, hi: float) -> float:
    return min(max(q, lo), hi)


@njit(cache=True, nogil=True, inline="always")
def query_point(qx, qy, boxes, nearest, state, geo, unknown_blocks):
    """(distance, point x, point y, kind) of the nearest obstacle to (qx, qy), or with
    `unknown_blocks` of the nearest cell not known free (beyond the window is unknown).

    `nearest` is the matching distance field's nearest-cell index and `boxes` the matching
    `cell_boxes`; the answer is refined over the 3 x 3 cells around the field's nearest.
    """
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    gx, gy = (qx - ox) / res, (qy - oy) / res
    best, bx, by, kind = np.inf, qx, qy, FREE  # best: squared distance
    if unknown_blocks:
        if not (0.0 <= gx < nx and 0.0 <= gy < ny):
            return 0.0, qx, qy, UNKNOWN
        ix, iy = int(gx), int(gy)
        if state[iy, ix] != FREE:
            b = boxes[iy, ix]
            return 0.0, _clamp(qx, b[0], b[2]), _clamp(qy, b[1], b[3]), np.int64(state[iy, ix])
        left, right, bottom, top = qx - ox, ox + nx * res - qx, qy - oy, oy + ny * res - qy
        edge = min(left, right, bottom, top)
        best, kind = edge * edge, UNKNOWN
        if edge == left:
            bx = ox
        elif edge == right:
            bx = ox + nx * res
        elif edge == bottom:
            by = oy
        else:
            by = oy + ny * res
    else:
        ix = min(max(math.floor(gx), 0), nx - 1)
        iy = min(max(math.floor(gy), 0), ny - 1)
    k = nearest[iy, ix]
    if k >= 0:
        cy, cx = k // nx, k % nx
        wy, wx = -1, -1
        for yy in range(max(cy - 1, 0), min(cy + 2, ny)):
            for xx in range(max(cx - 1, 0), min(cx + 2, nx)):
                b = boxes[yy, xx]
                px, py = _clamp(qx, b[0], b[2]), _clamp(qy, b[1], b[3])
                d = (px - qx) * (px - qx) + (py - qy) * (py - qy)
                if d < best:
                    best, bx, by, wy, wx = d, px, py, yy, xx
        if wy >= 0:
            kind = np.int64(state[wy, wx])
    return math.sqrt(best), bx, by, kind


@njit(cache=True, nogil=True)
def query_one(qx, qy, state, nearest_blocked, nearest_obstacle, boxes_blocked,
              boxes_obstacle, geo):
    """(clearance, kind of what limits it, obstacle distance, obstacle x, obstacle y)."""
    clearance, _, _, kind = query_point(qx, qy, boxes_blocked, nearest_blocked, state, geo,
                                        True)
    d, px, py, _ = query_point(qx, qy, boxes_obstacle, nearest_obstacle, state, geo, False)
    if d <= clearance:  # the two refinements may settle on different cells
        clearance, kind = d, OBSTACLE
    return clearance, kind, d, px, py


@njit(cache=True, nogil=True)
def query_points(xy, state, nearest_blocked, nearest_obstacle, boxes_blocked, boxes_obstacle,
                 geo, unknown_blocks, out):
    """Clearance (unknown_blocks) or obstacle distance of each (x, y) row (see query_one)."""
    for i in range(xy.shape[0]):
        d = query_point(xy[i, 0], xy[i, 1], boxes_obstacle, nearest_obstacle, state, geo,
                        False)[0]
        if unknown_blocks:
            d = min(d, query_point(xy[i, 0], xy[i, 1], boxes_blocked, nearest_blocked, state,
                                   geo, True)[0])
        out[i] = d


@njit(cache=True, nogil=True)
def polar_kernel(qx, qy, yaw, max_range, state, boxes, geo, ranges, kinds):
    """Per angular bin, the range of the nearest non-free cell within max_range.

    Every blocked cell is spread over the bins its square subtends, so nothing thin is
    missed between bins; the window's edge counts as unknown.
    """
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    bins = ranges.shape[0]
    width = 2.0 * math.pi / bins
    for b in range(bins):
        ranges[b] = np.inf
        kinds[b] = FREE
        a = yaw + (b + 0.5) * width - math.pi
        dx, dy = math.cos(a), math.sin(a)
        exit_t = np.inf  # leaving the window: unknown from there on
        if dx > 0:
            exit_t = min(exit_t, (ox + nx * res - qx) / dx)
        elif dx < 0:
            exit_t = min(exit_t, (ox - qx) / dx)
        if dy > 0:
            exit_t = min(exit_t, (oy + ny * res - qy) / dy)
        elif dy < 0:
            exit_t = min(exit_t, (oy - qy) / dy)
        if exit_t <= max_range:
            ranges[b] = max(exit_t, 0.0)
            kinds[b] = UNKNOWN
    half_diag = res * math.sqrt(0.5)
    x_lo = max(int((qx - max_range - half_diag - ox) / res), 0)
    x_hi = min(int((qx + max_range + half_diag - ox) / res) + 1, nx)
    y_lo = max(int((qy - max_range - half_diag - oy) / res), 0)
    y_hi = min(int((qy + max_range + half_diag - oy) / res) + 1, ny)
    for y in range(y_lo, y_hi):
        for x in range(x_lo, x_hi):
            if state[y, x] == FREE:
                continue
            b = boxes[y, x]
            r = math.hypot(_clamp(qx, b[0], b[2]) - qx, _clamp(qy, b[1], b[3]) - qy)
            if r > max_range:
                continue
            cx, cy = ox + (x + 0.5) * res - qx, oy + (y + 0.5) * res - qy
            rc = math.hypot(cx, cy)
            spread = math.pi if rc <= half_diag else math.asin(half_diag / rc)
            centre = math.atan2(cy, cx) - yaw + math.pi
            b0 = math.floor((centre - spread) / width)
            b1 = math.floor((centre + spread) / width)
            for b in range(b0, b1 + 1):
                bb = b % bins
                if r < ranges[bb]:
                    ranges[bb] = r
                    kinds[bb] = state[y, x]


@njit(cache=True, nogil=True)
def _segment_distance(px, py, ax, ay, bx, by):
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 == 0.0 else min(max(((px - ax) * ex + (py - ay) * ey) / length2, 0.0), 1.0)
    return math.hypot(px - ax - t * ex, py - ay - t * ey)


@njit(cache=True, nogil=True)
def polygon_margin(polygon, radius, state, points, geo):
    """Least signed distance (negative inside) from the polygon (K, 2) in map to what is
    not known free within `radius` of it: obstacle points, unknown cells (their square,
    bounded by its circumcircle) and the window's edge; and the kind of that thing."""
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    xmin, xmax = polygon[:, 0].min() - radius, polygon[:, 0].max() + radius
    ymin, ymax = polygon[:, 1].min() - radius, polygon[:, 1].max() + radius
    best, kind = radius, FREE
    half_diag = res * math.sqrt(0.5)
    k = polygon.shape[0]
    for i in range(k):  # the edge is nearest at a vertex
        px, py = polygon[i, 0], polygon[i, 1]
        edge = min(px - ox, ox + nx * res - px, py - oy, oy + ny * res - py)
        if edge < best:
            best, kind = edge, UNKNOWN
    for y in range(max(int((ymin - oy) / res), 0), min(int((ymax - oy) / res) + 1, ny)):
        for x in range(max(int((xmin - ox) / res), 0), min(int((xmax - ox) / res) + 1, nx)):
            if state[y, x] == FREE:
                continue
            if state[y, x] == OBSTACLE:
                px, py, reach = float(points[y, x, 0]), float(points[y, x, 1]), 0.0
            else:  # unknown: its square, bounded by the circle around it
                px, py, reach = ox + (x + 0.5) * res, oy + (y + 0.5) * res, half_diag
            d = np.inf
            inside = False
            for i in range(k):
                ax, ay = polygon[i, 0], polygon[i, 1]
                bx, by = polygon[(i + 1) % k, 0], polygon[(i + 1) % k, 1]
                d = min(d, _segment_distance(px, py, ax, ay, bx, by))
                if (ay > py) != (by > py) and px < ax + (py - ay) * (bx - ax) / (by - ay):
                    inside = not inside
            d = -d - reach if inside else d - reach
            if d < best:
                best, kind = d, state[y, x]
    return best, kind


@dataclass(frozen=True, eq=False)
class ObstacleSnapshot:
    """One consistent obstacle map (immutable): the segmentation, two distance fields (over
    cells not known free, and over obstacle cells only) with their `cell_boxes`, and the
    data time."""

    segmentation: Segmentation
    nearest_blocked: np.ndarray
    nearest_obstacle: np.ndarray
    boxes_blocked: np.ndarray
    boxes_obstacle: np.ndarray
    stamp: float
    geometry: np.ndarray  # origin x, origin y, resolution, nx, ny

    @classmethod
    def from_segmentation(cls, seg: Segmentation, stamp: float) -> ObstacleSnapshot:
        """Build both distance fields and freeze every array."""
        _, blocked = distance_transform(seg.state != FREE)
        _, obstacle = distance_transform(seg.state == OBSTACLE)
        ny, nx = seg.shape
        geometry = np.array([seg.origin[0], seg.origin[1], seg.resolution, nx, ny], np.float64)
        boxes_blocked = cell_boxes(seg.state, seg.points, geometry, True)
        boxes_obstacle = cell_boxes(seg.state, seg.points, geometry, False)
        for array in (seg.state, seg.points, seg.floor_height, seg.is_floor, seg.band_logodds,
                      seg.updated, blocked, obstacle, boxes_blocked, boxes_obstacle, geometry):
            array.setflags(write=False)
        return cls(seg, blocked, obstacle, boxes_blocked, boxes_obstacle, float(stamp),
                   geometry)

    def query(self, x: float, y: float) -> tuple[float, int, float, float, float]:
        """(clearance, what limits it, obstacle distance, obstacle x, obstacle y)."""
        return query_one(float(x), float(y), self.segmentation.state, self.nearest_blocked,
                         self.nearest_obstacle, self.boxes_blocked, self.boxes_obstacle,
                         self.geometry)

    def distances(self, points: np.ndarray, unknown_blocks: bool) -> np.ndarray:
        """Clearance (unknown_blocks) or obstacle distance of each (x, y) row."""
        xy = np.ascontiguousarray(np.asarray(points, dtype=np.float64)[:, :2])
        out = np.empty(len(xy))
        query_points(xy, self.segmentation.state, self.nearest_blocked, self.nearest_obstacle,
                     self.boxes_blocked, self.boxes_obstacle, self.geometry, unknown_blocks,
                     out)
        return out


class ObstacleMap:
    """The controller's view: the latest snapshot, with staleness and fault handling.

    max_age: seconds after the newest scan's stamp beyond which answers are STALE;
    clock: the time source, in the same clock as the scan stamps.
    """

    def __init__(self, robot: RobotShape | None = None, max_age: float = 1.0,
                 clock: Callable[[], float] = time.monotonic,
                 floor_params: FloorParams | None = None,
                 fallback_floor: float | None = None) -> None:
        if not (math.isfinite(max_age) and max_age > 0):
            raise MapError(f"ObstacleMap.max_age: expected a finite number > 0, got {max_age}")
        self.robot = robot or RobotShape()
        self.max_age = float(max_age)
        self.clock = clock
        self.floor_params = floor_params
        self.fallback_floor = fallback_floor
        self._snapshot: ObstacleSnapshot | None = None
        self._fault: str | None = None
        self._update_lock = threading.Lock()

    # -- mapper side -------------------------------------------------------------------
    def update(self, grid: HeightGrid, bounds: tuple[float, float, float, float] | None = None,
               ) -> ObstacleSnapshot:
        """Segment the grid (inside bounds, default all of it), build and publish a snapshot."""
        with self._update_lock:
            seg = segment(grid.layers(bounds), self.robot, self.floor_params,
                          self.fallback_floor)
            snapshot = ObstacleSnapshot.from_segmentation(seg, grid.stamp)
            self._snapshot = snapshot
        return snapshot

    def publish(self, snapshot: ObstacleSnapshot) -> None:
        """Make `snapshot` the one queries see."""
        self._snapshot = snapshot

    def set_fault(self, reason: str) -> None:
        """Mark the sensor faulted: every query reports FAULTED and no clearance."""
        self._fault = str(reason) or "fault"

    def clear_fault(self) -> None:
        """The sensor works again."""
        self._fault = None

    @property
    def fault(self) -> str | None:
        """The fault reason, or None."""
        return self._fault

    @property
    def snapshot(self) -> ObstacleSnapshot | None:
        """The snapshot queries currently see."""
        return self._snapshot

    # -- controller side ---------------------------------------------------------------
    def _usable(self) -> tuple[ObstacleSnapshot | None, float, Status]:
        """The snapshot to answer from (None when it must not be used), its age, status."""
        snap = self._snapshot
        if snap is None:
            return None, math.inf, Status.UNKNOWN
        age = self.clock() - snap.stamp
        if self._fault is not None:
            return None, age, Status.FAULTED
        if not age <= self.max_age:  # also NaN
            return None, age, Status.STALE
        return snap, age, Status.OK

    def nearest(self, x: float, y: float) -> Nearest:
        """The nearest obstacle to (x, y) in map, and the known free clearance there."""
        snap, age, status = self._usable()
        if snap is None:
            return Nearest(0.0, math.nan, (math.nan, math.nan), 0.0, age, status)
        clearance, kind, d, px, py = snap.query(x, y)
        bearing = math.atan2(py - y, px - x) if 0.0 < d < math.inf else math.nan
        return Nearest(d, bearing, (px, py), clearance, age,
                       Status.OK if kind == OBSTACLE else Status.UNKNOWN)

    def _distances(self, points: np.ndarray, unknown_blocks: bool) -> np.ndarray:
        xy = np.asarray(points, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] < 2:
            raise MapError(f"ObstacleMap.distance: points must be (N, 2), got {xy.shape}")
        snap, _, _ = self._usable()
        if snap is None or not len(xy):
            return np.zeros(len(xy))
        return snap.distances(xy, unknown_blocks)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Metres of known free space around each (x, y) row of points (N, 2+): the distance
        to the nearest obstacle or unknown cell, 0 inside them and when the data are stale,
        faulted or absent. What a controller may rely on."""
        return self._distances(points, unknown_blocks=True)

    def obstacle_distance(self, points: np.ndarray) -> np.ndarray:
        """Metres from each (x, y) row to the nearest obstacle, ignoring unknown space (inf
        when there is none): for planners and evaluation, not a safety clearance."""
        return self._distances(points, unknown_blocks=False)

    def polar(self, x: float, y: float, yaw: float, bins: int = 360,
              max_range: float = 4.0) -> PolarScan:
        """Virtual range scan around (x, y): bin b covers robot-frame angles
        -pi + [b, b+1) * 2 pi / bins; stale or faulted data give zero ranges."""
        if not (isinstance(bins, int) and bins > 0):
            raise MapError(f"ObstacleMap.polar: bins must be a positive integer, got {bins!r}")
        angles = -math.pi + (np.arange(bins) + 0.5) * (2 * math.pi / bins)
        ranges = np.zeros(bins)
        kinds = np.full(bins, UNKNOWN, np.uint8)
        snap, age, status = self._usable()
        if snap is not None:
            s = snap.segmentation
            polar_kernel(float(x), float(y), float(yaw), float(max_range), s.state,
                         snap.boxes_blocked,
                         snap.geometry, ranges, kinds)
            status = Status.UNKNOWN if (kinds == UNKNOWN).any() else Status.OK
        return PolarScan(angles, ranges, kinds, age, status)

    def clearance(self, pose: tuple[float, float, float],
                  footprint: float | np.ndarray | None = None) -> Clearance:
        """Does the footprint at pose (x, y, yaw) touch non-free space, and by what margin.

        footprint: a circle radius (m), a polygon (K, 2) in base_link, or None for the
        robot's circle. Status UNKNOWN when the margin is limited by unknown space.
        """
        snap, age, status = self._usable()
        if snap is None:
            return Clearance(True, 0.0, age, status)
        x, y, yaw = map(float, pose)
        fp = self.robot.radius if footprint is None else footprint
        d, kind, _, _, _ = snap.query(x, y)
        if np.ndim(fp) == 0:
            margin = d - float(fp)
        else:
            polygon = np.asarray(fp, dtype=np.float64)
            if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3:
                raise MapError(f"ObstacleMap.clearance: footprint polygon must be (K>=3, 2), "
                               f"got {polygon.shape}")
            c, s = math.cos(yaw), math.sin(yaw)
            in_map = polygon @ np.array([[c, s], [-s, c]]) + (x, y)
            reach = float(np.hypot(*(in_map - (x, y)).T).max())
            s_ = snap.segmentation
            margin, kind = polygon_margin(in_map, d + reach, s_.state, s_.points,
                                          snap.geometry)
        return Clearance(bool(margin <= 0.0), float(margin), age,
                         Status.OK if kind in (OBSTACLE, FREE) else Status.UNKNOWN)
