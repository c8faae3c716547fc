"""Each cell's state: FREE, OBSTACLE, DROP_OFF or UNKNOWN.

Obstacles (docs/architecture.md): occupied space between floor + step height and floor + robot
height. A cell is FREE only if its floor height is known and not unlit (`_unseen`), nothing
occupies the band,
rays have seen at least `min_coverage` (half) of the band's height bins free there (on
known floor - a floor hit within a cell, or a gap - not beside a drop-off: there or
within `coverage_reach`, one cell, since the laser's lines cross a 5 cm cell at a few
heights only and its neighbours at others; an object hidden at the heights only the
neighbours saw is narrower than a cell and was never lit), and
no height it has not seen is suspect: occupied (within two height bins) in a
neighbouring cell, or possibly under an overhanging board (a table top seen only at its
rim), and it is not floor on one or two hits within two cells of a drop-off or a dip
(at the real extraction's noise, 0.3 px, a rim's or far wall's hits land up to two
cells inside a hole) or beside a cell without a hit within `max_hole` of such a dip
through cells without a hit (a hole seen only by its far wall's top), nor floor next
to a drop-off whose hits reach more than `plane_tolerance` below the largest floor
plane (the rim and the far wall's top in one level), nor floor between two drop-off
cells across it; otherwise it is UNKNOWN.
Occupied means a level with log-odds of at least `min_logodds`: one below it (seen,
then seen through more often since: where a person walked on) leaves its cell UNKNOWN,
neither an obstacle nor free. The footprint cells, observed floor or not, are FREE
unless something occupies their band or may overhang them. Of two FREE cells side by
side whose floors lie more than a step apart (a step's face on their boundary, or seen
only from its top), the lower is an OBSTACLE (the upper, where the robot stood on the
lower), as a drop-off lies beyond a rim and a raised floor's face at its foot: no robot
crosses there.

Why the map of one scan is mostly UNKNOWN: a cell is seen free at the heights that the
rays crossing it have there, and every ray of this scanner falls from the camera (1 m
up) to where it ends. From one place, a cell 1-2 m away is crossed only by rays ending
not far beyond it, near the floor; the band's upper heights there are crossed only by
rays ending much farther away, beyond the 4 m range or where nothing returns. In the
simulator's office one scan sees a median 35 % of the band in floor cells 1-1.5 m away,
21 % at 2-3 m, so almost none is FREE although its floor was hit. Scans from other
places cross the same cells at other heights: after the 24 scans round the office table
92 % of the floor is FREE. The rule stays: a cell whose band was mostly never looked at
may hold anything there, and a map of several scans (examples/planner.py) is the cure.
"""

from __future__ import annotations

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import CellLayers
from scanmap.navigation import morphology
from scanmap.navigation._kernels import DROP_OFF, FREE, OBSTACLE, UNKNOWN
from scanmap.navigation.floor._band_kernels import classify_band, free_steps, pooled_bits
from scanmap.navigation.floor._drop_offs import DropOffs
from scanmap.navigation.floor._model import FloorModel
from scanmap.navigation.floor._unseen import Unseen
from scanmap.navigation.floor.config import FloorConfig, RobotShape


