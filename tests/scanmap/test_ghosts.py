"""People pass, walls stay (issue 17): the evidence that clears a person who walked on,
on a synthetic grid, and the people corridor of the simulator against its truth."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_hazards import people_run
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation.floor import FREE, OBSTACLE, UNKNOWN, FloorConfig, RobotShape, segment
from scanmap_driver.sim import builtin_scene

CELL = (1.025, 1.025)  # the centre of the cell a person's arm is seen in


def floor_grid() -> HeightGrid:
    """A 2 m x 2 m floor, each cell hit once by a vertical ray from 1 m above (its whole
    band seen free)."""
    grid = HeightGrid(GridConfig(extent=20.0))
    xs = np.arange(0.025, 2.0, 0.05)
    gx, gy = np.meshgrid(xs, xs)
    floor = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    grid.insert(floor, floor + [0.0, 0.0, 1.0], 0.0, stood=np.array([[30.0, 30.0]]))
    return grid


def pass_through(grid: HeightGrid, z: float, stamp: float) -> None:
    """One scan: one horizontal ray along the cell's row at height z, ending far beyond."""
    start, end = np.array([-1.0, CELL[1], z]), np.array([3.9, CELL[1], z])
    grid.insert(end[None], start, stamp, stood=np.array([[30.0, 30.0]]))


def state_of_cell(grid: HeightGrid) -> int:
    seg = segment(grid.layers((0.0, 0.0, 2.0, 2.0)), RobotShape(), FloorConfig())
    ix = int(np.floor((CELL[0] - seg.origin[0]) / seg.resolution))
    iy = int(np.floor((CELL[1] - seg.origin[1]) / seg.resolution))
    return int(seg.state[iy, ix])


def test_a_surface_seen_once_and_seen_through_twice_is_no_longer_an_obstacle():
    """An arm seen at 0.5 m in one scan (log-odds 0.85), then one ray a scan through its
    height bin: after one the cell is still an OBSTACLE (0.45), after two (0.05, as
    likely gone as there) it is UNKNOWN - not an obstacle, and not free either."""
    grid = floor_grid()
    assert state_of_cell(grid) == FREE
    arm = np.array([[CELL[0], CELL[1], 0.5]])
    grid.insert(arm, np.array([-1.0, CELL[1], 0.5]), 1.0, stood=np.array([[30.0, 30.0]]))
    assert state_of_cell(grid) == OBSTACLE
    pass_through(grid, 0.505, 2.0)
    assert state_of_cell(grid) == OBSTACLE
    pass_through(grid, 0.505, 3.0)
    assert state_of_cell(grid) == UNKNOWN


@pytest.fixture(scope="module")
def corridor() -> dict[str, float]:
    """The built-in people corridor, all 60 scans: a walker, an overtaker and a person
    standing 20 scans near the robot's path."""
    return people_run(scene=builtin_scene("people"))


def test_walls_seen_through_sixty_scans_with_people_never_erode(corridor):
    assert corridor["wall_cells_eroded"] == 0
    assert corridor["wall_recall_people"] == 1.0
    assert corridor["wall_recall_empty"] == 1.0


def test_most_cells_people_left_are_not_obstacles_three_scans_later(corridor):
    """The share of cells the people left (within 2 m of the robot, summed over the scans)
    still OBSTACLE three scans later: 8.2 % before issue 17's fixes, 4.6 % after, 3.9 %
    once cells a person's side grazes are not counted as left; what stays is mostly
    heights no later ray crossed (the robot's blind disc) and the feet merged with the
    floor (bench_hazards). Of the cells the later rays saw through, at every height the
    map holds something, 65 of 14675 (0.44 %) stay; tracing every ray to its origin
    (GridConfig.bundle_run 0) leaves 11, at four times the fusion time."""
    assert corridor["left_cells"] > 40000
    assert corridor["ghost_cells"] / corridor["left_cells"] <= 0.05
    assert corridor["left_cells_seen_through"] > 10000
    assert corridor["ghost_cells_seen_through"] / corridor["left_cells_seen_through"] <= 0.006
