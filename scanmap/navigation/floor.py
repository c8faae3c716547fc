"""Floor segmentation and the obstacle layer: where the robot can drive, and what is in its way.

Floor: a cell's lowest level is a floor candidate when it is thin (a surface, not an
object). RANSAC over the candidates' heights finds the dominant near-horizontal plane;
its inliers seed a region growing over candidates whose neighbours differ by at most
the robot's step height, so a ramp or a low sill joins the floor, while a table top or
the top of a box (cut off by its vertical faces) does not. The growth also crosses a
cell without any hit (a gap between the laser's lines, which cut a ramp seen from afar
into islands) to a candidate two cells away, if the height between them changes no
faster than `max_slope` allows (a chain of such jumps does not climb a step's face),
and each end lies within a step of the cells beside the other end that are within a
step of it, every candidate counted, also those too steep to be floor (a jump from a
level a step's face left in a cell, 3 cm down beside the floor, does not land on the
floor 6 cm below). Across two such cells it reaches a candidate three away only along a
plane: each end that has a tangent plane (its slope's gradient, `local_slope`) passes
within twice `plane_noise` of the other (a ramp seen from afar is cut into islands by
gaps two cells wide between the laser's lines; its raised end, too small to fit a plane
of its own, was an obstacle), and no candidate beside either end lies a step off that
plane.
Planes are then fitted to the floor region by sequential RANSAC and reported (the
floor, a ramp, a raised part).
Cells without observed floor (under objects, under occluded table tops) take the height
of the nearest floor cell within `fill_radius` (not of a step's edge joined to the floor,
`touching_floor`), and beyond it that of the largest plane.

Floor per cell: each candidate's slope is that of the plane, fitted to the candidates'
mean hits within `slope_reach` of a cell near it, that fits them within the noise and
explains the cell best (at a crease a window on the cell's own side: the first rows of a
steep ramp are steep, not half as steep; `_kernels.local_slope`); a cell steeper than
`max_slope` (default 15 deg) does not join the floor: it is never FREE, and an OBSTACLE
where its surface rises into the robot's band; nor does one whose lowest level reaches
from a candidate beside it more than a step down (a face the robot cannot climb crosses
it; `_kernels.faces_below`). So a ramp within max_slope and a step within the robot's
step height (default 5 cm) are driven on; a steeper ramp or a higher step is not. A cell
that holds the edge of a higher step between two floors (the raised end or a side of a
ramp that ends above the floor beside it: one level, or levels each less than
`clearance` above the last (a side face seen at 5 cm and the ramp's surface at 18 cm,
no room for the robot between), spanning more than a step, up to
within `plane_tolerance` of the ramp's surface and from the floor below, or from higher
up its face where the rays saw no lower, both floors at most two cells away) is floor,
as both its parts are, and an OBSTACLE: the robot may not cross the step. A step's face
leaves thin levels at in-between heights in the cells it crosses (0, -2, -6, -8 cm down
an 8 cm step; four in-between levels where a 6 cm step's face crosses the cells at a
slant), each within a step of the next: a candidate within a step of two candidates on
either side of it that differ by more than a step and lie within 3.4 cells of each other
(as far as a ramp at `max_slope` rises 9/10 of a step: `bridged_steps`), joins the floor
only from a floor cell next to it, and the growth goes no further from it, so the floor
below the step is not reached through it.

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
the gaps between floor samples (below), so its edge is within a cell of the last floor
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

Obstacles (docs/architecture.md): occupied space between floor + step height and floor + robot
height. A cell is FREE only if its floor height is known and not unlit (above), nothing
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
cells inside a hole), nor floor next to a drop-off whose hits reach more than
`plane_tolerance` below the largest floor plane (the rim and the far wall's top in one
level), nor floor between two drop-off cells across it; otherwise it is UNKNOWN.
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

import functools
import math
from dataclasses import dataclass

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import CellLayers
from scanmap.navigation import _kernels as nk
from scanmap.navigation import morphology
from scanmap.navigation._kernels import DROP_OFF as DROP_OFF  # re-exported: the cell states
from scanmap.navigation._kernels import FREE as FREE
from scanmap.navigation._kernels import OBSTACLE as OBSTACLE
from scanmap.navigation._kernels import UNKNOWN as UNKNOWN
from scanmap.navigation.distance_field import distance_transform
from scanmap_driver.errors import MapError

# RANSAC counts no more hypotheses once, at this confidence, one of those drawn was three
# cells of the best plane so far (`ransac_iterations` at most): 16 when that plane holds
# 90 % of the candidates, 86 at 60 %, all 200 below 46.5 %
RANSAC_CONFIDENCE = 1.0 - 1e-9
# A floor candidate this gentle (`nk.local_slope`) lies on level floor, for
# `nk.bridged_steps`: two level floors more than a step apart are a step's two sides, not
# a ramp (a floor's cells at 0.3 px of laser peak noise: 1.5 deg at the 90th percentile;
# the cells a step's face crosses, 4-17 deg)
LEVEL_SLOPE = math.radians(5.0)
# how far across (m) a turned step's face leaves levels at in-between heights: up to three
# cells and a half (noise, the face at a slant to the cells), the default robot's reach
FACE_SPAN = 0.17


@dataclass(frozen=True)
class RobotShape:
    """What the robot drives over (step_height), under (height) and its footprint radius."""

    step_height: float = 0.05
    height: float = 1.0
    radius: float = 0.25

    def __post_init__(self) -> None:
        for name in ("step_height", "height", "radius"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise MapError(f"RobotShape.{name}: expected a finite number > 0, got {value!r}")
        if self.step_height >= self.height:
            raise MapError(f"RobotShape: step_height {self.step_height} must be below height "
                           f"{self.height}")


@dataclass(frozen=True)
class FloorConfig:
    """Tuning of the segmentation.

    thickness: most vertical extent (m) of a level that can be floor; clearance: free
    height above it (m) that a floor cell needs.
    plane_tolerance: distance (m) of the floor plane's inliers (its hypotheses are scored
    within seed_tolerance, `ransac_plane`), and the floor's noise elsewhere: a
    surface lower than that below the floor is a sign of a hole (a gap's rim dipping so
    is no gap). max_slope: steepest floor plane (rad).
    min_plane_cells: support of a reported plane. min_seed_cells, seed_tolerance: the
    floor grows from the largest plane's inliers, but from a patch of fewer than
    min_seed_cells of them (8-connected) only where within seed_tolerance (m) of the
    plane. A lone inlier may be the foot of a wall, hit up to plane_tolerance off the
    floor beside a floor a step lower (a dock 6 cm down), from which the floor would grow
    down there; lone floor samples (far off, between furniture) lie closer.
    fill_radius: how far (m) the height of a floor cell is carried into cells without
    observed floor (the largest floor plane gives it beyond). detect: False for data
    that never see the floor (a 2-D laser: every point at one height), which then rely
    on the `fallback_floor` of `segment`.
    min_coverage: fraction of the robot band's height bins that rays must have seen free
    for a cell to be FREE (as Nav2's voxel layer tolerates unknown voxels in a column).
    This scanner rarely sees every bin of a column (rays at 0.7-1 m over a cell 2 m away
    end beyond 4 m, returning nothing), so 1.0 leaves most of a room unknown; below 1, a
    thin object hanging in unseen heights is caught by the suspect rules of
    `classify_band` instead.
    overhang_reach: how far (m) the heights of an overhanging board (a table top seen
    only at its rim: this scanner's laser, 0.5 m up, never lights a top above it) are
    assumed to extend over cells that never saw those heights: 1 m covers a desk seen at
    one end only (at 0.6 m, cells under the far end of the office's table, which rays
    reached only beneath its top, were FREE); overhang_thickness: the thickest level
    taken for such a board (a table top, a seat, a shelf).
    coverage_reach: on known floor, band heights seen free this far (m) from a cell count
    for its coverage (0: the cell alone); the cell itself must have seen one.
    slope_reach: radius (m) of the neighbourhood a cell's floor slope is fitted over;
    plane_noise: the RMS (m) within which its cells fit one plane for it to be one
    surface, without a crease (`_kernels.local_slope`): 3 mm, below the 4.4 mm a
    16 deg ramp's first row leaves with the floor before it, noise-free.
    drop_reach: how far (m) a drop-off spreads from the cells that show it through cells
    without observed floor, no farther from the nearest place the robot stood than they
    (and half a cell), nearer by at most rim_shadow times their range (and a cell), and
    within half of max_gap and a cell of the line of sight through one of them and a
    cell of it on its other side, or between two of them (from the nearest place the
    robot stood, if at least blind_range off): rays
    reach step_height and a height bin or two below the floor (`below_floor`) about
    (step_height + 2 mask_dz) / camera height times the range past the rim, 0.1 for a
    camera 1 m up. max_hole: the largest patch without hits (m, each side of its
    bounding box) inside consistent floor that is taken as floor. max_gap: the widest
    opening (m) between two floor samples along a row, column or diagonal taken as floor,
    measured between where the floor hits of the cells at its ends lie (their mean: the
    hits nearest the opening lie no farther out), from the far edge of an end cell without
    floor hits (it may be lit on part of its width only), away from any drop-off, surface
    below the floor model, level reaching more than a step below it or level reaching more than
    plane_tolerance below the floor beside it (`_dips`) (the diagonal of a hole max_gap
    plus two cells wide, as wide as a hole without unobserved space wider than max_gap in
    it: turned to the lines, its far wall lies that far from its near corner) and from any such
    wider unobserved space (max_gap): this scanner's lines lie r * 2 pi / 53 apart on the
    floor at range r (0.19 m at 1.6 m, 0.3 m at 2.5 m), so a hole of max_gap seen from
    2.5 m or nearer is crossed by a line and shows itself (below the floor, or a
    drop-off) before its cells are filled.
    floor_probe: rays that passed this low (m) over a cell's floor should have lit it
    (the stripe runs along them); without a return there it is not FREE. Nor is a cell
    without a hit within max_gap of floor a laser line crossed without a return
    (`CellLayers.unlit`, `scanmap.grid.unlit`: black carpet, a black-lined hole), however
    small the patch: no gap between samples lies there.
    min_logodds: the log-odds a level in the robot's band needs to make its cell an
    OBSTACLE. Below it the level is as likely gone as there (a surface seen in one scan
    and seen through twice since: 0.85 - 2 x 0.4 = 0.05 with the grid's defaults, a
    person who walked on): its cell is UNKNOWN, neither an obstacle nor free. Between
    0.05 and one hit less one miss (0.45), so a surface seen once and through once stays.
    max_pinhole: the largest patch (m, each side) of UNKNOWN cells without any hit whose
    every neighbour is FREE that is taken as FREE: a pinhole between the laser's samples
    in floor seen free all round (a hole there shows its far wall as hits, which are not
    FREE). 0.15 m: three cells, the span `interpolated` fills between floor samples.
    blind_range: the nearest floor (m) the scanner sees from where it stands (1.49 m for
    the reference scanner, its camera 1 m up): a drop-off's spread keeps to the line of
    sight from the nearest place the robot stood through a cell showing it only where
    that place lies at least this far off. Nearer, it was seen from elsewhere: from one
    of the places the robot stood blind_range to view_range off (any), whose line of
    sight and ranges then bound it, the rim's shadow reaching nearer by d /
    (emitter_height + d) of the range of a cell showing the floor missing d deep (at
    least rim_shadow).
    view_range: the farthest floor (m) the scanner sees (the reference scanner's
    max_range). emitter_height: the laser emitter's height (m) over the floor (0.5 m on
    the reference scanner): its light over a rim reaches d below the floor at
    (emitter_height + d) / emitter_height times the rim's range.
    """

    thickness: float = 0.06
    clearance: float = 0.2
    plane_tolerance: float = 0.03
    max_slope: float = math.radians(15.0)
    min_plane_cells: int = 100
    min_seed_cells: int = 3
    seed_tolerance: float = 0.01
    max_planes: int = 4
    fill_radius: float = 1.0
    min_coverage: float = 0.5
    coverage_reach: float = 0.05
    overhang_reach: float = 1.0
    overhang_thickness: float = 0.1
    ransac_iterations: int = 200
    seed: int = 0
    detect: bool = True
    slope_reach: float = 0.1
    plane_noise: float = 0.003
    drop_reach: float = 0.5
    rim_shadow: float = 0.1
    max_hole: float = 0.3
    max_gap: float = 0.3
    floor_probe: float = 0.1
    min_logodds: float = 0.2
    max_pinhole: float = 0.15
    blind_range: float = 1.5
    view_range: float = 4.0
    emitter_height: float = 0.5


@dataclass(frozen=True)
class FloorPlane:
    """A floor plane normal . p = offset (unit normal, z up) and the floor cells it explains."""

    normal: tuple[float, float, float]
    offset: float
    cells: int

    def height_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Plane height at (x, y)."""
        a, b, c = self.normal
        return (self.offset - a * np.asarray(x) - b * np.asarray(y)) / c


@dataclass(frozen=True, eq=False)
class Segmentation:
    """Floor and obstacle layers of a window of the grid (row = y, column = x).

    floor_height: (ny, nx) float32, NaN where unknown. is_floor: open floor: known floor
    (seen there, stood on, or a small gap in it, not within max_gap of floor a laser
    line crossed without a return: `scanmap.grid.unlit`), nothing is in the robot's band, and
    nothing may hang above unseen (not the floor under a table); and the edge of a step
    between two floors (an OBSTACLE). Traversable = is_floor and FREE (the band was
    seen). slope: (ny, nx) float32 floor slope (rad) of the cells
    with observed floor, NaN elsewhere.
    state: UNKNOWN / FREE / OBSTACLE / DROP_OFF per cell. points: (ny, nx, 2) float32, the obstacle
    point of each obstacle cell (mean of its hits in the band), the centre elsewhere.
    band_logodds: (ny, nx) float32, highest log-odds of the band's levels of at least
    `FloorConfig.min_logodds` (NaN where none).
    updated: (ny, nx) float64 last update time.
    """

    origin: tuple[float, float]
    resolution: float
    robot: RobotShape
    floor_height: np.ndarray
    is_floor: np.ndarray
    planes: tuple[FloorPlane, ...]
    state: np.ndarray
    points: np.ndarray
    band_logodds: np.ndarray
    updated: np.ndarray
    slope: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx)."""
        return tuple(self.state.shape)


def ransac_plane(points: np.ndarray, params: FloorConfig,
                 rng: np.random.Generator) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The near-horizontal plane with most points within `seed_tolerance` (the floor's
    own noise) among `ransac_iterations` hypotheses (fewer once RANSAC_CONFIDENCE is
    reached), refined by least squares on those points; its inliers are the points within
    `plane_tolerance`; or None. Scored within plane_tolerance, a plane half way down a
    dock 6 cm deep held the floor and the dock both."""
    if len(points) < 3:
        return None
    triples = rng.integers(0, len(points), (params.ransac_iterations, 3))
    normals, anchors = nk.level_hypotheses(np.ascontiguousarray(points, dtype=np.float64),
                                           triples, math.cos(params.max_slope))
    if not len(normals):
        return None
    coords = np.ascontiguousarray(points.T, dtype=np.float64)
    sample = rng.integers(0, len(points), min(len(points), 4000))
    count, normal, offset = nk.best_plane(coords, sample, anchors, normals,
                                          params.seed_tolerance, RANSAC_CONFIDENCE, 2)
    if count < 3:
        return None
    if normal[2] < math.cos(params.max_slope):
        return None
    return normal, offset, np.abs(points @ normal - offset) <= params.plane_tolerance


