"""Known floor where the robot stood (issue 17 item 6): the cells its footprint covers at
the poses it scanned from are FREE, on observed floor too, though rays saw little of the
robot's band there (a closed form: cells within the robot's radius of the sensor)."""

from __future__ import annotations

import math

import numpy as np

from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation.floor import FREE, RobotShape, segment


def floor_points(centre: tuple[float, float], radii: tuple[float, float],
                 spacing: float) -> np.ndarray:
    """Points on the floor (z = 0) at distances within radii of centre, on a square lattice."""
    r = radii[1]
    a = np.arange(-r, r + spacing / 2, spacing)
    x, y = np.meshgrid(a, a)
    d = np.hypot(x, y)
    keep = (d >= radii[0]) & (d <= radii[1])
    return np.column_stack([x[keep] + centre[0], y[keep] + centre[1], np.zeros(keep.sum())])


def test_floor_under_the_robot_seen_only_from_afar_is_free_where_it_stood():
    grid = HeightGrid(GridConfig(extent=20.0))
    # From 2 m away, the floor under the next pose: rays cross it only near the floor
    grid.insert(floor_points((0.0, 0.0), (0.0, 0.4), 0.02), np.array([-2.0, 0.0, 1.0]), 1.0)
    # Standing at the origin: the floor hits 1.7-2.8 m away, as this scanner sees it
    grid.insert(floor_points((0.0, 0.0), (1.7, 2.8), 0.03), np.array([0.0, 0.0, 1.0]), 2.0)
    robot = RobotShape()
    seg = segment(grid.layers((-1.0, -1.0, 1.0, 1.0)), robot)
    x, y = seg.origin[0] + (np.arange(seg.shape[1]) + 0.5) * seg.resolution, \
        seg.origin[1] + (np.arange(seg.shape[0]) + 0.5) * seg.resolution
    d = np.hypot(*np.meshgrid(x, y))
    under = d <= robot.radius
    assert under.sum() >= math.pi * (robot.radius / seg.resolution - 1) ** 2
    assert seg.is_floor[under].all()
    assert (seg.state[under] == FREE).all()
    assert not (seg.state[(d > robot.radius + seg.resolution) & (d < 0.4)] == FREE).all()
    # Every cell the body overlaps, not only those whose centres it covers: the robot's
    # own body never touches unknown space where it stood
    gx, gy = np.meshgrid(x, y)
    half = 0.5 * seg.resolution
    gap = np.hypot(np.maximum(np.abs(gx) - half, 0.0), np.maximum(np.abs(gy) - half, 0.0))
    body = gap < robot.radius - 1e-9  # not those it touches at one point
    assert (seg.state[body] == FREE).all()
    assert body.sum() > under.sum()


def test_the_footprint_is_swept_along_the_path_the_robot_took_during_a_scan():
    grid = HeightGrid(GridConfig(extent=20.0))
    grid.insert(floor_points((0.3, 0.0), (0.0, 0.6), 0.02), np.array([-2.0, 0.0, 1.0]), 1.0)
    path = np.column_stack([np.linspace(0.0, 0.6, 61), np.zeros(61), np.ones(61)])
    grid.insert(floor_points((0.3, 0.0), (1.7, 2.8), 0.03), np.array([0.3, 0.0, 1.0]), 2.0,
                stood=path)
    robot = RobotShape()
    seg = segment(grid.layers((-1.0, -1.0, 1.6, 1.0)), robot)
    x, y = seg.origin[0] + (np.arange(seg.shape[1]) + 0.5) * seg.resolution, \
        seg.origin[1] + (np.arange(seg.shape[0]) + 0.5) * seg.resolution
    gx, gy = np.meshgrid(x, y)
    along = np.clip(gx, 0.0, 0.6)  # distance to the segment from (0, 0) to (0.6, 0)
    d = np.hypot(gx - along, gy)
    swept = d <= robot.radius - 0.5 * seg.resolution
    assert (seg.state[swept] == FREE).all()
    assert (swept & (np.hypot(gx - 0.3, gy) > robot.radius + seg.resolution)).sum() > 20
    assert not (seg.state[(d > robot.radius + seg.resolution) & (d < 0.4)] == FREE).all()
