"""The floor's local slope (`_plane_kernels.local_slope`) against the closed form of a plane,
sampled at the cells' centres or where their hits lie, clean or noisy, and a chain of
cells too thin for a plane: the foot of a wall, a laser line's arc; the cells a step's
face leaves between its two floors (`_growth_kernels.bridged_steps`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation import floor
from scanmap.navigation.floor import FloorConfig, RobotShape, _model
from scanmap.navigation.floor._growth_kernels import bridged_steps
from scanmap.navigation.floor._plane_kernels import local_slope

from .growth import grow_region

RES = 0.05
STEP = 0.05
REACH = 2
REACH_OF_A_STEP = _model._bridge_reach(RobotShape(), FloorConfig(), RES)  # `bridged_steps`'
NOISE = FloorConfig().plane_noise
MAX_SLOPE = FloorConfig().max_slope
DEFAULT_ROBOT = (RobotShape(), FloorConfig(), RES)  # `_bridged_steps`' robot


def slope_of(heights: np.ndarray, step: float = STEP, offsets: np.ndarray | None = None,
             noise: float = NOISE) -> np.ndarray:
    """`local_slope` of candidate heights sampled at the cells' centres (or `offsets`)."""
    if offsets is None:
        offsets = np.zeros(heights.shape + (2,))
    return local_slope(heights, offsets, REACH, step, RES, noise,
                       np.zeros(heights.shape, bool))[0]


@settings(max_examples=60, deadline=None)
@given(gx=st.floats(-0.6, 0.6), gy=st.floats(-0.6, 0.6), base=st.floats(-100.0, 100.0))
def test_the_slope_of_a_plane_is_its_gradient(gx, gy, base):
    y, x = np.mgrid[0:9, 0:9] * RES
    heights = (base + gx * x + gy * y).astype(np.float64)
    slope, tangent = local_slope(heights, np.zeros((9, 9, 2)), REACH, 10.0, RES, NOISE,
                                 np.zeros((9, 9), bool))
    assert math.isclose(slope[4, 4], math.atan(math.hypot(gx, gy)), abs_tol=1e-4)
    np.testing.assert_allclose(tangent[4, 4], (heights[4, 4], 4 * RES, 4 * RES, gx, gy),
                               atol=1e-4, rtol=1e-6)


@settings(max_examples=60, deadline=None)
@given(g=st.floats(-1.0, 1.0), direction=st.sampled_from([(0, 1), (1, 0), (1, 1), (1, -1)]))
def test_a_line_of_cells_has_the_slope_along_it(g, direction):
    # One cell wide, so no plane fits: the slope along the line, steep or not
    dy, dx = direction
    heights = np.full((11, 11), np.nan)
    for k in range(-5, 6):
        heights[5 + k * dy, 5 + k * dx] = g * k * RES * math.hypot(dy, dx)
    slope = slope_of(heights, 10.0)
    assert math.isclose(slope[5, 5], math.atan(abs(g)), abs_tol=1e-4)


def test_a_staircase_of_small_steps_along_a_wall_is_steep():
    # Each cell 4 cm below the last (within a 5 cm step of its neighbour) along a row: a
    # 39 deg slope down, not floor to drive on, though every step alone is climbable
    heights = np.full((7, 12), np.nan)
    heights[3] = -0.04 * np.arange(12)
    slope = slope_of(heights)
    assert (slope[3, 1:-1] > math.radians(30.0)).all()


@settings(max_examples=40, deadline=None)
@given(degrees=st.floats(3.0, 35.0))
def test_the_first_row_of_a_ramp_is_steep_only_when_the_ramp_is(degrees):
    # Floor up to row 4, a ramp rising from the boundary between rows 4 and 5: row 5's
    # centre lies tan(slope) x 2.5 cm up. One plane over both surfaces gives it about 2/3
    # of the ramp's slope (a 20 deg ramp's first row counted as floor); where that plane
    # fits them badly (a crease: any ramp steeper than max_slope), the cells at or above
    # it are the ramp alone, so its slope is the ramp's. The floor before it, the lowest
    # there, stays under max_slope (7 deg beside a 20 deg ramp, 14 beside 35)
    heights = np.zeros((12, 9))
    heights[5:] = math.tan(math.radians(degrees)) * (np.arange(5, 12)[:, None] - 4.5) * RES
    slope = slope_of(heights)
    assert np.allclose(slope[7:10, 2:7], math.radians(degrees), atol=1e-4)  # ramp only
    assert (slope[5:7, 2:7] <= math.radians(degrees) + 1e-4).all()
    assert (slope[5, 2:7] > MAX_SLOPE).all() == (degrees > 15.0)
    assert (slope[4, 2:7] < MAX_SLOPE).all()
    assert (np.abs(slope[:3, 2:7]) < 1e-9).all()  # flat (to the rounding of the mean)


@settings(max_examples=60, deadline=None)
@given(degrees=st.floats(0.0, 40.0), direction=st.floats(0.0, 2.0 * math.pi),
       seed=st.integers(0, 2**32 - 1))
def test_a_plane_sampled_off_the_cells_centres_has_its_slope_where_its_hits_lie(
        degrees, direction, seed):
    # A turned ramp's lines cross its cells anywhere: the height there is the plane's at
    # the hits, up to 1.3 cm off the centre's on a 15 deg ramp; at the hits, exact
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-0.5 * RES, 0.5 * RES, (9, 9, 2))
    y, x = np.mgrid[0:9, 0:9] * RES
    g = math.tan(math.radians(degrees))
    heights = g * (math.cos(direction) * (x + offsets[..., 0])
                   + math.sin(direction) * (y + offsets[..., 1]))
    slope = slope_of(heights, 10.0, offsets)
    assert math.isclose(slope[4, 4], math.radians(degrees), abs_tol=1e-4)