def _planes_of(points: np.ndarray, params: FloorConfig,
               rng: np.random.Generator) -> tuple[FloorPlane, ...]:
    """Sequential RANSAC planes explaining the floor cells, largest first."""
    planes = []
    remaining = points
    while len(planes) < params.max_planes and len(remaining) >= params.min_plane_cells:
        found = ransac_plane(remaining, params, rng)
        if found is None or found[2].sum() < params.min_plane_cells:
            break
        normal, offset, inliers = found
        planes.append(FloorPlane(tuple(map(float, normal)), offset, int(inliers.sum())))
        remaining = remaining[~inliers]
    return tuple(planes)


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
    the part segmented, `_carry`), else of the largest plane (else
    `fallback_floor`, else NaN), as segmenting the whole window gives them (to the
    rounding of the cell centres, computed from another origin). A window round the
    robot often holds much that no ray reached (behind a corridor's walls: two thirds of
    an 8 m window).
    """
    robot = robot or RobotShape()
    params = params or FloorConfig()
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
        floor_height = nk.plane_heights(inner.planes[0].normal, inner.planes[0].offset, xs, ys)
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


def _reach(params: FloorConfig, resolution: float) -> int:
    """How far (cells) any rule that decides a cell's state reaches from the cells that
    were observed: a drop-off spread, a gap bridged, an overhang spread out and back (to
    an observed cell: half its reach; farther out it covers cells UNKNOWN anyway), and a
    few cells more for the 3 x 3 and 5 x 5 neighbourhoods on the way. The floor's height
    carried farther is `_carry`'s."""
    farthest = max(params.drop_reach, params.max_gap, params.max_hole,
                   0.5 * params.overhang_reach)
    return math.ceil(farthest / resolution) + 3


