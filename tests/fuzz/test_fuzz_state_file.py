"""Fuzzed mapper state files (`load_state`): MapError naming the file, or a state whose
trajectory and points are the file's values exactly (numpy's reading is the truth).

The mapper's own arrays are mutated here; the grid's (read by `map_files.load_map`) in
test_fuzz_map_files.py."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scanmap.grid.height_grid import HeightGrid
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.state_file import MapperState, load_state, save_state
from scanmap_driver.errors import MapError
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.transforms import se2_to_pose

from .mutations import FUZZ, mutated_npz, read_within

MAPPER_PREFIXES = ("mapper_", "scanner", "trajectory_", "resume_", "points", "point_colors",
                   "loop_closure_")


@pytest.fixture(scope="module")
def original(tmp_path_factory) -> dict[str, np.ndarray]:
    """The arrays of a small state: three scans, a few surface points, one wall."""
    rng = np.random.default_rng(5)
    config = MapperConfig()
    grid = HeightGrid(config.grid)
    wall = np.column_stack([np.full(50, 1.5), np.linspace(-1, 1, 50), np.full(50, 0.4)])
    grid.insert(wall, np.zeros((50, 3)), 1.0)
    poses = np.array([se2_to_pose(0.1 * i, 0.0, 0.05 * i) for i in range(3)])
    state = MapperState(grid=grid, config=config, model=reference_scanner(),
                        stamps=np.array([1.0, 2.0, 3.0]), poses=poses, index=np.arange(3),
                        status=np.array(["fused"] * 3), odometry=poses,
                        resume_points=rng.normal(size=(10, 3)), resume_sigma=np.full(10, 0.01),
                        points=rng.normal(size=(20, 3)),
                        point_colors=rng.integers(0, 256, (20, 3), dtype=np.uint8))
    path = tmp_path_factory.mktemp("state") / "map.npz"
    save_state(path, state)
    with np.load(path) as npz:
        return {key: npz[key] for key in npz.files}


@FUZZ
@given(data=st.data())
def test_fuzzed_state_file_is_refused_or_read_as_stored(original, tmp_path_factory, data):
    path = tmp_path_factory.mktemp("fuzz") / "map.npz"
    mapper_keys = [key for key in original if key.startswith(MAPPER_PREFIXES)]
    path.write_bytes(data.draw(mutated_npz(original, mapper_keys)))
    state = read_within(lambda: load_state(path), MapError, path)
    if state is None:
        return
    with np.load(path) as npz:
        for name in ("stamps", "poses", "index", "odometry"):
            stored = npz[f"trajectory_{name}"]
            assert stored.dtype.kind in "iuf" and np.isfinite(stored).all()
            assert np.array_equal(getattr(state, name), stored)
        for name in ("points", "point_colors", "resume_points", "resume_sigma"):
            stored = npz[name]
            assert stored.dtype.kind in "iuf" and np.isfinite(stored).all()
            assert np.array_equal(getattr(state, name), stored)