def test_a_noisy_ramp_just_under_max_slope_is_not_steep_but_one_just_over_is():
    # 1 mm of noise on each cell's height (a turned ramp's, at 5 cm cells, after several
    # scans): the steepest of three fits everywhere overshot a 14 deg ramp by 1-2.6 deg;
    # one plane, where it fits, stays within half a degree
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:40, 0:40] * RES
    direction = math.radians(30.0)
    for degrees, steep in ((14.0, False), (16.0, True)):
        rise = math.tan(math.radians(degrees)) * (math.cos(direction) * x
                                                  + math.sin(direction) * y)
        slope = slope_of(rise + rng.normal(0.0, 0.001, rise.shape))[2:-2, 2:-2]
        assert (slope > MAX_SLOPE).all() if steep else not (slope > MAX_SLOPE).any()
        old = slope_of(rise + rng.normal(0.0, 0.001, rise.shape), noise=0.0)[2:-2, 2:-2]
        assert np.nanmax(old) > np.nanmax(slope)  # the steepest of three overshoots


@pytest.mark.parametrize("degrees", [15.5, 16.0, 17.0])
def test_a_noisy_steep_ramps_foot_is_steep_and_the_floor_before_it_is_not(degrees):
    # A ramp turned 30 deg to the cells, 1 mm of noise on each height: the plane over the
    # window round a cell of its first 10 cm takes in the floor before it and, bent within
    # the noise, has a gentler slope (ramp rooms: those cells floor, F1 0.94-0.97). The
    # window on the ramp alone explains such a cell better (the steepest-of-three took
    # 65-94 % of them steep at 15.5-17 deg, 10 seeds; this rule 96-98 %)
    y, x = np.mgrid[0:30, 0:30] * RES
    across = math.cos(math.radians(30.0)) * (x - 0.7) + math.sin(math.radians(30.0)) * (y - 0.7)
    inner = np.zeros(across.shape, bool)
    inner[2:-2, 2:-2] = True
    foot, floor_before = inner & (across > 0.0) & (across < 2 * RES), inner & (across < -RES)
    steep_foot = floor_steep = 0
    for seed in range(10):
        noise = np.random.default_rng(seed).normal(0.0, 0.001, across.shape)
        rise = np.where(across > 0.0, math.tan(math.radians(degrees)) * across, 0.0)
        slope = slope_of(rise + noise)
        steep_foot += int((slope[foot] > MAX_SLOPE).sum())
        floor_steep += int((slope[floor_before] > MAX_SLOPE).sum())
    assert steep_foot >= 0.95 * 10 * foot.sum()
    assert floor_steep == 0


def cell_means(surface, shape: tuple[int, int], samples: int = 8) -> np.ndarray:
    """Each cell's mean height of `surface(x, y)` (m, from the first cell's centre) over
    `samples` x `samples` points spread evenly across it: the mean hit of a cell a
    laser's lines cross all over (their mean lies at its centre)."""
    sub = (np.arange(samples) + 0.5) / samples - 0.5
    y, x = np.mgrid[0:shape[0], 0:shape[1]] * RES
    return np.mean([surface(x + dx * RES, y + dy * RES) for dy in sub for dx in sub], axis=0)


def test_a_steep_ramps_foot_cells_fall_on_the_side_of_the_crease_their_centres_lie_on():
    # 40 wall-to-wall ramps of 20-35 deg, turned anyhow, their crease anywhere across the
    # cells, each cell's height the mean of the surface over it with 1 mm of noise: a
    # cell the crease crosses holds the floor and the ramp, its mean a few mm up, so the
    # floor's window explains it about as well as the ramp's, and the plane over its
    # whole window took it at 10-14 deg (random room 11106 at 0.3 px: a 25 deg ramp's
    # foot cells FREE; here 39 of the 1909 cells a centimetre or more onto the ramps,
    # none now, `_across_crease`). The floor a centimetre or more before the crease stays
    # floor (1 of its 11,291 cells steep)
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:30, 0:30] * RES
    inner = np.zeros(x.shape, bool)
    inner[3:-3, 3:-3] = True
    foot_gentle = foot = floor_steep = floor_cells = 0
    for _ in range(40):
        degrees, turn = rng.uniform(20.0, 35.0), rng.uniform(0.0, 2.0 * math.pi)
        crease = 0.7 + rng.uniform(0.0, RES)  # from the first cell, along the turn

        def across(x, y, turn=turn, crease=crease):
            return math.cos(turn) * (x - crease) + math.sin(turn) * (y - crease)

        def surface(x, y, degrees=degrees, across=across):
            return math.tan(math.radians(degrees)) * np.maximum(across(x, y), 0.0)

        slope = slope_of(cell_means(surface, x.shape) + rng.normal(0.0, 0.001, x.shape))
        onto = inner & (across(x, y) > 0.01) & (across(x, y) < 2 * RES)
        before = inner & (across(x, y) < -0.01)
        foot += int(onto.sum())
        foot_gentle += int((slope[onto] <= MAX_SLOPE).sum())
        floor_cells += int(before.sum())
        floor_steep += int((slope[before] > MAX_SLOPE).sum())
    assert foot_gentle <= 0.005 * foot
    assert floor_steep <= 0.001 * floor_cells


def test_the_floor_beside_a_steep_ramps_foot_stays_floor():
    # 60 ramps of 20-35 deg rising along x from x0, their side along y = side: the floor
    # beside the side, a cell and more off, lies below the ramp's plane carried on
    # sideways, not past a crease (`_across_crease` claims a cell only where the ramp's
    # cells lie uphill of it: without, 4 of these 480 cells came out steep; random room
    # 1, a floor cell 7 cm beside a 27 deg ramp's foot, 17 deg)
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:20, 0:24] * RES
    steep = beside = 0
    for _ in range(60):
        degrees = rng.uniform(20.0, 35.0)
        x0, side = 0.5 + rng.uniform(0.0, RES), 0.5 + rng.uniform(0.0, RES)

        def surface(x, y, degrees=degrees, x0=x0, side=side):
            on = (x > x0) & (y < side)
            return np.where(on, math.tan(math.radians(degrees)) * (x - x0), 0.0)

        slope = slope_of(cell_means(surface, x.shape) + rng.normal(0.0, 0.001, x.shape))
        floor = (y > side + RES) & (y < side + 3 * RES) & (x > x0) & (x < x0 + 0.2)
        beside += int(floor.sum())
        steep += int((slope[floor] > MAX_SLOPE).sum())
    assert beside == 480
    assert steep == 0