def cell_states(layers: CellLayers, robot: RobotShape, params: FloorConfig,
                model: FloorModel, drops: DropOffs, unseen: Unseen, stood: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each cell's state, obstacle point and band log-odds (the module docstring's
    "Obstacles"), the cells that may lie under an overhanging board, and the lower of two
    FREE cells a step apart (made an OBSTACLE)."""
    ny, nx = layers.shape
    res = layers.resolution
    is_floor, floor_height, planes = model.is_floor, model.floor_height, model.planes
    drop, dips, bottom = unseen.drop, unseen.dips, drops.bottom
    state = np.empty((ny, nx), np.uint8)
    points = np.empty((ny, nx, 2), np.float32)
    band_logodds = np.empty((ny, nx), np.float32)
    covered = np.zeros((ny, nx), np.bool_)
    pool = round(params.coverage_reach / res)
    counted = layers.seen
    if pool:  # known floor off a drop-off's rim: the coverage over it and its neighbours
        known = morphology.dilate(is_floor) | unseen.holes | unseen.lines
        known &= ~morphology.dilate(drop)
        counted = np.where(known, pooled_bits(layers.seen, pool), layers.seen)
    classify_band(layers.levels, layers.nlev, layers.seen, counted, floor_height, is_floor,
                  robot.step_height, robot.height, layers.z_min, layers.mask_dz,
                  params.min_coverage, round(params.overhang_reach / res),
                  params.overhang_thickness, layers.origin[0], layers.origin[1], res,
                  state, points, band_logodds, covered, params.min_logodds)
    state[(state == FREE) & unseen.unlit] = UNKNOWN
    state[model.edges] = OBSTACLE  # floor on both sides, a step the robot cannot take between
    state[stood & (state != OBSTACLE) & ~covered] = FREE  # not under a board seen overhead
    # the face of a step down to floor reached round its ends and the shadow it spread
    # into are an edge: the floor there is not missing, but no robot crosses it
    sunk = drops.sunk
    step_down = morphology.geodesic_dilate(sunk, drop, ny * nx) if sunk.any() else sunk
    state[drop & ~step_down & (state != OBSTACLE)] = DROP_OFF
    state[step_down] = OBSTACLE
    state[_pinholes(state, layers.nlev, round(params.max_pinhole / res)) & ~unseen.dim] = FREE
    # Floor on one or two hits within two cells of a drop-off or a dip (a hole's far
    # wall seen only at its top): at the laser's noise a rim's or far wall's hits land up
    # to two cells inside the hole (the cells between unknown), and so few are no floor
    # to drive on there. A dip counts where it lies below every floor beside it, or next
    # to a cell without a hit (a hole's far wall, its side wall's top) and below every
    # floor within two cells that is no dip itself; not the face of a raised ramp seen
    # whole from its foot on the floor beside it up to its surface, nor that foot, level
    # with the floor round it (a dip only against the ramp rising beside it): the ramp's
    # cells beside them, crossed by one laser line or two, were left UNKNOWN
    scant = (layers.counts[:, :, 0, gk.HITS] <= 2) & (layers.nlev > 0) & ~stood
    dropped = (state == DROP_OFF) | step_down  # the rules below only take FREE to UNKNOWN
    beside_unseen = dips & morphology.dilate(layers.nlev == 0)
    if beside_unseen.any():
        beside_unseen &= _below_all_floor(layers.nlev, bottom, is_floor & ~dips, 0.0)
    sunken = dips & _below_all_floor(layers.nlev, bottom, is_floor, params.plane_tolerance) \
        | beside_unseen
    near_hole = morphology.dilate(dropped | sunken, 2)
    # and beside cells without a hit within max_hole of such a dip through cells without a
    # hit: a hole seen only by its far wall's top, whose near rim's noisy hits land in it
    # (mixed room 18405 at 0.3 px: a rim point 3.4 cm off, seen from 3 m, in the corner
    # cell two rims bound, 4-5 cells from the far walls: FREE in two scans)
    if sunken.any():
        hitless = (state == UNKNOWN) & (layers.nlev == 0)
        near_hole |= morphology.dilate(morphology.geodesic_dilate(
            morphology.dilate(sunken) & hitless, hitless, round(params.max_hole / res)))
    state[scant & (state == FREE) & near_hole] = UNKNOWN
    # and such a cell jutting into space where nothing was seen (five or more of its eight
    # neighbours UNKNOWN without a hit: a corner or a tip): the stripe cut at a black-lined
    # hole's rim and a few cm of registration put a rim hit there (rendered mixed rooms 1
    # and 7: one hit 3-4 cm off its true place, 5-6 cm inside the hole in the map); and
    # any cell joined to the free space by one neighbour alone (seven of them unobserved),
    # which no robot wider than a cell drives on (rendered mixed room 3: a rim cell's 7
    # hits of one scan, 8 cm of registration drift along the room, inside a hole)
    unseen_around = morphology.neighbours((state == UNKNOWN) & (layers.nlev == 0))
    state[(state == FREE) & ~stood
          & ((unseen_around >= 7) | scant & (unseen_around >= 5))] = UNKNOWN
    # Floor next to a DROP_OFF cell more than plane_tolerance below the largest floor
    # plane: a hole's far wall's top, a few cm down, grown into the floor (rendered
    # rooms: FREE a cell inside the hole), or a rim the edge crosses; or a rim cell
    # mostly over the hole (`_over_the_rim`); the hole's side counting its cells without
    # a hit next to a DROP_OFF cell (between the laser's lines, no rim is known there)
    holeward = dropped | (state == UNKNOWN) & (layers.nlev == 0) & morphology.dilate(dropped)
    beside = (state == FREE) & (layers.nlev > 0) & ~stood & morphology.dilate(holeward)
    if beside.any():
        by, bx = _cells(beside)
        off = _over_the_rim(model.hits_at[by, bx], holeward, by, bx, res)
        if planes:
            xs, ys = layers.cell_centers()
            off |= bottom[by, bx] < planes[0].height_at(xs[bx], ys[by]) \
                - params.plane_tolerance
        state[by[off], bx[off]] = UNKNOWN
    # Floor between two DROP_OFF cells across it (a row or a column): a rim's or far
    # wall's hits landed inside the hole (rendered mixed room 3), or a strip a cell wide
    # between two holes that no robot drives
    state[(state == FREE) & ~stood & _between(dropped)] = UNKNOWN
    # Two FREE cells side by side whose floors differ by more than a step (a step's face
    # on their boundary, or seen from its top only: a ramp's raised or sunken side, 10-12
    # cm in terrain rooms): no robot crosses there, so the lower one is an edge, floor
    # still as a step's edge is. The heights carried under the robot where it saw no
    # floor are left out
    crossing = free_steps((state == FREE) & (is_floor | ~stood), floor_height,
                          robot.step_height, stood)
    state[crossing] = OBSTACLE
    return state, points, band_logodds, covered, crossing


def _over_the_rim(mean_hits: np.ndarray, dropped: np.ndarray, rows: np.ndarray,
                  cols: np.ndarray, resolution: float) -> np.ndarray:
    """Of the cells (rows, cols) beside `dropped` ones, those whose floor covers less than
    half of them: its hits' mean (`mean_hits`, (n, 2) x, y from the cell's centre) lies
    more than a quarter cell from the centre away from the dropped cells around. Hits
    spread over the part of a cell an edge leaves put their mean (1 - f) / 2 of a cell
    from its centre where the floor covers f of it; the cell's centre is then over the
    hole (ideal random rooms 1-3: 25 of the 39 FREE cells centred over a drop-off, and
    20 of the 351 beside one that are not)."""
    padded = np.pad(dropped, 1)
    toward = np.zeros((len(rows), 2))
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            there = padded[rows + 1 + dy, cols + 1 + dx]
            toward[:, 0] += dx * there
            toward[:, 1] += dy * there
    away = -(mean_hits[:, 0] * toward[:, 0] + mean_hits[:, 1] * toward[:, 1])
    return away > 0.25 * resolution * np.hypot(toward[:, 0], toward[:, 1])


def _cells(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the cells of `mask`, row by row: np.nonzero's, in a third of
    its time on a window's masks."""
    return np.divmod(np.flatnonzero(mask), mask.shape[1])


