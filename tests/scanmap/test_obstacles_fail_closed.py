"""The obstacle queries fail closed: driven with arbitrary floats (NaN, +-inf, subnormals,
1e300), no answer ever grants more clearance than the exact geometry of a small map
allows, and a pose that is not a pose gets no clearance and a status that is not OK.

The reference is brute force over the cells of the map: obstacle cells are their
measured points, unknown cells their squares, and everything beyond the window unknown.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from scanmap.navigation.floor import FREE, OBSTACLE, UNKNOWN, RobotShape, Segmentation
from scanmap.navigation.obstacles import (
    COORDINATE_LIMIT,
    ObstacleMap,
    ObstacleSnapshot,
    QueryStatus,
)
from scanmap_driver.errors import MapError

RES = 0.1
ORIGIN = (-0.6, -0.5)
EPS = 1e-9  # float64 rounding of the kernels' arithmetic

# Any float (NaN, +-inf, subnormals, 1e300 included), and often one near the map.
coordinates = st.one_of(st.floats(-1.5, 1.5), st.floats(),
                        st.sampled_from([math.nan, math.inf, -math.inf, 1e300, 5e-324]))


@st.composite
def obstacle_maps(draw) -> ObstacleMap:
    """A window of up to 10 x 10 cells, each unknown, free or an obstacle whose measured
    point lies anywhere in its cell, published to a map whose data are fresh."""
    ny, nx = draw(st.integers(2, 10)), draw(st.integers(2, 10))
    state = draw(hnp.arrays(np.uint8, (ny, nx),
                            elements=st.sampled_from([UNKNOWN, FREE, FREE, FREE, OBSTACLE])))
    offset = draw(hnp.arrays(np.float64, (ny, nx, 2), elements=st.floats(0.0, 1.0)))
    cells = np.stack(np.meshgrid(np.arange(nx), np.arange(ny)), axis=-1)
    points = (np.asarray(ORIGIN) + (cells + offset) * RES).astype(np.float32)
    robot = RobotShape()
    seg = Segmentation(origin=ORIGIN, resolution=RES, robot=robot,
                       floor_height=np.zeros((ny, nx), np.float32), is_floor=state == FREE,
                       planes=(), state=state, points=points,
                       band_logodds=np.ones((ny, nx), np.float32), updated=np.zeros((ny, nx)))
    obstacles = ObstacleMap(robot, max_age=1.0, clock=lambda: 0.0)
    obstacles.publish(ObstacleSnapshot.from_segmentation(seg, 0.0))
    return obstacles


def valid(*values: float) -> bool:
    return all(math.isfinite(v) and abs(v) <= COORDINATE_LIMIT for v in values)


def blockers(obstacles: ObstacleMap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Obstacle points (n, 2), unknown squares (m, 4: x lo, y lo, x hi, y hi), window box."""
    seg = obstacles.snapshot.segmentation
    ny, nx = seg.shape
    rows, cols = np.nonzero(seg.state == OBSTACLE)
    points = seg.points[rows, cols].astype(np.float64)
    rows, cols = np.nonzero(seg.state == UNKNOWN)
    lo = np.column_stack([ORIGIN[0] + cols * RES, ORIGIN[1] + rows * RES])
    window = np.array([ORIGIN[0], ORIGIN[1], ORIGIN[0] + nx * RES, ORIGIN[1] + ny * RES])
    return points, np.hstack([lo, lo + RES]), window


def exact_distances(obstacles: ObstacleMap, q: np.ndarray) -> tuple[float, float]:
    """(Clearance: distance from q to the nearest thing not known free, 0 in it; distance
    from q to the nearest obstacle point, inf without any)."""
    points, squares, window = blockers(obstacles)
    obstacle = float(np.hypot(*(points - q).T).min(initial=math.inf))
    if not (window[:2] <= q).all() or not (q < window[2:]).all():
        return 0.0, obstacle
    gap = np.clip(q, squares[:, :2], squares[:, 2:]) - q
    unknown = float(np.hypot(*gap.T).min(initial=math.inf))
    edge = float(min(q[0] - window[0], window[2] - q[0], q[1] - window[1], window[3] - q[1]))
    return min(obstacle, unknown, edge), obstacle


