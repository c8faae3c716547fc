"""Floor the laser lit and the camera saw nothing on (`scanmap.grid.unlit`), and the grid
cells that keep it."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.grid.rays import scan_rays
from scanmap.grid.unlit import (
    LIT_REACH,
    LIT_SHARE,
    MIN_RUN,
    MIN_SPAN,
    _line_returns,
    fan_end_lines,
    floor_crossings,
    frame_slots,
    line_returns,
    unlit_floor,
    unlit_lines,
)
from scanmap.io.map_files import load_map, save_map
from scanmap.mapping.rebuild import rebuild_grid, scan_contribution
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import CameraMount, HeadMount, LaserPlane, reference_scanner
from scanmap_driver.sim import Scene, builtin_scene
from scanmap_driver.sim.ideal import ideal_scans
from scanmap_driver.transforms import se2_to_pose, transform_points
from scanmap_driver.triangulation import project_head_points
from tests.scanmap.test_hazards import small_patch_scene

MODEL = reference_scanner()


def plain_unlit_lines(returned, floor, crossing, reach, ok) -> np.ndarray:
    """The rule of the module docstring, read literally line by line."""
    out = np.zeros(returned.shape, bool)
    for f in range(returned.shape[0]):
        lines = [u for u in range(returned.shape[1]) if returned[f, u]]
        for a, b in itertools.pairwise(lines):
            ends_on_floor = floor[f, a] and floor[f, b] and ok[f, a] and ok[f, b]
            span = np.hypot(*(crossing[f, b, :2] - crossing[f, a, :2]))
            if b - a - 1 < MIN_RUN or not ends_on_floor or span < MIN_SPAN:
                continue
            low = min(reach[f, a], reach[f, b]) - LIT_REACH
            high = max(reach[f, a], reach[f, b])
            on_floor = [v for v in lines if floor[f, v]]
            judged = [v for v in range(on_floor[0], on_floor[-1] + 1) if not a < v < b
                      and ok[f, v] and low <= reach[f, v] <= high
                      and (floor[f, v] or not returned[f, v])]
            lit = sum(bool(returned[f, v]) for v in judged)
            if lit >= LIT_SHARE * len(judged):
                out[f, a + 1:b] = ok[f, a + 1:b]
    return out


@settings(max_examples=200, deadline=None)
@given(arrays(bool, (3, 60)), arrays(bool, (3, 60)), arrays(bool, (3, 60)),
       st.floats(0.001, 0.05), st.floats(0.0, 1.0))
def test_unlit_lines_follow_the_rule_read_literally(returned, floor, missing, step, lit):
    """Lines `step` m apart along the floor, ranges growing with u; most lines measurable,
    `lit` of them returning the floor."""
    u = np.arange(60)
    crossing = np.zeros((3, 60, 3))
    crossing[..., 0] = 1.4 + step * u
    reach = crossing[..., 0].copy()
    ok = ~(missing & (u % 7 == 0))
    returned |= np.random.default_rng(0).random((3, 60)) < lit
    floor &= returned
    np.testing.assert_array_equal(unlit_lines(returned, floor, crossing, reach, ok),
                                  plain_unlit_lines(returned, floor, crossing, reach, ok))


def plain_fan_end_lines(returned, floor, crossing, reach, ok, lit) -> np.ndarray:
    """`fan_end_lines`' rule read literally: from a frame's outermost floor returns on,
    the lines without a return the scan lit, ended where the lit lines end."""
    out = np.zeros(returned.shape, bool)
    width = returned.shape[1]
    for f in range(returned.shape[0]):
        on_floor = [u for u in range(width) if returned[f, u] and floor[f, u]]
        for a, step in ((on_floor[0], -1), (on_floor[-1], 1)) if on_floor else ():
            run = []
            for v in range(a + step, -1 if step < 0 else width, step):
                if not lit[v] or returned[f, v]:
                    break
                run.append(v)
            after = a + step * (len(run) + 1)
            if (0 <= after < width and returned[f, after]) or len(run) < MIN_RUN:
                continue
            span = np.hypot(*(crossing[f, run[-1], :2] - crossing[f, a, :2]))
            if ok[f, a] and all(ok[f, run]) and reach[f, run[-1]] < reach[f, a] \
                    and span >= MIN_SPAN:
                out[f, run] = True
    return out


@settings(max_examples=200, deadline=None)
@given(arrays(bool, (3, 40)), arrays(bool, (3, 40)), arrays(bool, (40,)), st.integers(0, 39),
       st.floats(0.001, 0.05), st.sampled_from([-1, 1]))
def test_fan_end_lines_follow_the_rule_read_literally(returned, floor, lit, fan_end, step,
                                                      nearer):
    """Ranges falling (or growing) with u; the scan's lit lines end at `fan_end`."""
    u = np.arange(40)
    crossing = np.zeros((3, 40, 3))
    crossing[..., 0] = 2.5 + nearer * step * (u - 20)
    reach = crossing[..., 0].copy()
    ok = np.ones((3, 40), bool)
    ok[:, 7] = False
    lit |= u < fan_end
    floor &= returned
    np.testing.assert_array_equal(fan_end_lines(returned, floor, crossing, reach, ok, lit),
                                  plain_fan_end_lines(returned, floor, crossing, reach, ok,
                                                      lit))


