"""Scenes: the scanmap.scene/1 format, validation naming the field, the built-in scenes."""

from __future__ import annotations

import copy
import functools
import json
import math
import operator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap_driver.errors import SceneError
from scanmap_driver.sim.ideal import ideal_scans
from scanmap_driver.sim.scene import (
    FORMAT,
    Box,
    Cylinder,
    Scene,
    builtin_scene,
    builtin_scene_names,
    load_scene,
    resolve_scene,
)

DESIGN_EXAMPLE = {
    "format": "scanmap.scene/1",
    "name": "office",
    "floor": {"color": [120, 110, 100]},
    "ambient": 0.6,
    "objects": [
        {"type": "box", "center": [2.0, 0.0, 0.5], "size": [0.1, 6.0, 1.0], "yaw": 0.0,
         "color": [200, 200, 190]},
        {"type": "box", "center": [1.0, -1.0, 0.72], "size": [1.2, 0.6, 0.04], "yaw": 0.3,
         "color": [150, 90, 40]},
        {"type": "cylinder", "center": [1.0, 1.0, 0.2], "radius": 0.05, "height": 0.4,
         "color": [30, 30, 30]},
    ],
    "scan_poses": [[0.0, 0.0, 0.0], [0.3, 0.0, 0.05]],
}


def test_the_design_example_loads():
    scene = Scene.from_dict(DESIGN_EXAMPLE)
    assert scene.name == "office" and scene.ambient == 0.6
    assert isinstance(scene.objects[1], Box) and scene.objects[1].yaw == 0.3
    assert isinstance(scene.objects[2], Cylinder) and scene.objects[2].radius == 0.05
    np.testing.assert_array_equal(scene.scan_poses, [[0, 0, 0], [0.3, 0, 0.05]])


@pytest.mark.parametrize("name", ["corridor", "office"])
def test_builtin_scenes_round_trip_through_json(name, tmp_path):
    scene = builtin_scene(name)
    scene.save(tmp_path / "s.json")
    again = load_scene(tmp_path / "s.json")
    assert again.to_dict() == scene.to_dict()
    assert json.loads((tmp_path / "s.json").read_text())["format"] == FORMAT


def _mutated(path, value):
    data = copy.deepcopy(DESIGN_EXAMPLE)
    parent = functools.reduce(operator.getitem, path[:-1], data)
    if value is KeyError:
        parent.pop(path[-1])
    else:
        parent[path[-1]] = value
    return data


@pytest.mark.parametrize(("path", "value", "message"), [
    (("colour",), 1, "unknown field(s) colour"),
    (("objects", 0, "material"), "wood", "objects[0]: unknown field(s) material"),
    (("objects", 1, "size"), [1.2, -0.6, 0.04], "objects[1].size[1]: expected > 0"),
    (("objects", 1, "size"), [1.2, 0.0, 0.04], "objects[1].size[1]: expected > 0"),
    (("objects", 2, "radius"), -0.05, "objects[2].radius: expected > 0"),
    (("objects", 2, "height"), float("nan"), "objects[2].height: expected a finite number"),
    (("objects", 0, "center"), [2.0, float("nan"), 0.5], "objects[0].center[1]"),
    (("objects", 0, "color"), [300, 0, 0], "objects[0].color"),
    (("objects", 0, "type"), "sphere", "objects[0].type"),
    (("scan_poses",), [], "scan_poses: expected a non-empty list"),
    (("scan_poses",), KeyError, "missing field(s) scan_poses"),
    (("scan_poses", 1), [0.3, 0.0], "scan_poses[1]: expected a list of 3"),
    (("ambient",), 1.5, "ambient: expected <= 1.0"),
    (("ambient",), float("inf"), "ambient: expected a finite number"),
    (("format",), "scanmap.scene/2", "format: expected 'scanmap.scene/1'"),
    (("floor", "texture"), 1, "floor: unknown field(s) texture"),
    (("motion",), {"speed": 0.1, "yaw": 0.0}, "motion: unknown field(s) yaw"),
    (("odometry",), {"distance_sigma": -0.1}, "odometry.distance_sigma: expected >= 0.0"),
])
def test_bad_scenes_fail_naming_the_field(path, value, message, tmp_path):
    bad = tmp_path / "bad.json"
    # json.dumps writes NaN/Infinity, which json.loads reads back: the file path is real.
    bad.write_text(json.dumps(_mutated(path, value)))
    with pytest.raises(SceneError) as info:
        load_scene(bad)
    assert message in str(info.value)
    assert str(bad) in str(info.value)


