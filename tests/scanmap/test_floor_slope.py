"""The floor's local slope (`_kernels.local_slope`) against the closed form of a plane, and
a chain of cells too thin for a plane: the foot of a wall, a laser line's arc."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.navigation import _kernels as nk

RES = 0.05
STEP = 0.05
REACH = 2


@settings(max_examples=60, deadline=None)
@given(gx=st.floats(-0.6, 0.6), gy=st.floats(-0.6, 0.6), base=st.floats(-100.0, 100.0))
def test_the_slope_of_a_plane_is_its_gradient(gx, gy, base):
    y, x = np.mgrid[0:9, 0:9] * RES
    heights = (base + gx * x + gy * y).astype(np.float64)
    slope = nk.local_slope(heights, REACH, 10.0, RES)
    assert math.isclose(slope[4, 4], math.atan(math.hypot(gx, gy)), abs_tol=1e-4)


@settings(max_examples=60, deadline=None)
@given(g=st.floats(-1.0, 1.0), direction=st.sampled_from([(0, 1), (1, 0), (1, 1), (1, -1)]))
def test_a_line_of_cells_has_the_slope_along_it(g, direction):
    # One cell wide, so no plane fits: the slope along the line, steep or not
    dy, dx = direction
    heights = np.full((11, 11), np.nan)
    for k in range(-5, 6):
        heights[5 + k * dy, 5 + k * dx] = g * k * RES * math.hypot(dy, dx)
    slope = nk.local_slope(heights, REACH, 10.0, RES)
    assert math.isclose(slope[5, 5], math.atan(abs(g)), abs_tol=1e-4)


def test_a_staircase_of_small_steps_along_a_wall_is_steep():
    # Each cell 4 cm below the last (within a 5 cm step of its neighbour) along a row: a
    # 39 deg slope down, not floor to drive on, though every step alone is climbable
    heights = np.full((7, 12), np.nan)
    heights[3] = -0.04 * np.arange(12)
    slope = nk.local_slope(heights, REACH, STEP, RES)
    assert (slope[3, 1:-1] > math.radians(30.0)).all()


@settings(max_examples=40, deadline=None)
@given(degrees=st.floats(3.0, 35.0))
def test_the_first_row_of_a_ramp_has_the_ramps_slope_and_the_floor_before_it_less(degrees):
    # Floor up to row 4, a ramp rising from the boundary between rows 4 and 5: row 5's
    # centre lies tan(slope) x 2.5 cm up. One plane over both surfaces gave it about half
    # the ramp's slope (a 20 deg ramp's first row counted as floor); the cells at or above
    # it are the ramp alone, so its slope is the ramp's, and the floor before it, the
    # lowest there, stays under max_slope (7 deg beside a 20 deg ramp, 14 beside 35)
    heights = np.zeros((12, 9))
    heights[5:] = math.tan(math.radians(degrees)) * (np.arange(5, 12)[:, None] - 4.5) * RES
    slope = nk.local_slope(heights, REACH, STEP, RES)
    assert np.allclose(slope[5:10, 2:7], math.radians(degrees), atol=1e-4)
    assert (slope[4, 2:7] < math.radians(15.0)).all()
    assert (slope[:3, 2:7] == 0.0).all()


def test_too_few_cells_have_no_slope():
    heights = np.full((5, 5), np.nan)
    heights[2, 2] = heights[2, 3] = 0.0
    assert np.isnan(nk.local_slope(heights, REACH, STEP, RES)).all()


def _row(*heights: float) -> np.ndarray:
    """A 3-row candidate grid whose middle row holds `heights` (m), the rest empty."""
    grid = np.full((3, len(heights)), np.nan, np.float32)
    grid[1] = heights
    return grid


@pytest.mark.parametrize("heights,bridges", [
    ((0.0, 0.0, -0.02, -0.06, -0.08, -0.08), (2, 3)),  # an 8 cm step's face: 0 -> -8 cm
    ((0.0, 0.0, 0.045, 0.09, 0.09), (2,)),  # 9 cm up in two hops
    ((0.0, 0.0, 0.024, 0.048, 0.048), ()),  # a 4.8 cm sill: within the step
    (tuple(0.0122 * k for k in range(8)), ()),  # a 14 deg ramp: a step nowhere
    ((0.08, 0.08, 0.078, 0.03, 0.0, 0.0), (3,)),  # a ramp's edge, level with the ramp
    ((0.0, 0.0, 0.2, 0.2), ()),  # a box top: no candidate between
])
def test_bridged_steps_are_the_cells_between_two_sides_of_a_step(heights, bridges):
    flagged = nk.bridged_steps(_row(*heights), 0.05)
    assert tuple(np.flatnonzero(flagged[1])) == bridges
    assert not flagged[0].any() and not flagged[2].any()