@settings(max_examples=400, deadline=None)
@given(obstacles=obstacle_maps(), x=coordinates, y=coordinates)
def test_point_queries_never_exceed_the_exact_clearance(obstacles, x, y):
    near = obstacles.nearest(x, y)
    batch = obstacles.distance(np.array([[x, y]]))[0]
    to_obstacle = obstacles.obstacle_distance(np.array([[x, y]]))[0]
    if not valid(x, y):
        assert near.status == QueryStatus.INVALID
        assert near.clearance == near.distance == batch == to_obstacle == 0.0
        return
    clearance, obstacle = exact_distances(obstacles, np.array([x, y]))
    assert near.clearance <= clearance + EPS and batch <= clearance + EPS
    assert near.clearance == batch
    assert near.distance == to_obstacle and to_obstacle <= obstacle + EPS
    assert near.status in (QueryStatus.OK, QueryStatus.UNKNOWN)
    assert near.clearance <= near.distance


@settings(max_examples=150, deadline=None)
@given(obstacles=obstacle_maps(),
       rows=hnp.arrays(np.float64, st.tuples(st.integers(1, 30), st.just(2)),
                       elements=coordinates),
       valid_rows=hnp.arrays(np.float64, st.tuples(st.integers(1, 30), st.just(2)),
                             elements=st.floats(-1.5, 1.5)))
def test_a_bad_row_in_a_batch_changes_no_other_row(obstacles, rows, valid_rows):
    mixed = np.vstack([valid_rows, rows])
    ok = np.array([valid(x, y) for x, y in mixed])
    for query in (obstacles.distance, obstacles.obstacle_distance):
        got = query(mixed)
        np.testing.assert_array_equal(got[: len(valid_rows)], query(valid_rows))
        assert (got[~ok] == 0.0).all()
        np.testing.assert_array_equal(got[ok], query(mixed[ok]))


@settings(max_examples=300, deadline=None)
@given(obstacles=obstacle_maps(), x=coordinates, y=coordinates, yaw=coordinates,
       radius=st.floats(0.0, 1.0))
