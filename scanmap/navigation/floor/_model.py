"""The floor model: which cells are floor, their slope and height.

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
steep ramp are steep, not half as steep; `_plane_kernels.local_slope`; a cell the crease
crosses, its mean hit on both sides, takes the ramp's slope where its centre lies past
the crease, `_plane_kernels._across_crease`); a cell steeper than
`max_slope` (default 15 deg) does not join the floor: it is never FREE, and an OBSTACLE
where its surface rises into the robot's band; nor does one whose lowest level reaches
from a candidate beside it more than a step down (a face the robot cannot climb crosses
it; `_plane_kernels.faces_below`). So a ramp within max_slope and a step within the robot's
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
(as far as a ramp at `max_slope` rises 9/10 of a step: `bridged_steps`; two cells at
least, and two farther apart than that run only where their mean hits lie on a slope
steeper than such a ramp's or the cell's level spans more than a ramp's cell), joins the
floor only from a floor cell next to it, and the growth goes no further from it, so the
floor below the step is not reached through it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import CellLayers
from scanmap.navigation import morphology
from scanmap.navigation.distance_field import distance_transform
from scanmap.navigation.floor._growth_kernels import (
    bridged_steps,
    grow_region,
    rim_cells,
    step_edges,
    touching_floor,
)
from scanmap.navigation.floor._plane_kernels import (
    LEVEL_SLOPE,
    best_plane,
    cell_points,
    faces_below,
    floor_candidates,
    level_hypotheses,
    local_slope,
    mean_hit_heights,
    plane_heights,
)
from scanmap.navigation.floor.config import FloorConfig, RobotShape
from scanmap.navigation.floor.result import FloorPlane

# RANSAC counts no more hypotheses once, at this confidence, one of those drawn was three
# cells of the best plane so far (`ransac_iterations` at most): 16 when that plane holds
# 90 % of the candidates, 86 at 60 %, all 200 below 46.5 %
RANSAC_CONFIDENCE = 1.0 - 1e-9


# the share of a step a ramp at max_slope rises as far as `bridged_steps` looks for a
# step's two sides, the rest left for the floor's noise (`_ramp_run`)
RAMP_SHARE = 0.9


# how far across (m) a turned step's face leaves levels at in-between heights: up to three
# cells and a half (noise, the face at a slant to the cells), the default robot's reach
FACE_SPAN = 0.17


@dataclass(frozen=True, eq=False)
class FloorModel:
    """What `floor_model` found: the floor and its height in every cell of a window."""

    hits_at: np.ndarray  # (ny, nx, 2) mean hit offsets of each cell's lowest level
    one_surface: float  # the most a cell's heights span on one drivable surface (m)
    slope: np.ndarray  # (ny, nx) each candidate's slope (rad)
    steep: np.ndarray  # candidates too steep to be floor, or crossed by a face down a step
    bridges: np.ndarray  # in-between levels of a step's face (`_bridged_steps`)
    is_floor: np.ndarray
    planes: tuple[FloorPlane, ...]
    edges: np.ndarray  # a step's edge between two floors (an OBSTACLE)
    floor_height: np.ndarray  # float32, NaN where unknown
    assumed: np.ndarray  # cells whose floor is the caller's `fallback_floor`
    beyond: np.ndarray | None  # the heights carried into the margins (`_carry`)


def floor_model(layers: CellLayers, robot: RobotShape, params: FloorConfig,
                fallback_floor: float | None, margins: tuple[int, int, int, int],
                stood: np.ndarray) -> FloorModel:
    """The floor (the module docstring's "Floor" and "Floor per cell"): candidates, their
    slopes, the dominant plane's region grown over them, the step's edges between two
    floors and the floor heights, carried into the cells without floor."""
    rng = np.random.default_rng(params.seed)
    ny, nx = layers.shape
    res = layers.resolution
    xs, ys = layers.cell_centers()
    cand = floor_candidates(layers.levels, layers.nlev, params.thickness, params.clearance)
    hits_at = layers.levels[:, :, 0, gk.MX:gk.MY + 1]  # mean hit offsets (a view: copied
    # contiguous, they took a fifth more of the slope's time)
    # the most a cell's heights span on one surface one may drive on: max_slope across its
    # diagonal, and the noise on both ends (the extremes of a cell's tens of hits lie about
    # three times the noise off the surface: at twice, a 14.6 deg ramp's cells 3-4 m off,
    # at 0.3 px of laser peak noise, were too thick for their mean hits to count)
    one_surface = res * math.sqrt(2.0) * math.tan(params.max_slope) + 6.0 * params.plane_noise
    mean_heights = mean_hit_heights(layers.levels, layers.nlev, cand, one_surface)
    spans = layers.levels[:, :, 0, gk.HI] - layers.levels[:, :, 0, gk.LO]  # lowest levels'
    slope, tangents = local_slope(mean_heights, hits_at,
                                  max(round(params.slope_reach / res), 1),
                                  robot.step_height, res, params.plane_noise,
                                  (spans > robot.step_height) & ~np.isnan(cand))
    # steep, or crossed by a face down a step (no floor of its own: a step's edge between
    # two floors at most, `step_edges`)
    steep = (slope > params.max_slope) | faces_below(layers.levels, cand,
                                                     robot.step_height)  # False for NaN
    bridges = _bridged_steps(cand, slope <= LEVEL_SLOPE, robot, params, res,
                             (spans, mean_heights, hits_at)) & ~steep  # a step's face
    level = np.where(steep | bridges, np.nan, cand)
    has = ~np.isnan(level)
    gy, gx, cand_points = cell_points(has, level, xs, ys)
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
        is_floor = grow_region(level, seeds, robot.step_height, layers.nlev == 0,
                               math.tan(params.max_slope) * res, cand, tangents,
                               2.0 * params.plane_noise,
                               plane_heights(tuple(map(float, normal)), float(offset),
                                             xs, ys),
                               ~np.isnan(tangents[:, :, 3]))
        # one step on: a bridge joins the floor it touches, no further, and only within
        # half a step of it (nearer that floor than the other side of the step): a cell of
        # the floor below a 5.5 cm step, read 5 mm high, lay 4.9 cm under the floor's edge
        # beside it and joined it (step room 2027 at 0.3 px, FREE after its last scans)
        joined = touching_floor(cand, is_floor, bridges, 0.5 * robot.step_height)
        is_floor |= joined
        # and its height, in between on a step's face, goes no further either: carried
        # over a lower floor 5.5 cm down, it held that floor within a step of the floor
        carried = is_floor & ~joined
        bridges &= ~joined
        planes = _planes_of(cell_points(is_floor, cand, xs, ys)[2], params, rng)
    edges = step_edges(layers.levels, layers.nlev, cand, is_floor, robot.step_height,
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
        floor_height[unknown] = plane_heights(planes[0].normal, planes[0].offset, xs,
                                              ys)[unknown]
    assumed = np.zeros((ny, nx), bool)
    if fallback_floor is not None:  # the caller vouches for the floor there
        assumed = np.isnan(floor_height)
        floor_height[assumed] = fallback_floor
    edges &= ~stood
    return FloorModel(hits_at=hits_at, one_surface=one_surface, slope=slope, steep=steep,
                      bridges=bridges, is_floor=is_floor, planes=planes, edges=edges,
                      floor_height=floor_height, assumed=assumed, beyond=beyond)


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
    normals, anchors = level_hypotheses(np.ascontiguousarray(points, dtype=np.float64),
                                        triples, math.cos(params.max_slope))
    if not len(normals):
        return None
    coords = np.ascontiguousarray(points.T, dtype=np.float64)
    sample = rng.integers(0, len(points), min(len(points), 4000))
    count, normal, offset = best_plane(coords, sample, anchors, normals,
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


def _rims(levels: np.ndarray, nlev: np.ndarray, edges: np.ndarray, is_floor: np.ndarray,
          floor_height: np.ndarray, max_step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and tops of the step's edge cells (`step_edges`) that are the floor
    above the step at its rim: most of their hits lie on their top (the mean hit in the
    level's upper quarter; a face's cell holds the face's hits from its foot up), a floor
    cell beside them lies within a step of that top and none more than a step below it
    (the face's hits beyond the rim leave the cells beyond it an edge). A face on a cell's
    boundary scatters some of its hits over it at the laser's noise, and the cells along a
    ramp's side or raised end were an obstacle where the ramp's surface covers them."""
    return rim_cells(levels, nlev, edges, is_floor, floor_height, max_step)


def _ramp_run(robot: RobotShape, params: FloorConfig, resolution: float) -> float:
    """How far (cells) a ramp at `max_slope` rises RAMP_SHARE of a step, a tenth left for
    the floor's noise (0.168 m, 3.4 cells at the defaults)."""
    return RAMP_SHARE * robot.step_height / max(math.tan(params.max_slope), 1e-9) / resolution


def _bridge_reach(robot: RobotShape, params: FloorConfig, resolution: float) -> float:
    """How far apart (cells) `bridged_steps` looks for a step's two sides: `_ramp_run`,
    at least two cells, and no farther than FACE_SPAN: a face's in-between levels lie
    across a few cells whatever the robot, and farther out a raised ramp's cells lie
    more than a step above the floor beside it (a robot with a 10 cm step and 10 deg
    looked 0.51 m across: a third of a 7.7 deg ramp's cells bridges)."""
    return max(min(_ramp_run(robot, params, resolution), FACE_SPAN / resolution), 2.0)


def _bridged_steps(heights: np.ndarray, level: np.ndarray, robot: RobotShape,
                   params: FloorConfig, resolution: float,
                   hits: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                   ) -> np.ndarray:
    """`bridged_steps` for `robot` (`level`: the candidates on level floor; `hits`: the
    heights each cell's lowest level spans, its mean hit's height and x, y offset from
    the centre, m; None: thin levels, their hits at the centres at `heights`), looking
    only where the candidates in the square of its reach round a cell span more than a
    step (a bridge needs two that far apart within reach of it): on level floor that is
    few cells, and their search was a twentieth of a segmentation."""
    if hits is None:
        hits = (np.zeros(heights.shape, np.float32), heights,
                np.zeros((*heights.shape, 2), np.float32))
    limits = _bridge_limits(robot, params, resolution)
    varied = morphology.span_filter(heights, 2 * int(limits[0]) + 1) > robot.step_height
    return bridged_steps(heights, level, robot.step_height, limits[0], varied, *hits,
                         resolution, *limits[1:])


def _bridge_limits(robot: RobotShape, params: FloorConfig, resolution: float
                  ) -> tuple[float, float, float, float]:
    """`bridged_steps`' limits for `robot`: its reach and the ramp's run (cells), the
    gradient past which two sides farther apart than the run count (max_slope's over
    RAMP_SHARE) and the most a ramp's cell spans (m: max_slope across its diagonal)."""
    gradient = math.tan(params.max_slope)
    return (_bridge_reach(robot, params, resolution), _ramp_run(robot, params, resolution),
            gradient / RAMP_SHARE, gradient * resolution * math.sqrt(2.0))