def _carry(heights: np.ndarray, carried: np.ndarray, into: np.ndarray, fill_radius: float,
           resolution: float, margins: tuple[int, int, int, int]) -> np.ndarray:
    """Give the cells `into` within `fill_radius` (m) of a cell of `carried` that cell's
    height (the nearest's), in place. Returns the heights so carried into a border of
    `margins` (top, bottom, left, right) cells round the array (NaN elsewhere and inside
    it): a box segmented alone gives the cells round it the height of its floor as
    segmenting the whole window would, from the same distance transform."""
    top, bottom, left, right = margins
    ny, nx = carried.shape
    inside = (slice(top, top + ny), slice(left, left + nx))
    sources = np.zeros((ny + top + bottom, nx + left + right), bool)
    sources[inside] = carried
    distance, nearest = distance_transform(sources)
    reached = distance * resolution <= fill_radius
    padded = np.full(sources.shape, np.nan, np.float32)
    padded[inside] = heights
    fill = into & reached[inside]
    heights[fill] = padded.reshape(-1)[nearest[inside][fill]]
    reached[inside] = False
    beyond = np.full(sources.shape, np.nan, np.float32)
    beyond[reached] = padded.reshape(-1)[nearest[reached]]
    return beyond


def _observed_box(layers: CellLayers, robot: RobotShape, reach: int) -> tuple[slice, slice]:
    """Rows and columns of the smallest box holding every cell with a hit or with heights
    rays saw, and every place the robot stood, grown by `reach` cells (within the window;
    empty when nothing was observed)."""
    ny, nx = layers.shape
    top, bottom, left, right = nk.observed_span(
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
    None where no floor was seen)."""
    rng = np.random.default_rng(params.seed)
    ny, nx = layers.shape
    res = layers.resolution
    xs, ys = layers.cell_centers()
    cand = nk.floor_candidates(layers.levels, layers.nlev, params.thickness, params.clearance)
    hits_at = layers.levels[:, :, 0, gk.MX:gk.MY + 1]  # mean hit offsets (a view: copied
    # contiguous, they took a fifth more of the slope's time)
    # the most a cell's heights span on one surface one may drive on: max_slope across its
    # diagonal, and the noise on both ends (the extremes of a cell's tens of hits lie about
    # three times the noise off the surface: at twice, a 14.6 deg ramp's cells 3-4 m off,
    # at 0.3 px of laser peak noise, were too thick for their mean hits to count)
    one_surface = res * math.sqrt(2.0) * math.tan(params.max_slope) + 6.0 * params.plane_noise
    mean_heights = nk.mean_hit_heights(layers.levels, layers.nlev, cand, one_surface)
    slope, tangents = nk.local_slope(mean_heights, hits_at,
                                     max(round(params.slope_reach / res), 1),
                                     robot.step_height, res, params.plane_noise,
                                     _taller_than(layers, cand, robot.step_height))
    # steep, or crossed by a face down a step (no floor of its own: a step's edge between
    # two floors at most, `step_edges`)
    steep = (slope > params.max_slope) | nk.faces_below(layers.levels, cand,
                                                        robot.step_height)  # False for NaN
    bridges = _bridged_steps(cand, slope <= LEVEL_SLOPE, robot.step_height,
                             _bridge_reach(robot, params, res)) & ~steep  # a step's face
    level = np.where(steep | bridges, np.nan, cand)
    has = ~np.isnan(level)
    gy, gx, cand_points = nk.cell_points(has, level, xs, ys)
    is_floor = np.zeros((ny, nx), bool)
    carried = is_floor  # the floor whose heights `fill_radius` carries
    planes: tuple[FloorPlane, ...] = ()
    dominant = ransac_plane(cand_points, params, rng) if params.detect else None
    if dominant is not None and dominant[2].sum() >= params.min_plane_cells:
        normal, offset, inliers = dominant
        seeds = np.zeros((ny, nx), bool)
        seeds[gy[inliers], gx[inliers]] = True
        close = np.zeros((ny, nx), bool)
        close[gy, gx] = np.abs(cand_points @ normal - offset) <= params.seed_tolerance
        seeds &= morphology.large_components(seeds, params.min_seed_cells) | close
        is_floor = nk.grow_region(level, seeds, robot.step_height, layers.nlev == 0,
                                   math.tan(params.max_slope) * res, cand, tangents,
                                   2.0 * params.plane_noise,
                                   nk.plane_heights(tuple(map(float, normal)), float(offset),
                                                    xs, ys),
                                   ~np.isnan(tangents[:, :, 3]))
        # one step on: a bridge joins the floor it touches, no further, and only within
        # half a step of it (nearer that floor than the other side of the step): a cell of
        # the floor below a 5.5 cm step, read 5 mm high, lay 4.9 cm under the floor's edge
        # beside it and joined it (step room 2027 at 0.3 px, FREE after its last scans)
        joined = nk.touching_floor(cand, is_floor, bridges, 0.5 * robot.step_height)
        is_floor |= joined
        # and its height, in between on a step's face, goes no further either: carried
        # over a lower floor 5.5 cm down, it held that floor within a step of the floor
        carried = is_floor & ~joined
        bridges &= ~joined
        planes = _planes_of(nk.cell_points(is_floor, cand, xs, ys)[2], params, rng)
    edges = nk.step_edges(layers.levels, layers.nlev, cand, is_floor, robot.step_height,
                          params.clearance, params.plane_tolerance)
    floor_height = np.where(is_floor, cand, np.nan).astype(np.float32)
    rim_y, rim_x, rim_top = _rims(layers.levels, layers.nlev, edges, is_floor, floor_height,
                                  robot.step_height)
    edges[rim_y, rim_x] = False
    is_floor[rim_y, rim_x] = True
    floor_height[rim_y, rim_x] = rim_top
    beyond = None
    if carried.any():
        beyond = _carry(floor_height, carried, ~is_floor, params.fill_radius, res, margins)
    if planes:  # farther out, the largest floor plane
        unknown = np.isnan(floor_height)
        floor_height[unknown] = nk.plane_heights(planes[0].normal, planes[0].offset, xs,
                                                 ys)[unknown]
    assumed = np.zeros((ny, nx), bool)
    if fallback_floor is not None:  # the caller vouches for the floor there
        assumed = np.isnan(floor_height)
        floor_height[assumed] = fallback_floor
    stood = _footprint_cells(layers, robot.radius)  # observed floor or not: it stood there
    edges &= ~stood
    # Below the lowest floor near the cell (a cell between two floors at a step is neither's)
    lowest = morphology.min_filter(np.where(np.isnan(floor_height), np.inf, floor_height), 5)
    lowest = np.where(np.isfinite(lowest), lowest, floor_height).astype(np.float32)
    drop = nk.below_floor(layers.levels, layers.nlev, layers.seen, lowest,
                          robot.step_height, layers.z_min, layers.mask_dz,
                          one_surface) & ~is_floor & ~stood
    ranges = None  # `_ranges`, when a rule needs them
    if drop.any():  # and below the floor where the robot stood nearest (`_stood_floor`)
        ranges, nearest = _ranges(layers)
        drop &= nk.below_floor(layers.levels, layers.nlev, layers.seen,
                               _stood_floor(lowest, floor_height, nearest), robot.step_height,
                               layers.z_min, layers.mask_dz, one_surface)
    bottom = np.ascontiguousarray(layers.levels[:, :, 0, gk.LO])  # of each lowest level
    lowest_free = nk.lowest_seen(layers.seen, layers.z_min, layers.mask_dz)
    # a step down to floor reached round its ends: spread as a drop-off is (its shadow is
    # no place to drive either), then an edge, not a drop-off (below)
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
        shadow &= ~nk.interpolated(known, (layers.nlev > 0) | drop | _beyond_spans(known, hole),
                                   floor_height, hole, robot.step_height, False, nk.NO_SAMPLES)
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
        rim = (layers.nlev == 0) & ~morphology.within_distance(seeds, 1.0) & ~nk.interpolated(
            known, (layers.nlev > 0) | drop | _beyond_spans(known, 2), floor_height, 2,
            robot.step_height, False, nk.NO_SAMPLES)
        own = _seen_from_cells(layers).reshape(-1, 2)[sources]
        own[sources < 0] = np.nan
        drop |= morphology.dilate_in_range(spread & ~seeds, rim, ranges, near, ranges, 1,
                                           viewed_from, 0.5,
                                           elsewhere._replace(above=0.0, own=own))
    holes &= ~drop
    # Patches without any hit in or around them (3 x 3): a gap between the laser's samples
    # if the whole patch is small and inside level floor; where rays passed low over one
    # (not the foot of a surface a ray ended on) the laser should have lit it
    probed = lowest_free <= floor_height + params.floor_probe
    bare = ~morphology.max_filter(layers.nlev > 0, 3)
    dips = _dips(layers.nlev, bottom, is_floor, params.plane_tolerance)
    holes |= _lit_gaps(bare & ~is_floor & ~stood & ~assumed, layers.nlev, is_floor,
                       floor_height, drop, dips, round(params.max_hole / res),
                       robot.step_height)
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
    seen_floor = nk.interpolated(known_floor, informative | lone, floor_height, 1,
                                 robot.step_height, True, samples)
    # but not next to a sign of a hole (a drop-off, a dip): the span may cross the hole's
    # corner, from its near rim's floor to the top of its far wall
    seen_floor &= known_floor | ~morphology.dilate(drop | dips)
    drop |= _sunk(bare & ~holes & ~is_floor & ~stood & ~assumed, layers, is_floor, lowest,
                  drop, round(params.max_hole / res), params.plane_tolerance, ranges)
    gap = round(params.max_gap / res)
    lines = np.zeros((ny, nx), bool)
    if gap > 2:
        wide = ~morphology.within_distance(observed, 0.5 * (gap + 1))  # unobserved > max_gap
        with np.errstate(invalid="ignore"):  # the feet of surfaces standing on the floor
            foot = (layers.nlev > 0) & ~known_floor \
                & (np.abs(bottom - floor_height) <= robot.step_height)
        # An opening of at most gap cells (`interpolated`'s size + 2), measured between
        # the floor hits of the cells at its ends (from the far edge of an end without)
        lines = nk.interpolated(known_floor | foot, informative | wide, floor_height, gap - 2,
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
    unlit = (probed & bare) | steep | bridges
    unlit &= ~is_floor & ~stood & ~assumed & ~holes & ~lines
    unlit |= ~seen_floor
    # Near floor a laser line crossed without a return (`scanmap.grid.unlit`: black
    # carpet, a black-lined hole), no cell without a hit is a gap between samples: the
    # laser was aimed there and nothing came back
    dark = layers.unlit & (layers.nlev == 0)
    dim = morphology.within_distance(dark, gap) & (layers.nlev == 0) & ~stood \
        if dark.any() else dark
    unlit |= dim
    state = np.empty((ny, nx), np.uint8)
    points = np.empty((ny, nx, 2), np.float32)
    band_logodds = np.empty((ny, nx), np.float32)
    covered = np.zeros((ny, nx), np.bool_)
    pool = round(params.coverage_reach / res)
    counted = layers.seen
    if pool:  # known floor off a drop-off's rim: the coverage over it and its neighbours
        known = morphology.dilate(is_floor) | holes | lines
        known &= ~morphology.dilate(drop)
        counted = np.where(known, nk.pooled_bits(layers.seen, pool), layers.seen)
    nk.classify_band(layers.levels, layers.nlev, layers.seen, counted, floor_height,
                     robot.step_height, robot.height, layers.z_min, layers.mask_dz,
                     params.min_coverage, round(params.overhang_reach / res),
                     params.overhang_thickness, layers.origin[0], layers.origin[1], res,
                     state, points, band_logodds, covered, params.min_logodds)
    state[(state == FREE) & unlit] = UNKNOWN
    state[edges] = OBSTACLE  # floor on both sides, a step the robot cannot take between
    state[stood & (state != OBSTACLE) & ~covered] = FREE  # not under a board seen overhead
    # the face of a step down to floor reached round its ends and the shadow it spread
    # into are an edge: the floor there is not missing, but no robot crosses it
    step_down = morphology.geodesic_dilate(sunk, drop, ny * nx) if sunk.any() else sunk
    state[drop & ~step_down & (state != OBSTACLE)] = DROP_OFF
    state[step_down] = OBSTACLE
    state[_pinholes(state, layers.nlev, round(params.max_pinhole / res)) & ~dim] = FREE
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
    state[scant & (state == FREE) & morphology.dilate(dropped | sunken, 2)] = UNKNOWN
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
        off = _over_the_rim(hits_at[by, bx], holeward, by, bx, res)
        if planes:
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
    crossing = nk.free_steps((state == FREE) & (is_floor | ~stood), floor_height,
                             robot.step_height, stood)
    state[crossing] = OBSTACLE
    return Segmentation(origin=layers.origin, resolution=res, robot=robot,
                        floor_height=floor_height,
                        is_floor=((is_floor | stood | holes & ~dim)
                                  & ((state != OBSTACLE) | crossing) & ~drop & ~covered) | edges,
                        planes=planes, state=state, points=points, band_logodds=band_logodds,
                        updated=layers.updated,
                        slope=np.where(is_floor, slope, np.nan).astype(np.float32)), beyond


def _rims(levels: np.ndarray, nlev: np.ndarray, edges: np.ndarray, is_floor: np.ndarray,
          floor_height: np.ndarray, max_step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and tops of the step's edge cells (`step_edges`) that are the floor
    above the step at its rim: most of their hits lie on their top (the mean hit in the
    level's upper quarter; a face's cell holds the face's hits from its foot up), a floor
    cell beside them lies within a step of that top and none more than a step below it
    (the face's hits beyond the rim leave the cells beyond it an edge). A face on a cell's
    boundary scatters some of its hits over it at the laser's noise, and the cells along a
    ramp's side or raised end were an obstacle where the ramp's surface covers them."""
    return nk.rim_cells(levels, nlev, edges, is_floor, floor_height, max_step)


