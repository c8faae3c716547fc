"""Where the floor is missing.

Negative obstacles: a cell not on the floor where a level lies wholly more than a step
below the floor height around it, or where rays passed more than a step below it (the
floor is not where it must be; among floor hits, seen from them down unbroken, not one
noisy hit), and below the floor where the robot stood nearest, is a
DROP_OFF (a trench no lower than that floor, behind a ramp's raised top or beside a
platform, may be reached round its ends: UNKNOWN until seen); the drop-off spreads up to
`drop_reach` through cells without any hit that touch no hit but the drop-off's own and
do not lie between two floor cells at most `max_hole` apart (the shadow of the rim: not
the gaps between the laser's samples, nor the shadow of an object standing beside the
drop-off), and from that shadow one cell on up to the rim (towards where the robot stood
nearest, or where the grid saw the cell showing it from, `CellLayers.seen_from`) but for
the gaps between floor samples (`_unseen`), so its edge is within a cell of the last floor
seen (the cells showing
the drop-off themselves are where it is: no cell on from them, nor into a cell beside one
in a row or a column, as along a hole's side wall). It spreads across the
scanner's view (between its lines: within half of `max_gap` and a cell of the line of
sight through a cell showing it, and within a cell of it on the other side, or between
two such cells, one on either side: past the outermost line that shows it, the hole's
edge lies anywhere up to the next line) but not away from where the robot stood, beyond the
cells that show it (past a hole's far wall the floor is lit, its unlit cells are gaps
between the lines), and towards it only across the rim's shadow (`rim_shadow`): rays
that cross the floor's height at a hole's near rim pass below it only farther on.
DROP_OFF is never free and lethal in the costmap. Where floor lies within `drop_reach`
of a cell showing it more than a step below the floor the cell was judged against, and
nothing in the cell lies more than a step below that floor, the cell is the face of a
step down to a floor the robot reaches round its ends (a sunken floor joined by a ramp:
the floor there is not missing): it and the cells its spread joined are an OBSTACLE, as
a step's edge is, not a DROP_OFF.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import CellLayers
from scanmap.navigation import morphology
from scanmap.navigation.distance_field import distance_transform
from scanmap.navigation.floor._model import FloorModel
from scanmap.navigation.floor._seen_kernels import (
    NO_SAMPLES,
    below_floor,
    interpolated,
    lowest_seen,
    ring_heights,
)
from scanmap.navigation.floor.config import FloorConfig, RobotShape


@dataclass(frozen=True, eq=False)
class DropOffs:
    """What `drop_offs` found: where the floor is missing, and the cells' depths."""

    drop: np.ndarray  # DROP_OFF cells (the step-down faces among them: `sunk`)
    sunk: np.ndarray  # the face of a step down to floor reached round its ends
    holes: np.ndarray  # small patches without a hit inside level floor (`_small_holes`)
    lowest: np.ndarray  # the lowest floor near each cell (5 x 5)
    bottom: np.ndarray  # the bottom of each cell's lowest level
    lowest_free: np.ndarray  # the lowest height rays saw free in each cell
    ranges: np.ndarray | None  # `stood_ranges`' distances, where a rule needed them


