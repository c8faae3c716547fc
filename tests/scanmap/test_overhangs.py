"""Overhanging boards in the segmentation, on hand-built cells: what a table top seen only
at its rim hides, and what is no overhang (a box's top, the pieces of a wall face)."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import CellLayers
from scanmap.navigation.floor import FREE, RobotShape, segment

N = 24  # cells per side, 5 cm
Z_MIN, DZ = -0.35, 0.025
ROBOT = RobotShape(step_height=0.05, height=1.0)


def heights(lo: float, hi: float) -> np.uint64:
    """The observed-height bits covering [lo, hi] (m)."""
    return gk.height_mask(lo, hi, Z_MIN, DZ)


def floor_cells() -> CellLayers:
    """N x N cells of floor (a thin level at z = 0), each with every height seen free."""
    levels = np.zeros((N, N, 3, gk.N_FLOAT_FIELDS), np.float32)
    levels[:, :, 0, gk.HI] = 0.002
    levels[:, :, 0, gk.LOGODDS] = 3.5
    return CellLayers(origin=(0.0, 0.0), resolution=0.05, z_min=Z_MIN, mask_dz=DZ,
                      levels=levels, counts=np.ones((N, N, 3, 2), np.uint32),
                      nlev=np.ones((N, N), np.uint8),
                      seen=np.full((N, N), heights(-0.01, 1.0), np.uint64),
                      updated=np.zeros((N, N)))


def add_level(layers: CellLayers, where, lo: float, hi: float) -> None:
    """An occupied level [lo, hi] above the floor in the cells `where` (an index of N x N)."""
    cells = layers.levels[where]
    cells[..., 1, gk.LO], cells[..., 1, gk.HI], cells[..., 1, gk.LOGODDS] = lo, hi, 3.5
    layers.levels[where] = cells
    layers.nlev[where] = 2


def test_a_table_top_seen_at_its_rim_covers_the_cells_that_saw_only_under_it():
    """The rim (0.72-0.76 m) of a 12 x 12 cell table is hit, with rays seen under and over
    it; the cells inside saw the band only up to 0.6 m (more than half of it, so the
    coverage rule alone would call them free): none of them may be free floor."""
    layers = floor_cells()
    rim = np.zeros((N, N), bool)
    rim[6:18, 6:18] = True
    inside = np.zeros((N, N), bool)
    inside[7:17, 7:17] = True
    rim &= ~inside
    add_level(layers, rim, 0.72, 0.76)
    layers.seen[rim] = heights(-0.01, 0.7) | heights(0.78, 1.0)
    layers.seen[inside] = heights(-0.01, 0.6)
    seg = segment(layers, ROBOT)
    assert not (seg.state[inside] == FREE).any()
    assert not seg.is_floor[inside].any()
    outside = np.ones((N, N), bool)
    outside[5:19, 5:19] = False
    assert (seg.state[outside] == FREE).all() and seg.is_floor[outside].all()


def test_the_top_of_a_box_is_no_overhang_and_the_floor_behind_it_stays_free():
    """A 0.4 m box hit only on its top (rays from above, nothing seen under the top in its
    cells) shades the floor behind it up to 0.45 m. The cells behind saw more than half
    of the band and no overhang can reach over them: free floor, except those next to
    the box, whose unseen heights may hold the box."""
    layers = floor_cells()
    box = (slice(10, 14), slice(6, 10))
    layers.levels[box + (0,)] = 0.0
    layers.levels[box + (0, gk.LO)] = 0.39
    layers.levels[box + (0, gk.HI)] = 0.40
    layers.levels[box + (0, gk.LOGODDS)] = 3.5
    layers.seen[box] = heights(0.39, 1.0)
    behind = (slice(8, 16), slice(10, N))
    layers.seen[behind] = heights(-0.01, 0.04) | heights(0.45, 1.0)
    seg = segment(layers, ROBOT)
    assert not (seg.state[10:14, 10] == FREE).any()
    assert (seg.state[8:16, 11:] == FREE).all() and seg.is_floor[8:16, 11:].all()


@pytest.mark.parametrize("case", ["in front of the wall", "rising along the face",
                                  "rising 5 cm a cell"])
def test_pieces_of_a_wall_face_are_no_overhang(case):
    """Thin pieces of a wall face, with free space seen under them (rays that ended lower
    on the face): in front of the full-height wall they hold, or rising cell by cell as one
    sloping laser line leaves them (7.5 cm a cell; or 5 cm, so that each piece's heights
    touch its neighbours' at their edges, as a stray line of hits did in the corridor
    recording, covering the corridor 0.6 m around it). Cells in front that missed their
    heights stay free."""
    layers = floor_cells()
    face = 12
    rows = np.arange(2, N - 2)
    if case == "in front of the wall":
        add_level(layers, (rows, face + 1), 0.05, 1.0)
        pieces = [(0.40, 0.42)] * len(rows)
    elif case == "rising along the face":
        pieces = [(0.1 + 0.075 * k, 0.12 + 0.075 * k) for k in range(len(rows))]
    else:
        pieces = [(0.07 + 0.05 * k, 0.12 + 0.05 * k) for k in range(len(rows))]
    for row, (lo, hi) in zip(rows, pieces, strict=True):
        add_level(layers, (row, face), lo, hi)
        layers.seen[row, face] = heights(-0.01, 1.0) & ~heights(lo, hi)
    front = (slice(2, N - 2), slice(0, face))
    layers.seen[front] = heights(-0.01, 0.25) | heights(0.55, 1.0) if case == \
        "in front of the wall" else heights(-0.01, 0.04) | heights(0.35, 1.0)
    seg = segment(layers, ROBOT)
    away = (slice(2, N - 2), slice(0, face - 1))  # not next to the pieces
    assert (seg.state[away] == FREE).all() and seg.is_floor[away].all()


def test_pieces_of_a_wall_face_before_its_unseen_inside_are_no_overhang():
    """Pieces of a wall face a few mm inside their cells, where laser lines crossed it
    (0.15-0.2 m and 0.6-0.65 m), with the cells' free part seen under and between them
    and nothing below lit yet, in front of the wall's inside (never seen, nothing hit):
    a table's rim to every other test, they covered the cells up to 1 m in front that
    missed their heights (approach rooms: a ramp's cells 0.7 m from a corridor's wall not
    floor). Behind a table's rim rays pass under its top; behind a face, nothing."""
    layers = floor_cells()
    face = 12
    rows = np.arange(2, N - 2)
    for lo, hi in ((0.15, 0.2), (0.6, 0.65)):
        cells = layers.levels[rows, face]
        k = 1 if lo < 0.5 else 2
        cells[:, k, gk.LO], cells[:, k, gk.HI], cells[:, k, gk.LOGODDS] = lo, hi, 3.5
        layers.levels[rows, face] = cells
    layers.nlev[rows, face] = 3
    layers.seen[rows, face] = heights(-0.01, 1.0) & ~heights(0.15, 0.2) & ~heights(0.6, 0.65)
    inside = (slice(None), slice(face + 1, N))  # the wall's inside
    layers.nlev[inside] = 0
    layers.levels[inside] = 0.0
    layers.seen[inside] = 0
    # in front: more than half the band seen, not the pieces' heights
    layers.seen[2:N - 2, :face] = heights(-0.01, 0.12) | heights(0.25, 0.55) | heights(0.7, 1.0)
    seg = segment(layers, ROBOT)
    away = (slice(2, N - 2), slice(0, face - 1))
    assert (seg.state[away] == FREE).all() and seg.is_floor[away].all()