@pytest.mark.parametrize("degrees", [14.7, 15.3])
def test_a_noisy_ramp_near_max_slope_falls_on_its_side_of_it(degrees):
    # A plane 0.3 deg from max_slope, turned, 1 mm of noise on each cell's height (the
    # mean of its hits at about 0.3 px of laser peak noise): the slope of the one window
    # that explains a cell best was off by 0.17 deg (standard deviation), and 202 of the
    # 5760 inner cells of a 14.7 deg ramp came out over max_slope (fresh ramp room 501);
    # the mean of the nine windows' agreeing gradients is off by 0.06
    y, x = np.mgrid[0:30, 0:30] * RES
    along = math.cos(0.5) * x + math.sin(0.5) * y
    wrong, spread = 0, []
    for seed in range(10):
        noise = np.random.default_rng(seed).normal(0.0, 0.001, along.shape)
        slope = slope_of(math.tan(math.radians(degrees)) * along + noise)[3:-3, 3:-3]
        wrong += int(((slope > MAX_SLOPE) != (degrees > 15.0)).sum())
        spread.append(np.degrees(slope).std())
    assert wrong <= 5
    assert np.mean(spread) < 0.1


def test_too_few_cells_have_no_slope():
    heights = np.full((5, 5), np.nan)
    heights[2, 2] = heights[2, 3] = 0.0
    assert np.isnan(slope_of(heights)).all()


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
    row = _row(*heights)
    flagged = _model._bridged_steps(row, np.zeros(row.shape, bool), *DEFAULT_ROBOT)
    assert tuple(np.flatnonzero(flagged[1])) == bridges
    assert not flagged[0].any() and not flagged[2].any()


NAN = math.nan
# Random room 609's step down, 6.1 cm deep and turned 5 deg to the cells, at its 23rd scan:
# each cell's floor candidate near a corner (mm; NaN for none), rows north to south. Its
# face left candidates 1.4 to 4.9 cm down in the cells it crosses, each within a step of
# the next and the step's two sides three cells apart: grown cell by cell, the floor went
# down them onto the lower floor, which was FREE although the robot cannot take the step
TURNED_STEP_MM = [
    [-60, NAN, NAN, NAN, NAN, NAN, NAN, 0, 0],
    [NAN, NAN, NAN, NAN, NAN, NAN, -1, 0, -1],
    [NAN, NAN, NAN, NAN, -1, 0, 0, -1, 0],
    [NAN, NAN, NAN, -14, -16, 0, -1, 0, 0],
    [NAN, NAN, NAN, NAN, -26, NAN, 0, 0, NAN],
    [NAN, -62, -60, -35, NAN, 0, 0, NAN, NAN],
    [-61, -60, -60, -49, NAN, NAN, NAN, NAN, NAN],
    [-61, -61, -61, -61, -41, NAN, NAN, NAN, NAN],
    [-60, -61, -62, -62, NAN, NAN, NAN, NAN, NAN],
]


def test_the_floor_grown_down_a_turned_steps_face_stops_at_the_step():
    heights = (np.array(TURNED_STEP_MM[::-1]) / 1000.0).astype(np.float32)
    bridges = _model._bridged_steps(heights, np.zeros(heights.shape, bool),
                                    *DEFAULT_ROBOT)
    grown = grow_region(np.where(bridges, np.nan, heights), heights > -0.003, STEP,
                        np.isnan(heights), math.tan(FloorConfig().max_slope) * RES, heights)
    lower = heights < -0.055
    assert lower.sum() == 14 and not (grown & lower).any()


# Step room 1009's step down, 5.7 cm deep, at its third scan at 0.3 px of laser peak noise:
# the floor candidates (mm) round a cell its face crosses (-36), rows north to south. The
# floor above the face and the floor below that lie within reach of each other both lie
# west of that cell, and the gaps beside it let the growth jump from the floor onto it
# (3.8 cm down two cells: within max_slope) and on onto the lower floor: FREE for six scans
SPARSE_FACE_MM = [
    [1, -1, -2, NAN, NAN, 0, 0, -1, NAN],
    [1, 0, -2, 0, 0, NAN, NAN, 0, 0],
    [NAN, 0, 2, NAN, 1, 1, -1, -3, -1],
    [NAN, NAN, NAN, NAN, NAN, NAN, 1, 1, 1],
    [NAN, NAN, NAN, NAN, -36, NAN, NAN, NAN, NAN],
    [NAN, -58, NAN, NAN, -20, -15, NAN, NAN, NAN],
    [-57, -57, -57, NAN, NAN, 0, 0, NAN, NAN],
    [-55, -57, -58, -56, -58, NAN, 0, -1, NAN],
    [NAN, -56, -57, -57, -57, -57, NAN, 1, 0],
]


def test_a_face_cell_with_both_floors_to_one_side_bridges_the_step_where_both_are_level():
    heights = (np.array(SPARSE_FACE_MM[::-1]) / 1000.0).astype(np.float32)
    face = (heights < -0.01) & (heights > -0.05)
    level = ~face & ~np.isnan(heights)  # the floors' cells, 0-1 deg; the face's 4-17 deg
    bridges = _model._bridged_steps(heights, level, *DEFAULT_ROBOT)
    centre = (4, 4)
    assert bridges[centre] and not bridges[~face].any()
    assert not _model._bridged_steps(heights, np.zeros(heights.shape, bool),
                                     *DEFAULT_ROBOT)[centre]  # by the sides alone: none
    lower = heights < -0.05
    for left_out in (bridges, np.zeros(heights.shape, bool)):
        grown = grow_region(np.where(left_out, np.nan, heights), heights > -0.005, STEP,
                            np.isnan(heights), math.tan(MAX_SLOPE) * RES, heights)
        assert (grown & lower).any() == (not left_out.any())