def drop_offs(layers: CellLayers, robot: RobotShape, params: FloorConfig,
              model: FloorModel, stood: np.ndarray) -> DropOffs:
    """Where the floor is missing (the module docstring's "Negative obstacles"): cells
    below the floor near them and where the robot stood, spread through the rim's shadow
    across the scanner's view and up to the rim; the small holes inside level floor."""
    ny, nx = layers.shape
    res = layers.resolution
    is_floor, floor_height = model.is_floor, model.floor_height
    # Below the lowest floor near the cell (a cell between two floors at a step is neither's)
    lowest = morphology.min_filter(np.where(np.isnan(floor_height), np.inf, floor_height), 5)
    lowest = np.where(np.isfinite(lowest), lowest, floor_height).astype(np.float32)
    drop = below_floor(layers.levels, layers.nlev, layers.seen, lowest,
                       robot.step_height, layers.z_min, layers.mask_dz,
                       model.one_surface) & ~is_floor & ~stood
    ranges = None  # `stood_ranges`, when a rule needs them
    if drop.any():  # and below the floor where the robot stood nearest (`_stood_floor`)
        ranges, nearest = stood_ranges(layers)
        drop &= below_floor(layers.levels, layers.nlev, layers.seen,
                            _stood_floor(lowest, floor_height, nearest), robot.step_height,
                            layers.z_min, layers.mask_dz, model.one_surface)
    bottom = np.ascontiguousarray(layers.levels[:, :, 0, gk.LO])  # of each lowest level
    lowest_free = lowest_seen(layers.seen, layers.z_min, layers.mask_dz)
    # a step down to floor reached round its ends: spread as a drop-off is (its shadow is
    # no place to drive either), then an edge, not a drop-off (`cell_states`)
    sunk = _step_to_floor(layers.nlev, bottom, lowest_free + layers.mask_dz, drop, is_floor,
                          floor_height, lowest, robot.step_height,
                          round(params.drop_reach / res)) \
        if drop.any() else np.zeros((ny, nx), bool)  # not `drop`: it grows in place
    seeds = drop.copy()
    holes = _small_holes(layers.nlev, is_floor, floor_height, drop,
                         round(params.max_hole / res), robot.step_height)
    if drop.any():  # through the rim's shadow: no hit there or next to it but the drop's
        # own, not between floor samples (a gap in the floor, the shadow of an object)
        known = is_floor | stood | holes
        shadow = ~morphology.dilate(known | (layers.nlev > 0) & ~drop) & (layers.nlev == 0)
        hole = round(params.max_hole / res)
        shadow &= ~interpolated(known, (layers.nlev > 0) | drop | _beyond_spans(known, hole),
                                floor_height, hole, robot.step_height, False, NO_SAMPLES)
        # across the scanner's view, no farther from where the robot stood than the cells
        # that show it (and half a cell, their far half: beyond a hole's far wall the
        # floor is lit, its unlit cells are gaps between the laser's lines; seen aslant,
        # a whole cell let it run two cells along the far wall), nearer only across the
        # rim's shadow, and sideways only into the gaps between the lines (half of
        # max_gap and a cell from the line of sight through a cell showing it: along a
        # far wall seen aslant it ran on past the wall's end, in rendered frames as far
        # as 5 cells into the unlit floor beyond); a cell showing it nearer than
        # blind_range to every place the robot stood was seen from farther off: from one
        # of the places blind_range to view_range off, any, each giving its line of
        # sight and bounds, the rim's shadow as deep as the laser's light over the rim
        # leaves it (`_shadow_share`: ramp room 1's pit, 27 cm deep, seen from its path
        # 2-4 m on, holds hits 7-13 cells beyond its near rim). Spread without a line of
        # sight, mixed room 5017's pit at 0.3 px took the floor round its corner 2 cells
        # towards the path the robot passed it by
        near = ranges * (1.0 - params.rim_shadow) - 1.0  # the rim's shadow, a cell more
        viewed_from = np.where(ranges >= params.blind_range / res, nearest, -1)
        # Sideways only between two lines that show it, a cell past the outermost: out to
        # one side of some cell showing it and to the other of another (beyond, the hole's
        # edge lies anywhere up to the next line, which on rendered frames far off often
        # returned nothing: up to 4 cells of floor taken)
        gap = 0.5 * params.max_gap / res + 1.0
        elsewhere = morphology.Viewpoints(
            np.column_stack(_stood_rows_cols(layers)).astype(np.float64),
            params.blind_range / res, params.view_range / res,
            np.minimum(_shadow_share(lowest, layers.nlev, bottom, lowest_free,
                                     params.emitter_height), 1.0 - params.rim_shadow), 0.5)
        sources = np.empty((ny, nx), np.int64)  # the cell showing it each came from
        spread_to = functools.partial(morphology.dilate_in_range, drop, shadow, ranges, near,
                                      ranges + 0.5, max(round(params.drop_reach / res), 1),
                                      viewed_from)
        spread = spread_to((1.0, gap), elsewhere, sources) & spread_to((gap, 1.0), elsewhere)
        drop |= spread
        # and from the shadow up to the rim (where the drop-off shows itself, it is there:
        # not a cell on from it, beside it in a row or a column, as at a hole's side wall),
        # along the line of sight through the spread cell (within half a cell of it), not
        # sideways: at a hole's corner a step sideways ran a cell past its side wall onto
        # the floor between two laser lines (rendered mixed room 4: 2.5 cells off the
        # edge; ramp room 6 1.28, mixed room 3 1.70 cells in a scan). From a cell showing
        # it seen from no place the robot stood, towards where that cell was seen from
        # where the grid knows it (`CellLayers.seen_from`), not towards any place in
        # reach: towards each, the step took a cell of floor round a hole's corner on every
        # side (rendered random room 4006: 2.97 cells off the edge)
        rim = (layers.nlev == 0) & ~morphology.within_distance(seeds, 1.0) & ~interpolated(
            known, (layers.nlev > 0) | drop | _beyond_spans(known, 2), floor_height, 2,
            robot.step_height, False, NO_SAMPLES)
        own = _seen_from_cells(layers).reshape(-1, 2)[sources]
        own[sources < 0] = np.nan
        drop |= morphology.dilate_in_range(spread & ~seeds, rim, ranges, near, ranges, 1,
                                           viewed_from, 0.5,
                                           elsewhere._replace(above=0.0, own=own))
    holes &= ~drop
    return DropOffs(drop=drop, sunk=sunk, holes=holes, lowest=lowest, bottom=bottom,
                    lowest_free=lowest_free, ranges=ranges)


