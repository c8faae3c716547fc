"""Obstacle queries for a controller: distance, nearest obstacle, virtual range scan, clearance,
free travel ahead.

A query never calls unknown space free, and a drop-off cell (DROP_OFF) counts as an
obstacle at its centre in every query. Two distance fields are kept: one over the
obstacle cells, one over every cell not known FREE (obstacles, unknown cells, and
beyond the window). Distances are exact: to measured surface points (the mean of the
hits in a cell) and unknown cells' squares, found by a search the fields bound. `distance()` and
a Nearest's `clearance` are radii of known free space - what a controller may rely on;
`obstacle_distance()` ignores unknown space, for planners and evaluation. QueryStatus:

* OK - the nearest thing not known free is an obstacle: clearance = obstacle distance.
* UNKNOWN - unknown space is nearer than any obstacle (or the query is in it): the
  clearance is how far the space is known free, 0 inside unknown space.
* STALE - the newest data are older than `max_age`; FAULTED - the sensor is faulted.
  Both report no clearance at all: distance and clearance 0, collision.
* INVALID - the pose is not finite or farther than COORDINATE_LIMIT from the map origin
  (an upstream filter diverged): no clearance either. A batch row of that kind gets 0
  and leaves the other rows alone. Malformed arguments (footprint, bins, max_range)
  raise MapError.

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

from scanmap.grid.height_grid import HeightGrid
from scanmap.navigation import _kernels as nk
from scanmap.navigation.distance_field import distance_transform
from scanmap.navigation.floor import (
    DROP_OFF,
    FREE,
    OBSTACLE,
    UNKNOWN,
    FloorConfig,
    RobotShape,
    Segmentation,
    segment,
)
from scanmap_driver.errors import MapError

COORDINATE_LIMIT = nk.COORDINATE_LIMIT


def _valid(*values: float) -> bool:
    """Whether every value is a coordinate a query may take (False for NaN and inf)."""
    return all(-COORDINATE_LIMIT <= v <= COORDINATE_LIMIT for v in values)


def _footprint(footprint: float | np.ndarray) -> float | np.ndarray:
    """A circle radius (float) or polygon (K, 2) of finite, bounded numbers; else MapError."""
    if np.ndim(footprint) == 0:
        radius = float(footprint)
        if not 0.0 <= radius <= COORDINATE_LIMIT:
            raise MapError(f"ObstacleMap.clearance: footprint radius must be a finite number "
                           f">= 0, got {footprint}")
        return radius
    polygon = np.asarray(footprint, dtype=np.float64)
    if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3:
        raise MapError(f"ObstacleMap.clearance: footprint polygon must be (K>=3, 2), "
                       f"got {polygon.shape}")
    if not (np.abs(polygon) <= COORDINATE_LIMIT).all():
        raise MapError("ObstacleMap.clearance: footprint polygon vertices must be finite")
    return polygon


class QueryStatus(enum.IntEnum):
    """How far an answer can be trusted (see the module docstring)."""

    OK = 0
    UNKNOWN = 1
    STALE = 2
    FAULTED = 3
    INVALID = 4


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
    status: QueryStatus
    stamp: float = math.nan  # the data time of the snapshot answered from (NaN: none)


@dataclass(frozen=True, eq=False)
class PolarScan:
    """A virtual 360 deg range scan: ranges (m, inf when free up to max_range) per bin
    centred at angles (rad, robot frame), what ends each bin (OBSTACLE/UNKNOWN/FREE)."""

    angles: np.ndarray
    ranges: np.ndarray
    kinds: np.ndarray
    age: float
    status: QueryStatus
    stamp: float = math.nan  # the data time of the snapshot answered from (NaN: none)


@dataclass(frozen=True)
class Clearance:
    """Whether the footprint touches non-free space, and the margin (m) to it."""

    collision: bool
    margin: float
    age: float
    status: QueryStatus
    stamp: float = math.nan  # the data time of the snapshot answered from (NaN: none)


@dataclass(frozen=True)
class Travel:
    """How far (m) the footprint can drive straight ahead before it touches space not
    known free, and what it touches (status UNKNOWN: unknown space; OK: an obstacle, a
    drop-off, or nothing within the distance asked)."""

    distance: float
    kind: int  # the cell state it touches (FREE: nothing within the distance asked)
    age: float
    status: QueryStatus
    stamp: float = math.nan  # the data time of the snapshot answered from (NaN: none)


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
        solid = np.where(seg.state == DROP_OFF, OBSTACLE, seg.state).astype(seg.state.dtype)
        _, blocked = distance_transform(solid != FREE, pad=1)
        _, obstacle = distance_transform(solid == OBSTACLE, pad=1)
        ny, nx = seg.shape
        geometry = np.array([seg.origin[0], seg.origin[1], seg.resolution, nx, ny], np.float64)
        boxes, points = nk.cell_boxes(solid, seg.points, geometry)
        for array in (seg.state, seg.points, seg.floor_height, seg.is_floor, seg.band_logodds,
                      seg.updated, blocked, obstacle, boxes, points, geometry):
            array.setflags(write=False)
        return cls(seg, blocked, obstacle, boxes, points, float(stamp), geometry)

    def query(self, x: float, y: float) -> tuple[float, int, float, float, float]:
        """(clearance, what limits it, obstacle distance, obstacle x, obstacle y)."""
        return nk.query_one(float(x), float(y), self.segmentation.state, self.nearest_blocked,
                         self.nearest_obstacle, self.boxes, self.points, self.geometry)

    def distances(self, points: np.ndarray, unknown_blocks: bool) -> np.ndarray:
        """Clearance (unknown_blocks) or obstacle distance of each (x, y) row."""
        xy = np.ascontiguousarray(np.asarray(points, dtype=np.float64)[:, :2])
        out = np.empty(len(xy))
        nk.query_points(xy, self.segmentation.state, self.nearest_blocked, self.nearest_obstacle,
                     self.boxes, self.points, self.geometry, unknown_blocks, out)
        return out


class ObstacleMap:
    """The controller's view: the latest snapshot, with staleness and fault handling.

    max_age: seconds after the newest scan's stamp beyond which answers are STALE;
    clock: the time source, in the same clock as the scan stamps.
    """

    def __init__(self, robot: RobotShape | None = None, max_age: float = 1.0,
                 clock: Callable[[], float] = time.monotonic,
                 floor_params: FloorConfig | None = None,
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
    def _usable(self) -> tuple[ObstacleSnapshot | None, float, QueryStatus]:
        """The snapshot to answer from (None when it must not be used), its age, status."""
        snap = self._snapshot
        if snap is None:
            return None, math.inf, QueryStatus.UNKNOWN
        age = self.clock() - snap.stamp
        if self._fault is not None:
            return None, age, QueryStatus.FAULTED
        if not age <= self.max_age:  # also NaN
            return None, age, QueryStatus.STALE
        return snap, age, QueryStatus.OK

    def nearest(self, x: float, y: float) -> Nearest:
        """The nearest obstacle to (x, y) in map, and the known free clearance there."""
        x, y = float(x), float(y)
        snap, age, status = self._usable()
        if snap is None or not (-COORDINATE_LIMIT <= x <= COORDINATE_LIMIT
                                and -COORDINATE_LIMIT <= y <= COORDINATE_LIMIT):
            return Nearest(0.0, math.nan, (math.nan, math.nan), 0.0, age,
                           status if snap is None else QueryStatus.INVALID)
        clearance, kind, d, px, py = snap.query(x, y)
        bearing = math.atan2(py - y, px - x) if 0.0 < d < math.inf else math.nan
        return Nearest(d, bearing, (px, py), clearance, age,
                       QueryStatus.OK if kind in (OBSTACLE, DROP_OFF) else QueryStatus.UNKNOWN,
                       snap.stamp)

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
        to the nearest obstacle or unknown cell, 0 inside them, for an invalid row, and
        when the data are stale, faulted or absent. What a controller may rely on."""
        return self._distances(points, unknown_blocks=True)

    def obstacle_distance(self, points: np.ndarray) -> np.ndarray:
        """Metres from each (x, y) row to the nearest obstacle, ignoring unknown space (inf
        when there is none; 0 for an invalid row and without usable data): for planners
        and evaluation, not a safety clearance."""
        return self._distances(points, unknown_blocks=False)

    def polar(self, x: float, y: float, yaw: float, bins: int = 360,
              max_range: float = 4.0) -> PolarScan:
        """Virtual range scan around (x, y): bin b covers robot-frame angles
        -pi + [b, b+1) * 2 pi / bins; stale, faulted or absent data and an invalid pose give
        zero ranges. max_range: metres, finite and > 0."""
        if not (isinstance(bins, int) and not isinstance(bins, bool) and bins > 0):
            raise MapError(f"ObstacleMap.polar: bins must be a positive integer, got {bins!r}")
        max_range = float(max_range)
        if not 0.0 < max_range <= COORDINATE_LIMIT:
            raise MapError(f"ObstacleMap.polar: max_range must be a finite number > 0, "
                           f"got {max_range}")
        x, y, yaw = float(x), float(y), float(yaw)
        angles = -math.pi + (np.arange(bins) + 0.5) * (2 * math.pi / bins)
        ranges = np.zeros(bins)
        kinds = np.full(bins, UNKNOWN, np.uint8)
        snap, age, status = self._usable()
        if snap is not None and not _valid(x, y, yaw):
            status = QueryStatus.INVALID
        elif snap is not None:
            s = snap.segmentation
            nk.polar_kernel(x, y, math.remainder(yaw, 2 * math.pi), max_range, s.state,
                            snap.boxes, snap.geometry, ranges, kinds)
            status = QueryStatus.UNKNOWN if (kinds == UNKNOWN).any() else QueryStatus.OK
        return PolarScan(angles, ranges, kinds, age, status,
                         math.nan if snap is None else snap.stamp)

    def travel(self, pose: tuple[float, float, float], max_distance: float = 2.0) -> Travel:
        """How far the robot's circle at pose (x, y, yaw) can drive straight along yaw
        before it touches a cell not known free (its square: obstacles count by their
        cells here, not their measured points), up to max_distance (m, finite, > 0): the
        path a controller is about to take, where `nearest` also counts what lies beside
        it. 0 when it touches one already; 0 for stale, faulted or absent data and an
        invalid pose."""
        try:
            x, y, yaw = map(float, pose)
        except (TypeError, ValueError):
            raise MapError(f"ObstacleMap.travel: pose must be (x, y, yaw), got {pose!r}"
                           ) from None
        max_distance = float(max_distance)
        if not 0.0 < max_distance <= COORDINATE_LIMIT:
            raise MapError(f"ObstacleMap.travel: max_distance must be a finite number > 0, "
                           f"got {max_distance}")
        snap, age, status = self._usable()
        if snap is None or not _valid(x, y, yaw):
            return Travel(0.0, UNKNOWN, age, status if snap is None else QueryStatus.INVALID)
        distance, kind = nk.travel_kernel(x, y, math.remainder(yaw, 2 * math.pi),
                                          self.robot.radius, max_distance,
                                          snap.segmentation.state, snap.geometry)
        return Travel(float(distance), int(kind), age,
                      QueryStatus.UNKNOWN if kind == UNKNOWN else QueryStatus.OK, snap.stamp)

    def clearance(self, pose: tuple[float, float, float],
                  footprint: float | np.ndarray | None = None) -> Clearance:
        """Does the footprint at pose (x, y, yaw) touch non-free space, and by what margin.

        footprint: a circle radius (m), a polygon (K, 2) in base_link, or None for the
        robot's circle. QueryStatus UNKNOWN when the margin is limited by unknown space.
        """
        try:
            x, y, yaw = map(float, pose)
        except (TypeError, ValueError):
            raise MapError(f"ObstacleMap.clearance: pose must be (x, y, yaw), got {pose!r}"
                           ) from None
        fp = _footprint(self.robot.radius if footprint is None else footprint)
        snap, age, status = self._usable()
        if snap is None or not _valid(x, y, yaw):
            return Clearance(True, 0.0, age, status if snap is None else QueryStatus.INVALID)
        d, kind, _, _, _ = snap.query(x, y)
        if isinstance(fp, float):
            margin = d - fp
        else:
            polygon = fp
            c, s = math.cos(yaw), math.sin(yaw)
            in_map = polygon @ np.array([[c, s], [-s, c]]) + (x, y)
            reach = float(np.hypot(*(in_map - (x, y)).T).max())
            s_ = snap.segmentation
            margin, kind = nk.polygon_margin(in_map, d + reach, s_.state, snap.points,
                                             snap.geometry)
        return Clearance(not margin > 0.0, float(margin), age,
                         QueryStatus.OK if kind in (OBSTACLE, DROP_OFF, FREE)
                         else QueryStatus.UNKNOWN, snap.stamp)
