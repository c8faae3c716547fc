"""`rebuild_grid` (tiles reserved at once, a base map) against plain insertion scan by scan;
`GridRebuilder` (resumes from its checkpoints) against `rebuild_grid`; `SubmapRebuilder`
(submaps merged whole, bent ones built again) against `rebuild_grid`."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.mapping.rebuild import Contribution, GridRebuilder, SubmapRebuilder, rebuild_grid
from scanmap.navigation.floor import segment
from scanmap_driver.errors import MapError
from scanmap_driver.transforms import se2_to_pose, transform_points


def kept_rays(ring_ideal: list) -> tuple[np.ndarray, list]:
    """Poses off the truth by a drift, and each scan's points (every 7th) from 0.3 m up;
    one scan not fused (None)."""
    poses = np.array([s.pose_start @ se2_to_pose(0.01 * k, 0.0, 0.002 * k)
                      for k, s in enumerate(ring_ideal)])
    kept = [Contribution.of_rays(s.scan.points[::7],
                                 np.broadcast_to([0.0, 0.0, 0.3], s.scan.points[::7].shape),
                                 float(s.scan.stamp)) for s in ring_ideal]
    kept[3] = None
    return poses, kept


def plain(grid: HeightGrid, poses: np.ndarray, kept: list) -> HeightGrid:
    """The reference: every scan inserted in order by `HeightGrid.insert`."""
    if grid.config.window is not None:
        grid.recenter(float(poses[-1][0, 3]), float(poses[-1][1, 3]))
    for pose, k in zip(poses, kept, strict=True):
        if k is not None:
            grid.insert(transform_points(pose, k.points), transform_points(pose, k.origins),
                        k.stamp)
    return grid


@pytest.mark.parametrize("distinct", [0, 1, 5, 70_000])
def test_kept_rays_keep_each_run_of_one_origin_once(distinct):
    """A scan's rays start from one camera position a frame: each run of equal origins is
    one row of the table, the origins come back exactly (as float32), and past 65,536
    rows the index widens."""
    rng = np.random.default_rng(distinct)
    cameras = rng.normal(0.0, 1.0, (distinct, 3))
    runs = rng.integers(1, 4, distinct) if distinct < 100 else np.ones(distinct, int)
    origins = np.repeat(cameras, runs, axis=0)
    if distinct == 5:  # a camera position met again later is a row of its own
        origins = np.vstack([origins, cameras[:1]])
    points = rng.normal(0.0, 3.0, (len(origins), 3))
    kept = Contribution.of_rays(points, origins, 7.5)
    np.testing.assert_array_equal(kept.origins, origins.astype(np.float32))
    np.testing.assert_array_equal(kept.points, points.astype(np.float32))
    assert len(kept.origin_table) == distinct + (distinct == 5) and kept.stamp == 7.5
    assert kept.origin_index.dtype == (np.uint32 if distinct > 2**16 else np.uint16)
    pose = se2_to_pose(1.0, -2.0, 0.3)
    ends, starts = kept.placed(pose)
    np.testing.assert_array_equal(ends, transform_points(pose, points.astype(np.float32)))
    np.testing.assert_array_equal(starts, transform_points(pose, origins.astype(np.float32)))


def test_kept_rays_keep_each_runs_laser_emitter_and_place_it():
    """Where a scan was fused with the laser's rays, each run of rays with one camera
    position and one emitter is one row of both tables (an emitter that moves while the
    camera does not starts a row too); the emitters come back exactly (as float32) and
    are placed with the rays."""
    rng = np.random.default_rng(4)
    origins = np.repeat(rng.normal(0.0, 1.0, (4, 3)), 3, axis=0)
    lasers = origins - [0.0, 0.0, 0.5]
    lasers[7:] += [0.01, 0.0, 0.0]  # the emitter moved in the third run
    points = rng.normal(0.0, 3.0, (len(origins), 3))
    kept = Contribution.of_rays(points, origins, 1.0, lasers=lasers)
    assert len(kept.origin_table) == len(kept.laser_table) == 5
    np.testing.assert_array_equal(kept.lasers, lasers.astype(np.float32))
    np.testing.assert_array_equal(kept.origins, origins.astype(np.float32))
    pose = se2_to_pose(-1.0, 0.5, 2.0)
    np.testing.assert_array_equal(kept.placed_lasers(pose),
                                  transform_points(pose, lasers.astype(np.float32)))
    without = Contribution.of_rays(points, origins, 1.0)
    assert without.lasers is None and without.placed_lasers(pose) is None


@pytest.mark.parametrize("window", [None, 12.0])
def test_rebuild_equals_plain_insertion(ring_ideal, window):
    config = GridConfig(window=window)
    poses, kept = kept_rays(ring_ideal)
    fast = rebuild_grid(config, poses, kept)
    reference = plain(HeightGrid(config), poses, kept)
    assert fast.tile_count == reference.tile_count > 0
    assert_same(fast, reference)


def test_rebuild_from_a_base_map_equals_plain_insertion_onto_it(ring_ideal):
    config = GridConfig()
    poses, kept = kept_rays(ring_ideal)
    base = plain(HeightGrid(config), poses[:10], kept[:10])
    fast = rebuild_grid(config, poses[10:], kept[10:], base.state())
    assert_same(fast, plain(base, poses[10:], kept[10:]))


def assert_same(a: HeightGrid, b: HeightGrid) -> None:
    assert a.bounds() == b.bounds()
    la, lb = a.layers(), b.layers()
    for name in ("levels", "counts", "nlev", "seen", "updated"):
        np.testing.assert_array_equal(getattr(la, name), getattr(lb, name), err_msg=name)


def assert_same_stood(a: HeightGrid, b: HeightGrid) -> None:
    assert_same(a, b)
    np.testing.assert_array_equal(a.layers().stood, b.layers().stood)


def moved(poses: np.ndarray, first: int, step: float) -> np.ndarray:
    """The poses from `first` on turned by `step` rad about the pose before it and
    shifted, as an optimisation moves the scans after a loop's older end."""
    out = poses.copy()
    pivot = poses[first - 1]
    turn = pivot @ se2_to_pose(0.02, -0.01, step) @ np.linalg.inv(pivot)
    out[first:] = turn @ poses[first:]
    return out


