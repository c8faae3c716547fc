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
def cell_boxes(state, points, geo) -> tuple[np.ndarray, np.ndarray]:
    """What distances are measured to, one record per cell of the window grown by a border
    of one cell (flat, row-major: cell (y, x) is record (y + 1) * (nx + 2) + x + 1), +inf
    on the border and where there is nothing (a query's distance to it is infinite):
    boxes (x lo, y lo, x hi, y hi) of the cells not known free (an obstacle cell's
    measured point, an unknown cell's square), and the obstacle cells' points (x, y)."""
    ny, nx = state.shape
    width = nx + 2
    boxes = np.full(((ny + 2) * width, 4), np.inf)
    obstacle_points = np.full(((ny + 2) * width, 2), np.inf)
    for y in range(ny):
        for x in range(nx):
            b = (y + 1) * width + x + 1
            if state[y, x] == OBSTACLE:
                boxes[b, 0] = boxes[b, 2] = obstacle_points[b, 0] = points[y, x, 0]
                boxes[b, 1] = boxes[b, 3] = obstacle_points[b, 1] = points[y, x, 1]
            elif state[y, x] == UNKNOWN:
                boxes[b, 0] = geo[0] + x * geo[2]
                boxes[b, 1] = geo[1] + y * geo[2]
                boxes[b, 2] = boxes[b, 0] + geo[2]
                boxes[b, 3] = boxes[b, 1] + geo[2]
    return boxes, obstacle_points


@njit(cache=True, nogil=True, inline="always")
def _clamp(q: float, lo: float, hi: float) -> float:
    return min(max(q, lo), hi)


@njit(cache=True, nogil=True, inline="always")
def _nearest_box(qx, qy, boxes, k, width):
    """Squared distance from (qx, qy) to the nearest of the 3 x 3 boxes around record k
    (never on the border), and that box's record (-1 when all are infinite). Compiles
    to running minima, without branches to mispredict."""
    best, arg = np.inf, -1
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            j = k + dy * width + dx
            px = _clamp(qx, boxes[j, 0], boxes[j, 2]) - qx
            py = _clamp(qy, boxes[j, 1], boxes[j, 3]) - qy
            d = px * px + py * py
            if d < best:
                best, arg = d, j
    return best, arg


@njit(cache=True, nogil=True, inline="always")
def _nearest_point(qx, qy, points, k, width):
    """`_nearest_box` for points (x, y): half the loads and no clamping."""
    best, arg = np.inf, -1
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            j = k + dy * width + dx
            px, py = points[j, 0] - qx, points[j, 1] - qy
            d = px * px + py * py
            if d < best:
                best, arg = d, j
    return best, arg


@njit(cache=True, nogil=True, inline="always")
def _window_edge(qx, qy, ox, oy, xmax, ymax):
    """Distance from (qx, qy), inside the window [ox, xmax) x [oy, ymax), to its edge."""
    return min(qx - ox, xmax - qx, qy - oy, ymax - qy)


@njit(cache=True, nogil=True, inline="always")
def _cell_of(qx, qy, ox, oy, inv, nx, ny):
    """(column, row) of the window cell holding (qx, qy), or of the window's cell nearest
    it, and whether the window holds it. inv: 1 / resolution."""
    gx, gy = (qx - ox) * inv, (qy - oy) * inv
    inside = 0.0 <= gx < nx and 0.0 <= gy < ny  # False for NaN
    ix = min(max(int(min(max(gx, 0.0), nx - 1.0)), 0), nx - 1)
    iy = min(max(int(min(max(gy, 0.0), ny - 1.0)), 0), ny - 1)
    return ix, iy, inside