def _bridge_reach(robot: RobotShape, params: FloorConfig, resolution: float) -> float:
    """How far apart (cells) `bridged_steps` looks for a step's two sides: as far as a
    ramp at `max_slope` rises nine tenths of a step, a tenth left for the floor's noise
    (0.17 m, 3.4 cells at the defaults), at least two cells, and no farther than
    FACE_SPAN: a face's in-between levels lie across a few cells whatever the robot, and
    farther out a raised ramp's cells lie more than a step above the floor beside it (a
    robot with a 10 cm step and 10 deg looked 0.51 m across: a third of a 7.7 deg ramp's
    cells bridges)."""
    run = 0.9 * robot.step_height / max(math.tan(params.max_slope), 1e-9)
    return max(min(run, FACE_SPAN) / resolution, 2.0)


def _bridged_steps(heights: np.ndarray, level: np.ndarray, max_step: float, reach: float
                   ) -> np.ndarray:
    """`nk.bridged_steps` (`level`: the candidates on level floor), looking only where the
    candidates in the square of `reach` cells round a cell span more than `max_step` (a
    bridge needs two that far apart within `reach` of it): on level floor that is few
    cells, and their search was a twentieth of a segmentation."""
    varied = morphology.span_filter(heights, 2 * int(reach) + 1) > max_step
    return nk.bridged_steps(heights, level, max_step, reach, varied)


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


