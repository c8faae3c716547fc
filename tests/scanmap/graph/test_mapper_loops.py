"""The Mapper with loop closure: the map follows the graph and stays true to the scene."""

from __future__ import annotations

import numpy as np

from scanmap.evaluation import ate_rmse, map_errors
from scanmap.graph import LoopClosureConfig
from scanmap.mapping import Mapper, MapperConfig
from scanmap_driver.sim import truth_raster
from scanmap_driver.sim.ideal import ideal_scans
from tests.scanmap.graph.ring_scene import corridor_b_end, ring_scene
from tests.scanmap.test_hazards import small_patch_scene


def mapped(ideal: list, loop_closure: bool) -> Mapper:
    config = MapperConfig(loop_closure=LoopClosureConfig(enabled=loop_closure),
                          update_obstacles=False)
    mapper = Mapper(config=config, offline=True, initial_pose=ideal[0].pose_start)
    mapper.map_scans(s.scan for s in ideal)
    mapper.close_loops()
    return mapper


def test_the_rebuilt_map_is_as_true_as_the_fused_one(ring_ideal):
    closing = mapped(ring_ideal, loop_closure=True)
    assert closing.loop_closer.loops and closing.loop_closer.version > 0
    np.testing.assert_allclose(closing.trajectory().poses,
                               closing.loop_closer.corrected_poses())
    raster = truth_raster(ring_scene())
    rebuilt = map_errors(closing.segment(), raster, np.eye(4))
    fused = map_errors(mapped(ring_ideal, loop_closure=False).segment(), raster, np.eye(4))
    for measure in ("obstacle_f1", "obstacle_precision", "free_precision"):
        assert rebuilt[measure] >= fused[measure] - 0.02, (measure, rebuilt, fused)


def test_a_map_saved_mid_run_keeps_its_graph_and_closes_the_loop_later(ring_ideal, tmp_path):
    config = MapperConfig(loop_closure=LoopClosureConfig(enabled=True), update_obstacles=False)
    first = Mapper(config=config, offline=True, initial_pose=ring_ideal[0].pose_start)
    half = corridor_b_end()
    first.map_scans(s.scan for s in ring_ideal[:half])
    first.save(tmp_path / "half.npz")
    saved_edges = len(first.loop_closer.graph.edges)
    first.loop_closer.close()

    resumed = Mapper.load(tmp_path / "half.npz", offline=True)
    assert len(resumed.loop_closer.graph) == half
    assert len(resumed.loop_closer.graph.edges) == saved_edges
    resumed.map_scans(s.scan for s in ring_ideal[half:])
    resumed.close_loops()
    closer = resumed.loop_closer
    assert any(loop.candidate < half <= loop.query for loop in closer.loops)
    truth = np.array([s.pose_start for s in ring_ideal])
    assert ate_rmse(resumed.trajectory().poses, truth, "se2") < 0.05


def test_a_saved_map_keeps_each_scans_unlit_floor_for_later_rebuilds(tmp_path):
    """Saved and resumed, the kept floor a scan's laser lines crossed unlit and each kept
    ray's laser emitter are the same, so a rebuild after the restart still keeps a dark
    patch out of the free space and clears along the laser's rays."""
    config = MapperConfig(loop_closure=LoopClosureConfig(enabled=True), update_obstacles=False)
    scene = small_patch_scene(0.0, 0.0, 0.5, x=2.0)
    ideal = list(ideal_scans(scene, scans=2))
    first = Mapper(config=config, offline=True, initial_pose=ideal[0].pose_start)
    first.map_scans(s.scan for s in ideal)
    first.save(tmp_path / "map.npz")
    first.loop_closer.close()
    resumed = Mapper.load(tmp_path / "map.npz", offline=True)
    before = [(k.unlit, k.lasers) for k in first._contributions]
    after = [(k.unlit, k.lasers) for k in resumed._contributions]
    resumed.loop_closer.close()
    assert sum(len(unlit) for unlit, _ in before) > 10
    for (unlit, lasers), (unlit_loaded, lasers_loaded) in zip(before, after, strict=True):
        np.testing.assert_array_equal(unlit, unlit_loaded)
        assert lasers is not None and len(lasers) > 100
        np.testing.assert_array_equal(lasers, lasers_loaded)


def test_a_scan_fused_without_points_keeps_the_others_laser_emitters(tmp_path):
    """A scan whose every point was left out before fusion (`stray_points`) keeps no
    rays, so no emitters either: the map still saves the other scans' emitters, and
    they load back in place."""
    from scanmap.mapping.rebuild import Contribution

    config = MapperConfig(loop_closure=LoopClosureConfig(enabled=True), update_obstacles=False)
    ideal = list(ideal_scans(small_patch_scene(0.0, 0.0, 0.5, x=2.0), scans=2))
    first = Mapper(config=config, offline=True, initial_pose=ideal[0].pose_start)
    first.map_scans(s.scan for s in ideal)
    empty = np.zeros((0, 3))
    first._contributions[0] = Contribution.of_rays(empty, empty, 0.0, lasers=empty)
    first.save(tmp_path / "map.npz")
    first.loop_closer.close()
    resumed = Mapper.load(tmp_path / "map.npz", offline=True)
    resumed.loop_closer.close()
    assert resumed._contributions[0].lasers is None
    np.testing.assert_array_equal(resumed._contributions[1].lasers,
                                  first._contributions[1].lasers)
