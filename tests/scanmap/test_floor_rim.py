"""A hole's rim in the segmentation, on hand-built cells: floor next to a drop-off whose
hits reach down the hole's far wall is not driven on."""

from __future__ import annotations

import pytest

from scanmap.grid import _kernels as gk
from scanmap.navigation.floor import DROP_OFF, FREE, UNKNOWN, segment
from tests.scanmap.test_overhangs import ROBOT, floor_cells

ROWS = slice(6, 18)  # the hole's extent across, and its rim's


def rim_cells(rim_bottom: float):
    """Floor sloping down 8 mm a cell over three columns to a rim column whose one level
    runs from -1.4 cm down to `rim_bottom`, then a hole 0.3 m deep; every cell hit 20
    times and seen free over the whole band."""
    layers = floor_cells()
    layers.counts[...] = 20
    for col, z in ((10, -0.008), (11, -0.016), (12, -0.024)):
        layers.levels[ROWS, col, 0, gk.LO], layers.levels[ROWS, col, 0, gk.HI] = z, z + 0.002
    layers.levels[ROWS, 13, 0, gk.LO], layers.levels[ROWS, 13, 0, gk.HI] = rim_bottom, -0.014
    layers.levels[ROWS, 14:20, 0, gk.LO], layers.levels[ROWS, 14:20, 0, gk.HI] = -0.31, -0.30
    return layers


@pytest.mark.parametrize("rim_bottom, free", [(-0.061, False), (-0.02, True)])
def test_floor_beside_a_drop_off_reaching_down_its_far_wall_is_not_free(rim_bottom, free):
    # Rendered mixed rooms 5 and 10: a cell holding the rim and the far wall's top, one
    # level from -1 cm down to -4.4 and -6.1 cm, was floor (its slope 11 deg, the cells
    # before it lowered too) and FREE a cell inside the hole. Floor next to a DROP_OFF
    # cell reaching more than plane_tolerance (3 cm) below the floor's plane is UNKNOWN;
    # a rim within it, or at the floor's height, stays FREE
    seg = segment(rim_cells(rim_bottom), ROBOT)
    assert (seg.state[ROWS, 14:20] == DROP_OFF).all()
    assert seg.is_floor[ROWS, 13].all()  # floor, but not driven on
    assert (seg.state[ROWS, 13] == (FREE if free else UNKNOWN)).all()
    assert (seg.state[ROWS.stop, 14:20] == FREE).all()  # the floor beside, at its height


@pytest.mark.parametrize("mean_x, free", [(-0.35, False), (-0.2, True), (0.35, True)])
def test_a_rim_cell_whose_hits_lie_on_its_far_side_from_the_hole_is_not_free(mean_x, free):
    # Ideal random rooms 1-3: 39 FREE cells had their centres over a hole, their floor's
    # hits on a rim part less than half of the cell. Hits spread over the part an edge
    # leaves put their mean (1 - f) / 2 of a cell from the centre where the floor covers
    # f of it: a mean more than a quarter cell from the centre away from the drop-off
    # leaves the cell UNKNOWN; nearer the centre, or towards the hole, it stays FREE
    layers = rim_cells(-0.02)
    layers.levels[ROWS, 13, 0, gk.MX] = mean_x * layers.resolution
    seg = segment(layers, ROBOT)
    assert (seg.state[ROWS, 14:20] == DROP_OFF).all()
    assert (seg.state[ROWS, 13] == (FREE if free else UNKNOWN)).all()
    assert (seg.state[ROWS, 12] == FREE).all()


def test_floor_between_two_drop_off_cells_is_not_free():
    # Rendered mixed room 3: a cell of floor-height hits (a rim's, landed a cell inside
    # the hole) with the hole's cells on either side of it was FREE more than a cell
    # inside. Floor between two DROP_OFF cells across it is UNKNOWN; the hole's rim, the
    # drop-off on one side only, stays FREE
    layers = rim_cells(-0.02)
    layers.levels[11, 16, 0, gk.LO], layers.levels[11, 16, 0, gk.HI] = 0.0, 0.002
    seg = segment(layers, ROBOT)
    assert seg.state[11, 15] == DROP_OFF and seg.state[11, 17] == DROP_OFF
    assert seg.state[11, 16] == UNKNOWN
    assert (seg.state[ROWS, 13] == FREE).all()


def blank_beside_floor():
    """Floor hit 20 times a cell, beside a patch nothing was seen in (rows 6-17, columns
    14-19: no hit, no height seen, as a black-lined hole leaves it)."""
    layers = floor_cells()
    layers.counts[...] = 20
    layers.nlev[ROWS, 14:20] = 0
    layers.seen[ROWS, 14:20] = 0
    return layers


@pytest.mark.parametrize("hits, state", [(1, UNKNOWN), (2, UNKNOWN), (3, FREE)])
def test_floor_on_few_hits_jutting_into_blank_space_is_not_free(hits, state):
    # Rendered mixed rooms 1 and 7: one floor-height hit of a black-lined hole's rim, 3-4
    # cm off its true place (the stripe cut by the rim) and a few cm of registration, a
    # cell inside the hole, was FREE with five of its eight neighbours unobserved
    layers = blank_beside_floor()
    layers.nlev[11, 14], layers.seen[11, 14] = 1, layers.seen[0, 0]
    layers.counts[11, 14, 0, gk.HITS] = hits
    seg = segment(layers, ROBOT)
    assert seg.state[11, 14] == state
    assert (seg.state[ROWS, 13] == FREE).all()  # the rim beside it, hit 20 times


def test_floor_on_one_hit_along_blank_space_stays_free():
    # The rim's cells on one hit each, two or three of their neighbours unobserved (a
    # straight edge, not a corner or a tip): they stay FREE
    layers = blank_beside_floor()
    layers.counts[5:19, 13, 0, gk.HITS] = 1
    seg = segment(layers, ROBOT)
    assert (seg.state[ROWS, 13] == FREE).all()
    assert (seg.state[ROWS, 14:20] == UNKNOWN).all()


def test_floor_joined_to_the_free_space_by_one_neighbour_is_not_free():
    # Rendered mixed room 3: a rim cell hit 7 times in one scan, 8 cm of registration
    # drift inside a hole, was FREE with seven of its eight neighbours unobserved. However
    # many hits it holds, such a cell is UNKNOWN; the one joining it, with four, stays FREE
    layers = blank_beside_floor()
    for col in (14, 15):
        layers.nlev[11, col], layers.seen[11, col] = 1, layers.seen[0, 0]
    seg = segment(layers, ROBOT)
    assert seg.state[11, 15] == UNKNOWN
    assert seg.state[11, 14] == FREE