def _sunk(dark: np.ndarray, layers: CellLayers, is_floor: np.ndarray, lowest: np.ndarray,
          drop: np.ndarray, size: int, tolerance: float, ranges: np.ndarray | None
          ) -> np.ndarray:
    """The patches of `dark` (no hit in or around them, not a gap) at most `size` cells on
    each side, not at the window's edge nor next to a drop-off (its shadow is the drop's
    own rule), with a surface wholly below the floor model (`_below_model`) within two
    cells, no nearer to where the robot stood than the patch's nearest cell (`ranges`:
    `_ranges`' distances, computed here when None): the floor goes down into a small
    patch nothing returned from (a hole's far wall, seen only at its top, lies beyond the
    hole; a patch beyond a lowered area's far edge is the unlit floor there). Not the
    cells around the patch: a hit or floor near, they may be floor (the hole's extent is
    not known there), so they stay UNKNOWN."""
    ny, nx = dark.shape
    low = _below_model(layers, is_floor, lowest, tolerance)
    out = np.zeros((ny, nx), bool)
    if not low.any():
        return out
    labels, boxes, ok = _small_patches(dark, size, margin=2)
    near = morphology.max_filter(low, 5)
    near_drop = morphology.max_filter(drop, 3)
    for index in np.flatnonzero(ok):
        rows, cols = morphology.box_slices(boxes[index])
        patch = labels[rows, cols] == index
        if not near[rows, cols][patch].any() or near_drop[rows, cols][patch].any():
            continue
        if ranges is None:
            ranges = _ranges(layers)[0]
        around = (slice(max(rows.start - 2, 0), rows.stop + 2),
                  slice(max(cols.start - 2, 0), cols.stop + 2))
        if ranges[around][low[around]].max() >= ranges[rows, cols][patch].min():
            out[rows, cols] |= patch
    return out


