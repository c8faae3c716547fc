"""Fuzzed simulator scene JSON (`load_scene`): SceneError naming the file, or a scene whose
every value is finite and which reads back as itself."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.errors import SceneError
from scanmap_driver.sim.scene import Scene, builtin_scene, load_scene

from .mutations import FUZZ, finite_json, mutated_json, read_within, sweep_json_reader

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
    sweep_json_reader(ORIGINAL, Scene.from_dict, SceneError, first_of_lists=True)