def near_patch(points: np.ndarray, scene: Scene, margin: float = 0.01) -> np.ndarray:
    """Whether each point lies within `margin` m of the scene's (axis-aligned) patch."""
    region = scene.floor_regions[0]
    return np.any([region.contains(points[:, 0] + dx, points[:, 1] + dy)
                   for dx in (-margin, 0.0, margin) for dy in (-margin, 0.0, margin)], axis=0)


@given(arrays(np.int32, st.integers(0, 40), elements=st.integers(0, 6)), st.booleans())
def test_frame_slots_are_numpys_unique(frame_index, in_order):
    """Frame by frame (a scan's order, without a sort) or not, the frames, their first
    points and the points' slots are what np.unique gives."""
    if in_order:
        frame_index = np.sort(frame_index)
    expected = np.unique(frame_index, return_index=True, return_inverse=True)
    for got, want in zip(frame_slots(frame_index), expected, strict=True):
        np.testing.assert_array_equal(got, want)


def test_a_black_patch_is_found_unlit_and_no_lit_floor_is():
    scene = small_patch_scene(0.0, 0.0, 0.5, x=2.0)
    found = [unlit_floor(i.scan, MODEL, i.frame_poses) for i in ideal_scans(scene)]
    points = np.concatenate(found)
    assert len(points) > 100  # measured: 152 over three scans
    assert near_patch(points, scene).all()  # where the line meets the floor
    assert np.abs(points[:, 2]).max() < 1e-9
    plain = small_patch_scene(0.0, 1.0, 0.5, x=2.0)
    assert not any(len(unlit_floor(i.scan, MODEL, i.frame_poses)) for i in ideal_scans(plain))


def test_a_black_patch_before_a_fading_stripe_is_found_unlit():
    """The stripe fades beyond the patch (a quarter of the floor returns past 2.05 m
    dropped, at random) and the laser's fan ends nearer than the floor's first return:
    neither the gaps beyond the run nor the lines past the fan's end count against it."""
    scene = small_patch_scene(0.0, 0.0, 0.3, x=1.8)
    found = 0
    for ideal in ideal_scans(scene):
        points = ideal.scan.points
        far = np.hypot(points[:, 0], points[:, 1]) > 2.05
        fade = far & (np.abs(points[:, 2]) < 0.05) \
            & (np.random.default_rng(ideal.scan.index).random(len(points)) < 0.25)
        unlit = unlit_floor(ideal.scan.select(~fade), MODEL, ideal.frame_poses)
        assert near_patch(unlit, scene, 0.03).all()
        found += len(unlit)
    assert found > 60  # measured: 98 (22 counting the lines beyond the run)


def test_a_black_patch_the_fans_end_falls_in_is_found_unlit():
    """The laser's fan lights no floor nearer than 1.45 m: the patch's lines run from its
    far rim's floor to the fan's end without a return, bounded by no lit floor nearer."""
    scene = small_patch_scene(0.0, 0.0, 0.5, x=2.0)
    ideal = list(ideal_scans(scene, scans=2))[1]
    unlit = unlit_floor(ideal.scan, MODEL, ideal.frame_poses)
    assert near_patch(unlit, scene, 0.03).all()
    assert len(unlit) > 100  # measured: 215 (none counting only runs between floor returns)