def _beyond_spans(known: np.ndarray, size: int) -> np.ndarray:
    """Cells more than `size` + 2 cells (along rows, columns or diagonals) from every cell
    of `known`: `interpolated` (size, no samples) bridges no span through them, nor through
    a cell next to them (a span's cells lie within size + 1 of its ends). Passed to it as
    hits they are skipped, and its result is the same (the unobserved space round a
    window's drop-offs: half its cells in the hazards scene)."""
    return ~morphology.max_filter(known, 2 * size + 5)


def _ranges(layers: CellLayers) -> tuple[np.ndarray, np.ndarray]:
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


def _between(mask: np.ndarray) -> np.ndarray:
    """Cells with a cell of `mask` on both sides of them in their row or in their
    column."""
    out = np.zeros(mask.shape, bool)
    np.logical_and(mask[:, :-2], mask[:, 2:], out=out[:, 1:-1])
    out[1:-1] |= mask[:-2] & mask[2:]
    return out


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
    (`_ranges`). Floor below the floor around it but not below the floor the robot stood
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


def _below_model(layers: CellLayers, is_floor: np.ndarray, floor: np.ndarray,
                 tolerance: float) -> np.ndarray:
    """Cells with hits, not floor, whose lowest level lies wholly more than `tolerance`
    below `floor` (the lowest floor around them, or their own): a surface below the floor
    model (a hole's far wall, seen only at its top, less than a step down)."""
    return nk.lowest_level_below(layers.levels, layers.nlev, is_floor, floor - tolerance,
                                 gk.HI)