# Step room 1083's step down, 6.9 cm deep, at its 2nd scan at 0.1 px: the floor candidates
# (mm) round the cells one laser line left crossing its turned face at a slant, grading
# from the floor (0) to the floor below (-69) along a chain one cell wide, each window
# round it holding that line alone (no plane); the floors' cells fit planes. Grown cell
# by cell within a step, the floor walked down the chain: 40 cells FREE
SLANTED_LINE_MM = [
    [NAN, NAN, NAN, 0, -1, 0, 0, 0, -1, 1, 1, NAN, NAN],
    [NAN, NAN, NAN, NAN, NAN, NAN, 0, 0, 0, -1, 0, 0, 0],
    [NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, 0, 0, -1, -1],
    [-69, -69, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN],
    [-69, -69, -68, -69, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN],
    [NAN, NAN, -69, -68, -66, -65, NAN, NAN, NAN, NAN, NAN, NAN, NAN],
    [NAN, NAN, NAN, NAN, NAN, -62, -54, NAN, NAN, NAN, NAN, NAN, NAN],
    [NAN, NAN, NAN, NAN, NAN, NAN, NAN, -43, -37, NAN, NAN, NAN, NAN],
    [NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, -33, -28, -21, NAN, NAN],
    [-69, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, -18, -15, 0],
    [-68, -69, -70, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, -1, 1],
    [-70, -68, -69, -69, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN],
    [NAN, -68, -69, -69, -70, -70, NAN, NAN, NAN, NAN, NAN, NAN, NAN],
]


def test_a_line_down_a_turned_steps_face_leads_the_floor_no_further_than_a_step():
    heights = (np.array(SLANTED_LINE_MM) / 1000.0).astype(np.float32)
    floors = (heights > -0.002) | (heights < -0.067)  # the two floors' cells fit planes
    lower = heights < -0.067
    seeds = heights > -0.002
    grown = {}
    everywhere = np.ones(heights.shape, bool)
    for label, planar in (("anchored", floors), ("every cell planar", everywhere)):
        grown[label] = grow_region(heights, seeds, STEP, np.isnan(heights),
                                   math.tan(MAX_SLOPE) * RES, heights, planar=planar)
    assert not (grown["anchored"] & lower).any()
    assert (grown["every cell planar"] & lower).any()  # the growth as it was
    # the chain's cells within a step of the floor still join it, none beyond
    chain = ~floors & ~np.isnan(heights)
    assert np.array_equal(grown["anchored"] & chain, chain & (heights >= -0.05))


# Step room 1022's step down, 5.5 cm deep, at its 6th scan at 0.3 px: the floor
# candidates (mm) round the step's face (`grow_region`'s heights; steep ones in the
# candidates only), the cells without a hit, the cells whose windows fit a plane (the
# floor below's) and the floor plane's seeds (its inliers, the face cell at -28 among
# them, all on the plane at 0). From the seed at -28 the growth jumped the gaps to -45,
# within a step of the plane, and on to the floor below, whose cells fit planes and so
# anchored themselves: 144 cells FREE
SEED_ON_A_FACE = {
    "heights": [
        [NAN, 2, -1, -33, NAN, NAN, 2, 0, NAN],
        [-2, NAN, NAN, -32, NAN, NAN, 5, NAN, NAN],
        [1, -28, -28, NAN, NAN, NAN, NAN, NAN, NAN],
        [-3, -11, NAN, NAN, -60, -55, NAN, NAN, NAN],
        [-8, -20, NAN, NAN, -45, NAN, NAN, -55, NAN],
        [-6, NAN, NAN, NAN, NAN, -55, -55, NAN, NAN],
        [NAN, NAN, NAN, NAN, -56, -57, NAN, NAN, NAN],
        [NAN, NAN, NAN, -56, -55, NAN, NAN, NAN, -55],
        [NAN, NAN, -57, -54, NAN, NAN, -55, -56, -55]],
    "candidates": [
        [NAN, 2, -1, -33, -23, NAN, 2, 0, NAN],
        [-2, 2, -31, -32, -26, -6, 5, NAN, NAN],
        [1, -28, -28, NAN, NAN, NAN, NAN, -50, -6],
        [-3, -11, NAN, NAN, -60, -55, -38, -12, -48],
        [-8, -20, NAN, NAN, -45, NAN, NAN, -55, NAN],
        [-6, NAN, NAN, NAN, NAN, -55, -55, NAN, NAN],
        [NAN, NAN, NAN, NAN, -56, -57, NAN, NAN, NAN],
        [NAN, NAN, NAN, -56, -55, NAN, NAN, NAN, -55],
        [NAN, NAN, -57, -54, NAN, NAN, -55, -56, -55]],
    "empty": ["100001001", "000000011", "000111100", "001100000", "001101100",
              "011110011", "111100111", "111001110", "110011000"],
    "planar": ["000000000", "000000000", "000000000", "000000000", "000000000",
               "000000000", "000011000", "000110001", "001100111"],
    "seeds": ["011000110", "100000100", "111000000", "110000000", "110000000",
              "100000000", "000000000", "000000000", "000000000"],
}


def test_a_cell_that_fits_a_plane_joins_only_within_a_step_of_the_anchor_it_is_reached_from():
    case = SEED_ON_A_FACE
    heights, candidates = (np.array(case[k], np.float32) / 1000.0
                           for k in ("heights", "candidates"))
    seeds, empty, planar = (np.array([[c == "1" for c in row] for row in case[k]])
                            for k in ("seeds", "empty", "planar"))
    lower = heights < -0.05
    grown = {label: grow_region(heights, seeds, STEP, empty, math.tan(MAX_SLOPE) * RES,
                                candidates, planar=mask, seed_floor=np.zeros_like(heights))
             for label, mask in (("anchored", planar),
                                 ("every cell planar", np.ones(heights.shape, bool)))}
    assert not (grown["anchored"] & lower).any()
    assert (grown["every cell planar"] & lower).any()  # cell by cell it walks down
    # the face's cells within a step of the floor plane still join it
    assert grown["anchored"][4, 4] and heights[4, 4] == pytest.approx(-0.045)


@settings(max_examples=60, deadline=None)
@given(degrees=st.floats(0.0, 14.5), step=st.floats(0.03, 0.12))
def test_a_ramp_whose_foot_holds_seeds_above_the_floor_plane_is_climbed_whatever_the_step(
        degrees, step):
    # The floor plane's inliers (within plane_tolerance, 3 cm) seed the growth, a ramp's
    # foot among them; each anchored at the plane's height, a robot with a 3 cm step
    # climbed no ramp past its seeds (ramp F1 0.31-0.55 in random rooms 1-6). A seed whose
    # window fits a plane anchors its own height, as any planar cell does. (A step under a
    # ramp's rise across two cells, 2.6 cm at 14.5 deg, stops it at `_spans_no_step`.)
    heights = np.tile(np.arange(24) * RES * math.tan(math.radians(degrees)),
                      (5, 1)).astype(np.float32)
    seeds = heights <= FloorConfig().plane_tolerance
    grown = grow_region(heights, seeds, step, np.zeros(heights.shape, bool),
                        math.tan(MAX_SLOPE) * RES, heights,
                        seed_floor=np.zeros_like(heights))
    assert grown.all()


