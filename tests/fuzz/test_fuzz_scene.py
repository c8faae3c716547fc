"""Fuzzed simulator scene JSON (`load_scene`): SceneError naming the file, or a scene whose
every value is finite and which reads back as itself."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.errors import SceneError
from scanmap_driver.sim.scene import Scene, builtin_scene, load_scene

from .mutations import FUZZ, every_json_mutation, finite_json, mutated_json, read_within

ORIGINAL = builtin_scene("office").to_dict()


@FUZZ
@given(data=st.data())
def test_fuzzed_scene_file_is_refused_or_read_whole(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("scene") / "scene.json"
    path.write_text(data.draw(mutated_json(ORIGINAL)))
    scene = read_within(lambda: load_scene(path), SceneError, path)
    if scene is None:
        return
    again = Scene.from_dict(finite_json(scene.to_dict()))
    assert again.to_dict() == scene.to_dict()


def test_every_field_deleted_or_hostile_is_refused_or_kept_as_written():
    for path, tree in every_json_mutation(ORIGINAL):
        if any(isinstance(key, int) and key > 0 for key in path[:-1]):
            continue  # the first of each list stands for the others
        try:
            value = Scene.from_dict(tree, source="sweep.json")
        except SceneError as exc:
            assert "sweep.json" in str(exc)
            continue
        written = finite_json(value.to_dict())
        for key in path[:-1]:
            written, tree = written[key], tree[key]
        kept = path[-1] in tree and path[-1] in written  # to_dict leaves out defaults
        if kept and not isinstance(tree[path[-1]], dict):
            assert written[path[-1]] == tree[path[-1]], path
