"""Levels the laser swept in view without lighting them are missed (`scanmap.grid.swept`):
a person who left the robot's side is cleared where no ray crosses the space they
left, against the simulator's truth; what is still there, hidden or outshone, stays."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.grid import _kernels as gk
from scanmap.grid import _swept_kernels as sk
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.grid.rays import laser_origins, scan_rays
from scanmap.grid.swept import (
    ABOVE,
    BLOCK_Z,
    DARK_MISSES,
    DARK_REACH,
    MISSES,
    NEAR_Z,
    OUTSHINE_MARGIN,
    REACH,
    SWEEP_TOLERANCE,
    swept_frames,
)
from scanmap.grid.unlit import line_returns, project_to_image, unlit_floor
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim import Scene, builtin_scene
from scanmap_driver.sim.ideal import IdealScan, ideal_scans
from scanmap_driver.triangulation import project_head_points

MODEL = reference_scanner()
SCANS = 6
GONE = 2  # the scan from which the person who leaves is gone


def person(x: float, y: float, until: int | None = None, name: str = "") -> dict:
    """A person standing at (x, y) from scan 0, gone from scan `until` (never: None)."""
    track = [[0, x, y], [SCANS, x, y]] if until is None else \
        [[0, x, y], [until - 1, x, y], [until, 30.0, y]]
    return {"radius": 0.2, "height": 1.7, "color": [90, 70, 160], "track": track,
            "name": name}


def corridor(*people: dict) -> Scene:
    """The people corridor, the robot standing still at its start for SCANS scans."""
    data = builtin_scene("people").to_dict()
    data["scan_poses"] = [[0.0, 0.0, 0.0]] * SCANS
    data["people"] = list(people)
    return Scene.from_dict(data)


def fuse(grid: HeightGrid, ideal: IdealScan, swept: bool, nearest: float | None = None
         ) -> None:
    """Insert one ideal scan as `Mapper` does, with or without the swept frames (their
    lines' nearest returns all at `nearest` m when given)."""
    poses = ideal.frame_poses
    points, origins = scan_rays(ideal.scan, MODEL, poses)
    returns = line_returns(ideal.scan, MODEL)
    frames = swept_frames(ideal.scan, MODEL, poses, returns) if swept else None
    if frames is not None and nearest is not None:
        frames = replace(frames, nearest=np.full_like(frames.nearest, nearest))
    grid.insert(points, origins, float(ideal.scan.time.max()),
                unlit=unlit_floor(ideal.scan, MODEL, poses, returns),
                lasers=laser_origins(ideal.scan, MODEL, poses), swept=frames)


def mapped(scene: Scene, swept: bool, nearest: float | None = None,
           extent: float = 20.0) -> list[HeightGrid]:
    """The grid after each scan of `scene` (copies)."""
    grid, out = HeightGrid(GridConfig(extent=extent)), []
    for ideal in ideal_scans(scene):
        fuse(grid, ideal, swept, nearest)
        out.append(grid.copy())
    return out


def raised_logodds(grid: HeightGrid, x: float, y: float, radius: float) -> np.ndarray:
    """The log-odds of the levels whose mean hit lies above ABOVE in the cells whose
    centres lie within `radius` of (x, y)."""
    layers = grid.layers((x - radius, y - radius, x + radius, y + radius))
    ny, nx = layers.nlev.shape
    cx = layers.origin[0] + (np.arange(nx) + 0.5) * layers.resolution
    cy = layers.origin[1] + (np.arange(ny) + 0.5) * layers.resolution
    inside = np.hypot(*np.meshgrid(cx - x, cy - y)) <= radius
    used = np.arange(layers.levels.shape[2]) < layers.nlev[..., None]
    return layers.levels[..., gk.LOGODDS][used & (layers.levels[..., gk.MZ] > ABOVE)
                                          & inside[..., None]]


def raised_levels(grid: HeightGrid, x: float, y: float, radius: float) -> int:
    """How many levels `raised_logodds` finds."""
    return len(raised_logodds(grid, x, y, radius))


@pytest.fixture(scope="module")
def left() -> dict[bool, list[HeightGrid]]:
    """A person 1.2 m from the robot for two scans, then gone: the grids without the
    swept frames and with them."""
    scene = corridor(person(1.2, 0.35, until=GONE))
    return {swept: mapped(scene, swept) for swept in (False, True)}


def test_a_person_who_left_is_cleared_where_the_laser_swept_them(left):
    """At 1.2 m no later camera ray crosses the heights their body left; the laser's
    plane sweeps them every scan and lights nothing there. It passes within
    SWEEP_TOLERANCE of a given mean hit in about a third of the scans (its frames lie 14
    cm apart there), so the levels go over a few scans: 34 raised levels, then 28, 13,
    12 and 2 with the swept frames, 29, 26, 22 and 15 without."""
    count = [[raised_levels(g, 1.2, 0.35, 0.25) for g in left[swept]] for swept in (0, 1)]
    assert count[1][GONE - 1] > 25  # the person was mapped
    assert count[0][GONE + 2] > 0.5 * count[0][GONE - 1]  # what no ray crosses stays
    assert count[1][GONE + 2] < 0.7 * count[0][GONE + 2]
    assert count[1][-1] <= 0.25 * count[0][-1]


def test_the_walls_are_the_same_with_the_swept_frames(left):
    """Static faces, and faces hit in this scan, are never missed."""
    for x0, y0, x1, y1 in ((-1.1, 0.95, 3.0, 1.1), (-1.1, -1.1, 3.0, -0.95)):
        a = left[False][-1].layers((x0, y0, x1, y1))
        b = left[True][-1].layers((x0, y0, x1, y1))
        np.testing.assert_array_equal(a.nlev, b.nlev)


def test_a_line_that_returned_something_nearer_proves_nothing():
    """One peak is kept per image line: with every line's nearest return 0.3 m from the
    camera, nothing the plane swept is missed, and the grid is the one without."""
    scene = corridor(person(1.2, 0.35, until=GONE))
    outshone, plain = mapped(scene, True, nearest=0.3)[-1], mapped(scene, False)[-1]
    a, b = plain.layers((-1.1, -1.1, 3.0, 1.1)), outshone.layers((-1.1, -1.1, 3.0, 1.1))
    np.testing.assert_array_equal(a.nlev, b.nlev)
    np.testing.assert_array_equal(a.levels, b.levels)


def test_a_line_without_any_return_weighs_less_beyond_dark_reach():
    """The stripe fades with range: with every line dark, a person 2.3 m off who left
    loses less of their levels' log-odds than with every line returning a point far
    beyond them, yet more than without the swept frames; one 1.2 m off loses as much
    either way."""
    for x, faded in ((2.3, True), (1.2, False)):
        scene = corridor(person(x, 0.35, until=GONE))
        plain, dark, lit = (raised_logodds(mapped(scene, swept, nearest)[-1], x, 0.35,
                                           0.25).sum()
                            for swept, nearest in ((False, None), (True, np.inf),
                                                   (True, 50.0)))
        assert plain > 10.0
        assert (lit < dark < plain) if faded else (dark == lit and dark < 0.5 * plain)


def test_far_from_the_origin_the_same_levels_are_missed():
    """The scene moved 2 km off the map's origin: the person who left goes as at the
    origin, scan by scan."""
    scene = corridor(person(1.2, 0.35, until=GONE))
    far = scene.moved(2000.0, -1500.0)
    near_counts = [raised_levels(g, 1.2, 0.35, 0.25) for g in mapped(scene, True)]
    far_counts = [raised_levels(g, 2001.2, -1499.65, 0.25)
                  for g in mapped(far, True, extent=2500.0)]
    assert far_counts == near_counts


def test_a_person_hidden_behind_another_stays():
    """A person 2 m off stands throughout; from scan 1 another stands between them and
    the robot, hiding most of them: their levels stay, hit or not."""
    far = person(2.0, 0.3, name="far")
    near = {**person(1.0, 0.15, name="near"),
            "track": [[0, 30.0, 0.15], [0.5, 30.0, 0.15], [1, 1.0, 0.15], [SCANS, 1.0, 0.15]]}
    grids = mapped(corridor(far, near), True)
    seen = raised_levels(grids[0], 2.0, 0.3, 0.25)
    assert seen > 20
    assert all(raised_levels(g, 2.0, 0.3, 0.25) >= seen for g in grids[1:])


def test_a_scan_without_frames_on_the_laser_plane_changes_nothing():
    """A scan from another sensor (points off the plane), and an empty one: no frames."""
    ideal = next(ideal_scans(corridor()))
    lifted = replace(ideal.scan, points=ideal.scan.points + [0.0, 0.0, 0.2])
    for scan in (lifted, ideal.scan.select(np.zeros(len(ideal.scan), bool))):
        frames = swept_frames(scan, MODEL, ideal.frame_poses)
        assert frames.to_head.shape == (0, 4, 4) and frames.nearest.shape == (0, 640)
        points, origins = scan_rays(ideal.scan, MODEL, ideal.frame_poses)
        grids = [HeightGrid(GridConfig(extent=20.0)) for _ in range(2)]
        for stamp in (1.0, 2.0):
            grids[0].insert(points[::2], origins[::2], stamp, swept=frames)
            grids[1].insert(points[::2], origins[::2], stamp)
        a, b = (g.layers((-1.1, -1.1, 3.0, 1.1)) for g in grids)
        np.testing.assert_array_equal(a.levels, b.levels)


def test_the_frames_reach_covers_the_cells_within_reach_of_the_head():
    ideal = next(ideal_scans(corridor()))
    frames = swept_frames(ideal.scan, MODEL, ideal.frame_poses)
    np.testing.assert_allclose(frames.box, [-REACH, -REACH, REACH, REACH], atol=1e-9)
    for k, f in enumerate(np.unique(ideal.scan.frame_index)):
        heading = ideal.scan.heading[ideal.scan.frame_index == f][0]
        want = np.linalg.inv(ideal.frame_poses[f] @ MODEL.head_pose(heading))
        np.testing.assert_allclose(frames.to_head[k], want, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.floats(-1.5, 1.5), st.floats(-1.0, 1.0), st.floats(0.2, 5.0),
       st.sampled_from([(0.0,) * 5, (0.12, -0.2, 0.002, -0.001, 0.05)]))
def test_the_compiled_projection_is_project_head_points(x, y, depth, distortion):
    """`project_to_image` against `project_head_points`, with and without distortion."""
    model = MODEL.with_changes(camera=replace(MODEL.camera, distortion=distortion))
    cam = model.camera
    rotation = model.camera_mount.rotation
    head = np.array(model.camera_mount.position) + rotation @ np.array([x, y, 1.0]) * depth
    u, v, ahead = project_to_image(*(head - model.camera_mount.position),
                                   rotation.T.ravel().copy(),
                                   np.array([cam.fx, cam.fy, cam.cx, cam.cy]),
                                   cam.dist_coeffs)
    assert ahead
    np.testing.assert_allclose([u, v], project_head_points(model, head[None])[0],
                               rtol=1e-9, atol=1e-6)
    behind = np.array(model.camera_mount.position) - rotation @ np.array([x, y, 1.0])
    assert not project_to_image(*(behind - model.camera_mount.position),
                                rotation.T.ravel().copy(),
                                np.array([cam.fx, cam.fy, cam.cx, cam.cy]),
                                cam.dist_coeffs)[2]



def _in_cell_span(a: np.ndarray, b: np.ndarray, ix: int, iy: int) -> tuple[float, float] | None:
    """The parameters (t0, t1), t0 < t1, over which the x-y segment a -> b (cell units)
    lies in cell (ix, iy) (slab clipping), or None."""
    t0, t1 = 0.0, 1.0
    for axis, low in ((0, ix), (1, iy)):
        d = b[axis] - a[axis]
        if d == 0.0:
            if not low <= a[axis] < low + 1:
                return None
            continue
        ta, tb = sorted(((low - a[axis]) / d, (low + 1 - a[axis]) / d))
        t0, t1 = max(t0, ta), min(t1, tb)
    return (t0, t1) if t0 < t1 else None


def _levels(grid: HeightGrid, ix: int, iy: int) -> list[int]:
    """The level records of cell (ix, iy) in use."""
    off = gk._cell_offset(grid._tile_index, ix, iy, grid._shift)
    if off < 0:
        return []
    nlev = grid._flat_pools()[3]
    return [off * grid.config.levels + k for k in range(int(nlev[off]))]


def _hit_now(grid: HeightGrid, li: int, scan: int) -> bool:
    _, lev_n, lev_flag, *_ = grid._flat_pools()
    return lev_n[li, gk.STAMP] == scan and bool(lev_flag[li] & gk.HIT_FLAG)


def _blocked_reference(grid: HeightGrid, p: np.ndarray, q: np.ndarray, scan: int) -> bool:
    """`_swept_kernels._blocked` by clipping the segment to each cell of its bounding box."""
    c, lev_f, lev_n = grid.config, *grid._flat_pools()[:2]
    a, b = (p[:2] - c.corner) / c.resolution, (q[:2] - c.corner) / c.resolution
    home = np.floor(a).astype(int)
    for ix in range(int(np.floor(min(a[0], b[0]))), int(np.floor(max(a[0], b[0]))) + 1):
        for iy in range(int(np.floor(min(a[1], b[1]))), int(np.floor(max(a[1], b[1]))) + 1):
            span = _in_cell_span(a, b, ix, iy)
            if span is None or (abs(ix - home[0]) <= 1 and abs(iy - home[1]) <= 1):
                continue
            z = [p[2] + (q[2] - p[2]) * t for t in span]
            for li in _levels(grid, ix, iy):
                if lev_f[li, gk.HI] >= min(z) - BLOCK_Z and lev_f[li, gk.LO] <= max(z) + BLOCK_Z \
                        and (_hit_now(grid, li, scan) or lev_n[li, gk.SCANS] >= c.static_scans):
                    return True
    return False


def _sweeps_reference(grid: HeightGrid, frames, p: np.ndarray, scan: int) -> int:
    """`_swept_kernels._unlit_sweeps` in numpy: the misses owed by the frames that swept
    p unlit."""
    misses = 0
    origin, normal = np.array(MODEL.laser.origin), np.array(MODEL.laser.normal)
    camera = np.array(MODEL.camera_mount.position)
    for f in range(len(frames.to_head)):
        head = (frames.to_head[f] @ np.append(p, 1.0))[:3]
        if abs((head - origin) @ normal) > SWEEP_TOLERANCE \
                or not MODEL.min_range <= np.hypot(head[0], head[1]) <= REACH:
            continue
        u, v = project_head_points(MODEL, head[None])[0]
        if not (0 <= u < MODEL.camera.width and 0 <= v < MODEL.camera.height):
            continue
        line = int(np.rint(u))
        beside = frames.nearest[f, max(line - 1, 0):line + 2]
        if (beside <= np.linalg.norm(head - camera) + OUTSHINE_MARGIN).any():
            continue
        if _blocked_reference(grid, p, frames.cameras[f], scan) \
                or _blocked_reference(grid, p, frames.emitters[f], scan):
            continue
        faded = np.isinf(beside).all() and np.hypot(head[0], head[1]) > DARK_REACH
        misses += DARK_MISSES if faded else MISSES
    return misses


def test_the_kernel_misses_what_the_plain_reference_does(left):
    """Scan GONE + 1 inserted without its swept frames into the grid before it, then
    `miss_swept_levels`: each level it left is the reference's, log-odds and all."""
    ideal = list(ideal_scans(corridor(person(1.2, 0.35, until=GONE))))[GONE + 1]
    grid = left[True][GONE].copy()
    fuse(grid, ideal, swept=False)
    frames = swept_frames(ideal.scan, MODEL, ideal.frame_poses)
    c, scan = grid.config, len(grid._scan_times) - 1
    lev_f, lev_n, lev_flag, *_ = grid._flat_pools()
    expected, swept_any = {}, 0
    x0, y0, x1, y1 = frames.box
    for ix in range(int((x0 - c.corner) // c.resolution), int((x1 - c.corner) // c.resolution) + 1):
        for iy in range(int((y0 - c.corner) // c.resolution),
                        int((y1 - c.corner) // c.resolution) + 1):
            for li in _levels(grid, ix, iy):
                z = lev_f[li, gk.MZ]
                beside = any(_hit_now(grid, lj, scan) and lev_f[lj, gk.LO] - NEAR_Z <= z
                             <= lev_f[lj, gk.HI] + NEAR_Z for dx in (-1, 0, 1)
                             for dy in (-1, 0, 1) for lj in _levels(grid, ix + dx, iy + dy))
                by_static = any(lev_n[lj, gk.SCANS] >= c.static_scans
                                and lev_f[lj, gk.LO] - c.mask_dz <= lev_f[li, gk.HI]
                                and lev_f[li, gk.LO] <= lev_f[lj, gk.HI] + c.mask_dz
                                for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy
                                for lj in _levels(grid, ix + dx, iy + dy))
                if lev_n[li, gk.SCANS] >= c.static_scans or z < ABOVE or beside or by_static:
                    continue
                p = np.array([c.corner + (ix + 0.5) * c.resolution + lev_f[li, gk.MX],
                              c.corner + (iy + 0.5) * c.resolution + lev_f[li, gk.MY], z])
                owed = _sweeps_reference(grid, frames, p, scan)
                swept_any += owed > 0
                used = lev_flag[li] & 0x7F if lev_n[li, gk.STAMP] == scan else 0
                misses = min(owed, max(c.max_misses - int(used), 0))
                expected[(ix, iy, round(float(z), 6))] = lev_f[li, gk.LOGODDS] \
                    - misses * np.float32(c.l_miss)
    assert swept_any > 5
    ip = np.array([grid._shift, c.levels, c.max_misses, scan, grid._ray_key, c.bundle_run,
                   c.static_scans, 0], np.int64)
    removed = sk.miss_swept_levels(frames.to_head, frames.cameras, frames.emitters,
                                   frames.nearest, frames.optics, frames.box, grid._tile_index,
                                   *grid._flat_pools()[:4], grid._fp, ip)
    assert removed == sum(v <= 0.0 for v in expected.values())
    for (ix, iy, z), logodds in expected.items():
        kept = [li for li in _levels(grid, ix, iy) if round(float(lev_f[li, gk.MZ]), 6) == z]
        if logodds <= 0.0:
            assert not kept
        else:
            assert lev_f[kept[0], gk.LOGODDS] == pytest.approx(logodds, abs=1e-5)