@settings(max_examples=60, deadline=None)
@given(degrees=st.floats(0.0, 15.0), direction=st.floats(0.0, 2.0 * math.pi),
       base=st.floats(-5.0, 5.0))
def test_no_cell_of_a_ramp_within_max_slope_bridges_a_step(degrees, direction, base):
    # `bridged_steps` looks as far as a ramp at max_slope rises 9/10 of a step
    assert FloorConfig().max_slope == pytest.approx(math.radians(15.0))
    y, x = np.mgrid[0:11, 0:11] * RES
    rise = math.tan(math.radians(degrees)) * (math.cos(direction) * x + math.sin(direction) * y)
    heights = (base + rise).astype(np.float32)
    level = np.full(heights.shape, degrees <= math.degrees(_model.LEVEL_SLOPE))
    assert not _model._bridged_steps(heights, level, *DEFAULT_ROBOT).any()


@settings(max_examples=60, deadline=None)
@given(degrees=st.floats(0.0, 19.0), direction=st.floats(0.0, 2.0 * math.pi),
       seed=st.integers(0, 2**32 - 1))
def test_no_cell_of_a_ramp_within_a_steep_slope_bridges_a_low_step(degrees, direction, seed):
    # A robot with a 3 cm step and 20 deg: `bridged_steps` looks two cells across, where
    # a ramp steeper than 16.7 deg rises more than a step (ramp room 11203's 17.2 deg
    # ramp: 250 of its 274 cells bridges, not floor). The middles of the cells' levels
    # stray from the ramp's plane at their centres where the lines cross the cells
    # unevenly (here by as little as leaves cells next to each other within a step);
    # their mean hits lie on it
    robot, params = RobotShape(step_height=0.03), FloorConfig(max_slope=math.radians(20.0))
    assert _model._bridge_reach(robot, params, RES) == 2.0 > _model._ramp_run(robot, params,
                                                                               RES)
    rng = np.random.default_rng(seed)
    gradient = math.tan(math.radians(degrees)) * np.array([math.cos(direction),
                                                           math.sin(direction)])
    y, x = np.mgrid[0:11, 0:11] * RES
    offsets = rng.uniform(-0.5 * RES, 0.5 * RES, (11, 11, 2)).astype(np.float32)
    hit_heights = ((x + offsets[..., 0]) * gradient[0]
                   + (y + offsets[..., 1]) * gradient[1]).astype(np.float32)
    middles = (x * gradient[0] + y * gradient[1]
               + rng.uniform(-0.0025, 0.0025, x.shape)).astype(np.float32)
    level = np.full(x.shape, degrees <= math.degrees(_model.LEVEL_SLOPE))
    spans = np.abs(np.float32(RES) * (np.abs(gradient[0]) + np.abs(gradient[1])))
    assert not _model._bridged_steps(middles, level, robot, params, RES,
                                     (np.full(x.shape, spans, np.float32), hit_heights,
                                      offsets)).any()


@pytest.mark.parametrize("depth", [0.034, 0.04])
def test_a_step_just_deeper_than_a_low_step_is_bridged_across_two_cells(depth):
    # For the same robot a step down 3.4 cm, its face cell half way down between its two
    # sides, rises 19 deg across them, but its face cell's level spans the step, more
    # than a ramp's cell: a bridge, floors level or not (by the slope alone the face
    # joined the floor, which lay within a step of the floor below: at 0.3 px half the
    # step's drop-off cells unknown)
    robot, params = RobotShape(step_height=0.03), FloorConfig(max_slope=math.radians(20.0))
    heights = np.zeros((9, 9), np.float32)
    heights[:, 5:] = -depth
    heights[:, 4] = -0.5 * depth
    spans = np.where(heights == heights[0, 4], depth, 0.002).astype(np.float32)
    hits = (spans, heights, np.zeros((*heights.shape, 2), np.float32))
    for level in (heights != heights[0, 4], np.zeros(heights.shape, bool)):
        bridges = _model._bridged_steps(heights, level, robot, params, RES, hits)
        assert bridges[:, 4].all() and not bridges[:, :3].any() and not bridges[:, 6:].any()


def test_a_raised_ramps_cells_are_no_bridges_for_a_robot_with_a_high_step_and_a_low_slope():
    # A 7.7 deg ramp rising 13 cm along x, the floor beside it across y: for a robot with
    # a 10 cm step and 10 deg, "as far as a ramp at max_slope rises 0.9 of a step" is
    # 0.51 m, and the ramp's upper cells lay within a step of both its top and the floor
    # beside, more than a step apart: bridges, not floor (ramp F1 0.75 in random room 1)
    robot, params = RobotShape(step_height=0.1), FloorConfig(max_slope=math.radians(10.0))
    reach = _model._bridge_reach(robot, params, RES)
    assert reach == pytest.approx(_model.FACE_SPAN / RES)
    assert _model._bridge_reach(RobotShape(), FloorConfig(), RES) < reach  # the default's
    heights = np.zeros((24, 28), np.float32)
    heights[8:] = np.arange(28) * RES * math.tan(math.radians(7.7))
    level = np.zeros(heights.shape, bool)
    level[:8] = True
    bridges = _model._bridged_steps(heights, level, robot, params, RES)
    # next to its side face, where that rises higher than a step, a cell or two may be
    # (as for the default robot); past them none (0.51 m across: 73 cells, rows 8-17)
    assert not bridges[10:].any() and bridges.sum() <= 10
    # a step of 12 cm beside the same floor is bridged still, a face cell between
    heights[8:] = 0.12
    heights[8, :] = 0.06
    assert _model._bridged_steps(heights, level, robot, params, RES)[8].all()


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(0.0, math.pi), seed=st.integers(0, 2**32 - 1))
def test_one_laser_lines_hits_across_flat_floor_are_not_steep(angle, seed):
    # The first scan's lines cross the far floor one at a time: the hits' mean positions
    # in a window lie within a few mm of one line (range noise, the line's bend), and a
    # plane through them would tilt with the noise
    rng = np.random.default_rng(seed)
    across = (-math.sin(angle), math.cos(angle))
    heights = np.full((9, 9), np.nan)
    offsets = np.zeros((9, 9, 2))
    along = (math.cos(angle), math.sin(angle))
    for t in np.linspace(-0.2, 0.2, 400):  # the line through the window's centre
        x, y = 0.2 + t * along[0], 0.2 + t * along[1]
        col, row = round(x / RES), round(y / RES)
        if 0 <= col < 9 and 0 <= row < 9 and np.isnan(heights[row, col]):
            heights[row, col] = rng.normal(0.0, 0.002)
            off = rng.normal(0.0, 0.003)
            offsets[row, col] = x + off * across[0] - col * RES, y + off * across[1] - row * RES
    slope = slope_of(heights, offsets=offsets)
    assert slope[4, 4] < math.radians(10.0)


