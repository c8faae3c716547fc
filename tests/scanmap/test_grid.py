"""The grid on geometric scenes (table, low step, high shelf, walking person, walls) and
its hard cases (far, non-finite, empty input; saturation; rolling window)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation.floor import FREE, OBSTACLE, RobotShape, segment
from scanmap_driver.errors import MapError

from . import scenes as S

ROBOT = RobotShape(height=0.8)  # the shelf board (0.85 m) is above it, the table (0.76) not
BOUNDS = (-3.1, -3.1, 3.1, 3.1)


@pytest.fixture(scope="module")
def room():
    scene = S.furnished_room()
    mapped = S.map_scene(scene, S.ROOM_POSES, HeightGrid(GridConfig(extent=50.0)))
    layers = mapped.grid.layers(BOUNDS)
    return scene, mapped, layers, segment(layers, ROBOT)


def box_cells(layers, box: S.Box) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of the cells whose centres lie in the box's footprint."""
    xs, ys = layers.cell_centers()
    inside = S.in_box_footprint(box, *np.meshgrid(xs, ys))
    return np.nonzero(inside)


def test_table_top_within_robot_height_is_an_obstacle_with_the_gap_under_it_seen(room):
    scene, mapped, layers, seg = room
    top = scene.boxes[4]
    rows, cols = box_cells(layers, top)
    seen_top = S.hit_cells(layers, mapped, [4])[rows, cols]
    assert seen_top.mean() > 0.8
    assert (seg.state[rows, cols][seen_top] == OBSTACLE).mean() >= 0.99
    assert not (seg.state[rows, cols] == FREE).any()  # never hit from above: unknown
    two_levels = layers.nlev[rows, cols] >= 2  # floor under the top, the top above
    assert two_levels.mean() > 0.5
    floor_level = layers.levels[rows, cols, 0]
    assert (np.abs(floor_level[two_levels, 1]) < 0.03).mean() > 0.95  # but at the legs


def test_low_step_is_floor_and_high_shelf_is_no_obstacle(room):
    scene, _, layers, seg = room
    sill, shelf = scene.boxes[10], scene.boxes[11]
    rows, cols = box_cells(layers, sill)
    assert not (seg.state[rows, cols] == OBSTACLE).any()
    hit = layers.nlev[rows, cols] > 0
    assert seg.is_floor[rows, cols][hit].mean() > 0.95
    rows, cols = box_cells(layers, shelf)
    assert not (seg.state[rows, cols] == OBSTACLE).any()
    taller = segment(layers, RobotShape(height=1.0))  # a taller robot hits the shelf
    assert (taller.state[rows, cols] == OBSTACLE).mean() > 0.5


def test_obstacle_f1_in_the_robot_band(room):
    scene, mapped, layers, seg = room
    xs, ys = layers.cell_centers()
    truth = S.truth_obstacles(scene, xs, ys, ROBOT.step_height, ROBOT.height)
    band_boxes = [k for k, b in enumerate(scene.boxes)
                  if b.hi[2] > ROBOT.step_height and b.lo[2] < ROBOT.height]
    seen = S.hit_cells(layers, mapped, band_boxes)  # truth cells some ray hit
    predicted = seg.state == OBSTACLE
    tp = (predicted & truth).sum()
    precision = tp / predicted.sum()
    recall = (predicted & truth & seen).sum() / (truth & seen).sum()
    assert 2 * precision * recall / (precision + recall) >= 0.97


def test_rays_under_a_table_and_over_a_low_box_do_not_erase_them(room):
    scene, mapped, _, _ = room
    grid = mapped.grid
    # Many more scans from one side: every ray to the floor under the table passes under its
    # top, and rays to the far wall pass over the low box.
    S.map_scene(scene, [(0.0, -0.6, 0.2 * k) for k in range(8)], grid, seed=100,
                first_stamp=20.0)
    layers = grid.layers(BOUNDS)
    seg = segment(layers, ROBOT)
    for box in (scene.boxes[4], scene.boxes[9]):
        rows, cols = box_cells(layers, box)
        assert (seg.state[rows, cols] == OBSTACLE).mean() >= 0.97


