"""While the map is rebuilt after a loop closure, mapping goes on and queries answer from
the old map; the finished rebuild is swapped in with every pose moved."""

from __future__ import annotations

import threading

import numpy as np

import scanmap.mapping.rebuild as rebuild_module
from scanmap.evaluation import ate_rmse
from scanmap.graph import LoopClosureConfig
from scanmap.mapping import Mapper, MapperConfig
from scanmap.navigation.obstacles import QueryStatus


def test_queries_answer_from_the_old_map_until_the_rebuild_is_swapped_in(ring_ideal,
                                                                         monkeypatch):
    started, release = threading.Event(), threading.Event()
    rebuild = rebuild_module.SubmapRebuilder.rebuild

    def held(self, *args):
        started.set()
        assert release.wait(120)
        return rebuild(self, *args)

    monkeypatch.setattr(rebuild_module.SubmapRebuilder, "rebuild", held)
    config = MapperConfig(loop_closure=LoopClosureConfig(enabled=True))
    mapper = Mapper(config=config, offline=True, initial_pose=ring_ideal[0].pose_start)
    scans = [s.scan for s in ring_ideal]
    mapper.map_scans(scans[:-3])
    mapper.loop_closer.finish()  # the ring has closed: an optimisation is waiting
    assert mapper.loop_closer.version > 0
    before = mapper.trajectory().poses
    old = mapper.grid

    mapper.add(scans[-3])  # starts the rebuild and returns
    assert started.wait(60)
    for scan in scans[-2:]:  # the robot keeps mapping meanwhile
        update = mapper.add(scan)
        assert update.fused
        x, y = update.pose[0, 3], update.pose[1, 3]
        assert mapper.grid is old
        answer = mapper.obstacles.nearest(x, y)  # from the old map, with this scan in it
        assert answer.status in (QueryStatus.OK, QueryStatus.UNKNOWN)
        assert np.isfinite(answer.distance) and answer.stamp == old.stamp
    np.testing.assert_array_equal(mapper.trajectory().poses[:len(before)], before)

    release.set()
    mapper.close_loops()
    assert mapper.grid is not old
    np.testing.assert_allclose(mapper.trajectory().poses, mapper.loop_closer.corrected_poses())
    truth = np.array([s.pose_start for s in ring_ideal])
    assert ate_rmse(mapper.trajectory().poses, truth, "se2") < 0.05