def _taller_than(layers: CellLayers, candidates: np.ndarray, span: float) -> np.ndarray:
    """Floor candidates whose lowest level spans more than `span` (m)."""
    return (layers.levels[:, :, 0, gk.HI] - layers.levels[:, :, 0, gk.LO] > span) \
        & ~np.isnan(candidates)


def _reaching_below(layers: CellLayers, is_floor: np.ndarray, floor: np.ndarray,
                    depth: float) -> np.ndarray:
    """Cells with hits, not floor, whose lowest level reaches more than `depth` below
    `floor` (as for `_below_model`): the far rim of a hole whose wall, seen only at its
    top, fell into the cell of the floor beyond it (one level from the wall's hits up to
    the floor's: not wholly below the floor, so not `_below_model`, yet a sign of a hole)."""
    return nk.lowest_level_below(layers.levels, layers.nlev, is_floor, floor - depth, gk.LO)


def _lit_gaps(bare: np.ndarray, nlev: np.ndarray, is_floor: np.ndarray,
              floor_height: np.ndarray, drop: np.ndarray, dips: np.ndarray, size: int,
              step: float) -> np.ndarray:
    """Patches of `bare` cells (no hit around them) at most `size` cells on each side, not
    at the window's edge nor next to a drop-off, whose hits within two cells are all floor
    with heights differing by at most `step`, none of `dips` (`_dips`): gaps between the
    laser's samples."""
    labels, boxes, ok = _small_patches(bare, size, margin=2)
    gaps = nk.floor_gaps(labels, boxes, ok, morphology.dilate(drop), nlev, is_floor,
                         floor_height, dips, step)
    return gaps.take(labels)