def test_a_walking_person_clears_within_a_few_scans():
    """A person (0.4 x 0.4 x 1.7 m) stands 1.4 m in front of a slowly moving robot for six
    scans, then walks 1.2 m aside. The cells where the robot saw them clear: most in two
    or three scans (a level at full confidence takes ceil(3.5 / (5 * 0.4)) = 2 scans
    with enough rays through it); a one-cell line at their foot, where the floor is hit
    every scan but rays seldom pass just above it, lingers longest."""
    person = S.cell_box(10, 10, 18, 18, 0.0, 1.7)
    scene = S.room((person,))
    grid = HeightGrid(GridConfig(extent=50.0))
    for k in range(6):
        S.map_scene(scene, [(-0.9 + 0.02 * k, 0.2, 0.3 * k)], grid, seed=k, first_stamp=k)
    layers = grid.layers(BOUNDS)
    rows, cols = box_cells(layers, person)
    was = segment(layers).state[rows, cols] == OBSTACLE
    assert was.sum() >= 10  # its front and side were seen
    walked = scene.moved(4, (0.0, -1.2, 0.0))
    remaining = []
    for k in range(1, 7):
        S.map_scene(walked, [(-0.78 + 0.02 * k, 0.2, 0.3 * k)], grid, seed=10 + k,
                    first_stamp=10 + k)
        state = segment(grid.layers(BOUNDS)).state
        remaining.append(int((state[rows, cols][was] == OBSTACLE).sum()))
        if k == 1:
            new_rows, new_cols = box_cells(layers, walked.boxes[4])
            assert (state[new_rows, new_cols] == OBSTACLE).any()  # seen at once where it is
    assert remaining[2] <= was.sum() / 3, remaining
    assert remaining[5] <= 2, remaining


def test_grazing_rays_along_a_corridor_do_not_erode_its_wall():
    wall = S.cell_box(-60, 20, 60, 22, 0.0, 2.0)  # y = 1.0125 .. 1.0875
    scene = S.Scene((wall,))
    grid = HeightGrid(GridConfig(extent=50.0))
    poses = [(x, 0.45, 0.0) for x in np.linspace(-2.0, 2.0, 12)]
    mapped = S.map_scene(scene, poses, grid)
    layers = grid.layers((-3.0, -1.0, 3.0, 1.5))
    seg = segment(layers)
    on_wall = mapped.labels == 0
    ix = np.floor((mapped.points[on_wall, 0] - layers.origin[0]) / 0.05).astype(int)
    iy = np.floor((mapped.points[on_wall, 1] - layers.origin[1]) / 0.05).astype(int)
    inside = (ix >= 0) & (ix < layers.shape[1])
    ever_hit = np.zeros(layers.shape, bool)
    ever_hit[iy[inside], ix[inside]] = True
    assert (seg.state[ever_hit] == OBSTACLE).mean() >= 0.99


def test_a_point_ten_kilometres_away_is_a_clear_error_and_allocates_nothing():
    grid = HeightGrid(GridConfig(extent=100.0))
    points = np.array([[1.0, 0.0, 0.0], [10_000.0, 5.0, 0.0]])
    with pytest.raises(MapError, match="extent"):
        grid.insert(points, np.array([0.0, 0.0, 1.0]), 0.0)
    assert grid.tile_count == 0 and grid.memory_bytes < 1_000_000


def test_a_far_point_inside_the_extent_is_dropped_not_traced():
    grid = HeightGrid(GridConfig(extent=1000.0, max_range=20.0))
    stats = grid.insert(np.array([[900.0, 0.0, 0.0], [2.0, 0.0, 0.0]]),
                        np.array([0.0, 0.0, 1.0]), 0.0)
    assert stats.too_far == 1 and stats.inserted == 1 and grid.tile_count <= 2


def test_non_finite_rays_are_skipped_and_counted():
    grid = HeightGrid(GridConfig(extent=50.0))
    points = np.array([[1.0, 0.0, 0.0], [np.nan, 0.0, 0.0], [np.inf, 1.0, 0.0],
                       [1.0, 1.0, 0.0]])
    origins = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 0, 1.0], [0, np.nan, 1.0]])
    stats = grid.insert(points, origins, 0.0)
    assert stats.inserted == 1 and stats.nonfinite == 3
    assert grid.layers().nlev.sum() == 1