def test_a_black_patch_on_the_lines_a_fading_stripe_dims_is_found_unlit():
    """As the rendered frames show the floor: only out to 1.85 m, a fifth of its returns
    dropped past 1.7 m. The patch, 0.6 m wide, darkens its lines in the frames facing it
    on top of the fading: at a share of 0.9 those lines counted as past the fan's end and
    nothing was found."""
    scene = small_patch_scene(0.0, 0.0, 0.6, x=2.3)
    found = 0
    for ideal in ideal_scans(scene):
        points = ideal.scan.points
        reach = np.hypot(points[:, 0], points[:, 1])
        fade = (np.abs(points[:, 2]) < 0.05) & ((reach > 1.85) | (reach > 1.7) & (
            np.random.default_rng(ideal.scan.index).random(len(points)) < 0.2))
        unlit = unlit_floor(ideal.scan.select(~fade), MODEL, ideal.frame_poses)
        assert near_patch(unlit, scene, 0.03).all()
        found += len(unlit)
    assert found > 40  # measured: 67, all from the third scan (0 at a share of 0.9)


TILTED = MODEL.with_changes(head_mount=HeadMount(position=(0.1, -0.05, 0.02), roll=0.02,
                                                  pitch=-0.03))


def first_corridor_scan(model=MODEL):
    return next(ideal_scans(builtin_scene("corridor"), model, scans=1)).scan


def test_a_stripe_fading_with_range_is_not_a_dark_patch():
    """Floor returns only out to 2.2 m (a dim stripe far off at grazing incidence): the
    lines beyond end at the walls, not at lit floor, so none is unlit."""
    scan = first_corridor_scan()
    assert len(unlit_floor(scan, MODEL)) == 0
    far = np.hypot(scan.points[:, 0], scan.points[:, 1]) > 2.2
    faded = scan.select(~(far & (np.abs(scan.points[:, 2]) < 0.05)))
    assert len(faded) < len(scan) - 500  # measured: 628 fewer
    assert len(unlit_floor(faded, MODEL)) == 0


def lines_of(scan, model) -> np.ndarray:
    """The image line u of each point of `scan`."""
    out = np.empty(len(scan))
    for i, (point, heading) in enumerate(zip(scan.points, scan.heading, strict=True)):
        head = np.linalg.inv(model.head_pose(heading)) @ np.append(point, 1.0)
        out[i] = project_head_points(model, head[None, :3])[0, 0]
    return np.rint(out)


