"""The Mapper with loop closure: the map follows the graph and stays true to the scene."""

from __future__ import annotations

import numpy as np

from scanmap.evaluation import map_errors
from scanmap.graph import LoopClosureConfig
from scanmap.mapping import Mapper, MapperConfig
from scanmap_driver.sim import truth_raster
from tests.scanmap.graph.ring_scene import ring_scene


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