@njit(cache=True, nogil=True)
def query_one(qx, qy, state, nearest_blocked, nearest_obstacle, boxes, points, geo):
    """(clearance, kind of what limits it, obstacle distance, obstacle x, obstacle y).

    The obstacle distance is to the nearest measured obstacle point, refined over the
    3 x 3 cells around the obstacle field's nearest cell (from the window's nearest cell
    when the query is outside it). The clearance is the distance to the nearest thing not
    known free, refined likewise around the blocked field's nearest (0 in or beyond the
    window's unknown or occupied cells), and never more than the obstacle distance (the
    two refinements may settle on different cells).
    """
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    width = nx + 2
    ix, iy, inside = _cell_of(qx, qy, ox, oy, 1.0 / res, nx, ny)
    d2, px, py = np.inf, qx, qy
    k = nearest_obstacle[iy, ix]
    if k >= 0:
        d2, j = _nearest_point(qx, qy, points, k, width)
        if j >= 0:
            px, py = points[j, 0], points[j, 1]
    d = math.sqrt(d2)
    if not inside:
        return 0.0, UNKNOWN, d, px, py
    if state[iy, ix] != FREE:
        return 0.0, np.int64(state[iy, ix]), d, px, py
    edge = _window_edge(qx, qy, ox, oy, ox + nx * res, oy + ny * res)
    best, kind = edge * edge, UNKNOWN
    k = nearest_blocked[iy, ix]
    if k >= 0:
        c2, j = _nearest_box(qx, qy, boxes, k, width)
        if c2 < best:
            best, kind = c2, np.int64(state[j // width - 1, j % width - 1])
    clearance = math.sqrt(best)
    if d <= clearance:
        clearance, kind = d, OBSTACLE
    return clearance, kind, d, px, py


@njit(cache=True, nogil=True)
def query_points(xy, state, nearest_blocked, nearest_obstacle, boxes, points, geo,
                 unknown_blocks, out):
    """Clearance (unknown_blocks) or obstacle distance of each (x, y) row, as `query_one`.

    The loop touches no array object but the data (no reference counting), divides by
    nothing, and skips the obstacle refinement when the two fields name the same cell
    (the blocked one then covered the same obstacle points).
    """
    ox, oy, res, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    inv, xmax, ymax = 1.0 / res, ox + nx * res, oy + ny * res
    width = nx + 2
    for i in range(xy.shape[0]):
        qx, qy = xy[i, 0], xy[i, 1]
        ix, iy, inside = _cell_of(qx, qy, ox, oy, inv, nx, ny)
        if unknown_blocks and not (inside and state[iy, ix] == FREE):
            out[i] = 0.0
            continue
        best = np.inf
        k = nearest_obstacle[iy, ix]
        if unknown_blocks:
            edge = _window_edge(qx, qy, ox, oy, xmax, ymax)
            best = edge * edge
            blocked = nearest_blocked[iy, ix]
            if blocked >= 0:
                best = min(best, _nearest_box(qx, qy, boxes, blocked, width)[0])
            if blocked == k:
                k = -1
        if k >= 0:
            best = min(best, _nearest_point(qx, qy, points, k, width)[0])
        out[i] = math.sqrt(best)


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
            b = (y + 1) * (nx + 2) + x + 1
            r = math.hypot(_clamp(qx, boxes[b, 0], boxes[b, 2]) - qx,
                           _clamp(qy, boxes[b, 1], boxes[b, 3]) - qy)
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
    cells not known free, and over obstacle cells only; their nearest cells are records
    of `cell_boxes`), the boxes and obstacle points of `cell_boxes`, and the data time."""

    segmentation: Segmentation
    nearest_blocked: np.ndarray
    nearest_obstacle: np.ndarray
    boxes: np.ndarray
    points: np.ndarray
    stamp: float
    geometry: np.ndarray  # origin x, origin y, resolution, nx, ny

    @classmethod
    def from_segmentation(cls, seg: Segmentation, stamp: float) -> ObstacleSnapshot:
        """Build both distance fields and freeze every array."""
        _, blocked = distance_transform(seg.state != FREE, pad=1)
        _, obstacle = distance_transform(seg.state == OBSTACLE, pad=1)
        ny, nx = seg.shape
        geometry = np.array([seg.origin[0], seg.origin[1], seg.resolution, nx, ny], np.float64)
        boxes, points = cell_boxes(seg.state, seg.points, geometry)
        for array in (seg.state, seg.points, seg.floor_height, seg.is_floor, seg.band_logodds,
                      seg.updated, blocked, obstacle, boxes, points, geometry):
            array.setflags(write=False)
        return cls(seg, blocked, obstacle, boxes, points, float(stamp), geometry)

    def query(self, x: float, y: float) -> tuple[float, int, float, float, float]:
        """(clearance, what limits it, obstacle distance, obstacle x, obstacle y)."""
        return query_one(float(x), float(y), self.segmentation.state, self.nearest_blocked,
                         self.nearest_obstacle, self.boxes, self.points, self.geometry)

    def distances(self, points: np.ndarray, unknown_blocks: bool) -> np.ndarray:
        """Clearance (unknown_blocks) or obstacle distance of each (x, y) row."""
        xy = np.ascontiguousarray(np.asarray(points, dtype=np.float64)[:, :2])
        out = np.empty(len(xy))
        query_points(xy, self.segmentation.state, self.nearest_blocked, self.nearest_obstacle,
                     self.boxes, self.points, self.geometry, unknown_blocks, out)
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
                         snap.boxes,
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