def stood_ranges(layers: CellLayers) -> tuple[np.ndarray, np.ndarray]:
    """Distance (cells) from each cell to the nearest place in the window the robot stood,
    and that place's cell (flat index); all 0 and -1 where it stood nowhere in it: no
    direction to tell."""
    cells = _stood_cells(layers)
    if not cells.any():
        return np.zeros(layers.shape, np.float32), np.full(layers.shape, -1, np.int64)
    return distance_transform(cells)


def _shadow_share(floor: np.ndarray, nlev: np.ndarray, bottom: np.ndarray,
                  lowest_free: np.ndarray, emitter_height: float) -> np.ndarray:
    """Per cell, the least share of its range from the scanner at which the rim of a
    drop-off it shows below `floor` may lie: the laser's light (from `emitter_height`
    up) over the rim reaches depth d below the floor at (emitter_height + d) /
    emitter_height times the rim's range, d the deepest the cell shows (its lowest
    level's `bottom` where it has `nlev` levels, or the lowest bin rays saw free in it,
    `lowest_free`); 1 where it shows nothing below."""
    with np.errstate(invalid="ignore"):
        deepest = np.fmin(np.where(nlev > 0, bottom, np.nan),
                          np.where(np.isfinite(lowest_free), lowest_free, np.nan))
        depth = np.nan_to_num(np.clip(floor - deepest, 0.0, None), nan=0.0)
    return emitter_height / (emitter_height + depth)


