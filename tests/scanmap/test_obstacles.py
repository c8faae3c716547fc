"""Obstacle queries: accuracy against the scene geometry, fail-safety, threads."""

from __future__ import annotations

import math
import threading

import cv2
import numpy as np
import pytest

from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation.floor import FREE, OBSTACLE, UNKNOWN, RobotShape, Segmentation
from scanmap.navigation.obstacles import ObstacleMap, ObstacleSnapshot, QueryStatus
from scanmap_driver.errors import MapError

from . import scenes as S

ROBOT = RobotShape(height=0.8)
BOUNDS = (-3.1, -3.1, 3.1, 3.1)


class Clock:
    """A settable clock for staleness tests."""

    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope="module")
def room():
    scene = S.furnished_room()
    grid = HeightGrid(GridConfig(extent=50.0))
    S.map_scene(scene, S.ROOM_POSES, grid)
    clock = Clock(grid.stamp + 0.5)
    obstacles = ObstacleMap(ROBOT, max_age=2.0, clock=clock)
    obstacles.update(grid, BOUNDS)
    return scene, grid, obstacles, clock


def free_queries(scene: S.Scene, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Random points in the room outside every band obstacle, with their true distance."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.9, 2.9, (n, 2))
    truth = S.truth_distance(scene, q[:, 0], q[:, 1], ROBOT.step_height, ROBOT.height)
    keep = truth > 0.02
    return q[keep], truth[keep]


def test_nearest_obstacle_distance_error_p95_under_3cm(room):
    scene, _, obstacles, _ = room
    q, truth = free_queries(scene, 20000)
    error = np.abs(obstacles.obstacle_distance(q) - truth)
    assert np.percentile(error, 95) < 0.03


def test_clearance_never_reaches_past_the_true_obstacle(room):
    scene, _, obstacles, _ = room
    q, truth = free_queries(scene, 20000, seed=1)
    clearance = obstacles.distance(q)
    assert (clearance <= truth + 0.03).all()
    assert (clearance <= obstacles.obstacle_distance(q) + 1e-9).all()


def test_single_queries_agree_with_the_vectorised_ones(room):
    scene, _, obstacles, _ = room
    q, _ = free_queries(scene, 200, seed=2)
    near = [obstacles.nearest(x, y) for x, y in q]
    np.testing.assert_allclose([n.clearance for n in near], obstacles.distance(q))
    np.testing.assert_allclose([n.distance for n in near], obstacles.obstacle_distance(q))
    for (x, y), n in zip(q, near, strict=True):
        assert n.status == (QueryStatus.OK if n.clearance == n.distance else QueryStatus.UNKNOWN)
        assert math.hypot(n.point[0] - x, n.point[1] - y) == pytest.approx(n.distance)
        assert math.atan2(n.point[1] - y, n.point[0] - x) == pytest.approx(n.bearing)


def reference_distances(snap: ObstacleSnapshot, q: np.ndarray) -> tuple[np.ndarray,
                                                                         np.ndarray]:
    """Clearance and obstacle distance of the queries, in numpy, by brute force: the
    nearest obstacle point, unknown cell square or window edge (0 outside the free cells),
    and the nearest obstacle point."""
    seg = snap.segmentation
    ny, nx = seg.shape
    rows, cols = np.nonzero(seg.state == UNKNOWN)
    lo = np.column_stack([seg.origin[0] + cols * seg.resolution,
                          seg.origin[1] + rows * seg.resolution])
    points = seg.points[seg.state == OBSTACLE].astype(np.float64)
    boxes = np.vstack([np.hstack([lo, lo + seg.resolution]), np.hstack([points, points])])
    clearance, obstacle = np.empty(len(q)), np.empty(len(q))
    for i in range(0, len(q), 100):  # chunks keep the (n, boxes, 2) arrays small
        p = q[i:i + 100, None, :]
        gap = np.clip(p, boxes[None, :, :2], boxes[None, :, 2:]) - p
        clearance[i:i + 100] = np.sqrt((gap ** 2).sum(-1).min(1))
        obstacle[i:i + 100] = np.sqrt(((p - points[None]) ** 2).sum(-1).min(1))
    grid = (q - seg.origin) * (1.0 / seg.resolution)
    inside = ((grid >= 0) & (grid < (nx, ny))).all(axis=1)
    ix = np.clip(grid[:, 0], 0, nx - 1).astype(int)
    iy = np.clip(grid[:, 1], 0, ny - 1).astype(int)
    x0, y0 = seg.origin
    edge = np.minimum.reduce([q[:, 0] - x0, x0 + nx * seg.resolution - q[:, 0],
                              q[:, 1] - y0, y0 + ny * seg.resolution - q[:, 1]])
    free = inside & (seg.state[iy, ix] == FREE)
    return np.where(free, np.minimum(clearance, edge), 0.0), obstacle


def test_distance_kernels_are_exact(room):
    _, _, obstacles, _ = room
    rng = np.random.default_rng(4)
    q = np.vstack([rng.uniform(-3.5, 3.5, (3000, 2)),  # some beyond the window
                   np.round(rng.uniform(-3.0, 3.0, (500, 2)) / 0.05) * 0.05])  # on edges
    clearance, obstacle = reference_distances(obstacles.snapshot, q)
    np.testing.assert_allclose(obstacles.distance(q), clearance, rtol=0, atol=1e-7)
    np.testing.assert_allclose(obstacles.obstacle_distance(q), obstacle, rtol=0, atol=1e-7)
    single = np.array([obstacles.nearest(x, y).clearance for x, y in q[::10]])
    np.testing.assert_allclose(single, clearance[::10], rtol=0, atol=1e-7)


def test_unknown_space_is_never_reported_free(room):
    _, grid, obstacles, _ = room
    seg = obstacles.snapshot.segmentation
    layers = grid.layers(BOUNDS)
    assert (layers.seen[seg.state == FREE] != 0).all()
    outside = obstacles.nearest(10.0, 10.0)  # never observed, outside the window
    assert outside.clearance == 0.0 and outside.status == QueryStatus.UNKNOWN
    rows, cols = np.nonzero(seg.state == UNKNOWN)
    xy = np.column_stack([seg.origin[0] + (cols + 0.5) * seg.resolution,
                          seg.origin[1] + (rows + 0.5) * seg.resolution])
    assert (obstacles.distance(xy) == 0).all()
    assert obstacles.clearance((10.0, 10.0, 0.0)).collision


def test_stale_faulted_or_missing_data_report_no_clearance(room):
    _, grid, obstacles, clock = room
    fresh = obstacles.nearest(0.0, 0.0)
    assert fresh.status in (QueryStatus.OK, QueryStatus.UNKNOWN) and fresh.age == pytest.approx(0.5)
    clock.now = grid.stamp + 5.0
    try:
        for answer in (obstacles.nearest(0.0, 0.0), obstacles.clearance((0.0, 0.0, 0.0)),
                       obstacles.polar(0.0, 0.0, 0.0)):
            assert answer.status == QueryStatus.STALE
        assert obstacles.nearest(0.0, 0.0).clearance == 0.0
        assert obstacles.clearance((0.0, 0.0, 0.0)).collision
        assert (obstacles.distance(np.zeros((3, 2))) == 0).all()
        assert (obstacles.polar(0.0, 0.0, 0.0).ranges == 0).all()
    finally:
        clock.now = grid.stamp + 0.5
    obstacles.set_fault("camera unplugged")
    try:
        assert obstacles.nearest(0.0, 0.0).status == QueryStatus.FAULTED
        assert obstacles.clearance((0.0, 0.0, 0.0)).collision
    finally:
        obstacles.clear_fault()
    assert ObstacleMap().nearest(0.0, 0.0).status == QueryStatus.UNKNOWN  # nothing published


def cast_truth(scene: S.Scene, x: float, y: float, angles: np.ndarray) -> np.ndarray:
    """Exact range from (x, y) to the nearest band obstacle footprint along each angle."""
    boxes = S.Scene(tuple(b for b in scene.boxes
                          if b.hi[2] > ROBOT.step_height and b.lo[2] < ROBOT.height))
    flat = S.Scene(tuple(S.Box((b.lo[0], b.lo[1], -1.0), (b.hi[0], b.hi[1], 1.0))
                         for b in boxes.boxes))
    directions = np.column_stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
    t, _ = S.cast(flat, np.array([x, y, 0.5]), directions)
    return t


def test_polar_scan_is_never_farther_than_the_true_obstacle(room):
    scene, _, obstacles, _ = room
    for x, y, yaw in ((0.25, -1.2, 0.0), (1.1, -0.6, 1.0), (-1.25, 0.25, -2.0)):
        scan = obstacles.polar(x, y, yaw, bins=720, max_range=4.0)
        truth = cast_truth(scene, x, y, scan.angles + yaw)
        limited = np.isfinite(scan.ranges)
        assert (scan.ranges[limited] <= truth[limited] + 0.02).all()
        obstacle = scan.kinds == OBSTACLE  # where an obstacle ends the bin: its true range
        assert obstacle.sum() > 5
        assert np.percentile(np.abs(scan.ranges - truth)[obstacle], 90) < 0.05


def polygon_margin_reference(seg, polygon: np.ndarray) -> float:
    """Signed distance (OpenCV's pointPolygonTest) from the polygon to every obstacle point
    and every unknown cell (centre minus half its diagonal), and to the window's edge."""
    rows, cols = np.nonzero(seg.state != FREE)
    obstacle = seg.state[rows, cols] == OBSTACLE
    centres = np.column_stack([seg.origin[0] + (cols + 0.5) * seg.resolution,
                               seg.origin[1] + (rows + 0.5) * seg.resolution])
    points = np.where(obstacle[:, None], seg.points[rows, cols], centres)
    reach = np.where(obstacle, 0.0, seg.resolution * math.sqrt(0.5))
    contour = polygon.astype(np.float32).reshape(-1, 1, 2)
    signed = np.array([-cv2.pointPolygonTest(contour, (float(x), float(y)), True)
                       for x, y in points]) - reach
    ny, nx = seg.shape
    x0, y0 = seg.origin
    edge = np.minimum.reduce([polygon[:, 0] - x0, x0 + nx * seg.resolution - polygon[:, 0],
                              polygon[:, 1] - y0, y0 + ny * seg.resolution - polygon[:, 1]])
    return float(min(signed.min(), edge.min()))


def test_clearance_of_circle_and_polygon_footprints(room):
    scene, _, obstacles, _ = room
    table = scene.boxes[4]
    near_table = (table.lo[0] - 0.4, 0.5 * (table.lo[1] + table.hi[1]), 0.0)
    circle = obstacles.clearance(near_table, 0.3)
    nearest = obstacles.nearest(*near_table[:2])
    assert circle.margin == pytest.approx(nearest.clearance - 0.3)
    assert circle.collision == (circle.margin <= 0)
    rectangle = np.array([[0.45, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.45, -0.2]])
    seg = obstacles.snapshot.segmentation
    for yaw in (0.0, math.pi / 2, 2.0):
        answer = obstacles.clearance((*near_table[:2], yaw), rectangle)
        c, s = math.cos(yaw), math.sin(yaw)
        in_map = rectangle @ np.array([[c, s], [-s, c]]) + near_table[:2]
        assert answer.margin == pytest.approx(polygon_margin_reference(seg, in_map), abs=1e-4)
    with pytest.raises(MapError):
        obstacles.clearance(near_table, np.zeros((2, 2)))


def test_a_footprint_reaching_an_obstacle_collides_and_turned_away_clears():
    """A known-free 2 m square with one obstacle point at (0.5, 0)."""
    state = np.full((40, 40), FREE, np.uint8)
    points = np.zeros((40, 40, 2), np.float32)
    state[20, 30] = OBSTACLE
    points[20, 30] = (0.5, 0.0)
    seg = Segmentation(origin=(-1.0, -1.0), resolution=0.05, robot=ROBOT,
                       floor_height=np.zeros((40, 40), np.float32), is_floor=state == FREE,
                       planes=(), state=state, points=points,
                       band_logodds=np.zeros((40, 40), np.float32), updated=np.zeros((40, 40)))
    obstacles = ObstacleMap(ROBOT, max_age=1.0, clock=lambda: 0.0)
    obstacles.publish(ObstacleSnapshot.from_segmentation(seg, 0.0))
    rectangle = np.array([[0.6, 0.1], [-0.2, 0.1], [-0.2, -0.1], [0.6, -0.1]])
    straight = obstacles.clearance((0.0, 0.0, 0.0), rectangle)
    assert straight.collision and straight.margin == pytest.approx(-0.1)
    turned = obstacles.clearance((0.0, 0.0, math.pi / 2), rectangle)
    assert not turned.collision and turned.margin == pytest.approx(0.4)
    assert turned.status == QueryStatus.UNKNOWN  # the window's edge (unknown) is as near


def test_queries_from_another_thread_see_whole_snapshots():
    """The mapper inserts scans and publishes snapshots while a controller polls."""
    scene = S.furnished_room()
    grid = HeightGrid(GridConfig(extent=50.0))
    obstacles = ObstacleMap(ROBOT, max_age=1e9, clock=lambda: 1e6)
    S.map_scene(scene, S.ROOM_POSES[:1], grid)
    obstacles.update(grid, BOUNDS)
    errors: list[BaseException] = []
    stop = threading.Event()

    def mapper() -> None:
        try:
            for k, pose in enumerate(S.ROOM_POSES[1:6], start=1):
                S.map_scene(scene, [pose], grid, seed=k, first_stamp=k)
                obstacles.update(grid, BOUNDS)
        except BaseException as exc:  # reported to the main thread
            errors.append(exc)
        finally:
            stop.set()

    thread = threading.Thread(target=mapper)
    thread.start()
    stamps = []
    while not stop.is_set():
        answer = obstacles.nearest(0.3, 0.2)
        assert answer.status in (QueryStatus.OK, QueryStatus.UNKNOWN)
        assert 0.0 <= answer.clearance <= answer.distance
        stamps.append(obstacles.snapshot.stamp)
    thread.join()
    assert not errors and stamps == sorted(stamps) and stamps[-1] == 5.0