def ramp_slopes_through_the_grid(seed: int, degrees: float, noise: float, dense: int
                                 ) -> np.ndarray:
    """The slopes `segment` gives the cells of a `degrees` ramp more than REACH cells from
    its border, each cell hit `dense` times in a random quarter of it and twice anywhere,
    as laser lines cross a turned ramp's cells, with height noise `noise` (m); each hit a
    vertical ray that clears nothing."""
    rng = np.random.default_rng(seed)
    grid = HeightGrid(GridConfig(extent=10.0, bundle_run=0))
    corners = rng.integers(0, 2, (20, 20, 2)) * 0.5 * RES  # each cell's dense quarter
    cells = np.stack(np.mgrid[0:20, 0:20], -1)[..., ::-1] * RES  # (x, y) of each corner
    in_quarter = rng.uniform(0, 0.5 * RES, (20, 20, dense, 2))
    sparse = cells[:, :, None] + rng.uniform(0, RES, (20, 20, 2, 2))
    xy = np.concatenate([cells[:, :, None] + corners[:, :, None] + in_quarter, sparse],
                        axis=2).reshape(-1, 2) + 1e-4
    z = math.tan(math.radians(degrees)) * xy[:, 0] + rng.normal(0.0, noise, len(xy))
    points = np.column_stack([xy, z])
    grid.insert(points, points + [0.0, 0.0, 0.5], 0.0)
    seg = floor.segment(grid.layers((0.0, 0.0, 20 * RES, 20 * RES)), RobotShape(),
                        FloorConfig())
    return seg.slope[REACH:-REACH, REACH:-REACH]


@pytest.mark.parametrize("seed", range(4))
def test_a_ramp_whose_cells_are_hit_unevenly_has_its_slope_from_the_mean_hits(seed):
    # The middle of a cell's heights lies 1.4 mm RMS off the plane at its mean hit, and
    # the slopes fitted through them came out 0.1-0.2 deg low in the median and up to
    # 15.0 deg; the mean hit's height lies on the plane (0.25 mm: the 1 mm noise averaged)
    inner = ramp_slopes_through_the_grid(seed, 14.6, 0.001, 12)
    assert (inner < MAX_SLOPE).all()
    assert abs(np.median(inner) - math.radians(14.6)) < math.radians(0.05)


@pytest.mark.parametrize("seed", range(4))
def test_a_noisy_ramps_thick_cells_take_their_mean_hits_height_for_the_slope(seed):
    # A 14 deg ramp with 5 mm of height noise (3-4 m off at 0.3 px of laser peak noise)
    # and 38 hits a cell: their extremes lie about three times the noise off the plane,
    # and the cells' levels span 24 mm in the median, a third of them more than
    # max_slope across a cell's diagonal and twice the noise. Taking their middles, 1-3
    # of its 256 cells came out steeper than max_slope (up to 15.0 deg) in each of six
    # seeds; through the mean hits, 14.5-14.8 at most
    inner = ramp_slopes_through_the_grid(seed, 14.0, 0.005, 36)
    assert (inner < MAX_SLOPE).all()  # False for NaN: no floor
    assert abs(np.median(inner) - math.radians(14.0)) < math.radians(0.1)


@pytest.mark.parametrize("degrees", [12.0, 14.0, 14.6])
def test_a_ramps_side_over_the_floor_a_little_lower_has_the_ramps_slope(degrees):
    # A ramp rising along x from x = 0, its side along y = 0, the floor beside it and
    # before it at 0: near its low corner the floor beside lies within a step below its
    # side cells, and the plane over a side cell's whole window tilts towards it, steeper
    # than the ramp (ramp rooms: a 14.6 deg ramp's side cells 15-19 deg, not floor); the
    # plane over the cells at or above the cell (the ramp alone) does not
    y, x = (np.mgrid[0:16, 0:24] - np.array([5, 5])[:, None, None] + 0.5) * RES
    rise = math.tan(math.radians(degrees))
    heights = np.where((x > 0.0) & (y > 0.0), rise * x, 0.0)
    slope = slope_of(heights)
    side = (y > 0.0) & (y < 2 * RES) & (x > 0.0) & (rise * x < STEP)
    assert side.sum() >= 8  # two rows of four cells or more
    assert np.allclose(slope[side], math.radians(degrees), atol=math.radians(0.05))


def test_the_floor_grows_no_staircase_down_a_steps_edge():
    # A 5.6 cm step down: the upper floor's edge cells, partly over the face, 9 mm low
    # (too near the floor to bridge the step), each within a step of the floor below
    # (4.7 cm): grown cell by cell, the floor walked down the two (step room 11: 18 cells
    # of its lower floor FREE). Every floor cell next to the edge cell lies more than a
    # step above the floor below, so the edge cell is no way down
    heights = np.zeros((7, 12), np.float32)
    heights[:, 5], heights[:, 6:] = -0.009, -0.056
    seeds = np.zeros((7, 12), bool)
    seeds[3, 0] = True
    grown = grow_region(heights, seeds, STEP, np.zeros((7, 12), bool),
                        math.tan(MAX_SLOPE) * RES, heights)
    assert grown[:, :6].all() and not grown[:, 6:].any()


@settings(max_examples=60, deadline=None)
@given(heights=arrays(np.float32, st.tuples(st.integers(1, 16), st.integers(1, 16)),
                      elements=st.sampled_from([0.0, 0.0, 0.0, 0.0, 0.0, 0.03, 0.06, np.nan]),
                      fill=st.nothing()))
