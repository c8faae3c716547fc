"""The cells no return leaves unknown.

No return is not free: a cell is FREE only where the floor was seen - a floor hit in the
cell - or is known otherwise: the cells the robot's footprint overlaps at the poses it
scanned from (it stood there; FREE unless something occupies its band), the assumed
`fallback_floor` of a 2-D laser, a patch without any hit no larger than `max_hole` (0.3
m, each side) enclosed by floor whose heights differ by at most a step, or whose hits
within two cells are all such floor, none reaching more than `plane_tolerance` below the
floor beside it (a gap between the laser's samples; a line grazing a hole's corner lands
a few cm down its far wall), away from any drop-off, and a cell without any hit between
two such cells along a row, a column or a diagonal whose floor hits lie at most three
cells (15 cm) apart (from a cell's far edge where it holds none), with heights within a
step (the gaps between samples too narrow to hold a cell without a hit next to it),
unless it touches a drop-off or a cell whose hits reach that far below the floor beside
it (such a span may cross a turned hole's corner, from its near rim's floor to the top
of its far wall); last, a patch without any hit at most `max_pinhole` (15 cm) each side
whose every neighbour ended FREE. Every other cell - black carpet, a hole nothing
returned from, the floor beyond the last floor hit before a drop-off, floor never lit at
all - stays UNKNOWN however much of the band rays saw over it (its floor height carried
from nearby floor is an assumption, not a sighting), as does a cell too steep to be
floor. A real hole of max_hole or less returns hits below the floor (its far wall) that
are not floor, so it is not a gap; it is a DROP_OFF where those lie more than a step
down, and its cells without any hit around them are when a surface lies wholly below the
floor model (more than `plane_tolerance`) within two cells of them and no nearer to
where the robot stood, away from any other drop-off: the floor goes down into a small
patch nothing returned from (seen from afar, this scanner's laser lands only on the top
few cm of a hole's far wall, which lies beyond the hole).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import CellLayers
from scanmap.navigation import morphology
from scanmap.navigation.floor._drop_offs import DropOffs, stood_ranges
from scanmap.navigation.floor._model import FloorModel
from scanmap.navigation.floor._seen_kernels import (
    floor_gaps,
    floor_samples,
    interpolated,
    lowest_level_below,
)
from scanmap.navigation.floor.config import FloorConfig, RobotShape


@dataclass(frozen=True, eq=False)
class Unseen:
    """What `unseen_cells` found: the cells that may not be FREE for want of a sighting."""

    unlit: np.ndarray  # no floor seen, nor known otherwise: never FREE
    dim: np.ndarray  # near floor a laser line crossed without a return
    drop: np.ndarray  # the drop-offs, with the small patches the floor goes down into
    holes: np.ndarray  # the small holes, with the gaps between the laser's samples
    lines: np.ndarray  # openings between the laser's lines, floor on both sides
    dips: np.ndarray  # cells whose hits lie below the floor cells beside them (`_dips`)


def unseen_cells(layers: CellLayers, robot: RobotShape, params: FloorConfig,
                 model: FloorModel, drops: DropOffs, stood: np.ndarray) -> Unseen:
    """The cells no return leaves unknown (the module docstring's "No return is not
    free"): every cell but the floor seen, a gap between the laser's samples, stood on,
    assumed, or between two such cells; and a small patch the floor goes down into."""
    ny, nx = layers.shape
    res = layers.resolution
    is_floor, floor_height = model.is_floor, model.floor_height
    assumed, drop, bottom = model.assumed, drops.drop, drops.bottom
    # Patches without any hit in or around them (3 x 3): a gap between the laser's samples
    # if the whole patch is small and inside level floor; where rays passed low over one
    # (not the foot of a surface a ray ended on) the laser should have lit it
    probed = drops.lowest_free <= floor_height + params.floor_probe
    bare = ~morphology.max_filter(layers.nlev > 0, 3)
    dips = _dips(layers.nlev, bottom, is_floor, params.plane_tolerance)
    holes = drops.holes | _lit_gaps(bare & ~is_floor & ~stood & ~assumed, layers.nlev,
                                    is_floor, floor_height, drop, dips,
                                    round(params.max_hole / res), robot.step_height)
    # No return is not free: the floor seen (a hit there), a gap, stood on, assumed, or
    # between two such cells: their floor hits at most three cells apart anywhere, at most
    # max_gap apart (the spacing of the laser's lines) away from any sign of a hole
    known_floor = is_floor | holes | stood | assumed
    informative = (layers.nlev > 0) | drop
    # A cell farther than half a span from every known or hit cell lies on no such span:
    # passed to `interpolated` as a hit, it is skipped (the result is the same)
    observed = known_floor | informative
    lone = ~morphology.within_distance(observed, 2.0)
    samples = _floor_samples(layers, is_floor)
    seen_floor = interpolated(known_floor, informative | lone, floor_height, 1,
                              robot.step_height, True, samples)
    # but not next to a sign of a hole (a drop-off, a dip): the span may cross the hole's
    # corner, from its near rim's floor to the top of its far wall
    seen_floor &= known_floor | ~morphology.dilate(drop | dips)
    drop = drop | _sunk(bare & ~holes & ~is_floor & ~stood & ~assumed, layers, is_floor,
                        drops.lowest, drop, round(params.max_hole / res),
                        params.plane_tolerance, drops.ranges)
    gap = round(params.max_gap / res)
    lines = np.zeros((ny, nx), bool)
    if gap > 2:
        wide = ~morphology.within_distance(observed, 0.5 * (gap + 1))  # unobserved > max_gap
        with np.errstate(invalid="ignore"):  # the feet of surfaces standing on the floor
            foot = (layers.nlev > 0) & ~known_floor \
                & (np.abs(bottom - floor_height) <= robot.step_height)
        # An opening of at most gap cells (`interpolated`'s size + 2), measured between
        # the floor hits of the cells at its ends (from the far edge of an end without)
        lines = interpolated(known_floor | foot, informative | wide, floor_height, gap - 2,
                             robot.step_height, True, samples) & ~seen_floor & ~foot
        if lines.any():  # not near a sign of a hole, nor within max_gap of a wider gap
            # through cells without a hit (not of the space behind a wall). A hole too
            # narrow to hold a `wide` cell (under gap + 2 cells) shows at most its far
            # wall, up to its diagonal from a span across its near corner: the signs reach
            # that far, measured against each cell's own floor (the lowest around it may
            # be a far wall's top taken for floor)
            lines &= ~morphology.within_distance(drop | dips | _below_model(
                layers, is_floor, floor_height, params.plane_tolerance) | _reaching_below(
                layers, is_floor, floor_height, robot.step_height), (gap + 2) * math.sqrt(2.0))
            lines &= ~morphology.dilate(wide, gap, within=~observed)
        seen_floor |= lines
    unlit = (probed & bare) | model.steep | model.bridges
    unlit &= ~is_floor & ~stood & ~assumed & ~holes & ~lines
    unlit |= ~seen_floor
    # Near floor a laser line crossed without a return (`scanmap.grid.unlit`: black
    # carpet, a black-lined hole), no cell without a hit is a gap between samples: the
    # laser was aimed there and nothing came back
    dark = layers.unlit & (layers.nlev == 0)
    dim = morphology.within_distance(dark, gap) & (layers.nlev == 0) & ~stood \
        if dark.any() else dark
    unlit |= dim
    return Unseen(unlit=unlit, dim=dim, drop=drop, holes=holes, lines=lines, dips=dips)


def _lit_gaps(bare: np.ndarray, nlev: np.ndarray, is_floor: np.ndarray,
              floor_height: np.ndarray, drop: np.ndarray, dips: np.ndarray, size: int,
              step: float) -> np.ndarray:
    """Patches of `bare` cells (no hit around them) at most `size` cells on each side, not
    at the window's edge nor next to a drop-off, whose hits within two cells are all floor
    with heights differing by at most `step`, none of `dips` (`_dips`): gaps between the
    laser's samples."""
    labels, boxes, ok = morphology.small_patches(bare, size, margin=2)
    gaps = floor_gaps(labels, boxes, ok, morphology.dilate(drop), nlev, is_floor,
                      floor_height, dips, step)
    return gaps.take(labels)


def _sunk(dark: np.ndarray, layers: CellLayers, is_floor: np.ndarray, lowest: np.ndarray,
          drop: np.ndarray, size: int, tolerance: float, ranges: np.ndarray | None
          ) -> np.ndarray:
    """The patches of `dark` (no hit in or around them, not a gap) at most `size` cells on
    each side, not at the window's edge nor next to a drop-off (its shadow is the drop's
    own rule), with a surface wholly below the floor model (`_below_model`) within two
    cells, no nearer to where the robot stood than the patch's nearest cell (`ranges`:
    `stood_ranges`' distances, computed here when None): the floor goes down into a small
    patch nothing returned from (a hole's far wall, seen only at its top, lies beyond the
    hole; a patch beyond a lowered area's far edge is the unlit floor there). Not the
    cells around the patch: a hit or floor near, they may be floor (the hole's extent is
    not known there), so they stay UNKNOWN."""
    ny, nx = dark.shape
    low = _below_model(layers, is_floor, lowest, tolerance)
    out = np.zeros((ny, nx), bool)
    if not low.any():
        return out
    labels, boxes, ok = morphology.small_patches(dark, size, margin=2)
    near = morphology.max_filter(low, 5)
    near_drop = morphology.max_filter(drop, 3)
    for index in np.flatnonzero(ok):
        rows, cols = morphology.box_slices(boxes[index])
        patch = labels[rows, cols] == index
        if not near[rows, cols][patch].any() or near_drop[rows, cols][patch].any():
            continue
        if ranges is None:
            ranges = stood_ranges(layers)[0]
        around = (slice(max(rows.start - 2, 0), rows.stop + 2),
                  slice(max(cols.start - 2, 0), cols.stop + 2))
        if ranges[around][low[around]].max() >= ranges[rows, cols][patch].min():
            out[rows, cols] |= patch
    return out


def _floor_samples(layers: CellLayers, is_floor: np.ndarray) -> np.ndarray:
    """(ny, nx, 2) where each floor cell's floor hits lie (the mean of its lowest level's:
    x and y offsets from the cell's centre, in cells), NaN off the floor: the ends of an
    opening between the laser's lines, to measure it to the hits rather than to the
    cells' edges (the hits nearest the opening lie no farther out than their mean)."""
    return floor_samples(layers.levels, layers.nlev, is_floor, layers.resolution)


def _dips(nlev: np.ndarray, bottom: np.ndarray, is_floor: np.ndarray,
          tolerance: float) -> np.ndarray:
    """Cells with hits whose lowest level's `bottom` lies more than `tolerance` below the
    highest bottom of the floor cells in their 3 x 3 square: a line grazing a hole lands
    a few cm down its far wall, in the cell of the rim's floor, so a hole as wide as the
    gaps between lines, lying between two, may show itself only so. Bottoms against
    bottoms (each a level's lowest hit), not floor heights: noise lowers them alike."""
    with np.errstate(invalid="ignore"):
        floor_bottom = np.where(is_floor & (nlev > 0), bottom, -np.inf)
        highest = -morphology.min_filter(-floor_bottom, 3)
        return (nlev > 0) & (bottom < highest - tolerance)


def _below_model(layers: CellLayers, is_floor: np.ndarray, floor: np.ndarray,
                 tolerance: float) -> np.ndarray:
    """Cells with hits, not floor, whose lowest level lies wholly more than `tolerance`
    below `floor` (the lowest floor around them, or their own): a surface below the floor
    model (a hole's far wall, seen only at its top, less than a step down)."""
    return lowest_level_below(layers.levels, layers.nlev, is_floor, floor - tolerance,
                              gk.HI)


def _reaching_below(layers: CellLayers, is_floor: np.ndarray, floor: np.ndarray,
                    depth: float) -> np.ndarray:
    """Cells with hits, not floor, whose lowest level reaches more than `depth` below
    `floor` (as for `_below_model`): the far rim of a hole whose wall, seen only at its
    top, fell into the cell of the floor beyond it (one level from the wall's hits up to
    the floor's: not wholly below the floor, so not `_below_model`, yet a sign of a hole)."""
    return lowest_level_below(layers.levels, layers.nlev, is_floor, floor - depth, gk.LO)