def test_the_raised_end_of_a_ramp_hit_past_it_is_no_overhang():
    """A ramp 12 cells wide rising 1.25 cm a cell (14 deg) from the floor to 23.75 cm,
    where it ends over the floor beyond, more than `clearance` above it; its top edge hit
    in the cells past the end, whose floor rays saw under it: a table's rim to the
    overhang rule, carried round the floor beside the ramp (seen over it), it covered the
    ramp's lower cells, whose bands (from 5 cm over their floor) reach its height and did
    not see it (ramp room 8006: 30 of its cells not floor). It is the rim of the floor
    beside it: every ramp cell is free floor."""
    layers = floor_cells()
    rows, cols = np.arange(6, 18), np.arange(2, 21)
    tops = 0.0125 * (cols - 1)
    for col, top in zip(cols, tops, strict=True):
        layers.levels[rows, col, 0, gk.LO] = top
        layers.levels[rows, col, 0, gk.HI] = top + 0.002
        layers.seen[rows, col] = heights(top - 0.01, top + 0.04) | heights(top + 0.3, 1.0)
    past = (rows, cols[-1] + 1)
    add_level(layers, past, tops[-1], tops[-1] + 0.002)
    layers.seen[past] = heights(-0.01, tops[-1] - 0.025) | heights(tops[-1] + 0.025, 1.0)
    # the floor beside it and beyond, seen over the ramp
    over = heights(-0.01, 0.04) | heights(0.3, 1.0)
    for side in (rows[0] - 1, rows[-1] + 1):
        layers.seen[side, cols[0]:past[1] + 2] = over
    layers.seen[rows[0] - 1:rows[-1] + 2, past[1] + 1] = over
    seg = segment(layers, ROBOT)
    ramp = np.ix_(rows[1:-1], cols)  # its side rows lie beside the floor up to 24 cm lower
    assert seg.is_floor[ramp].all()
    assert (seg.state[ramp] == FREE).all()
