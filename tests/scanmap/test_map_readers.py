"""Map files as standard readers read them: ROS 1 map_server and Nav2's map_server (before
and after ros-navigation/navigation2 PR #5278) load our trinary maps with the states we
wrote. The reader here is the textbook rule, implemented independently of scanmap."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from scanmap.io.map_files import load_ros_map, save_ros_map
from scanmap_driver.errors import MapError

UNKNOWN, FREE, OCCUPIED = -1, 0, 100

# (strict comparisons as map_server, or inclusive ones as a careless reader) x precision
READERS = [(strict, dtype) for strict in (True, False) for dtype in (np.float64, np.float32)]


def map_server_read(yaml_path: Path, strict: bool = True,
                    dtype: type[np.floating] = np.float64) -> np.ndarray:
    """States (-1, 0, 100; row 0 = lowest y) by the map_server rule: occ = (255 - p) / 255,
    occupied if occ > occupied_thresh, else free if occ < free_thresh, else unknown."""
    meta = yaml.safe_load(yaml_path.read_text())
    assert meta["mode"] == "trinary" and meta["negate"] == 0
    shade = cv2.imread(str(yaml_path.parent / meta["image"]), cv2.IMREAD_UNCHANGED)
    occ = (dtype(255) - shade.astype(dtype)) / dtype(255)
    free, occupied = dtype(meta["free_thresh"]), dtype(meta["occupied_thresh"])
    above, below = (np.greater, np.less) if strict else (np.greater_equal, np.less_equal)
    state = np.where(above(occ, occupied), OCCUPIED, np.where(below(occ, free), FREE, UNKNOWN))
    return state[::-1]


def written_states(occupancy: np.ndarray, free_thresh: float,
                   occupied_thresh: float) -> np.ndarray:
    """What the map_saver rule makes of occupancy values (percent, -1 unknown): free up to
    free_thresh, occupied from occupied_thresh (it wins when the two meet), else unknown."""
    v = occupancy.astype(np.int64)
    known = (v >= 0) & (v <= 100)
    state = np.where(known & (v <= round(free_thresh * 100)), FREE, UNKNOWN)
    return np.where(known & (v >= round(occupied_thresh * 100)), OCCUPIED, state)


EVERY_VALUE = np.arange(-128, 128, dtype=np.int8).reshape(16, 16)


@pytest.mark.parametrize("strict, dtype", READERS)
def test_every_reader_loads_every_written_state(tmp_path, strict, dtype):
    save_ros_map(tmp_path / "map.yaml", EVERY_VALUE, 0.05, (0.0, 0.0))
    expected = written_states(EVERY_VALUE, 0.25, 0.65)
    assert {UNKNOWN, FREE, OCCUPIED} <= set(np.unique(expected))
    np.testing.assert_array_equal(map_server_read(tmp_path / "map.yaml", strict, dtype),
                                  expected)


@settings(max_examples=60, deadline=None)
@given(occupancy=hnp.arrays(np.int8, st.tuples(st.integers(1, 6), st.integers(1, 6))),
       free=st.floats(0.0, 1.0), occupied=st.floats(0.0, 1.0))
def test_any_thresholds_write_a_map_every_reader_reads_right(tmp_path_factory, occupancy,
                                                              free, occupied):
    assume(free < occupied)
    path = tmp_path_factory.mktemp("map") / "map.yaml"
    save_ros_map(path, occupancy, 0.1, (1.0, -2.0), occupied_thresh=occupied,
                 free_thresh=free)
    expected = written_states(occupancy, free, occupied)
    for strict, dtype in READERS:
        np.testing.assert_array_equal(map_server_read(path, strict, dtype), expected)
    np.testing.assert_array_equal(load_ros_map(path).data, expected)


def test_our_reader_follows_map_server_on_a_legacy_map(tmp_path):
    """A map saved with free_thresh 0.25 (Nav2 before the fix): map_server reads its unknown
    shade as free, and so does our reader - no special case hides what planners see."""
    image = np.array([[0, 205, 254], [100, 128, 255]], np.uint8)
    cv2.imwrite(str(tmp_path / "old.pgm"), image)
    (tmp_path / "old.yaml").write_text(
        "image: old.pgm\nmode: trinary\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    expected = map_server_read(tmp_path / "old.yaml")
    assert expected[1, 1] == FREE  # 205 -> occ 0.196 < 0.25
    np.testing.assert_array_equal(load_ros_map(tmp_path / "old.yaml").data, expected)


def test_non_integer_occupancy_is_refused(tmp_path):
    with pytest.raises(MapError, match="integer"):
        save_ros_map(tmp_path / "m.yaml", np.array([[np.nan, 0.0]]), 0.05, (0.0, 0.0))
