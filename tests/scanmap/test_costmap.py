"""Nav2-convention costmaps and OccupancyGrid values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from scanmap.navigation.costmap import (
    INSCRIBED,
    LETHAL,
    NO_INFORMATION,
    costmap_to_occupancy,
    inflate,
    occupancy_grid,
)
from scanmap.navigation.floor import FREE, OBSTACLE, UNKNOWN, RobotShape, Segmentation
from scanmap_driver.errors import MapError


def segmentation(state: np.ndarray, logodds: float = 2.0) -> Segmentation:
    ny, nx = state.shape
    return Segmentation(origin=(0.0, 0.0), resolution=0.05, robot=RobotShape(radius=0.2),
                        floor_height=np.zeros((ny, nx), np.float32),
                        is_floor=state == FREE, planes=(), state=state.astype(np.uint8),
                        points=np.zeros((ny, nx, 2), np.float32),
                        band_logodds=np.where(state == OBSTACLE, logodds, np.nan)
                        .astype(np.float32), updated=np.zeros((ny, nx)))


def test_inflation_follows_nav2s_cost_function():
    state = np.full((40, 50), FREE, np.uint8)
    state[20, 25] = state[5, 5] = OBSTACLE
    state[30:, 40:] = UNKNOWN
    costs = inflate(segmentation(state), inscribed_radius=0.2, inflation_radius=0.55,
                    cost_scaling_factor=3.0)
    d = ndimage.distance_transform_edt(state != OBSTACLE) * 0.05
    expected = np.zeros(state.shape, np.int64)
    for (y, x), dist in np.ndenumerate(d):
        if dist == 0:
            cost = LETHAL
        elif dist <= 0.2:
            cost = INSCRIBED
        elif dist <= 0.55:
            cost = int((INSCRIBED - 1) * math.exp(-3.0 * (dist - 0.2)))
        else:
            cost = 0
        if state[y, x] == UNKNOWN:
            cost = cost if cost >= INSCRIBED else NO_INFORMATION
        expected[y, x] = cost
    np.testing.assert_array_equal(costs, expected)


def test_inscribed_radius_defaults_to_the_robot_and_bad_radii_fail():
    state = np.full((10, 10), FREE, np.uint8)
    state[5, 5] = OBSTACLE
    costs = inflate(segmentation(state))
    assert costs[5, 9] == INSCRIBED and costs[5, 5] == LETHAL  # 0.2 m: the robot's radius
    with pytest.raises(MapError):
        inflate(segmentation(state), inflation_radius=-1.0)


def test_cost_translation_is_nav2s_table():
    costs = np.array([0, 1, 2, 126, 252, 253, 254, 255], np.uint8)
    np.testing.assert_array_equal(costmap_to_occupancy(costs),
                                  [0, 1, 1, 49, 98, 99, 100, -1])


def test_occupancy_grid_is_minus_one_unknown_zero_free_and_percent_occupied():
    state = np.array([[UNKNOWN, FREE, OBSTACLE]], np.uint8)
    grid = occupancy_grid(segmentation(state, logodds=0.85))
    np.testing.assert_array_equal(grid, [[-1, 0, round(100 / (1 + math.exp(-0.85)))]])
    assert grid.dtype == np.int8


@pytest.mark.parametrize("costs", [np.array([0.0, math.nan]), np.array([0, 256]),
                                   np.array([-1, 0]), np.array([1.5])])
def test_costs_that_are_not_costs_are_a_clear_error(costs):
    """A cast to uint8 would wrap them: 256 and NaN to FREE_SPACE, -1 to NO_INFORMATION."""
    with pytest.raises(MapError, match=r"integers 0\.\.255"):
        costmap_to_occupancy(costs)


@pytest.mark.parametrize("name", ["inscribed_radius", "inflation_radius",
                                  "cost_scaling_factor"])
@pytest.mark.parametrize("value", [math.nan, math.inf, -0.1])
def test_inflation_refuses_non_finite_or_negative_parameters(name, value):
    state = np.full((5, 5), FREE, np.uint8)
    with pytest.raises(MapError, match=name):
        inflate(segmentation(state), **{name: value})


def test_an_obstacle_cell_without_log_odds_is_occupied():
    state = np.array([[OBSTACLE, FREE]], np.uint8)
    seg = segmentation(state)
    seg.band_logodds[0, 0] = np.nan
    np.testing.assert_array_equal(occupancy_grid(seg), [[100, 0]])