def _step_to_floor(nlev: np.ndarray, bottom: np.ndarray, free_top: np.ndarray,
                   drop: np.ndarray, is_floor: np.ndarray, floor_height: np.ndarray,
                   lowest: np.ndarray, step: float, reach: int) -> np.ndarray:
    """Cells of `drop` beside floor more than a step below the floor they were judged
    against (`lowest`), within `reach` cells, that hold nothing lower than a step under
    it (their lowest level's `bottom`, the top of their lowest bin seen free, `free_top`:
    the floor lies under it): the face of a step down to a floor the robot reaches round
    its ends (a sunken floor joined by a ramp), which is floor, not missing."""
    lower = morphology.min_filter(np.where(is_floor, floor_height, np.inf), 2 * reach + 1)
    deepest = np.fmin(np.where(nlev > 0, bottom, np.inf), free_top)
    return drop & (lower < lowest - step) & (deepest >= lower - step)


def _stood_floor(lowest: np.ndarray, floor_height: np.ndarray, nearest: np.ndarray
                 ) -> np.ndarray:
    """`lowest` or, where lower, the floor height at the place the robot stood nearest
    (`stood_ranges`). Floor below the floor around it but not below the floor the robot stood
    on is a trench the floor may reach round its ends (the floor behind a ramp's raised
    top or beside a platform, in their shadow): UNKNOWN until seen, not a drop-off."""
    if nearest.size and nearest.flat[0] < 0:  # it stood nowhere in the window
        return lowest
    return np.fmin(lowest, floor_height.reshape(-1)[nearest]).astype(np.float32)


def _stood_rows_cols(layers: CellLayers) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the window's cells that hold a place the robot stood
    (`layers.stood`; places beyond the window left out)."""
    ny, nx = layers.shape
    stood = np.asarray(layers.stood, dtype=np.float64).reshape(-1, 2)
    cols = np.floor((stood[:, 0] - layers.origin[0]) / layers.resolution).astype(np.int64)
    rows = np.floor((stood[:, 1] - layers.origin[1]) / layers.resolution).astype(np.int64)
    inside = (cols >= 0) & (cols < nx) & (rows >= 0) & (rows < ny)
    return rows[inside], cols[inside]


def _seen_from_cells(layers: CellLayers) -> np.ndarray:
    """(ny, nx, 2) the row and column of the window's cells (beyond it too) where each
    cell's lowest level was seen from (`CellLayers.seen_from`); NaN where unknown."""
    res = layers.resolution
    return np.stack([np.floor((layers.seen_from[..., 1] - layers.origin[1]) / res),
                     np.floor((layers.seen_from[..., 0] - layers.origin[0]) / res)],
                    axis=-1).astype(np.float64)


def _stood_cells(layers: CellLayers) -> np.ndarray:
    """The cells of the window that hold a place the robot stood (`layers.stood`)."""
    cells = np.zeros(layers.shape, bool)
    cells[_stood_rows_cols(layers)] = True
    return cells


def _beyond_spans(known: np.ndarray, size: int) -> np.ndarray:
    """Cells more than `size` + 2 cells (along rows, columns or diagonals) from every cell
    of `known`: `interpolated` (size, no samples) bridges no span through them, nor through
    a cell next to them (a span's cells lie within size + 1 of its ends). Passed to it as
    hits they are skipped, and its result is the same (the unobserved space round a
    window's drop-offs: half its cells in the hazards scene)."""
    return ~morphology.max_filter(known, 2 * size + 5)


def _small_holes(nlev: np.ndarray, is_floor: np.ndarray, floor_height: np.ndarray,
                 drop: np.ndarray, size: int, step: float) -> np.ndarray:
    """Patches of cells without any hit, at most `size` cells on each side, inside floor
    (not touching the window's edge) whose heights around them differ by at most `step`,
    and showing no drop-off."""
    labels, _, ok = morphology.small_patches(~is_floor, size)
    count = len(ok) - 1
    if not count:
        return np.zeros(is_floor.shape, bool)
    ok[labels[(nlev > 0) | drop]] = False
    # The ring of a patch: floor cells next to it (a patch is a whole component of the
    # cells off the floor, so every neighbour outside it is floor)
    low, high = ring_heights(labels, count, is_floor, floor_height)
    ok &= high - low <= step
    return ok.take(labels)
