"""Geometric test scenes for the grid: boxes on a floor, scanned by an ideal scanner.

Independent truth for the mapping tests until the simulator offers its raster: rays
leave the reference scanner's camera centre (through a rolled stripe of pixels, as the
real stripe runs across the image) and stop at the first surface, found by exact
ray-box and ray-plane intersection. The truth rasters come from the box geometry
alone, never from the grid.

Box faces sit a quarter cell inside cells (x = k * 0.05 + 0.0125 or + 0.0375) so that
every cell is unambiguously in or out of a box at the 5 cm test resolution.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel, reference_scanner
from scanmap_driver.transforms import se2_to_pose, transform_points

FLOOR = -1  # surface label of the floor plane z = 0


@dataclass(frozen=True)
class Box:
    """An axis-aligned box from lo to hi (x, y, z), metres."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


@dataclass(frozen=True)
class Scene:
    """Boxes standing on (or hanging above) the floor plane z = 0."""

    boxes: tuple[Box, ...] = field(default_factory=tuple)

    def moved(self, index: int, offset: tuple[float, float, float]) -> Scene:
        """The scene with box `index` shifted by offset (a moving object)."""
        b = self.boxes[index]
        moved = Box(tuple(np.add(b.lo, offset)), tuple(np.add(b.hi, offset)))
        return Scene(self.boxes[:index] + (moved,) + self.boxes[index + 1:])

    def without(self, index: int) -> Scene:
        """The scene with box `index` removed."""
        return Scene(self.boxes[:index] + self.boxes[index + 1:])


