"""Fuzzed TUM trajectories (`read_tum`): MapError naming the file, or poses that are
finite rigid transforms at the file's times."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from scanmap.io.trajectory import Trajectory, read_tum, write_tum
from scanmap_driver.errors import MapError
from scanmap_driver.transforms import se2_to_pose

from .mutations import FUZZ, mutated_bytes, read_within


def _original(folder) -> bytes:
    poses = np.array([se2_to_pose(0.1 * i, -0.05 * i, 0.2 * i) for i in range(12)])
    path = folder / "original.txt"
    write_tum(path, Trajectory(np.arange(12) * 0.5, poses))
    return path.read_bytes()


@FUZZ
@given(data=st.data())
def test_fuzzed_tum_file_is_refused_or_read_as_rigid_poses(tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("tum")
    path = folder / "trajectory.txt"
    path.write_bytes(data.draw(mutated_bytes(_original(folder))))
    trajectory = read_within(lambda: read_tum(path), MapError, path)
    if trajectory is None:
        return
    rows = [line.split("#")[0].replace(",", " ").split() for line in path.read_text().splitlines()]
    rows = [r for r in rows if r]
    assert len(trajectory.times) == len(rows)
    assert np.array_equal(trajectory.times, [float(r[0]) for r in rows])
    rotations = trajectory.poses[:, :3, :3]
    assert np.isfinite(trajectory.poses).all()
    assert np.allclose(rotations @ rotations.transpose(0, 2, 1), np.eye(3), atol=1e-2)
