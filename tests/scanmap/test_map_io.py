"""Map files: ROS map_server YAML + PGM both ways, the full-map .npz, corrupt files."""

from __future__ import annotations

import threading
import zipfile

import cv2
import numpy as np
import pytest

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.io.map_files import load_map, load_ros_map, read_pgm, save_map, save_ros_map
from scanmap_driver.errors import MapError

from . import scenes as S


def test_ros_map_round_trip_with_map_saver_thresholds(tmp_path):
    occupancy = np.array([[-1, 0, 20, 25, 30], [64, 65, 100, 0, -1]], np.int8)
    pgm = save_ros_map(tmp_path / "map.yaml", occupancy, 0.05, (-1.5, 2.0))
    loaded = load_ros_map(tmp_path / "map.yaml")
    np.testing.assert_array_equal(loaded.data, [[-1, 0, 0, 0, -1], [-1, 100, 100, 0, -1]])
    assert loaded.resolution == 0.05 and loaded.origin == (-1.5, 2.0, 0.0)
    image = cv2.imread(str(pgm), cv2.IMREAD_UNCHANGED)  # an independent PGM reader
    np.testing.assert_array_equal(image, [[205, 0, 0, 254, 205], [205, 254, 254, 254, 205]])


def test_origin_is_the_lower_left_pixel(tmp_path):
    occupancy = np.zeros((3, 4), np.int8)
    occupancy[0, 0] = 100  # row 0 is the lowest y: the bottom-left pixel of the image
    pgm = save_ros_map(tmp_path / "m.yaml", occupancy, 0.1, (5.0, 6.0))
    image = cv2.imread(str(pgm), cv2.IMREAD_UNCHANGED)
    assert image[-1, 0] == 0 and (image[:-1] == 254).all()
    assert load_ros_map(tmp_path / "m.yaml").data[0, 0] == 100
    assert "origin: [5.0, 6.0, 0.0]" in (tmp_path / "m.yaml").read_text()


def test_reads_a_hand_written_map_server_map(tmp_path):
    (tmp_path / "lab.pgm").write_text("P2\n# a comment\n3 2\n255\n0 205 254\n100 128 255\n")
    (tmp_path / "lab.yaml").write_text(
        "# map_server metadata\nimage: 'lab.pgm'\nresolution: 0.1\n"
        "origin: [1.0, -2.0, 0.5]  # yaw is kept\nnegate: 0\noccupied_thresh: 0.65\n"
        "free_thresh: 0.196\nmode: trinary\n")
    m = load_ros_map(tmp_path / "lab.yaml")
    # Bottom image row first: 100 -> occ 0.61 unknown, 128 -> 0.498 unknown, 255 -> free.
    np.testing.assert_array_equal(m.data, [[-1, -1, 0], [100, -1, 0]])
    assert m.origin == (1.0, -2.0, 0.5)


@pytest.mark.parametrize("text, match", [
    ("P5\n3 2\n255\n\x00\x00", "truncated"),
    ("P6\n3 2\n255\n", "not a PGM"),
    ("P5\n3", "truncated PGM header"),
    ("P2\n2 2\n255\n1 2 3", "truncated"),
])
def test_a_corrupt_pgm_is_a_clear_error(tmp_path, text, match):
    path = tmp_path / "bad.pgm"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(MapError, match=match):
        read_pgm(path)


THRESHOLDS = "occupied_thresh: 0.65\nfree_thresh: 0.196\n"


@pytest.mark.parametrize("yaml, match", [
    ("resolution: 0.1\norigin: [0, 0, 0]\n", "missing field image"),
    ("image: x.pgm\norigin: [0, 0, 0]\n", "missing field resolution"),
    ("image: x.pgm\nresolution: 0.1\norigin: [0, 0]\n", "origin"),
    ("image: x.pgm\nresolution: fast\norigin: [0, 0, 0]\n", "resolution must be a number"),
    ("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", "missing field occupied_thresh"),
    ("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.65\n",
     "missing field free_thresh"),
    ("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: raw\n" + THRESHOLDS, "mode"),
    ("just words\n", "key: value"),
    ("image: missing.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n" + THRESHOLDS, "cannot read"),
])
def test_a_bad_map_yaml_names_the_field(tmp_path, yaml, match):
    (tmp_path / "x.pgm").write_bytes(b"P5\n1 1\n255\n\xfe")
    (tmp_path / "m.yaml").write_text(yaml)
    with pytest.raises(MapError, match=match):
        load_ros_map(tmp_path / "m.yaml")