@pytest.mark.parametrize("model", [MODEL, TILTED], ids=["upright", "tilted head"])
def test_lines_without_a_return_on_the_floor_are_unlit_where_their_floor_points_were(model):
    scan = first_corridor_scan(model)
    on_floor = np.abs(scan.points[:, 2]) < 0.01
    frame = scan.frame_index == np.bincount(scan.frame_index[on_floor]).argmax()
    u = lines_of(scan.select(frame), model)
    floor_lines = np.unique(u[on_floor[frame]])
    start = floor_lines[len(floor_lines) // 2]
    for run, expected in ((MIN_RUN - 1, 0), (MIN_RUN + 5, MIN_RUN + 5)):
        gone = np.zeros(len(scan), bool)
        gone[np.flatnonzero(frame)] = (u >= start) & (u < start + run)
        assert gone.sum() == run
        unlit = unlit_floor(scan.select(~gone), model)
        assert len(unlit) == expected  # a missed peak or two is no dark patch
        if expected:  # each line's floor point is where its return was (noise: mm)
            lost = scan.points[gone].astype(np.float64)
            np.testing.assert_allclose(unlit[:, :2], lost[:, :2], atol=0.01)


LOW_CAMERA = MODEL.with_changes(  # a camera 0.6 m up, tilted more; the emitter 0.3 m up
    camera_mount=CameraMount(position=(-0.05, 0.0, 0.6), tilt=0.45),
    laser=LaserPlane((-0.05, 0.0, 0.3), MODEL.laser.normal), name="low")


def empty_floor_scan(model) -> Scan:
    """One ideal scan of an empty floor by `model`, without peak noise."""
    empty = replace(builtin_scene("corridor"), objects=(), floor_regions=(),
                    scan_poses=np.zeros((1, 3)))
    return next(ideal_scans(empty, model, scans=1, pixel_sigma=0.0)).scan


@pytest.mark.parametrize("model", [MODEL, LOW_CAMERA], ids=["reference", "camera 0.6 m up"])
def test_each_floor_return_lies_where_its_lines_floor_crossing_is(model):
    """On every image line that returns the floor, the line's floor crossing is measurable
    and is the return (an empty floor's ideal scan, its points on whole image lines). A
    line the laser plane's horizon crosses had none, its first pixel's ray meeting the
    plane behind the camera: the reference scanner's far floor on 34 of its lines, a
    camera 0.6 m up on 131 of 487, never judged unlit. (Not the tilted head: its camera
    sees the floor through the disk's shaft hole, which the simulator leaves open.)"""
    scan = empty_floor_scan(model)
    returns = line_returns(scan, model)
    crossing, _, ok = floor_crossings(model, scan.heading[returns.first])
    to_head = np.linalg.inv(model.head_poses(scan.heading))
    head = np.einsum("nij,nj->ni", to_head[:, :3, :3], scan.points.astype(np.float64)) \
        + to_head[:, :3, 3]
    pixels = project_head_points(model, head)
    inside = (pixels[:, 1] >= 0.0) & (pixels[:, 1] <= model.camera.height - 1.0)  # not
    # past the first or last row's centre, beyond the lines' ends
    frame, line = returns.slot[inside], np.rint(pixels[inside, 0]).astype(np.int64)
    assert inside.mean() > 0.99 and ok[frame, line].all()
    np.testing.assert_allclose(crossing[frame, line, :2], scan.points[inside, :2], atol=1e-3)


def test_empty_and_pointless_scans_are_unlit_nowhere():
    scan = first_corridor_scan()
    assert unlit_floor(scan.select(np.zeros(len(scan), bool)), MODEL).shape == (0, 3)
    one = scan.select(np.arange(len(scan)) == 0)
    assert unlit_floor(one, MODEL).shape == (0, 3)


def unlit_grid() -> HeightGrid:
    """A grid of one ray over flat floor, with unlit floor at three points: two in its
    tiles, one outside every tile (not marked)."""
    grid = HeightGrid(GridConfig(extent=20.0))
    unlit = np.array([[1.02, 0.02, 0.0], [1.52, 0.02, 0.0], [15.0, 15.0, 0.0]])
    grid.insert(np.array([[2.0, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]), 1.0, unlit=unlit)
    return grid


def test_the_grid_keeps_unlit_cells_through_files_and_merges(tmp_path):
    grid = unlit_grid()
    layers = grid.layers((0.0, -1.0, 3.0, 1.0))
    marked = np.argwhere(layers.unlit)
    np.testing.assert_array_equal(marked, [[20, 20], [20, 30]])  # (row, column)
    assert grid.layers((14.0, 14.0, 16.0, 16.0)).unlit.sum() == 0
    save_map(tmp_path / "map.npz", grid)
    loaded = load_map(tmp_path / "map.npz").grid.layers((0.0, -1.0, 3.0, 1.0))
    np.testing.assert_array_equal(loaded.unlit, layers.unlit)
    base = HeightGrid(grid.config)
    base.insert(np.array([[2.0, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]), 0.5)
    base.merge(grid)
    np.testing.assert_array_equal(base.layers((0.0, -1.0, 3.0, 1.0)).unlit, layers.unlit)


def test_a_map_file_of_version_2_loads_without_unlit_cells(tmp_path):
    grid = unlit_grid()
    save_map(tmp_path / "map.npz", grid)
    arrays = dict(np.load(tmp_path / "map.npz", allow_pickle=False))
    arrays["format_version"] = np.array(2)
    # a version-2 file holds neither the unlit scans nor where cells were seen from
    arrays["cells"] = np.delete(arrays["cells"], [gk.UNLIT, gk.FROM], axis=-1)
    np.savez(tmp_path / "v2.npz", **arrays)
    old = load_map(tmp_path / "v2.npz").grid
    assert not old.layers((0.0, -1.0, 3.0, 1.0)).unlit.any()
    np.testing.assert_array_equal(old.layers((0.0, -1.0, 3.0, 1.0)).seen,
                                  grid.layers((0.0, -1.0, 3.0, 1.0)).seen)


def test_points_off_the_laser_plane_are_another_sensors_and_show_nothing_unlit():
    """A cloud read from a bag (not this scanner's triangulated points) is no evidence."""
    scan = next(ideal_scans(small_patch_scene(0.0, 0.0, 0.5, x=2.0), scans=1)).scan
    assert len(unlit_floor(scan, MODEL))
    rng = np.random.default_rng(0)
    moved = Scan(**{name: getattr(scan, name) for name in
                    ("colors", "time", "heading", "frame_index", "range_sigma")},
                 points=scan.points + rng.normal(0.0, 0.05, scan.points.shape) * [1, 1, 0])
    assert len(unlit_floor(moved, MODEL)) == 0


def test_a_stripe_that_misses_the_floor_often_shows_nothing_unlit():
    """Rendered frames return the floor on at most 76 % of the lines at any range: where
    the floor returns that unreliably, no run without a return means a dark patch."""
    scan = next(ideal_scans(small_patch_scene(0.0, 0.0, 0.5, x=2.0), scans=1)).scan
    on_floor = np.abs(scan.points[:, 2]) < 0.01
    dropped = on_floor & (np.random.default_rng(0).random(len(scan)) < 0.3)
    assert len(unlit_floor(scan, MODEL)) and not len(unlit_floor(scan.select(~dropped), MODEL))


def test_a_rebuild_after_loop_closure_keeps_the_unlit_floor_where_the_scan_moved():
    ideal = next(ideal_scans(small_patch_scene(0.0, 0.0, 0.5, x=2.0), scans=1))
    points, origins = scan_rays(ideal.scan, MODEL, ideal.frame_poses)
    unlit = unlit_floor(ideal.scan, MODEL, ideal.frame_poses)
    pose = ideal.pose_start
    kept = scan_contribution(points, origins, pose, 1.0, 0.05, unlit)
    moved = se2_to_pose(0.5, 0.0, 0.0) @ pose  # the corrected pose, half a metre on
    grid = rebuild_grid(GridConfig(extent=20.0), moved[None], [kept])
    box = (-1.0, -2.0, 5.0, 2.0)
    marked = grid.layers(box).unlit
    shifted = transform_points(moved @ np.linalg.inv(pose), unlit)
    direct = HeightGrid(GridConfig(extent=20.0))
    direct.insert(transform_points(moved @ np.linalg.inv(pose), points),
                  transform_points(moved @ np.linalg.inv(pose), origins), 1.0, unlit=shifted)
    assert marked.sum() > 10  # measured: 18
    np.testing.assert_array_equal(marked, direct.layers(box).unlit)


def test_the_compiled_image_lines_are_those_of_project_head_points_with_distortion():
    """`_line_returns` inlines the projection: the same line for every point, with a
    distorted camera and a tilted head as well."""
    model = TILTED.with_changes(
        camera=replace(MODEL.camera, distortion=(0.12, -0.2, 0.002, -0.001, 0.05)))
    scan = first_corridor_scan()
    frames, slot = np.unique(scan.frame_index, return_inverse=True)
    nearest = np.full((len(frames), model.camera.width), np.inf)
    counts = np.zeros(len(frames), np.int64)  # the points of each frame
    cam = model.camera
    _line_returns(scan.points, scan.heading, slot.astype(np.int64),
                  np.linalg.inv(model.head_mount.pose), model.camera_mount.rotation.T.copy(),
                  np.array(model.camera_mount.position), np.array([cam.fx, cam.fy, cam.cx,
                                                                   cam.cy]),
                  cam.dist_coeffs, np.array([*model.laser.origin, *model.laser.normal]),
                  nearest, np.zeros(nearest.shape, bool), np.zeros(len(frames), np.int64),
                  counts)
    np.testing.assert_array_equal(counts, np.bincount(slot))
    returned = np.isfinite(nearest)
    expected = np.zeros_like(returned)
    for point, heading, row in zip(scan.points, scan.heading, slot, strict=True):
        head = np.linalg.inv(model.head_pose(heading)) @ np.append(point, 1.0)
        u = np.rint(project_head_points(model, head[None, :3])[0, 0])
        if 0 <= u < cam.width:
            expected[row, int(u)] = True
    np.testing.assert_array_equal(returned, expected)


def test_nan_and_inf_points_or_headings_mark_nothing_false():
    """Non-finite points return no line; a frame whose heading is not finite is not
    judged: neither marks floor that was lit."""
    scene = small_patch_scene(0.0, 0.0, 0.5, x=2.0)
    scan = next(ideal_scans(scene, scans=1)).scan
    found = unlit_floor(scan, MODEL)
    fields = {name: getattr(scan, name) for name in ("colors", "time", "frame_index",
                                                     "range_sigma")}
    points = scan.points.copy()
    points[::50], points[1::50] = np.nan, np.inf
    damaged = unlit_floor(Scan(points=points, heading=scan.heading, **fields), MODEL)
    assert len(damaged) and near_patch(damaged, scene).all()
    assert len(damaged) <= len(found) + 10
    heading = scan.heading.copy()
    heading[scan.frame_index % 3 == 0] = np.nan  # a third of the frames
    unjudged = unlit_floor(Scan(points=scan.points, heading=heading, **fields), MODEL)
    assert np.isfinite(unjudged).all() and 0 < len(unjudged) < len(found)  # 105 of 152
    assert near_patch(unjudged, scene).all()