def test_a_rebuilder_with_no_tolerance_equals_rebuild_grid_after_every_optimisation(
        ring_ideal):
    config = GridConfig()
    poses, kept = kept_rays(ring_ideal)
    n = len(poses)
    size = rebuild_grid(config, poses, kept).used_bytes
    rebuilds = GridRebuilder(config, tolerance=0.0, ratio=0.0, max_bytes=3 * size)
    for count, first, step in ((n - 6, 0, 0.0), (n - 3, n - 9, 0.01), (n, n - 4, -0.02),
                               (n, 5, 0.01), (n, n, 0.0)):
        poses = moved(poses, first, step) if 0 < first < n else poses
        grid = rebuilds.rebuild(poses[:count], kept[:count])
        assert_same_stood(grid, rebuild_grid(config, poses[:count], kept[:count]))
        # The Mapper fuses later scans into the grid it got: the checkpoints stay apart.
        grid.insert(transform_points(poses[0], kept[0].points),
                    transform_points(poses[0], kept[0].origins), 1e9)
    assert rebuilds.reused == n  # nothing moved: nothing redone
    # ratio 0 takes a checkpoint wherever one is due: some are kept, thinned to max_bytes
    assert rebuilds._checkpoints
    assert sum(g.used_bytes for _, g in rebuilds._checkpoints) <= rebuilds.max_bytes


def test_a_rebuilder_redoes_only_the_scans_after_the_first_that_moved(ring_ideal):
    config = GridConfig()
    poses, kept = kept_rays(ring_ideal)
    rebuilds = GridRebuilder(config, tolerance=0.25, ratio=0.0, max_bytes=1 << 40)
    rebuilds.rebuild(poses, kept)
    # Scans 0..9 move by a tenth of a cell (kept where they were), from 12 on by more.
    nudged = poses.copy()
    nudged[:10, 0, 3] += 0.1 * config.resolution
    later = moved(nudged, 12, 0.01)
    grid = rebuilds.rebuild(later, kept)
    reused = rebuilds.reused  # from its checkpoint before scan 12, the first that moved
    assert reused == 12
    placed = np.concatenate([poses[:reused], later[reused:]])
    assert_same_stood(grid, rebuild_grid(config, placed, kept))
    # A turn that moves the scan's farthest kept point by half a cell counts as moved.
    reach = np.linalg.norm(kept[4].points, axis=1).max()
    turned = placed.copy()
    turned[4] = turned[4] @ se2_to_pose(0.0, 0.0, 0.5 * config.resolution / reach)
    assert rebuilds._first_moved(turned, kept) == 4
    turned[4] = placed[4] @ se2_to_pose(0.0, 0.0, 0.2 * config.resolution / reach)
    assert rebuilds._first_moved(turned, kept) == len(kept)


