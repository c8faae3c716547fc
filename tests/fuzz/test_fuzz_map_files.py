"""Fuzzed map files: map_server YAML + PGM (`load_ros_map`, `read_pgm`) and the full map
.npz (`load_map`). MapError naming the file, or a map whose values are the stored ones:
occupancy in -1..100, a finite resolution > 0 and origin."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scanmap.grid.height_grid import HeightGrid
from scanmap.io.map_files import load_map, load_ros_map, save_map, save_ros_map
from scanmap_driver.errors import MapError

from .mutations import FUZZ, every_npz_mutation, mutated_bytes, mutated_npz, read_within


@pytest.fixture(scope="module")
def ros_map(tmp_path_factory):
    """(yaml text, pgm bytes) of a 30 x 20 map with free, occupied and unknown cells."""
    occupancy = np.full((20, 30), -1, np.int8)
    occupancy[2:18, 2:28] = 0
    occupancy[10, 5:25] = 100
    occupancy[12, 5:25] = 50
    yaml = save_ros_map(tmp_path_factory.mktemp("ros") / "map.yaml", occupancy, 0.05,
                        (-1.0, -0.5, 0.0)).with_suffix(".yaml")
    return yaml.read_text(), yaml.with_suffix(".pgm").read_bytes()


@pytest.fixture(scope="module")
def full_map(tmp_path_factory) -> dict[str, np.ndarray]:
    grid = HeightGrid()
    wall = np.column_stack([np.full(60, 1.5), np.linspace(-1, 1, 60), np.full(60, 0.4)])
    grid.insert(wall, np.zeros((60, 3)), 1.0)
    path = tmp_path_factory.mktemp("map") / "map.npz"
    save_map(path, grid)
    with np.load(path) as npz:
        return {key: npz[key] for key in npz.files}


def check_ros_map(folder) -> None:
    path = folder / "map.yaml"
    ros = read_within(lambda: load_ros_map(path), MapError, folder)
    if ros is not None:
        assert ros.data.dtype == np.int8 and ((ros.data >= -1) & (ros.data <= 100)).all()
        assert np.isfinite(ros.resolution) and ros.resolution > 0
        assert np.isfinite(ros.origin).all()


@FUZZ
@given(data=st.data())
def test_fuzzed_map_yaml_is_refused_or_read(ros_map, tmp_path_factory, data):
    yaml, pgm = ros_map
    folder = tmp_path_factory.mktemp("fuzz")
    (folder / "map.yaml").write_bytes(data.draw(mutated_bytes(yaml.encode())))
    (folder / "map.pgm").write_bytes(pgm)
    check_ros_map(folder)


@FUZZ
@given(data=st.data())
def test_fuzzed_pgm_is_refused_or_read(ros_map, tmp_path_factory, data):
    yaml, pgm = ros_map
    folder = tmp_path_factory.mktemp("fuzz")
    (folder / "map.yaml").write_text(yaml)
    (folder / "map.pgm").write_bytes(data.draw(mutated_bytes(pgm)))
    check_ros_map(folder)


@FUZZ
@given(data=st.data())
def test_fuzzed_full_map_is_refused_or_read(full_map, tmp_path_factory, data):
    path = tmp_path_factory.mktemp("fuzz") / "map.npz"
    path.write_bytes(data.draw(mutated_npz(full_map)))
    saved = read_within(lambda: load_map(path), MapError, path)
    if saved is not None:
        with np.load(path) as npz:
            assert npz["resolution"].dtype.kind == "f"
            assert saved.grid.config.resolution == float(npz["resolution"])


@pytest.mark.parametrize(("field", "value"), [
    ("negate", "2"), ("occupied_thresh", "2"), ("free_thresh", "0.9"),
    ("resolution", "nan"), ("resolution", "-1"), ("origin", "[.nan, 0, 0]"),
])
def test_hostile_yaml_field_is_refused(ros_map, tmp_path, field, value):
    yaml, pgm = ros_map
    lines = [f"{field}: {value}" if line.startswith(f"{field}:") else line
             for line in yaml.splitlines()]
    (tmp_path / "map.yaml").write_text("\n".join(lines) + "\n")
    (tmp_path / "map.pgm").write_bytes(pgm)
    with pytest.raises(MapError, match=field):
        load_ros_map(tmp_path / "map.yaml")


def test_ascii_pgm_with_a_non_integer_pixel_is_refused(ros_map, tmp_path):
    (tmp_path / "map.yaml").write_text(ros_map[0])
    (tmp_path / "map.pgm").write_bytes(b"P2\n30 20\n255\n" + b"254 " * 599 + b"1e3\n")
    with pytest.raises(MapError, match=r"map\.pgm"):
        load_ros_map(tmp_path / "map.yaml")


def test_every_full_map_array_deleted_or_hostile_is_refused_or_read(full_map, tmp_path):
    path = tmp_path / "map.npz"
    for _, data in every_npz_mutation(full_map):
        path.write_bytes(data)
        read_within(lambda: load_map(path), MapError, path)