def _floor_samples(layers: CellLayers, is_floor: np.ndarray) -> np.ndarray:
    """(ny, nx, 2) where each floor cell's floor hits lie (the mean of its lowest level's:
    x and y offsets from the cell's centre, in cells), NaN off the floor: the ends of an
    opening between the laser's lines, to measure it to the hits rather than to the
    cells' edges (the hits nearest the opening lie no farther out than their mean)."""
    return nk.floor_samples(layers.levels, layers.nlev, is_floor, layers.resolution)


def _below_all_floor(nlev: np.ndarray, bottom: np.ndarray, is_floor: np.ndarray,
                     tolerance: float) -> np.ndarray:
    """Cells with hits whose lowest level's `bottom` lies more than `tolerance` below the
    lowest bottom of the floor cells in their 5 x 5 square (of `_dips`, those below every
    floor near them: not the face of a raised ramp, whose foot is the floor beside it,
    two cells off where a turned ramp's face crosses two)."""
    with np.errstate(invalid="ignore"):
        floor_bottom = np.where(is_floor & (nlev > 0), bottom, np.inf)
        return (nlev > 0) & (bottom < morphology.min_filter(floor_bottom, 5) - tolerance)


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


def _footprint_cells(layers: CellLayers, radius: float) -> np.ndarray:
    """Cells the footprint (a disc of `radius` round where the sensor stood) overlaps: the
    robot's own body never touches unknown space where it stood, as queries measure it
    (to the cells' squares)."""
    xs, ys = layers.cell_centers()
    return nk.footprint_cells(np.asarray(layers.stood, dtype=np.float64).reshape(-1, 2), xs,
                              ys, layers.origin[0], layers.origin[1], layers.resolution,
                              radius, math.ceil(radius / layers.resolution))


def _small_patches(mask: np.ndarray, size: int, margin: int = 1
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Components of `mask`: labels, each label's box (x, y, width, height) and whether it
    is at most `size` cells on each side and at least `margin` cells from the window's
    edge (False for label 0, off the mask)."""
    ny, nx = mask.shape
    labels, boxes = morphology.component_boxes(mask)
    x, y, w, h = boxes.T
    ok = (w <= size) & (h <= size) & (x >= margin) & (y >= margin) \
        & (x + w <= nx - margin) & (y + h <= ny - margin)
    ok[0] = False
    return labels, boxes, ok


def _pinholes(state: np.ndarray, nlev: np.ndarray, size: int) -> np.ndarray:
    """Patches of UNKNOWN cells without any hit, at most `size` cells on each side, not
    touching the window's edge, whose every neighbour is FREE."""
    patch = (state == UNKNOWN) & (nlev == 0)
    labels, _, ok = _small_patches(patch, size)
    ok[labels[morphology.dilate((state != FREE) & ~patch) & patch]] = False
    return ok.take(labels)


def _small_holes(nlev: np.ndarray, is_floor: np.ndarray, floor_height: np.ndarray,
                 drop: np.ndarray, size: int, step: float) -> np.ndarray:
    """Patches of cells without any hit, at most `size` cells on each side, inside floor
    (not touching the window's edge) whose heights around them differ by at most `step`,
    and showing no drop-off."""
    labels, _, ok = _small_patches(~is_floor, size)
    count = len(ok) - 1
    if not count:
        return np.zeros(is_floor.shape, bool)
    ok[labels[(nlev > 0) | drop]] = False
    # The ring of a patch: floor cells next to it (a patch is a whole component of the
    # cells off the floor, so every neighbour outside it is floor)
    low, high = nk.ring_heights(labels, count, is_floor, floor_height)
    ok &= high - low <= step
    return ok.take(labels)