def test_not_json_and_missing_file_name_the_file(tmp_path):
    broken = tmp_path / "broken.json"
    broken.write_text("{\"format\": ")
    with pytest.raises(SceneError, match=r"broken\.json: not valid JSON"):
        load_scene(broken)
    with pytest.raises(SceneError, match=r"nope\.json: file not found"):
        load_scene(tmp_path / "nope.json")


def test_resolve_scene_by_name_or_path(tmp_path):
    assert resolve_scene("office").name == "office"
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(DESIGN_EXAMPLE))
    assert resolve_scene(path).name == "office"
    with pytest.raises(SceneError, match="neither a scene file nor a built-in scene"):
        resolve_scene("atlantis")
    with pytest.raises(SceneError, match="unknown built-in scene"):
        builtin_scene("atlantis")


def test_builtin_corridor_matches_the_issue():
    scene = builtin_scene("corridor")
    assert set(builtin_scene_names()) >= {"corridor", "office"}
    low, high = scene.bounds()
    assert high[0] - low[0] == pytest.approx(23.2, abs=0.5)  # about 20 m of corridor
    walls = [o for o in scene.objects if isinstance(o, Box) and "wall" in o.name
             and o.size[0] > 5.0]
    inner = sorted({round(abs(o.center[1]) - o.size[1] / 2, 6) for o in walls})
    assert inner == [0.75]  # 1.5 m wide
    assert any("recess" in o.name for o in scene.objects)
    steps = np.hypot(*np.diff(scene.scan_poses[:, :2], axis=0).T)
    assert np.all((steps >= 0.3) & (steps <= 0.5))


def test_builtin_office_matches_the_issue():
    scene = builtin_scene("office")
    names = [o.name for o in scene.objects]
    table = scene.objects[names.index("table top")]
    assert table.center[2] - table.size[2] / 2 > 0.5  # an overhang
    assert sum(n == "chair leg" for n in names) >= 4
    step = scene.objects[names.index("low step")]
    assert step.center[2] + step.size[2] / 2 < 0.05  # below the default step height
    reds = [o for o in scene.objects if o.color[0] > 190 and max(o.color[1:]) < 40]
    assert len(reds) >= 2
    steps = np.hypot(*np.diff(scene.scan_poses[:, :2], axis=0).T)
    assert np.all((steps >= 0.3) & (steps <= 0.5))


def test_scan_poses_keep_the_robot_clear_of_objects():
    """A robot of 0.25 m radius at each scan pose touches no object's footprint."""
    from scanmap_driver.sim.scene import footprint_corners

    for name in builtin_scene_names():
        scene = builtin_scene(name)
        for x, y, _ in scene.scan_poses:
            for obj in scene.objects:
                if obj.center[2] - (obj.size[2] if isinstance(obj, Box) else obj.height) / 2 \
                        > 1.0:
                    continue
                if isinstance(obj, Cylinder):
                    gap = math.hypot(x - obj.center[0], y - obj.center[1]) - obj.radius
                else:
                    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
                    dx, dy = x - obj.center[0], y - obj.center[1]
                    lx, ly = abs(c * dx + s * dy), abs(-s * dx + c * dy)
                    ex, ey = max(lx - obj.size[0] / 2, 0), max(ly - obj.size[1] / 2, 0)
                    gap = math.hypot(ex, ey)
                low_step = isinstance(obj, Box) and obj.center[2] + obj.size[2] / 2 < 0.05
                assert low_step or gap > 0.25, (name, obj.name, x, y)
        assert footprint_corners(scene.objects[0]).shape == (4, 2)