def test_a_circle_footprint_never_clears_more_than_the_geometry(obstacles, x, y, yaw, radius):
    answer = obstacles.clearance((x, y, yaw), radius)
    if not valid(x, y, yaw):
        assert answer.collision and answer.status == QueryStatus.INVALID
        return
    clearance, _ = exact_distances(obstacles, np.array([x, y]))
    assert answer.margin <= clearance - radius + EPS
    assert answer.collision == (answer.margin <= 0.0)
    if clearance <= radius:
        assert answer.collision


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance from point p to the segment a-b."""
    e = b - a
    t = 0.0 if not e.any() else float(np.clip((p - a) @ e / (e @ e), 0.0, 1.0))
    return float(np.hypot(*(p - a - t * e)))


def contains(polygon: np.ndarray, p: np.ndarray) -> bool:
    """Even-odd rule: is p inside the simple polygon (K, 2)?"""
    inside = False
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        if (a[1] > p[1]) != (b[1] > p[1]):
            inside ^= bool(p[0] < a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]))
    return inside


def segments_cross(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> bool:
    def side(p, q, r):
        return np.sign((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))
    return side(a, b, c) * side(a, b, d) <= 0 and side(c, d, a) * side(c, d, b) <= 0


def polygon_gap(polygon: np.ndarray, other: np.ndarray) -> float:
    """Exact distance between two simple polygons, 0 when they touch or overlap."""
    edges = list(zip(polygon, np.roll(polygon, -1, axis=0), strict=True))
    others = list(zip(other, np.roll(other, -1, axis=0), strict=True))
    if contains(polygon, other[0]) or contains(other, polygon[0]) or any(
            segments_cross(a, b, c, d) for a, b in edges for c, d in others):
        return 0.0
    return min(min(segment_distance(p, a, b) for p in other for a, b in edges),
               min(segment_distance(p, c, d) for p in polygon for c, d in others))


def exact_polygon_margin(obstacles: ObstacleMap, polygon: np.ndarray) -> float:
    """Signed distance from the polygon (in map) to what is not known free: negative by
    the depth of an obstacle point inside, 0 when it touches an unknown cell or leaves
    the window."""
    points, squares, window = blockers(obstacles)
    edges = list(zip(polygon, np.roll(polygon, -1, axis=0), strict=True))
    margins = [math.inf]
    for p in points:
        d = min(segment_distance(p, a, b) for a, b in edges)
        margins.append(-d if contains(polygon, p) else d)
    for x0, y0, x1, y1 in squares:
        margins.append(polygon_gap(polygon, np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])))
    margins.append(float(min((polygon[:, :2] - window[:2]).min(),
                             (window[2:] - polygon[:, :2]).min())))
    return min(margins)


@settings(max_examples=200, deadline=None)
@given(obstacles=obstacle_maps(), x=coordinates, y=coordinates, yaw=coordinates,
       radii=st.lists(st.floats(0.02, 0.5), min_size=3, max_size=7),
       turns=st.lists(st.floats(0.05, 1.0), min_size=7, max_size=7))
def test_a_polygon_footprint_never_clears_more_than_the_geometry(obstacles, x, y, yaw, radii,
                                                                 turns):
    """Star-shaped polygons (vertices in angular order): simple, convex or not."""
    angles = np.cumsum(turns[: len(radii)])
    angles *= 2 * math.pi / (angles[-1] + turns[len(radii) - 1])
    polygon = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    answer = obstacles.clearance((x, y, yaw), polygon)
    if not valid(x, y, yaw):
        assert answer.collision and answer.status == QueryStatus.INVALID
        return
    c, s = math.cos(yaw), math.sin(yaw)
    in_map = polygon @ np.array([[c, s], [-s, c]]) + (x, y)
    exact = exact_polygon_margin(obstacles, in_map)
    assert answer.margin <= exact + EPS
    assert answer.collision == (answer.margin <= 0.0)
    if exact <= 0.0:
        assert answer.collision


def samples(obstacles: ObstacleMap) -> np.ndarray:
    """Points of everything not known free: obstacle points, a 5 x 5 lattice over each
    unknown square, and the window's edge every 5 mm."""
    points, squares, window = blockers(obstacles)
    t = np.linspace(0.0, 1.0, 5)
    u, v = (a.ravel() for a in np.meshgrid(t, t))
    lattice = [np.column_stack([x0 + u * (x1 - x0), y0 + v * (y1 - y0)])
               for x0, y0, x1, y1 in squares]
    x0, y0, x1, y1 = window
    sx = np.linspace(x0, x1, int((x1 - x0) / 0.005) + 1)
    sy = np.linspace(y0, y1, int((y1 - y0) / 0.005) + 1)
    edge = np.vstack([np.column_stack([sx, np.full_like(sx, y0)]),
                      np.column_stack([sx, np.full_like(sx, y1)]),
                      np.column_stack([np.full_like(sy, x0), sy]),
                      np.column_stack([np.full_like(sy, x1), sy])])
    return np.vstack([points, *lattice, edge])


@settings(max_examples=200, deadline=None)
@given(obstacles=obstacle_maps(), x=coordinates, y=coordinates, yaw=coordinates,
       bins=st.integers(4, 90), max_range=st.floats(0.05, 2.0))
def test_a_polar_scan_never_sees_past_what_is_not_free(obstacles, x, y, yaw, bins,
                                                       max_range):
    scan = obstacles.polar(x, y, yaw, bins=bins, max_range=max_range)
    if not valid(x, y, yaw):
        assert scan.status == QueryStatus.INVALID and (scan.ranges == 0.0).all()
        return
    rel = samples(obstacles) - (x, y)
    r = np.hypot(*rel.T)
    near = (r <= max_range) & (r > 1e-9)
    bearing = np.arctan2(rel[near, 1], rel[near, 0]) - yaw

    def ranges_at(angle: np.ndarray) -> np.ndarray:
        b = np.floor(((angle + math.pi) % (2 * math.pi)) / (2 * math.pi / bins)).astype(int)
        return scan.ranges[b % bins]

    # A bin's sector is closed: a point on a boundary (to rounding) may end either bin.
    seen = np.minimum(ranges_at(bearing - EPS), ranges_at(bearing + EPS))
    assert (seen <= r[near] + EPS).all()
    clearance, _ = exact_distances(obstacles, np.array([x, y]))
    if scan.status == QueryStatus.OK:
        assert clearance > 0.0


