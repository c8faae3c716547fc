"""A new session over a saved map: its first scan located in the map, by place or near a
hint, before mapping goes on (issue 18 item 4: a building mapped across days)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from scanmap.cli import main
from scanmap.evaluation import ate_rmse
from scanmap.graph import LoopClosureConfig
from scanmap.graph.localise import NotLocalised
from scanmap.mapping import Mapper, MapperConfig
from scanmap_driver.sim import builtin_scene, ideal_scans
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose
from tests.scanmap.graph.ring_scene import corridor_b_end

CORRIDOR_A = 21  # scans along corridor A, the first part of the ring's path
RESTART = 10  # the new session starts mid-corridor A, 6 m from where the robot stopped
CONFIG = MapperConfig(loop_closure=LoopClosureConfig(enabled=True), update_obstacles=False)


def saved_map(ideal: list, scans: int, path) -> np.ndarray:
    """Map the first `scans` of the ring with loop closure, save it at `path`; the saved
    corrected poses."""
    mapper = Mapper(config=CONFIG, offline=True, initial_pose=ideal[0].pose_start)
    mapper.map_scans(s.scan for s in ideal[:scans])
    mapper.save(path)
    mapper.loop_closer.close()
    return mapper.trajectory().poses


@pytest.fixture(scope="module")
def corridor_a(ring_ideal, tmp_path_factory):
    """The map of corridor A alone: (path, saved poses)."""
    path = tmp_path_factory.mktemp("corridor_a") / "map.npz"
    return path, saved_map(ring_ideal, CORRIDOR_A, path)


def pose_error(found: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(m, deg) between two poses."""
    x, y, yaw = pose_to_se2(invert_pose(truth) @ found)
    return float(np.hypot(x, y)), float(np.degrees(abs(yaw)))


def test_a_session_started_elsewhere_is_located_by_place_and_extends_the_map(ring_ideal,
                                                                               corridor_a):
    path, saved = corridor_a
    mapper = Mapper.load(path, offline=True, localise=True)  # hint: where it stopped, 6 m off
    for k in (RESTART, RESTART + 1):  # located by place, confirmed 1.2 m on
        with pytest.raises(NotLocalised, match="confirmed"):
            mapper.add(ring_ideal[k].scan)
        assert len(mapper) == len(saved) and mapper.localising  # kept, not yet mapped
    mapper.add(ring_ideal[RESTART + 2].scan)
    found = mapper.localisation
    assert found.found_by == "place" and len(mapper) == len(saved) + 3
    for k, pose in zip(range(RESTART, RESTART + 3), mapper.trajectory().poses[-3:],
                       strict=True):
        metres, degrees = pose_error(pose, ring_ideal[k].pose_start)
        assert metres < 0.03 and degrees < 0.5, (k, metres, degrees)
    join = [e for e in mapper.loop_closer.graph.edges if e.target == CORRIDOR_A]
    assert len(join) == 1 and not join[0].loop and join[0].source == found.node  # no odometry
    # On past the end of the saved map: up the connector and into corridor B.
    mapper.map_scans(s.scan for s in ring_ideal[RESTART + 3:CORRIDOR_A + 7])
    mapper.close_loops()
    poses = mapper.trajectory().poses
    truth = np.array([s.pose_start for s in ring_ideal[:CORRIDOR_A]]
                     + [s.pose_start for s in ring_ideal[RESTART:CORRIDOR_A + 7]])
    assert len(poses) == len(truth)
    assert ate_rmse(poses, truth, "none") < 0.05
    assert np.abs(poses[:CORRIDOR_A, :2, 3] - saved[:, :2, 3]).max() < 0.05  # the old map held


def test_a_hint_near_the_robot_locates_it_without_a_place_search(ring_ideal, corridor_a):
    truth = ring_ideal[RESTART].pose_start
    hint = truth @ se2_to_pose(0.5, -0.4, np.radians(12.0))
    mapper = Mapper.load(corridor_a[0], offline=True, localise=True, hint=hint)
    mapper.add(ring_ideal[RESTART].scan)
    assert mapper.localisation.found_by == "hint"
    metres, degrees = pose_error(mapper.localisation.pose, truth)
    assert metres < 0.03 and degrees < 0.5, (metres, degrees)