def test_the_bridges_searched_where_heights_vary_are_those_searched_everywhere(heights):
    """`_model._bridged_steps` looks only where the candidates round a cell span more than
    a step; the kernel asked to look everywhere finds the same cells (on level floor
    with a few cells a step's face or its far side apart: bridges here and there)."""
    level = heights != np.float32(0.03)  # the face's cells are not level
    limits = _model._bridge_limits(*DEFAULT_ROBOT)
    everywhere = bridged_steps(heights, level, STEP, limits[0], np.ones(heights.shape, bool),
                               np.zeros(heights.shape, np.float32), heights,
                               np.zeros((*heights.shape, 2), np.float32), RES, *limits[1:])
    assert np.array_equal(_model._bridged_steps(heights, level, *DEFAULT_ROBOT),
                          everywhere)


# Step room 1196's step down, 5.8 cm deep, turned 47 deg, at its 4th scan at 0.1 px: the
# floor candidates' mean hit heights (mm) round its face (rows along y), the heights their
# lowest levels span (mm) and where their hits lie. Lines lit the face at several heights,
# so the cells it crosses hold levels up to 6 cm tall, their middles half way down (-28 to
# -36 mm); the cells between them and the two floors held no hit, so the floor above, the
# face's cells and the floor below (-58 mm) lay on one 12 deg plane, and the growth
# crossed the face through them: 118 cells of the floor below FREE
FACE_HALF_WAY_MM = [
    [-1, -1, 0, 0, NAN, NAN, 0, 0, 0, NAN, 1],
    [NAN, NAN, 0, NAN, NAN, 0, 0, 0, NAN, 0, -29],
    [NAN, 0, 0, NAN, 0, 0, NAN, NAN, -1, -28, -58],
    [0, 0, 0, 0, 0, NAN, NAN, NAN, -29, -59, NAN],
    [0, 1, 0, 0, NAN, NAN, -30, -30, NAN, NAN, NAN],
    [1, 0, 0, NAN, NAN, -30, -31, NAN, NAN, NAN, -58],
    [0, 1, NAN, NAN, -33, -31, NAN, NAN, NAN, -58, -59],
    [0, NAN, NAN, -35, -34, NAN, NAN, -57, -58, NAN, -58],
    [NAN, NAN, -31, -36, NAN, NAN, -58, -58, NAN, -58, -58],
    [NAN, -32, -33, NAN, -59, -58, -58, -58, -58, -58, NAN],
    [0, -58, NAN, -58, -58, -58, -57, -58, -57, NAN, NAN],
]
FACE_HALF_WAY_SPANS_MM = [
    [1, 0, 1, 1, NAN, NAN, 2, 3, 2, NAN, 3],
    [NAN, NAN, 2, NAN, NAN, 3, 4, 0, NAN, 1, 60],
    [NAN, 3, 1, NAN, 2, 3, NAN, NAN, 2, 60, 1],
    [1, 2, 3, 3, 2, NAN, NAN, NAN, 60, 0, NAN],
    [3, 2, 3, 3, NAN, NAN, 48, 59, NAN, NAN, NAN],
    [4, 3, 4, NAN, NAN, 22, 41, NAN, NAN, NAN, 3],
    [0, 3, NAN, NAN, 13, 12, NAN, NAN, NAN, 3, 1],
    [3, NAN, NAN, 40, 25, NAN, NAN, 2, 3, NAN, 2],
    [NAN, NAN, 56, 47, NAN, NAN, 2, 2, NAN, 4, 3],
    [NAN, 53, 52, NAN, 2, 4, 4, 2, 2, 1, NAN],
    [3, 2, NAN, 2, 2, 2, 0, 3, 0, NAN, NAN],
]

FACE_HALF_WAY_X_MM = [  # where each cell's hits lie off its centre, x and y
    [1, -25, 21, -13, 0, 0, 21, 1, 1, 0, 7],
    [0, 0, 0, 0, 0, 19, -3, -19, 0, 11, -4],
    [0, 13, -20, 0, 9, -6, 0, 0, 13, -6, -12],
    [21, -12, 4, 4, -7, 0, 0, 0, -8, -22, 0],
    [5, 2, 7, -7, 0, 0, 16, -8, 0, 0, 0],
    [-15, 17, -4, 0, 0, 13, -9, 0, 0, 0, 8],
    [16, -9, 0, 0, 12, -10, 0, 0, 0, -3, -19],
    [-9, 0, 0, 8, -14, 0, 0, 14, 0, 0, 9],
    [0, 0, 10, -16, 0, 0, 7, -9, 0, 3, -6],
    [0, 8, -15, 0, 21, -1, -1, 3, 2, -18, 0],
    [0, -8, 0, 14, -3, 2, -16, 1, -23, 0, 0],
]
FACE_HALF_WAY_Y_MM = [
    [3, -22, 20, -5, 0, 0, 20, 2, -11, 0, 3],
    [0, 0, 1, 0, 0, 20, -4, -19, 0, 6, -1],
    [0, 7, -18, 0, 8, -8, 0, 0, 11, -1, -18],
    [21, -5, 16, -4, -5, 0, 0, 0, -5, -23, 0],
    [2, -3, 4, -7, 0, 0, 16, -8, 0, 0, 0],
    [-16, 17, -11, 0, 0, 14, -11, 0, 0, 0, 11],
    [16, -7, 0, 0, 11, -14, 0, 0, 0, 6, -19],
    [-9, 0, 0, 11, -14, 0, 0, 19, -8, 0, 12],
    [0, 0, 8, -17, 0, 0, 10, -14, 0, 10, -14],
    [0, 9, -12, 0, 24, 4, 2, 2, -1, -19, 0],
    [-6, -11, 0, 18, -2, -5, -18, 3, -19, 0, 0],
]