def cast(scene: Scene, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """First hit distance t (inf when none) and surface label (FLOOR or box index) per ray."""
    origins = np.broadcast_to(origins, directions.shape)
    t_best = np.full(len(directions), np.inf)
    label = np.full(len(directions), -2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(directions[:, 2] < 0, -origins[:, 2] / directions[:, 2], np.inf)
        better = t_floor > 0
        t_best[better] = t_floor[better]
        label[better] = FLOOR
        inv = 1.0 / directions
        for k, box in enumerate(scene.boxes):
            t1 = (np.array(box.lo) - origins) * inv
            t2 = (np.array(box.hi) - origins) * inv
            t_near = np.nanmax(np.minimum(t1, t2), axis=1)
            t_far = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (t_near <= t_far) & (t_near > 1e-9) & (t_near < t_best)
            t_best[hit] = t_near[hit]
            label[hit] = k
    return t_best, label


def scanner_rays(model: ScannerModel, heading: float, rays: int,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit ray directions (rays, 3) in base_link for one frame.

    The pixels follow a stripe rolled across the image (v changes with u), jittered.
    """
    cam = model.camera
    u = np.linspace(0.0, cam.width - 1.0, rays) + rng.uniform(-0.5, 0.5, rays)
    v = cam.cy + 0.45 * (u - cam.cx) + rng.uniform(-2.0, 2.0, rays)
    in_camera = np.column_stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(rays)])
    head_pose = model.head_pose(heading)
    rotation = head_pose[:3, :3] @ model.camera_mount.rotation
    directions = in_camera @ rotation.T
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    centre = transform_points(head_pose, np.array([model.camera_mount.position]))[0]
    return centre, directions


def scan_scene(scene: Scene, pose: tuple[float, float, float], *, frames: int = 50,
               rays: int = 400, seed: int = 0, model: ScannerModel | None = None,
               stamp: float = 0.0) -> tuple[Scan, np.ndarray]:
    """One ideal 360 deg scan from robot pose (x, y, yaw): the Scan and each point's label."""
    model = model or reference_scanner()
    rng = np.random.default_rng(seed)
    to_map = se2_to_pose(*pose)
    points, headings, frame_idx, labels = [], [], [], []
    for f in range(frames):
        heading = 2 * np.pi * f / frames + rng.uniform(0, 2 * np.pi / frames)
        centre, directions = scanner_rays(model, heading, rays, rng)
        origin_map = transform_points(to_map, centre[None])[0]
        dirs_map = directions @ to_map[:3, :3].T
        t, label = cast(scene, origin_map, dirs_map)
        base = centre + t[:, None] * directions
        keep = np.isfinite(t) & (np.hypot(base[:, 0], base[:, 1]) >= model.min_range) \
            & (np.hypot(base[:, 0], base[:, 1]) <= model.max_range)
        points.append(base[keep])
        headings.append(np.full(keep.sum(), heading))
        frame_idx.append(np.full(keep.sum(), f))
        labels.append(label[keep])
    pts = np.vstack(points)
    n = len(pts)
    scan = Scan(points=pts, colors=np.zeros((n, 3), np.uint8), time=np.full(n, stamp),
                heading=np.concatenate(headings), frame_index=np.concatenate(frame_idx),
                range_sigma=np.zeros(n), stamp=stamp)
    return scan, np.concatenate(labels)


def in_box_footprint(box: Box, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Whether the points (x, y) lie inside the box's footprint."""
    return (x >= box.lo[0]) & (x <= box.hi[0]) & (y >= box.lo[1]) & (y <= box.hi[1])


def truth_obstacles(scene: Scene, xs: np.ndarray, ys: np.ndarray, step: float,
                    height: float) -> np.ndarray:
    """(ny, nx) cells whose centre lies in a box with space in the band (step, height)."""
    x, y = np.meshgrid(xs, ys)
    out = np.zeros(x.shape, bool)
    for box in scene.boxes:
        if box.hi[2] > step and box.lo[2] < height:
            out |= in_box_footprint(box, x, y)
    return out


def truth_floor(scene: Scene, xs: np.ndarray, ys: np.ndarray, step: float,
                height: float) -> np.ndarray:
    """(ny, nx) open floor cells: nothing in the robot's band (step, height) above them
    (boxes lower than the step are driven over, so their tops are floor; the floor under
    a table top is not open)."""
    return ~truth_obstacles(scene, xs, ys, step, height)


def truth_distance(scene: Scene, x: np.ndarray, y: np.ndarray, step: float,
                   height: float) -> np.ndarray:
    """Exact distance from (x, y) to the nearest footprint of a box in the band."""
    best = np.full(np.shape(x), np.inf)
    for box in scene.boxes:
        if box.hi[2] > step and box.lo[2] < height:
            dx = np.maximum(np.maximum(box.lo[0] - x, x - box.hi[0]), 0.0)
            dy = np.maximum(np.maximum(box.lo[1] - y, y - box.hi[1]), 0.0)
            best = np.minimum(best, np.hypot(dx, dy))
    return best


def cell_box(x0: int, y0: int, x1: int, y1: int, z0: float, z1: float,
             res: float = 0.05) -> Box:
    """A box covering cells x0..x1-1, y0..y1-1 (in 5 cm cells), faces a quarter cell in."""
    return Box((x0 * res + res / 4, y0 * res + res / 4, z0),
               (x1 * res - res / 4, y1 * res - res / 4, z1))


def room(extra: tuple[Box, ...] = ()) -> Scene:
    """A 6 m x 6 m room (cells -60..60) with 10 cm walls 2 m high, plus `extra` boxes."""
    walls = (cell_box(-62, -62, 62, -60, 0, 2.0), cell_box(-62, 60, 62, 62, 0, 2.0),
             cell_box(-62, -60, -60, 60, 0, 2.0), cell_box(60, -60, 62, 60, 0, 2.0))
    return Scene(walls + tuple(extra))


def furnished_room() -> Scene:
    """The room with a table (top 0.72-0.76 m on four legs), a low box, a low sill and a
    high shelf board (0.85-0.88 m, on two posts at its ends outside the robot's view)."""
    table = (cell_box(10, -30, 34, -18, 0.72, 0.76),
             cell_box(10, -30, 11, -29, 0, 0.72), cell_box(33, -30, 34, -29, 0, 0.72),
             cell_box(10, -19, 11, -18, 0, 0.72), cell_box(33, -19, 34, -18, 0, 0.72))
    low_box = (cell_box(-30, 10, -20, 20, 0, 0.30),)
    sill = (cell_box(-10, -40, 10, -37, 0, 0.03),)
    shelf = (cell_box(-40, -30, -20, -24, 0.85, 0.88),)
    return room(table + low_box + sill + shelf)



@dataclass
class MappedScene:
    """A grid filled with ideal scans of a scene, with the hits and their surface labels."""

    grid: object
    points: np.ndarray
    labels: np.ndarray


def map_scene(scene: Scene, poses: list[tuple[float, float, float]], grid, *, seed: int = 0,
              first_stamp: float = 0.0, frames: int = 50, rays: int = 400) -> MappedScene:
    """Insert one ideal scan per pose into `grid` (stamps first_stamp, +1, ...)."""
    from scanmap.grid.rays import scan_rays

    model = reference_scanner()
    points, labels = [], []
    for i, pose in enumerate(poses):
        stamp = first_stamp + i
        scan, label = scan_scene(scene, pose, seed=seed + i, stamp=stamp, frames=frames,
                                 rays=rays, model=model)
        pts, origins = scan_rays(scan, model, se2_to_pose(*pose))
        grid.insert(pts, origins, stamp)
        points.append(pts)
        labels.append(label)
    return MappedScene(grid, np.vstack(points), np.concatenate(labels))


def hit_cells(layers, mapped: MappedScene, labels: list[int]) -> np.ndarray:
    """(ny, nx) cells of `layers` holding a hit on one of the labelled surfaces."""
    sel = np.isin(mapped.labels, labels)
    ix = np.floor((mapped.points[sel, 0] - layers.origin[0]) / layers.resolution).astype(int)
    iy = np.floor((mapped.points[sel, 1] - layers.origin[1]) / layers.resolution).astype(int)
    inside = (ix >= 0) & (ix < layers.shape[1]) & (iy >= 0) & (iy < layers.shape[0])
    out = np.zeros(layers.shape, bool)
    out[iy[inside], ix[inside]] = True
    return out


ROOM_POSES = [(0.0, 0.0, 0.0), (1.5, 1.5, 0.3), (-1.5, 1.5, 0.6), (-1.5, -1.5, 0.9),
              (1.5, -1.5, 1.2), (0.0, 2.2, 1.5), (2.2, 0.0, 1.8), (-2.2, 0.0, 2.1),
              (0.0, -2.2, 2.4), (1.0, -0.3, 2.7)]