def _between(mask: np.ndarray) -> np.ndarray:
    """Cells with a cell of `mask` on both sides of them in their row or in their
    column."""
    out = np.zeros(mask.shape, bool)
    np.logical_and(mask[:, :-2], mask[:, 2:], out=out[:, 1:-1])
    out[1:-1] |= mask[:-2] & mask[2:]
    return out


def _below_all_floor(nlev: np.ndarray, bottom: np.ndarray, is_floor: np.ndarray,
                     tolerance: float) -> np.ndarray:
    """Cells with hits whose lowest level's `bottom` lies more than `tolerance` below the
    lowest bottom of the floor cells in their 5 x 5 square (of `_dips`, those below every
    floor near them: not the face of a raised ramp, whose foot is the floor beside it,
    two cells off where a turned ramp's face crosses two)."""
    with np.errstate(invalid="ignore"):
        floor_bottom = np.where(is_floor & (nlev > 0), bottom, np.inf)
        return (nlev > 0) & (bottom < morphology.min_filter(floor_bottom, 5) - tolerance)


def _pinholes(state: np.ndarray, nlev: np.ndarray, size: int) -> np.ndarray:
    """Patches of UNKNOWN cells without any hit, at most `size` cells on each side, not
    touching the window's edge, whose every neighbour is FREE."""
    patch = (state == UNKNOWN) & (nlev == 0)
    labels, _, ok = morphology.small_patches(patch, size)
    ok[labels[morphology.dilate((state != FREE) & ~patch) & patch]] = False
    return ok.take(labels)