@settings(max_examples=40, deadline=None)
@given(dx=st.floats(-50.0, 50.0), dy=st.floats(-50.0, 50.0), yaw=st.floats(-math.pi, math.pi),
       u=st.floats(0.0, 1.0), v=st.floats(0.0, 1.0))
def test_a_moved_scene_is_the_same_world(dx, dy, yaw, u, v):
    scene = builtin_scene("hazards")
    moved = scene.moved(dx, dy, yaw)
    low, high = scene.bounds()
    xy = low + np.array([u, v]) * (high - low)
    c, s = math.cos(yaw), math.sin(yaw)
    there = np.array([c * xy[0] - s * xy[1] + dx, s * xy[0] + c * xy[1] + dy])
    assert np.allclose(moved.floor_at(*there), scene.floor_at(*xy), atol=1e-9)
    assert np.allclose(moved.scan_poses[:, 2] - scene.scan_poses[:, 2], yaw)
    first = scene.scan_poses[0, :2]
    assert np.allclose(moved.scan_poses[0, :2],
                       [c * first[0] - s * first[1] + dx, s * first[0] + c * first[1] + dy])


def test_a_moved_scene_gives_the_same_scans():
    # The scanner sees the same world from the same place in it: the same points in its
    # own frame, wherever the world lies on the map (floor regions, a ramp, boxes)
    scene = builtin_scene("hazards")
    moved = scene.moved(0.013, -0.021, math.radians(33.0))
    for ours, theirs in zip(ideal_scans(scene, scans=2), ideal_scans(moved, scans=2),
                            strict=True):
        assert len(ours.true_points) > 10_000
        assert np.allclose(ours.true_points, theirs.true_points, atol=1e-6)


def test_a_moved_scene_moves_its_people():
    scene = builtin_scene("people")
    moved = scene.moved(1.0, -2.0, math.pi / 2)
    for index in (0.0, 2.5, 7.0):
        for ours, theirs in zip(scene.at_scan(index).objects, moved.at_scan(index).objects,
                                strict=True):
            x, y, z = ours.center
            assert np.allclose(theirs.center, (-y + 1.0, x - 2.0, z))


def _with_regions(*regions: dict) -> dict:
    return DESIGN_EXAMPLE | {"floor_regions": [
        {"height": -0.1, "color": [90, 90, 90]} | r for r in regions]}


@pytest.mark.parametrize("second", [
    {"center": [3.5, 0.5], "size": [1.0, 1.0]},  # corners inside the first
    {"center": [3.0, 0.0], "size": [0.4, 0.4], "yaw": 0.7},  # wholly inside, turned
    {"polygon": [[2.0, -1.0], [4.0, 1.0], [2.0, 1.0]]},  # a triangle across it
])
def test_overlapping_floor_regions_fail_naming_both(second, tmp_path):
    path = tmp_path / "overlap.json"
    path.write_text(json.dumps(_with_regions(
        {"center": [3.0, 0.0], "size": [2.0, 2.0], "name": "pit"}, second)))
    with pytest.raises(SceneError, match=r"floor_regions\[1\]: overlaps floor_regions\[0\] "
                       r"\(pit\)"):
        load_scene(path)


def test_floor_regions_may_share_an_edge_or_a_corner():
    scene = Scene.from_dict(_with_regions(
        {"center": [3.0, 0.0], "size": [2.0, 2.0]},
        {"center": [5.0, 0.0], "size": [2.0, 2.0]},  # along x = 4
        {"center": [5.0, 2.0], "size": [2.0, 2.0]},  # along y = 1 with the second
        {"center": [3.0, 2.0], "size": [2.0, 2.0]}))  # a corner with the second
    assert len(scene.floor_regions) == 4