@pytest.mark.parametrize("call", [
    lambda m: m.clearance((0.0, 0.0, 0.0), math.nan),
    lambda m: m.clearance((0.0, 0.0, 0.0), -0.1),
    lambda m: m.clearance((0.0, 0.0, 0.0), math.inf),
    lambda m: m.clearance((0.0, 0.0, 0.0), [[math.nan, 0.0], [1.0, 0.0], [0.0, 1.0]]),
    lambda m: m.clearance((0.0, 0.0, 0.0), [[1e300, 0.0], [1.0, 0.0], [0.0, 1.0]]),
    lambda m: m.clearance((0.0, 0.0), 0.2),
    lambda m: m.polar(0.0, 0.0, 0.0, max_range=math.nan),
    lambda m: m.polar(0.0, 0.0, 0.0, max_range=-1.0),
    lambda m: m.polar(0.0, 0.0, 0.0, max_range=math.inf),
    lambda m: m.polar(0.0, 0.0, 0.0, bins=True),
    lambda m: m.distance(np.zeros(3)),
])
def test_malformed_arguments_are_a_clear_error(call):
    obstacles = ObstacleMap(RobotShape(), max_age=1.0, clock=lambda: 0.0)
    with pytest.raises(MapError):
        call(obstacles)


def spread_over_bins(obstacles: ObstacleMap, x: float, y: float, yaw: float, bins: int,
                     max_range: float) -> np.ndarray:
    """Brute-force polar ranges: the window's edge (the kernel on the same window with
    every cell free), then every blocked cell within max_range, in no particular order,
    lowering each bin its square subtends to the cell's distance."""
    snap = obstacles.snapshot
    state = snap.segmentation.state
    edge = ObstacleMap(obstacles.robot, max_age=1.0, clock=lambda: 0.0)
    free = dataclasses.replace(snap.segmentation, state=np.full_like(state, FREE))
    edge.publish(ObstacleSnapshot.from_segmentation(free, 0.0))
    ranges = edge.polar(x, y, yaw, bins=bins, max_range=max_range).ranges.copy()
    width, half_diag = 2 * math.pi / bins, RES * math.sqrt(0.5)
    nx = state.shape[1]
    for row, col in np.argwhere(state != FREE):
        box = snap.boxes[(row + 1) * (nx + 2) + col + 1]
        r = math.hypot(min(max(x, box[0]), box[2]) - x, min(max(y, box[1]), box[3]) - y)
        if r > max_range:
            continue
        cx, cy = ORIGIN[0] + (col + 0.5) * RES - x, ORIGIN[1] + (row + 0.5) * RES - y
        rc = math.hypot(cx, cy)
        spread = math.pi if rc <= half_diag else math.asin(half_diag / rc)
        centre = math.atan2(cy, cx) - math.remainder(yaw, 2 * math.pi) + math.pi
        for b in range(math.floor((centre - spread) / width),
                       math.floor((centre + spread) / width) + 1):
            ranges[b % bins] = min(ranges[b % bins], r)
    return ranges


@settings(max_examples=200, deadline=None)
@given(obstacles=obstacle_maps(), x=st.floats(-0.6, 0.39), y=st.floats(-0.5, 0.49),
       yaw=st.floats(-4.0, 4.0), bins=st.integers(4, 90), max_range=st.floats(0.05, 2.0))
def test_the_polar_scan_stops_its_rings_only_where_nothing_nearer_remains(
        obstacles, x, y, yaw, bins, max_range):
    """The kernel visits cells ring by ring and stops early: its ranges equal the
    brute-force spread of every blocked cell (to the last bits: the kernel's distance and
    math.hypot may round differently; a cell missed by stopping early is 5 cm off)."""
    scan = obstacles.polar(x, y, yaw, bins=bins, max_range=max_range)
    expected = spread_over_bins(obstacles, x, y, yaw, bins, max_range)
    np.testing.assert_allclose(scan.ranges, expected, rtol=1e-12, atol=0)
