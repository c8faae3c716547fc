"""`segment`: the floor and obstacle layers of a window of the grid, in four stages
(`_model`, `_drop_offs`, `_unseen`, `_states`), over the part of the window within reach
of what was observed."""

from __future__ import annotations

import functools
import math

import numpy as np

from scanmap.grid.height_grid import CellLayers
from scanmap.navigation._kernels import OBSTACLE, UNKNOWN
from scanmap.navigation.floor._drop_offs import drop_offs
from scanmap.navigation.floor._model import floor_model
from scanmap.navigation.floor._plane_kernels import plane_heights
from scanmap.navigation.floor._seen_kernels import footprint_cells, observed_span
from scanmap.navigation.floor._states import cell_states
from scanmap.navigation.floor._unseen import unseen_cells
from scanmap.navigation.floor.config import FloorConfig, RobotShape
from scanmap.navigation.floor.result import Segmentation
from scanmap_driver.errors import MapError
from scanmap_driver.scanner_model import ScannerModel, reference_scanner


def segment(layers: CellLayers, robot: RobotShape | None = None,
            params: FloorConfig | None = None,
            fallback_floor: float | None = None) -> Segmentation:
    """Floor, floor height and obstacle state of every cell of `layers`.

    fallback_floor: height assumed where no floor is known within fill_radius (e.g. 0.0
    for a 2-D laser that never sees the floor); None leaves those cells UNKNOWN.

    Only the part of the window within reach of what was observed is segmented (every
    rule that decides a cell's state reaches at most `_reach` cells from a hit, a cell
    rays saw or a place the robot stood): beyond it each cell is UNKNOWN, off the floor,
    its floor height that of the nearest floor within `fill_radius` (carried there as in
    the part segmented, `_model._carry`), else of the largest plane (else
    `fallback_floor`, else NaN), as segmenting the whole window gives them (to the
    rounding of the cell centres, computed from another origin). A window round the
    robot often holds much that no ray reached (behind a corridor's walls: two thirds of
    an 8 m window).
    """
    robot = robot or RobotShape()
    params = (params or FloorConfig()).for_scanner(_reference_scanner())
    if fallback_floor is not None and not math.isfinite(fallback_floor):
        raise MapError(f"segment: fallback_floor must be a finite height or None, got "
                       f"{fallback_floor}")
    reach = _reach(params, layers.resolution)
    rows, cols = _observed_box(layers, robot, reach)
    ny, nx = layers.shape
    area = (rows.stop - rows.start) * (cols.stop - cols.start)
    if not area or area > 0.8 * ny * nx:  # nothing seen, or little to leave out
        return _segment(layers, robot, params, fallback_floor)[0]
    # the border round the box that the floor's height is carried into
    pad = max(math.floor(params.fill_radius / layers.resolution) - reach, 0)
    margins = (min(pad, rows.start), min(pad, ny - rows.stop), min(pad, cols.start),
               min(pad, nx - cols.stop))
    inner, beyond = _segment(_cropped(layers, rows, cols), robot, params, fallback_floor,
                             margins)
    xs, ys = layers.cell_centers()
    if inner.planes:
        floor_height = plane_heights(inner.planes[0].normal, inner.planes[0].offset, xs, ys)
    else:
        floor_height = np.full((ny, nx), np.nan if fallback_floor is None else fallback_floor,
                               np.float32)
    state = np.full((ny, nx), UNKNOWN, np.uint8)
    points = np.empty((ny, nx, 2), np.float32)
    points[..., 0], points[..., 1] = xs[None, :], ys[:, None]
    band_logodds = np.full((ny, nx), np.nan, np.float32)
    is_floor = np.zeros((ny, nx), bool)
    slope = np.full((ny, nx), np.nan, np.float32)
    for whole, part in ((floor_height, inner.floor_height), (state, inner.state),
                        (points, inner.points), (band_logodds, inner.band_logodds),
                        (is_floor, inner.is_floor), (slope, inner.slope)):
        whole[rows, cols] = part
    if beyond is not None:  # the height of the floor seen in the box, carried round it
        outer = floor_height[rows.start - margins[0]:rows.stop + margins[1],
                             cols.start - margins[2]:cols.stop + margins[3]]
        carried = ~np.isnan(beyond)
        outer[carried] = beyond[carried]  # a view: in place
    return Segmentation(origin=layers.origin, resolution=layers.resolution, robot=robot,
                        floor_height=floor_height, is_floor=is_floor, planes=inner.planes,
                        state=state, points=points, band_logodds=band_logodds,
                        updated=layers.updated, slope=slope)