def test_an_empty_scan_changes_nothing():
    grid = HeightGrid(GridConfig(extent=50.0))
    stats = grid.insert(np.zeros((0, 3)), np.array([0.0, 0.0, 1.0]), 0.0)
    assert stats.inserted == 0 and grid.tile_count == 0
    with pytest.raises(MapError):
        grid.insert(np.zeros((4, 2)), np.zeros(3), 0.0)


def test_a_scan_entirely_of_floor_gives_floor_and_no_obstacle():
    grid = HeightGrid(GridConfig(extent=50.0))
    S.map_scene(S.Scene(), [(0.0, 0.0, 0.0), (0.7, 0.2, 1.0)], grid)
    layers = grid.layers((-4.0, -4.0, 4.0, 4.0))
    seg = segment(layers)
    assert not (seg.state == OBSTACLE).any()
    observed = layers.nlev > 0
    assert seg.is_floor[observed].mean() > 0.99
    assert len(seg.planes) == 1 and seg.planes[0].normal[2] > 0.9999


def test_log_odds_saturate_and_a_long_seen_object_still_clears_in_few_scans():
    """A bar (0.28-0.32 m high) hit by 60 rays for 3000 scans saturates at l_max without
    overflow; once it has gone, rays through it clear it in ceil(l_max / (max_misses *
    l_miss)) scans."""
    config = GridConfig(extent=50.0, bundle_run=0)
    grid = HeightGrid(config)
    rng = np.random.default_rng(0)
    y = rng.uniform(-0.08, 0.08, 60)
    z = rng.uniform(0.28, 0.32, 60)
    origin = np.array([0.0, 0.0, 0.3])
    x_bar = 1.0125
    hits = np.column_stack([np.full(60, x_bar), y, z])
    for stamp in range(3000):
        grid.insert(hits, origin, float(stamp))
    layers = grid.layers()
    used = layers.nlev > 0
    logodds = layers.levels[..., 2][np.arange(3)[None, None] < layers.nlev[..., None]]
    assert logodds.max() == pytest.approx(config.l_max) and np.isfinite(logodds).all()
    assert layers.counts[..., 0].sum() == 3000 * 60  # no counter overflowed
    behind = np.column_stack([np.full(60, 3.0), y * 3.0 / x_bar, z])  # the bar has gone
    needed = math.ceil(config.l_max / (config.max_misses * config.l_miss))
    for k in range(needed):
        grid.insert(behind, origin, 3000.0 + k)
    layers = grid.layers()
    xs, _ = layers.cell_centers()
    column = np.abs(xs - x_bar) < 0.03
    assert not (layers.nlev[:, column] > 0).any(), "the old box is still in the map"
    assert used.any()


def test_rolling_window_keeps_tiles_near_the_robot_only():
    grid = HeightGrid(GridConfig(extent=200.0, window=12.8))
    with pytest.raises(MapError, match="recenter"):
        grid.insert(np.ones((1, 3)), np.zeros(3), 0.0)
    grid.recenter(0.0, 0.0)
    stats = grid.insert(np.array([[2.0, 0.0, 0.0], [30.0, 0.0, 0.0]]),
                        np.array([0.0, 0.0, 1.0]), 0.0)
    assert stats.inserted == 1 and stats.outside_window == 1
    before = grid.tile_count
    grid.recenter(60.0, 0.0)
    assert grid.tile_count == 0 < before
    grid.insert(np.array([[62.0, 1.0, 0.0]]), np.array([60.0, 0.0, 1.0]), 1.0)
    b = grid.bounds()
    assert b is not None and b[0] >= 60.0 - 6.4 - 3.2


def test_memory_follows_the_area_seen():
    grid = HeightGrid(GridConfig(extent=500.0))
    grid.insert(np.array([[2.0, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]), 0.0)
    grid.insert(np.array([[302.0, 0.0, 0.0]]), np.array([300.0, 0.0, 1.0]), 1.0)
    assert grid.tile_count <= 4  # not the 300 m between them
