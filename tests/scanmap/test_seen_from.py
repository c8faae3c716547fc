"""Where each cell's lowest level was seen from (the grid's `FROM` field, read as
`CellLayers.seen_from`): the camera's cell at the last hit on the cell's lowest level, or
at the ray that looked deepest into the cell below its every level; the drop-off a cell
shows keeps to the line of sight from there (`scanmap.navigation.floor`)."""

from __future__ import annotations

import math

import numpy as np

from scanmap.grid.height_grid import GridConfig, HeightGrid

CONFIG = GridConfig(extent=50.0)
RES = CONFIG.resolution


def centre(x: float, y: float) -> np.ndarray:
    """The centre of the grid cell holding (x, y) (the grid's cells start at -25 m)."""
    return (np.floor(np.array([x, y]) / RES) + 0.5) * RES


def seen_from(grid: HeightGrid, x: float, y: float) -> np.ndarray:
    """`seen_from` of the cell holding (x, y)."""
    layers = grid.layers((x - 0.01, y - 0.01, x + 0.01, y + 0.01))
    assert layers.shape == (1, 1)
    return layers.seen_from[0, 0]


def test_a_hit_on_a_cells_lowest_level_records_where_the_camera_stood():
    grid = HeightGrid(CONFIG)
    cell = (2.02, 0.02)
    assert np.isnan(seen_from(grid, *cell)).all()  # nothing seen yet
    first, above, last = (0.31, 0.12, 1.0), (0.0, 1.5, 1.0), (-1.0, -1.03, 1.0)
    grid.insert(np.array([[*cell, -0.2]]), np.array(first), 1.0)  # deep in a hole
    np.testing.assert_allclose(seen_from(grid, *cell), centre(*first[:2]), atol=1e-5)
    grid.insert(np.array([[*cell, 0.5]]), np.array(above), 2.0)  # a level higher up
    np.testing.assert_allclose(seen_from(grid, *cell), centre(*first[:2]), atol=1e-5)
    grid.insert(np.array([[cell[0], 0.03, -0.2]]), np.array(last), 3.0)  # the lowest again
    np.testing.assert_allclose(seen_from(grid, *cell), centre(*last[:2]), atol=1e-5)


def test_a_ray_that_looked_deepest_below_a_cells_levels_records_where_it_came_from():
    # Rays along the x axis over cell (1.025, 0.025) to points beyond it: one 0.5 m over
    # it, one 0.09 m (deeper: it counts), one 0.81 m (not as deep: it does not)
    grid = HeightGrid(CONFIG)
    cell, end = (1.025, 0.025), (2.025, 0.025)
    rays = [((0.025, 0.025, 1.0), 0.0), ((0.225, 0.025, 0.4), -0.3),
            ((0.425, 0.025, 1.0), 0.5)]
    expected = [0, 1, 1]
    for scan, ((origin, z), kept) in enumerate(zip(rays, expected, strict=True)):
        grid.insert(np.array([[*end, z]]), np.array(origin), float(scan + 1))
        np.testing.assert_allclose(seen_from(grid, *cell), centre(*rays[kept][0][:2]),
                                   atol=1e-5)
    # Over a level (a floor hit at 0.0), a ray passing above it tells nothing of a hole
    grid.insert(np.array([[*cell, 0.0]]), np.array([-0.475, 0.025, 1.0]), 4.0)
    np.testing.assert_allclose(seen_from(grid, *cell), centre(-0.475, 0.025), atol=1e-5)
    grid.insert(np.array([[*end, 0.0]]), np.array([0.625, 0.025, 0.3]), 5.0)
    np.testing.assert_allclose(seen_from(grid, *cell), centre(-0.475, 0.025), atol=1e-5)


def test_a_camera_off_the_grid_records_nothing():
    grid = HeightGrid(CONFIG)
    grid.insert(np.array([[0.02, 0.02, -0.2]]), np.array([math.nan, 0.0, 1.0]), 1.0)
    assert np.isnan(seen_from(grid, 0.02, 0.02)).all()