@pytest.fixture(scope="module")
def mapped_grid():
    grid = HeightGrid(GridConfig(extent=50.0))
    S.map_scene(S.furnished_room(), S.ROOM_POSES[:3], grid)
    return grid


def test_full_map_round_trip_keeps_every_layer(tmp_path, mapped_grid):
    layers = {"state": np.arange(12, dtype=np.uint8).reshape(3, 4)}
    save_map(tmp_path / "map.npz", mapped_grid, layers, origin=(-3.1, -3.1))
    saved = load_map(tmp_path / "map.npz")
    bounds = (-3.1, -3.1, 3.1, 3.1)
    before, after = mapped_grid.layers(bounds), saved.grid.layers(bounds)
    for name in ("levels", "counts", "nlev", "seen", "updated", "stood", "seen_from"):
        np.testing.assert_array_equal(getattr(before, name), getattr(after, name))
    assert np.isfinite(after.seen_from).any()
    assert len(after.stood) == 3  # one place per scan: known floor, as before saving
    np.testing.assert_array_equal(saved.layers["state"], layers["state"])
    assert saved.origin == (-3.1, -3.1) and saved.grid.config == mapped_grid.config
    assert saved.grid.stamp == mapped_grid.stamp
    more = np.array([[1.0, 1.0, 0.3]])  # and mapping goes on in the loaded grid
    assert saved.grid.insert(more, np.zeros(3) + [0, 0, 1.0], 99.0).inserted == 1


def test_a_map_written_before_it_kept_where_the_robot_stood_loads_without_it(
        tmp_path, mapped_grid):
    """`stood` is optional: older version-3 files load with no place known stood on;
    one that is not (M, 2) finite x, y is refused, naming the field."""
    path = tmp_path / "map.npz"
    save_map(path, mapped_grid)
    arrays = dict(np.load(path, allow_pickle=False))
    np.savez(tmp_path / "old.npz", **{k: v for k, v in arrays.items() if k != "stood"})
    old = load_map(tmp_path / "old.npz").grid
    assert old.layers((-3.1, -3.1, 3.1, 3.1)).stood.shape == (0, 2)
    np.testing.assert_array_equal(old.state()["lev_f"], arrays["lev_f"])
    for bad in (arrays["stood"][:, :1], np.full((2, 2), np.nan)):
        np.savez(tmp_path / "bad.npz", **{**arrays, "stood": bad})
        with pytest.raises(MapError, match=r"bad\.npz: stood"):
            load_map(tmp_path / "bad.npz")


def older_map(tmp_path, grid: HeightGrid, version: int, array: str, column: int):
    """`grid` written as a map file of format `version`, from before `array` held
    `column` (of its last axis)."""
    path = tmp_path / "map.npz"
    save_map(path, grid)
    arrays = dict(np.load(path, allow_pickle=False))
    arrays["format_version"] = np.array(version)
    arrays[array] = np.delete(arrays[array], column, axis=-1)
    np.savez(tmp_path / f"v{version}.npz", **arrays)
    return tmp_path / f"v{version}.npz"


def test_a_version_1_map_loads_with_no_scans_counted(tmp_path, mapped_grid):
    """Maps written before the level record counted its scans still load; their levels
    count none, every other layer is as saved."""
    new = mapped_grid.state()
    assert new["lev_n"][..., gk.SCANS].max() >= 1  # the mapped grid counted scans
    old = load_map(older_map(tmp_path, mapped_grid, 1, "lev_n", gk.SCANS)).grid.state()
    assert (old["lev_n"][..., gk.SCANS] == 0).all()
    np.testing.assert_array_equal(np.delete(old["lev_n"], gk.SCANS, axis=-1),
                                  np.delete(new["lev_n"], gk.SCANS, axis=-1))
    for name in ("lev_f", "nlev", "cells", "tile_coords"):
        np.testing.assert_array_equal(old[name], new[name])