@functools.cache
def _reference_scanner() -> ScannerModel:
    """The scanner whose geometry `segment` takes where its FloorConfig leaves it None."""
    return reference_scanner()


def _reach(params: FloorConfig, resolution: float) -> int:
    """How far (cells) any rule that decides a cell's state reaches from the cells that
    were observed: a drop-off spread, a gap bridged, an overhang spread out and back (to
    an observed cell: half its reach; farther out it covers cells UNKNOWN anyway), and a
    few cells more for the 3 x 3 and 5 x 5 neighbourhoods on the way. The floor's height
    carried farther is `_carry`'s."""
    farthest = max(params.drop_reach, params.max_gap, params.max_hole,
                   0.5 * params.overhang_reach)
    return math.ceil(farthest / resolution) + 3


def _observed_box(layers: CellLayers, robot: RobotShape, reach: int) -> tuple[slice, slice]:
    """Rows and columns of the smallest box holding every cell with a hit or with heights
    rays saw, and every place the robot stood, grown by `reach` cells (within the window;
    empty when nothing was observed)."""
    ny, nx = layers.shape
    top, bottom, left, right = observed_span(
        layers.nlev, layers.seen, np.asarray(layers.stood, dtype=np.float64).reshape(-1, 2),
        layers.origin[0], layers.origin[1], layers.resolution)
    if bottom < 0:
        return slice(0, 0), slice(0, 0)
    reach += math.ceil(robot.radius / layers.resolution)  # the footprint round a place
    return (slice(max(top - reach, 0), min(bottom + reach + 1, ny)),
            slice(max(left - reach, 0), min(right + reach + 1, nx)))


def _cropped(layers: CellLayers, rows: slice, cols: slice) -> CellLayers:
    """The cells (rows, cols) of `layers` as a window of their own, copied contiguous: the
    kernels then see the one array layout a whole window has, so each is compiled, cached
    and loaded once, not again for strided views."""
    def crop(array: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(array[rows, cols])

    return CellLayers(
        origin=(layers.origin[0] + cols.start * layers.resolution,
                layers.origin[1] + rows.start * layers.resolution),
        resolution=layers.resolution, z_min=layers.z_min, mask_dz=layers.mask_dz,
        levels=crop(layers.levels), counts=crop(layers.counts), nlev=crop(layers.nlev),
        seen=crop(layers.seen), updated=crop(layers.updated), stood=layers.stood,
        unlit=crop(layers.unlit), seen_from=crop(layers.seen_from))


def _segment(layers: CellLayers, robot: RobotShape, params: FloorConfig,
             fallback_floor: float | None, margins: tuple[int, int, int, int] = (0, 0, 0, 0)
             ) -> tuple[Segmentation, np.ndarray | None]:
    """`segment` on the whole of `layers`, and the floor heights it carried (up to
    `fill_radius` from the floor seen) into a border of `margins` cells round it (`_carry`;
    None where no floor was seen). Four stages, each a module of this package whose
    docstring gives its rules: the floor, the drop-offs, the cells no return leaves
    unknown, the cells' states."""
    stood = _footprint_cells(layers, robot.radius)  # observed floor or not: it stood there
    model = floor_model(layers, robot, params, fallback_floor, margins, stood)
    drops = drop_offs(layers, robot, params, model, stood)
    unseen = unseen_cells(layers, robot, params, model, drops, stood)
    state, points, band_logodds, covered, crossing = cell_states(layers, robot, params, model,
                                                                 drops, unseen, stood)
    is_floor = ((model.is_floor | stood | unseen.holes & ~unseen.dim)
                & ((state != OBSTACLE) | crossing) & ~unseen.drop & ~covered) | model.edges
    return Segmentation(origin=layers.origin, resolution=layers.resolution, robot=robot,
                        floor_height=model.floor_height, is_floor=is_floor,
                        planes=model.planes, state=state, points=points,
                        band_logodds=band_logodds, updated=layers.updated,
                        slope=np.where(model.is_floor, model.slope, np.nan).astype(np.float32)
                        ), model.beyond


def _footprint_cells(layers: CellLayers, radius: float) -> np.ndarray:
    """Cells the footprint (a disc of `radius` round where the sensor stood) overlaps: the
    robot's own body never touches unknown space where it stood, as queries measure it
    (to the cells' squares)."""
    xs, ys = layers.cell_centers()
    return footprint_cells(np.asarray(layers.stood, dtype=np.float64).reshape(-1, 2), xs,
                           ys, layers.origin[0], layers.origin[1], layers.resolution,
                           radius, math.ceil(radius / layers.resolution))