def test_scans_from_a_place_the_map_never_saw_are_not_located(corridor_a):
    path, saved = corridor_a
    mapper = Mapper.load(path, offline=True, localise=True)
    for ideal in ideal_scans(builtin_scene("office"), scans=3):
        with pytest.raises(NotLocalised, match=re.escape(str(path))):
            mapper.add(ideal.scan)
    assert len(mapper) == len(saved) and mapper.localising  # nothing mapped
    mapper.loop_closer.close()


def test_look_alike_places_are_refused_without_a_hint_and_told_apart_with_one(ring_ideal,
                                                                              tmp_path):
    """The ring's corridor B is corridor A turned about the ring's centre: with both in
    the map, one scan from A matches A and B equally; a hint decides."""
    path = tmp_path / "ring.npz"
    saved_map(ring_ideal, corridor_b_end(), path)
    scan, truth = ring_ideal[RESTART].scan, ring_ideal[RESTART].pose_start
    mapper = Mapper.load(path, offline=True, localise=True)  # stopped at B's far end
    with pytest.raises(NotLocalised, match="two places"):
        mapper.add(scan)
    assert mapper.localising
    mapper.loop_closer.close()
    hint = truth @ se2_to_pose(-0.6, 0.3, np.radians(-20.0))
    hinted = Mapper.load(path, offline=True, localise=True, hint=hint)
    hinted.add(scan)
    metres, degrees = pose_error(hinted.localisation.pose, truth)
    assert metres < 0.03 and degrees < 0.5, (metres, degrees)
    hinted.loop_closer.close()


def test_a_map_saved_without_its_graph_says_it_cannot_be_localised_in(ring_ideal, tmp_path):
    mapper = Mapper(config=MapperConfig(update_obstacles=False), offline=True,
                    initial_pose=ring_ideal[0].pose_start)
    mapper.map_scans(s.scan for s in ring_ideal[:3])
    mapper.save(tmp_path / "plain.npz")
    with pytest.raises(NotLocalised, match=r"plain\.npz.*loop closure"):
        Mapper.load(tmp_path / "plain.npz", offline=True, localise=True)


def test_the_map_command_localises_a_resumed_map_and_says_where(ring_ideal, corridor_a,
                                                                tmp_path, capsys):
    scans = tmp_path / "scans"
    scans.mkdir()
    for item in ring_ideal[RESTART:RESTART + 4]:
        item.scan.save(scans / f"scan_{item.scan.index:04d}.npz")
    assert main(["map", str(scans), "--out", str(tmp_path / "map"), "--resume",
                 str(corridor_a[0]), "--localise"]) == 0
    x, y, _ = pose_to_se2(ring_ideal[RESTART + 2].pose_start)  # confirmed 1.2 m on
    report = json.loads((tmp_path / "map" / "report.json").read_text())
    localised = report["input"]["localised"]
    assert localised["found_by"] == "place" and len(report["notes"]) == 2
    assert all("kept" in note for note in report["notes"])
    assert np.hypot(localised["x"] - x, localised["y"] - y) < 0.03
    assert f"located in the map at ({localised['x']:.2f}, {localised['y']:.2f}) m" \
        in capsys.readouterr().out


def test_the_map_command_localises_only_in_a_map_given_by_resume(tmp_path, capsys):
    assert main(["map", str(tmp_path), "--out", str(tmp_path / "map"), "--localise"]) == 1
    assert "--resume" in capsys.readouterr().err


@pytest.mark.parametrize("hint, message", [("1,2", "X,Y,YAW"), ("1,nan,0", "finite")])
def test_the_map_command_rejects_a_hint_that_is_not_a_pose(hint, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exited:
        main(["map", str(tmp_path), "--out", str(tmp_path / "map"), "--resume", "map.npz",
              "--hint", hint])
    assert exited.value.code == 2 and message in capsys.readouterr().err
