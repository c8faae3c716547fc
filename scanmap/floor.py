"""Floor segmentation and the obstacle layer: where the robot can drive, and what is in its way.

Floor: a cell's lowest level is a floor candidate when it is thin (a surface, not an
object). RANSAC over the candidates' heights finds the dominant near-horizontal plane;
its inliers seed a region growing over candidates whose neighbours differ by at most
the robot's step height, so a ramp or a low sill joins the floor, while a table top or
the top of a box (cut off by its vertical faces) does not. Planes are then fitted to
the floor region by sequential RANSAC and reported (the floor, a ramp, a raised part).
Cells without observed floor (under objects, under occluded table tops) take the height
of the nearest floor cell within `fill_radius`, and beyond it that of the largest plane.

Obstacles (DESIGN.md): occupied space between floor + step height and floor + robot
height. A cell is FREE only if its floor height is known, nothing occupies the band,
rays have seen at least `min_coverage` (half) of the band's height bins free there, and
no height it has not seen is suspect: occupied (within two height bins) in a
neighbouring cell, or possibly under an overhanging board (a table top seen only at its
rim); otherwise it is UNKNOWN.

Why the map of one scan is mostly UNKNOWN: a cell is seen free at the heights that the
rays crossing it have there, and every ray of this scanner falls from the camera (1 m
up) to where it ends. From one place, a cell 1-2 m away is crossed only by rays ending
not far beyond it, near the floor; the band's upper heights there are crossed only by
rays ending much farther away, beyond the 4 m range or where nothing returns. In the
simulator's office one scan sees a median 35 % of the band in floor cells 1-1.5 m away,
21 % at 2-3 m, so almost none is FREE although its floor was hit. Scans from other
places cross the same cells at other heights: after the 24 scans round the office table
93 % of the floor is FREE. The rule stays: a cell whose band was mostly never looked at
may hold anything there, and a map of several scans (examples/planner.py) is the cure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from scanmap_driver.errors import MapError

from . import grid_kernels as gk
from .distance_field import distance_transform
from .grid import CellLayers

UNKNOWN, FREE, OBSTACLE = 0, 1, 2


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
class FloorParams:
    """Tuning of the segmentation.

    thickness: most vertical extent (m) of a level that can be floor; clearance: free
    height above it (m) that a floor cell needs.
    plane_tolerance: RANSAC inlier distance (m). max_slope: steepest floor plane (rad).
    min_plane_cells: support of a reported plane. fill_radius: how far (m) the height of
    a floor cell is carried into cells without observed floor (the largest floor plane
    gives it beyond). detect: False for data that never see the floor (a 2-D laser:
    every point at one height), which then rely on the `fallback_floor` of `segment`.
    min_coverage: fraction of the robot band's height bins that rays must have seen free
    for a cell to be FREE (as Nav2's voxel layer tolerates unknown voxels in a column).
    This scanner rarely sees every bin of a column (rays at 0.7-1 m over a cell 2 m away
    end beyond 4 m, returning nothing), so 1.0 leaves most of a room unknown; below 1, a
    thin object hanging in unseen heights is caught by the suspect rules of
    `classify_band` instead.
    overhang_reach: how far (m) the heights of an overhanging board (a table top seen
    only at its rim: this scanner's laser, 0.5 m up, never lights a top above it) are
    assumed to extend over cells that never saw those heights; overhang_thickness: the
    thickest level taken for such a board (a table top, a seat, a shelf).
    """

    thickness: float = 0.06
    clearance: float = 0.2
    plane_tolerance: float = 0.03
    max_slope: float = math.radians(15.0)
    min_plane_cells: int = 100
    max_planes: int = 4
    fill_radius: float = 1.0
    min_coverage: float = 0.5
    overhang_reach: float = 0.6
    overhang_thickness: float = 0.1
    ransac_iterations: int = 200
    seed: int = 0
    detect: bool = True


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

    floor_height: (ny, nx) float32, NaN where unknown. is_floor: open floor: the floor was
    seen there, nothing is in the robot's band, and nothing may hang above unseen (not
    the floor under a table). Traversable = is_floor and FREE (the band was seen).
    state: UNKNOWN / FREE / OBSTACLE per cell. points: (ny, nx, 2) float32, the obstacle
    point of each obstacle cell (mean of its hits in the band), the centre elsewhere.
    band_logodds: (ny, nx) float32, highest log-odds in the band (NaN where none).
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

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx)."""
        return tuple(self.state.shape)


@njit(cache=True, nogil=True)
def floor_candidates(levels: np.ndarray, nlev: np.ndarray, thickness: float,
                     clearance: float) -> np.ndarray:
    """Height of each cell's lowest level when it can be floor, else NaN: thin, and with
    `clearance` of space above it (not the foot of a wall or box sharing the cell)."""
    ny, nx = nlev.shape
    out = np.full((ny, nx), np.nan, np.float32)
    for y in range(ny):
        for x in range(nx):
            if nlev[y, x] > 0:
                lo, hi = levels[y, x, 0, gk.LO], levels[y, x, 0, gk.HI]
                if hi - lo <= thickness and (nlev[y, x] == 1
                                             or levels[y, x, 1, gk.LO] - hi >= clearance):
                    out[y, x] = 0.5 * (lo + hi)
    return out


@njit(cache=True, nogil=True)
def grow_region(heights: np.ndarray, seeds: np.ndarray, max_step: float) -> np.ndarray:
    """Cells reachable from the seeds through 8-neighbours whose heights differ <= max_step."""
    ny, nx = heights.shape
    inside = seeds.copy()
    queue = np.empty(ny * nx, np.int64)
    head, tail = 0, 0
    for y in range(ny):
        for x in range(nx):
            if seeds[y, x]:
                queue[tail] = y * nx + x
                tail += 1
    while head < tail:
        i = queue[head]
        head += 1
        y, x = i // nx, i % nx
        h = heights[y, x]
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                yy, xx = y + dy, x + dx
                if 0 <= yy < ny and 0 <= xx < nx and not inside[yy, xx]:
                    hh = heights[yy, xx]
                    if abs(hh - h) <= max_step:  # False for NaN (no candidate)
                        inside[yy, xx] = True
                        queue[tail] = yy * nx + xx
                        tail += 1
    return inside


@njit(cache=True, nogil=True)
def _popcount(v: np.uint64) -> int:
    count = 0
    while v:
        v &= v - np.uint64(1)
        count += 1
    return count


@njit(cache=True, nogil=True, inline="always")
def _widen(mask: np.uint64) -> np.uint64:
    """A surface seen as hits has a thickness nobody measured: widen it by two bins."""
    one = np.uint64(1)
    mask |= (mask << one) | (mask >> one)
    return mask | (mask << one) | (mask >> one)


@njit(cache=True, nogil=True, inline="always")
def _lowest_bit(bits: np.uint64) -> int:
    """Index of the lowest set bit of a non-zero mask."""
    low = 0
    while not (bits >> np.uint64(low)) & np.uint64(1):
        low += 1
    return low


@njit(cache=True, nogil=True, inline="always")
def _above_lowest_seen(seen: np.uint64) -> np.uint64:
    """Heights above the lowest height seen: where a board that has free space seen under
    it can continue unseen (under a table top), unlike heights below everything a cell
    saw (the shadow behind a box, seen only over it)."""
    if seen == 0:
        return np.uint64(0)
    low = _lowest_bit(seen)
    return ~((np.uint64(2) << np.uint64(low)) - np.uint64(1)) if low < 63 else np.uint64(0)


@njit(cache=True, nogil=True, inline="always")
def _below(bits: np.uint64, margin: int) -> np.uint64:
    """The heights more than `margin` bins below the lowest height in `bits` (non-zero)."""
    low = _lowest_bit(bits)
    return (np.uint64(1) << np.uint64(low - margin)) - np.uint64(1) if low > margin \
        else np.uint64(0)


@njit(cache=True, nogil=True)
def _plates(boards: np.ndarray, occupied: np.ndarray) -> np.ndarray:
    """The boards (their heights, widened) that overhang: they continue sideways at the
    same heights in at least two of the 8 neighbouring cells (a table top's rim does; a
    stray piece of a wall face does not), and no neighbour holds anything more than two
    bins below them (the side of a box under its top, the rest of a wall under a piece of
    it that rays grazing the face left apart)."""
    ny, nx = boards.shape
    out = np.zeros((ny, nx), np.uint64)
    for y in range(ny):
        for x in range(nx):
            if not boards[y, x]:
                continue
            below = _below(boards[y, x], 2)
            count = 0
            supported = False
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    if (yy != y or xx != x) and boards[yy, xx] & boards[y, x]:
                        count += 1
                    supported |= occupied[yy, xx] & below != 0
            if count >= 2 and not supported:
                out[y, x] = _widen(boards[y, x])
    return out


@njit(cache=True, nogil=True)
def _spread_overhangs(hanging: np.ndarray, gaps: np.ndarray, state: np.ndarray,
                      reach: int) -> np.ndarray:
    """Heights of overhanging obstacles carried up to `reach` cells into the cells around
    them (8-neighbours) with gaps at those heights in what they saw: the top of a table
    seen only at its rim covers the cells inside the rim."""
    ny, nx = hanging.shape
    spread = hanging.copy()
    size = ny * nx * 4
    queue = np.empty(size, np.int64)
    depth = np.empty(size, np.int64)
    head, tail = 0, 0
    for y in range(ny):
        for x in range(nx):
            if hanging[y, x] and tail < size:
                queue[tail], depth[tail] = y * nx + x, 0
                tail += 1
    while head < tail:
        i, d = queue[head % size], depth[head % size]
        head += 1
        if d >= reach:
            continue
        y, x = i // nx, i % nx
        for yy in range(max(y - 1, 0), min(y + 2, ny)):
            for xx in range(max(x - 1, 0), min(x + 2, nx)):
                if state[yy, xx] == OBSTACLE:
                    continue
                add = spread[y, x] & gaps[yy, xx] & ~spread[yy, xx]
                if add and tail - head < size:
                    spread[yy, xx] |= add
                    queue[tail % size], depth[tail % size] = yy * nx + xx, d + 1
                    tail += 1
    return spread


@njit(cache=True, nogil=True)
def classify_band(levels: np.ndarray, nlev: np.ndarray, seen: np.ndarray,
                  floor_height: np.ndarray, step: float, height: float, z_min: float,
                  mask_dz: float, coverage: float,
                  reach: int, thin: float, origin_x: float, origin_y: float, res: float,
                  state: np.ndarray, points: np.ndarray, band_logodds: np.ndarray,
                  covered: np.ndarray) -> None:
    """UNKNOWN / FREE / OBSTACLE per cell, obstacle points and the band's highest log-odds;
    `covered`: cells that may lie under an overhanging obstacle (see below).

    Heights no ray saw anywhere in the window (above the camera) are left out: nothing
    can be known there. A cell without anything in its band is FREE when rays saw at
    least `coverage` of the band's height bins free, and none of the heights it has not
    seen is suspect: within two bins of an obstacle in a neighbouring cell, or of an
    overhanging board within `reach` cells through cells that have not seen those heights
    either but saw lower ones. A board is the lowest level in its cell, at most `thin`
    thick, with free space seen under it at least a bin below its lowest hit (a ray that
    ends on a box's top marks only the heights above the hit), and `_plates` decides
    whether it overhangs. A cell under a table top that rays reached only under the top
    is thus not FREE, however much of the band they saw there.
    """
    ny, nx = nlev.shape
    occupied = np.zeros((ny, nx), np.uint64)  # band heights held by obstacles, per cell
    hanging = np.zeros((ny, nx), np.uint64)  # the same, of obstacles clear of the floor
    unseen = np.zeros((ny, nx), np.uint64)
    observable = np.uint64(0)  # heights some ray saw somewhere (not above the camera)
    for y in range(ny):
        for x in range(nx):
            observable |= seen[y, x]
    for y in range(ny):
        for x in range(nx):
            cx, cy = origin_x + (x + 0.5) * res, origin_y + (y + 0.5) * res
            points[y, x, 0], points[y, x, 1] = cx, cy
            band_logodds[y, x] = np.nan
            f = floor_height[y, x]
            state[y, x] = UNKNOWN
            if np.isnan(f):
                continue
            low, high = f + step, f + height
            band = gk.height_mask(low, high - 1e-6, z_min, mask_dz) & observable
            unseen[y, x] = band & ~seen[y, x]
            weight, sx, sy = 0.0, 0.0, 0.0
            for k in range(nlev[y, x]):
                lo, hi = levels[y, x, k, gk.LO], levels[y, x, k, gk.HI]
                if hi > low and lo < high:
                    bits = gk.height_mask(max(lo, low), min(hi, high), z_min, mask_dz)
                    if lo > low and hi - lo <= thin and occupied[y, x] == 0 \
                            and seen[y, x] & gk.height_mask(low, lo - mask_dz, z_min, mask_dz):
                        hanging[y, x] |= bits  # a board with free space under it
                    occupied[y, x] |= bits
                    w = 1.0 + levels[y, x, k, gk.LOGODDS]
                    weight += w
                    sx += w * levels[y, x, k, gk.MX]
                    sy += w * levels[y, x, k, gk.MY]
                    lo_k = levels[y, x, k, gk.LOGODDS]
                    if np.isnan(band_logodds[y, x]) or lo_k > band_logodds[y, x]:
                        band_logodds[y, x] = lo_k
            if weight > 0.0:
                state[y, x] = OBSTACLE
                points[y, x, 0], points[y, x, 1] = cx + sx / weight, cy + sy / weight
    gaps = np.empty((ny, nx), np.uint64)
    for y in range(ny):
        for x in range(nx):
            gaps[y, x] = unseen[y, x] & _above_lowest_seen(seen[y, x])
    overhang = _spread_overhangs(_plates(hanging, occupied), gaps, state, reach)
    for y in range(ny):
        for x in range(nx):
            f = floor_height[y, x]
            if state[y, x] == OBSTACLE or np.isnan(f):
                continue
            band = gk.height_mask(f + step, f + height - 1e-6, z_min, mask_dz) & observable
            suspect = overhang[y, x]
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    suspect |= _widen(occupied[yy, xx])
            covered[y, x] = unseen[y, x] & overhang[y, x] != 0
            if _popcount(band & seen[y, x]) >= max(coverage * _popcount(band), 1.0) \
                    and unseen[y, x] & suspect == 0:
                state[y, x] = FREE


def _fit_plane(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane through points (n, 3): unit normal with z >= 0, and offset."""
    centre = p.mean(axis=0)
    normal = np.linalg.svd(p - centre, full_matrices=False)[2][-1]
    normal = -normal if normal[2] < 0 else normal
    return normal, float(normal @ centre)


def ransac_plane(points: np.ndarray, params: FloorParams,
                 rng: np.random.Generator) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The near-horizontal plane with most inliers (refined by least squares), or None."""
    if len(points) < 3:
        return None
    iterations = params.ransac_iterations
    sample = points[rng.integers(0, len(points), (iterations, 3))]
    normals = np.cross(sample[:, 1] - sample[:, 0], sample[:, 2] - sample[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    normals = normals[ok] / norms[ok, None]
    normals *= np.where(normals[:, 2] < 0, -1.0, 1.0)[:, None]
    level = normals[:, 2] >= math.cos(params.max_slope)
    if not level.any():
        return None
    normals, anchors = normals[level], sample[ok][level, 0]
    subset = points[rng.integers(0, len(points), min(len(points), 4000))]
    distances = np.abs((subset[None] - anchors[:, None]) @ normals[..., None])[..., 0]
    best = int(np.argmax((distances <= params.plane_tolerance).sum(axis=1)))
    normal, offset = normals[best], float(normals[best] @ anchors[best])
    for _ in range(2):  # refine on all inliers
        inliers = np.abs(points @ normal - offset) <= params.plane_tolerance
        if inliers.sum() < 3:
            return None
        normal, offset = _fit_plane(points[inliers])
    if normal[2] < math.cos(params.max_slope):
        return None
    return normal, offset, np.abs(points @ normal - offset) <= params.plane_tolerance


def _planes_of(points: np.ndarray, params: FloorParams,
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
            params: FloorParams | None = None,
            fallback_floor: float | None = None) -> Segmentation:
    """Floor, floor height and obstacle state of every cell of `layers`.

    fallback_floor: height assumed where no floor is known within fill_radius (e.g. 0.0
    for a 2-D laser that never sees the floor); None leaves those cells UNKNOWN.
    """
    robot = robot or RobotShape()
    params = params or FloorParams()
    rng = np.random.default_rng(params.seed)
    ny, nx = layers.shape
    res = layers.resolution
    xs, ys = layers.cell_centers()
    cand = floor_candidates(layers.levels, layers.nlev, params.thickness, params.clearance)
    has = ~np.isnan(cand)
    gy, gx = np.nonzero(has)
    cand_points = np.column_stack([xs[gx], ys[gy], cand[gy, gx]])
    is_floor = np.zeros((ny, nx), bool)
    planes: tuple[FloorPlane, ...] = ()
    dominant = ransac_plane(cand_points, params, rng) if params.detect else None
    if dominant is not None and dominant[2].sum() >= params.min_plane_cells:
        seeds = np.zeros((ny, nx), bool)
        seeds[gy[dominant[2]], gx[dominant[2]]] = True
        is_floor = grow_region(cand, seeds, robot.step_height)
        fy, fx = np.nonzero(is_floor)
        planes = _planes_of(np.column_stack([xs[fx], ys[fy], cand[fy, fx]]), params, rng)
    floor_height = np.where(is_floor, cand, np.nan).astype(np.float32)
    if is_floor.any():
        distance, nearest = distance_transform(is_floor)
        fill = ~is_floor & (distance * res <= params.fill_radius)
        floor_height[fill] = floor_height.reshape(-1)[nearest[fill]]
    if planes:  # farther out, the largest floor plane
        far = np.isnan(floor_height)
        floor_height[far] = planes[0].height_at(*np.meshgrid(xs, ys))[far]
    if fallback_floor is not None:
        floor_height[np.isnan(floor_height)] = fallback_floor
    state = np.empty((ny, nx), np.uint8)
    points = np.empty((ny, nx, 2), np.float32)
    band_logodds = np.empty((ny, nx), np.float32)
    covered = np.zeros((ny, nx), np.bool_)
    classify_band(layers.levels, layers.nlev, layers.seen, floor_height,
                  robot.step_height, robot.height, layers.z_min, layers.mask_dz,
                  params.min_coverage,
                  round(params.overhang_reach / res), params.overhang_thickness,
                  layers.origin[0], layers.origin[1], res, state, points, band_logodds, covered)
    return Segmentation(origin=layers.origin, resolution=res, robot=robot,
                        floor_height=floor_height,
                        is_floor=is_floor & (state != OBSTACLE) & ~covered, planes=planes,
                        state=state, points=points, band_logodds=band_logodds,
                        updated=layers.updated)