@pytest.mark.parametrize("window", [None, 12.0])
def test_a_rebuilder_over_a_base_map_or_a_window_equals_rebuild_grid(ring_ideal, window):
    config = GridConfig(window=window)
    poses, kept = kept_rays(ring_ideal)
    base = plain(HeightGrid(GridConfig()), poses[:10], kept[:10]).state() \
        if window is None else None
    rebuilds = GridRebuilder(config, base, tolerance=0.0, ratio=0.0, max_bytes=1 << 40)
    rebuilds.rebuild(poses[10:], kept[10:])
    later = moved(poses, 15, 0.01)[10:]
    grid = rebuilds.rebuild(later, kept[10:])
    assert rebuilds.reused == (0 if window else 5)
    assert_same_stood(grid, rebuild_grid(config, later, kept[10:], base))


def test_a_grid_copy_fuses_as_the_grid(ring_ideal):
    config = GridConfig()
    poses, kept = kept_rays(ring_ideal)
    grid = rebuild_grid(config, poses[:8], kept[:8])
    copy = grid.copy()
    for g in (grid, copy):
        plain(g, poses[8:], kept[8:])
    assert_same_stood(copy, grid)
    assert copy.memory_bytes <= grid.memory_bytes


def test_a_rebuilder_keeps_no_checkpoint_that_would_cost_more_than_it_saves(ring_ideal):
    poses, kept = kept_rays(ring_ideal)
    rebuilds = GridRebuilder(GridConfig(), tolerance=0.0, ratio=1e9)
    rebuilds.rebuild(poses, kept)
    assert not rebuilds._checkpoints
    rebuilds.rebuild(poses, kept)
    assert rebuilds.reused == 0


def test_submaps_moved_whole_are_merged_and_bent_ones_built_again(ring_ideal):
    config = GridConfig()
    poses, kept = kept_rays(ring_ideal)
    n, size = len(poses), 10
    rebuilds = SubmapRebuilder(config, scans=size)
    rebuilds.prepare(poses, kept)
    assert len(rebuilds._submaps) == n // size
    grid = rebuilds.rebuild(poses, kept)
    assert rebuilds.reused == n // size * size  # every whole submap, as prepared
    # A loop moves everything from scan 15 on: submaps 2.. move whole, submap 1 is bent
    later = moved(poses, 15, 0.01)
    built = [s.grid for s in rebuilds._submaps]
    grid = rebuilds.rebuild(later, kept)
    assert rebuilds.reused == (n // size - 1) * size
    assert [s.grid is g for s, g in zip(rebuilds._submaps, built, strict=True)] == \
        [True, False] + [True] * (n // size - 2)
    reference = rebuild_grid(config, later, kept)
    assert grid.bounds() == reference.bounds()
    # Submaps turned by the loop are resampled (test_grid_merge measures that against the
    # truth); with these sparse rays 2-3 % of the cells differ, most free -> unknown
    ours, theirs = segment(grid.layers()).state, segment(reference.layers()).state
    assert (ours == theirs).mean() > 0.95
    assert len(grid.layers().stood) == len(reference.layers().stood)


def test_submaps_over_a_base_map_start_from_it(ring_ideal):
    config = GridConfig()
    poses, kept = kept_rays(ring_ideal)
    base = plain(HeightGrid(config), poses[:10], kept[:10])
    rebuilds = SubmapRebuilder(config, base.state(), scans=100)  # no whole submap
    assert_same(rebuilds.rebuild(poses[10:], kept[10:]), plain(base, poses[10:], kept[10:]))


def test_bad_submap_rebuilds_are_clear_errors(ring_ideal):
    poses, kept = kept_rays(ring_ideal)
    with pytest.raises(MapError, match="rolling window"):
        SubmapRebuilder(GridConfig(window=12.0))
    with pytest.raises(MapError, match="scans"):
        SubmapRebuilder(GridConfig(), scans=0)
    with pytest.raises(MapError, match="contributions"):
        SubmapRebuilder(GridConfig()).rebuild(poses, kept[:-1])