def test_a_version_3_map_loads_with_its_levels_mean_heights_at_their_middles(tmp_path,
                                                                            mapped_grid):
    """Maps written before the level record kept its mean hit's height still load: the
    middle of each level's heights stands in for it, every other layer as saved."""
    old = load_map(older_map(tmp_path, mapped_grid, 3, "lev_f", gk.MZ)).grid.state()
    new = mapped_grid.state()
    levels = old["lev_f"]
    np.testing.assert_allclose(levels[..., gk.MZ], 0.5 * (levels[..., gk.LO] + levels[..., gk.HI]))
    np.testing.assert_array_equal(np.delete(levels, gk.MZ, axis=-1),
                                  np.delete(new["lev_f"], gk.MZ, axis=-1))
    for name in ("lev_n", "nlev", "cells", "tile_coords"):
        np.testing.assert_array_equal(old[name], new[name])


def test_a_version_4_map_loads_with_no_cell_known_seen_from_anywhere(tmp_path, mapped_grid):
    """Maps written before the cells kept where their lowest level was seen from still
    load: none is known (a drop-off then keeps to where the robot stood), every other
    layer as saved."""
    old = load_map(older_map(tmp_path, mapped_grid, 4, "cells", gk.FROM)).grid
    assert (old.state()["cells"][..., gk.FROM] == 0).all()
    bounds = (-3.1, -3.1, 3.1, 3.1)
    before, after = mapped_grid.layers(bounds), old.layers(bounds)
    assert np.isnan(after.seen_from).all() and np.isfinite(before.seen_from).any()
    for name in ("levels", "counts", "nlev", "seen", "updated", "stood", "unlit"):
        np.testing.assert_array_equal(getattr(before, name), getattr(after, name))


def test_corrupt_or_truncated_full_map_is_a_clear_error(tmp_path, mapped_grid):
    path = tmp_path / "map.npz"
    save_map(path, mapped_grid)
    data = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "junk.npz").write_bytes(b"not a zip at all")
    for name in ("cut.npz", "junk.npz", "absent.npz"):
        with pytest.raises(MapError, match=name):
            load_map(tmp_path / name)
    arrays = dict(np.load(path, allow_pickle=False))
    arrays["nlev"] = arrays["nlev"][:, :5]
    np.savez(tmp_path / "shape.npz", **arrays)
    with pytest.raises(MapError, match="nlev"):
        load_map(tmp_path / "shape.npz")
    arrays = dict(np.load(path, allow_pickle=False))
    arrays["format_version"] = np.array(7)
    np.savez(tmp_path / "version.npz", **arrays)
    with pytest.raises(MapError, match="format_version"):
        load_map(tmp_path / "version.npz")
    arrays = dict(np.load(path, allow_pickle=False))
    arrays["config"] = np.array('{"resolution": -1}')
    np.savez(tmp_path / "config.npz", **arrays)
    with pytest.raises(MapError, match="resolution"):
        load_map(tmp_path / "config.npz")


def test_a_map_saved_while_being_updated_is_whole(tmp_path):
    scene = S.furnished_room()
    grid = HeightGrid(GridConfig(extent=50.0))
    S.map_scene(scene, S.ROOM_POSES[:1], grid)
    done = threading.Event()

    def mapper() -> None:
        try:
            S.map_scene(scene, S.ROOM_POSES[1:5], grid, seed=1, first_stamp=1.0)
        finally:
            done.set()

    thread = threading.Thread(target=mapper)
    thread.start()
    saves = 0
    while not done.is_set() or saves < 2:
        save_map(tmp_path / "live.npz", grid)
        saved = load_map(tmp_path / "live.npz")  # whole and self-consistent
        assert zipfile.is_zipfile(tmp_path / "live.npz")
        layers = saved.grid.layers((-3.1, -3.1, 3.1, 3.1))
        assert np.isfinite(layers.updated[layers.nlev > 0]).all()
        saves += 1
    thread.join()
    assert not list(tmp_path.glob(".live.npz.*"))  # no temporary file left behind
