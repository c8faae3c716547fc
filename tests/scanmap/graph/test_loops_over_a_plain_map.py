"""Loop closure switched on over a map saved without it: a new graph extends the map."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from scanmap.evaluation import ate_rmse
from scanmap.evaluation.ground_truth import map_errors
from scanmap.graph import LoopClosureConfig
from scanmap.grid.height_grid import HeightGrid
from scanmap.io.map_files import load_map
from scanmap.mapping import Mapper, MapperConfig
from scanmap.navigation.floor import segment
from scanmap_driver.sim import truth_raster
from scanmap_driver.transforms import transform_points
from tests.scanmap.graph.ring_scene import ring_scene

PLAIN = MapperConfig(update_obstacles=False)
CLOSING = MapperConfig(loop_closure=LoopClosureConfig(enabled=True), update_obstacles=False)


@pytest.mark.parametrize("submap_scans", [None, 25])
def test_a_map_without_a_graph_is_extended_by_a_new_one(ring_ideal, tmp_path, submap_scans):
    # None: rebuilt from every kept ray (the same grid as fusing them in turn); 25: from
    # submaps merged on the loaded map (the same obstacles and free space, nearly)
    closing = replace(CLOSING, rebuild_submap_scans=submap_scans)
    first = 6  # scans mapped on the first day, without loop closure
    day_one = Mapper(config=PLAIN, offline=True, initial_pose=ring_ideal[0].pose_start)
    day_one.map_scans(s.scan for s in ring_ideal[:first])
    day_one.save(tmp_path / "day1.npz")
    saved = day_one.trajectory().poses

    day_two = Mapper.load(tmp_path / "day1.npz", offline=True, config=closing)
    day_two.map_scans(s.scan for s in ring_ideal[first:])
    day_two.close_loops()
    closer = day_two.loop_closer
    assert closer.graph.fixed == first
    assert closer.loops and closer.version > 0  # the ring closed among day two's scans
    assert all(loop.candidate >= first for loop in closer.loops)  # day one has no points
    poses = day_two.trajectory().poses
    np.testing.assert_array_equal(poses[:first], saved)  # the loaded map does not move
    truth = np.array([s.pose_start for s in ring_ideal])
    assert ate_rmse(poses, truth, "se2") < 0.05

    # The map is day one's grid plus day two's kept rays at the corrected poses.
    reference = load_map(tmp_path / "day1.npz").grid
    for pose, kept in zip(poses[first:], day_two._contributions[first:], strict=True):
        if kept is not None:
            reference.insert(transform_points(pose, kept.points),
                             transform_points(pose, kept.origins), kept.stamp,
                             lasers=kept.placed_lasers(pose))
    if submap_scans is None:
        assert_same_grid(day_two.grid, reference)
    else:  # against the scene's truth, as good as the reference; nearly the same cells
        assert len(ring_ideal) >= first + submap_scans  # a whole submap was merged
        assert day_two._rebuilds.reused > 0  # built while mapping, merged moved after
        assert day_two.grid.bounds() == reference.bounds()
        ours, theirs = segment(day_two.grid.layers()), segment(reference.layers())
        raster = truth_raster(ring_scene())
        ours_errors, their_errors = (map_errors(seg, raster, np.eye(4)) for seg in (ours, theirs))
        assert ours_errors["free_cells_on_obstacles"] <= their_errors["free_cells_on_obstacles"]
        assert ours_errors["obstacle_f1"] >= their_errors["obstacle_f1"] - 0.01
        assert (ours.state == theirs.state).mean() > 0.99

    # Saved again and reloaded, the base map and the fixed nodes stay.
    day_two.save(tmp_path / "day2.npz")
    day_three = Mapper.load(tmp_path / "day2.npz", offline=True, config=closing)
    assert day_three.loop_closer.graph.fixed == first
    if submap_scans is not None:  # its submaps are built in the background once loaded
        day_three._rebuilder.submit(lambda: None).result(timeout=120)
        assert len(day_three._rebuilds._submaps) == len(ring_ideal) // submap_scans
    assert_same_grid(HeightGrid.from_state(closing.grid, day_three._base), load_map(
        tmp_path / "day1.npz").grid)


def assert_same_grid(a: HeightGrid, b: HeightGrid) -> None:
    la, lb = a.layers(), b.layers()
    assert a.bounds() == b.bounds()
    for name in ("levels", "counts", "nlev", "seen"):
        np.testing.assert_array_equal(getattr(la, name), getattr(lb, name), err_msg=name)