def floor_from_above(heights: np.ndarray, slope: np.ndarray, tangent: np.ndarray,
                     planar: np.ndarray) -> np.ndarray:
    """The floor grown from the cells at 0 (within 5 mm) over the cells no steeper than
    MAX_SLOPE, jumping the cells without a hit and along `tangent`'s planes, anchored at
    the `planar` cells (as `segmentation._segment` grows it, the floor plane at 0)."""
    level = np.where(slope > MAX_SLOPE, np.nan, heights).astype(np.float32)
    return grow_region(level, heights > -0.005, STEP, np.isnan(heights),
                       math.tan(MAX_SLOPE) * RES, heights, tangent, 2.0 * NOISE, planar,
                       np.zeros_like(heights))


def test_a_window_holding_a_steps_face_fits_no_plane_so_the_floor_stays_above_it():
    heights = (np.array(FACE_HALF_WAY_MM) / 1000.0).astype(np.float32)
    spans = np.array(FACE_HALF_WAY_SPANS_MM) / 1000.0
    offsets = np.stack([FACE_HALF_WAY_X_MM, FACE_HALF_WAY_Y_MM], axis=-1) / 1000.0
    faces = spans > STEP  # False for NaN
    lower = heights < -0.05
    grown = {}
    for label, marked in (("faces", faces), ("none", np.zeros(heights.shape, bool))):
        slope, tangent = local_slope(heights, offsets, REACH, STEP, RES, NOISE, marked)
        grown[label] = floor_from_above(heights, slope, tangent,
                                        ~np.isnan(tangent[:, :, 3]))
    assert (grown["none"] & lower).any()  # through a window on the 12 deg plane
    assert not (grown["faces"] & lower).any()
    assert grown["faces"][heights > -0.005].all()  # the floor above is floor still


# The same step's 3rd scan: one laser line crossed the face at a slant, its cells (mm)
# grading from the floor above to the floor below along a diagonal chain (-6 to -53),
# with a line on each floor beside it. The window of one of its cells (-29 mm) fits a
# 14.7 deg plane through the three lines, a ramp as far as they tell, and no other window
# round that cell agrees with it: as an anchor it let the floor half way down and on onto
# the floor below (51 cells FREE)
SLANTED_ACROSS_FLOORS_MM = [
    [-1, -1, NAN, NAN, NAN, NAN, 0, 0, 0, NAN, NAN],
    [NAN, NAN, NAN, NAN, NAN, 0, 0, 0, NAN, NAN, -58],
    [NAN, NAN, NAN, NAN, 0, 0, NAN, NAN, NAN, -57, -58],
    [NAN, NAN, 0, 0, 0, NAN, NAN, -59, -58, -59, NAN],
    [1, 1, 0, 0, NAN, NAN, -53, -57, NAN, NAN, NAN],
    [1, 0, 0, NAN, NAN, -40, -47, NAN, NAN, NAN, -58],
    [0, 1, NAN, NAN, -29, -37, NAN, NAN, NAN, -58, -59],
    [0, NAN, NAN, -18, -23, NAN, NAN, -57, -58, NAN, NAN],
    [NAN, NAN, -6, -12, NAN, NAN, -58, -58, NAN, -57, -58],
    [NAN, 0, 1, NAN, -59, -58, -58, -58, -58, NAN, NAN],
    [0, NAN, NAN, -58, -58, -58, -57, NAN, NAN, NAN, NAN],
]
SLANTED_ACROSS_FLOORS_X_MM = [
    [1, -25, 0, 0, 0, 0, 21, 1, 1, 0, 0],
    [0, 0, 0, 0, 0, 19, -3, -19, 0, 0, 8],
    [0, 0, 0, 0, 9, -6, 0, 0, 0, 2, -12],
    [0, 0, 4, 4, -7, 0, 0, 23, -2, -22, 0],
    [18, 2, 7, -7, 0, 0, 17, -4, 0, 0, 0],
    [-9, 17, -4, 0, 0, 9, -10, 0, 0, 0, 8],
    [16, -9, 0, 0, 13, -9, 0, 0, 0, -3, -19],
    [-9, 0, 0, 7, -16, 0, 0, 14, 0, 0, 0],
    [0, 0, 6, -17, 0, 0, 7, -9, 0, -5, 1],
    [0, 2, -22, 0, 21, -1, -1, 3, -2, 0, 0],
    [0, 0, 0, 14, -3, 2, -16, 0, 0, 0, 0],
]
SLANTED_ACROSS_FLOORS_Y_MM = [
    [3, -22, 0, 0, 0, 0, 20, 2, -11, 0, 0],
    [0, 0, 0, 0, 0, 20, -4, -19, 0, 0, 16],
    [0, 0, 0, 0, 8, -8, 0, 0, 0, 10, -18],
    [0, 0, 16, -4, -5, 0, 0, 18, 0, -23, 0],
    [17, -3, 4, -7, 0, 0, 15, -10, 0, 0, 0],
    [-17, 17, -11, 0, 0, 18, -10, 0, 0, 0, 11],
    [16, -7, 0, 0, 11, -15, 0, 0, 0, 6, -19],
    [-9, 0, 0, 12, -13, 0, 0, 19, -8, 0, 0],
    [0, 0, 9, -16, 0, 0, 10, -14, 0, 13, -12],
    [0, 4, -15, 0, 24, 4, 2, 2, -17, 0, 0],
    [-6, 0, 0, 18, -2, -5, -18, 0, 0, 0, 0],
]


def test_a_plane_no_other_window_round_a_cell_agrees_with_anchors_no_floor():
    heights = (np.array(SLANTED_ACROSS_FLOORS_MM) / 1000.0).astype(np.float32)
    offsets = np.stack([SLANTED_ACROSS_FLOORS_X_MM, SLANTED_ACROSS_FLOORS_Y_MM],
                       axis=-1) / 1000.0
    slope, tangent = local_slope(heights, offsets, REACH, STEP, RES, NOISE,
                                 np.zeros(heights.shape, bool))
    planar = ~np.isnan(tangent[:, :, 3])
    lone = (6, 4)  # its own window fits, no other round it does
    assert heights[lone] == pytest.approx(-0.029) and slope[lone] <= MAX_SLOPE
    assert not planar[lone]
    lower = heights < -0.05
    with_lone = planar.copy()
    with_lone[lone] = True
    grown = {label: floor_from_above(heights, slope, tangent, anchors)
             for label, anchors in (("agreeing", planar), ("lone too", with_lone))}
    assert (grown["lone too"] & lower).any()  # the floor as it grew before
    assert not (grown["agreeing"] & lower).any()
